"""phi_rs.Dataset reads what `phi dataset generate` wrote; phi_rs.Model rolls out as `phi
rollout` does."""

import _thread
import json
import signal
import threading

import numpy as np
import pytest

import phi_rs


def test_dataset_metadata_and_lengths(dataset_dir):
    ds = phi_rs.Dataset(dataset_dir)
    on_disk = json.loads((dataset_dir / "metadata.json").read_text())
    assert ds.metadata["dim"] == on_disk["dim"] == 2
    assert ds.metadata["splits"] == on_disk["splits"]
    assert ds.metadata["sequence_length"] == 12
    assert ds.splits == ["train"]
    assert ds.len("train") == 2
    assert ds.len() == 2


def test_dataset_trajectories_equal_the_files(dataset_dir):
    ds = phi_rs.Dataset(dataset_dir)
    for i in range(ds.len("train")):
        positions, types = ds["train", i]
        with np.load(dataset_dir / "train" / f"traj_{i:05d}.npz") as npz:
            assert positions.dtype == np.float32
            assert types.dtype == np.int64
            assert positions.shape == (13, types.shape[0], 2)
            assert np.array_equal(positions, npz["position"])
            assert np.array_equal(types, npz["particle_type"])
    last, _ = ds["train", -1]
    assert np.array_equal(last, ds["train", 1][0])


def test_dataset_errors_name_the_problem(dataset_dir, tmp_path):
    ds = phi_rs.Dataset(dataset_dir)
    with pytest.raises(phi_rs.DatasetError, match="index 2 is out of range"):
        ds["train", 2]
    with pytest.raises(phi_rs.DatasetError, match="valid"):
        ds["valid", 0]
    with pytest.raises(phi_rs.DatasetError, match="nothing-here"):
        phi_rs.Dataset(tmp_path / "nothing-here")


@pytest.fixture(scope="module")
def cli_rollout(phi, model_dir, dataset_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("rollout")
    phi("rollout", "--model", model_dir, "--data", dataset_dir, "--split", "train",
        "--trajectory", 0, "--steps", 5, "--out", out, "--frame-every", 0,
        "--backend", "ndarray")
    with np.load(out / "train_0" / "rollout.npz") as npz:
        return {key: npz[key] for key in npz.files}


def test_model_rollout_equals_cli_bit_for_bit(model_dir, dataset_dir, cli_rollout):
    model = phi_rs.Model.load(model_dir)
    assert model.dim == 2
    assert model.input_velocities == 2
    assert model.spec_dict["config"]["input_velocities"] == 2
    positions, types = phi_rs.Dataset(dataset_dir)["train", 0]
    start = int(cli_rollout["start"][0])
    predicted = model.rollout(positions, types, steps=5, start=start)
    assert predicted.dtype == np.float32
    assert predicted.shape == cli_rollout["predicted_position"].shape
    assert np.array_equal(predicted, cli_rollout["predicted_position"])
    # Kinematic particles follow the ground truth.
    kinematic = types == 0
    if kinematic.any():
        assert np.array_equal(predicted[:, kinematic], positions[start + 1:start + 6, kinematic])


def test_model_rollout_to_the_end_by_default(model_dir, dataset_dir):
    model = phi_rs.Model.load(model_dir, backend="ndarray")
    positions, types = phi_rs.Dataset(dataset_dir)["train", 1]
    predicted = model.rollout(positions, types)
    assert predicted.shape == (positions.shape[0] - 3, positions.shape[1], 2)
    assert np.isfinite(predicted).all()


def test_model_errors(model_dir, dataset_dir, tmp_path):
    with pytest.raises(phi_rs.ModelError, match="no-model"):
        phi_rs.Model.load(tmp_path / "no-model")
    model = phi_rs.Model.load(model_dir)
    positions, types = phi_rs.Dataset(dataset_dir)["train", 0]
    with pytest.raises(phi_rs.ModelError, match=r"positions: shape \(.*\): expected \[T, N, d\]"):
        model.rollout(positions[0], types)
    with pytest.raises(phi_rs.ModelError, match="particle_type"):
        model.rollout(positions, types[:-1])
    with pytest.raises(phi_rs.ModelError, match="rollout steps"):
        model.rollout(positions, types, steps=100)


def test_len_counts_the_trajectories_of_every_split(dataset_dir):
    ds = phi_rs.Dataset(dataset_dir)
    assert len(ds) == sum(ds.len(split) for split in ds.splits) == 2


def test_windows_in_order_are_every_slice_of_the_trajectories(dataset_dir):
    ds = phi_rs.Dataset(dataset_dir)
    c = 5
    windows = ds.windows("train", input_velocities=c)
    frames = ds.metadata["sequence_length"] + 1
    assert len(windows) == 2 * (frames - c - 1)
    items = list(windows)
    assert len(items) == 2 * (frames - c - 1) and len(windows) == 0
    k = 0
    for i in range(2):
        positions, types = ds["train", i]
        for t in range(c, frames - 1):
            (window, window_types), target = items[k]
            assert window.dtype == np.float32 and target.dtype == np.float32
            assert window.shape == (c + 1, positions.shape[1], 2)
            assert np.array_equal(window, positions[t - c:t + 1])
            assert np.array_equal(target, positions[t + 1])
            assert np.array_equal(window_types, types)
            k += 1


def test_drawn_windows_are_the_trainers_deterministic_batches(dataset_dir):
    ds = phi_rs.Dataset(dataset_dir)
    every = list(ds.windows("train", input_velocities=2))
    drawn = ds.windows("train", input_velocities=2, seed=42, batch_size=3, steps=4)
    assert len(drawn) == 12
    items = list(drawn)
    assert len(items) == 12
    # Each draw is one of the valid windows, and the same seed draws the same ones.
    for (window, types), target in items:
        assert any(np.array_equal(window, w) and np.array_equal(target, y)
                   for (w, _), y in every)
    again = list(ds.windows("train", input_velocities=2, seed=42, batch_size=3, steps=4))
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(items, again))
    # A resumed run (start_step=2) sees the batches of steps 2 and 3 of an uninterrupted one.
    resumed = list(ds.windows("train", input_velocities=2, seed=42, batch_size=3,
                              start_step=2, steps=2))
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(items[6:], resumed))
    endless = ds.windows("train", input_velocities=2, seed=1)
    next(endless)
    with pytest.raises(TypeError, match="endless"):
        len(endless)


def test_windows_errors(dataset_dir):
    ds = phi_rs.Dataset(dataset_dir)
    with pytest.raises(phi_rs.DatasetError, match="valid"):
        ds.windows("valid")
    with pytest.raises(phi_rs.DatasetError, match="no window of 15 frames"):
        ds.windows("train", input_velocities=13)


INIT_OPTIONS = dict(latent=16, hidden=16, hidden_layers=1, message_passing_steps=2,
                    input_velocities=2, seed=3)


def test_model_init_equals_phi_model_init(model_dir, dataset_dir, tmp_path):
    model = phi_rs.Model.init(dataset_dir, **INIT_OPTIONS)
    assert model.dir is None
    cli = phi_rs.Model.load(model_dir)
    assert model.spec_dict["config"] == cli.spec_dict["config"]
    assert model.spec_dict["normalisation"] == cli.spec_dict["normalisation"]
    model.save(tmp_path / "m")
    assert ((tmp_path / "m" / "model.safetensors").read_bytes()
            == (model_dir / "model.safetensors").read_bytes())
    loaded = phi_rs.Model.load(tmp_path / "m")
    assert loaded.spec_dict["provenance"]["made_by"] == "phi_rs.Model.init"
    with pytest.raises(phi_rs.ModelError, match="overwrite=True"):
        model.save(tmp_path / "m")
    model.save(tmp_path / "m", overwrite=True)


def test_model_init_errors(dataset_dir, tmp_path):
    with pytest.raises(phi_rs.DatasetError, match="no-data"):
        phi_rs.Model.init(tmp_path / "no-data")
    with pytest.raises(phi_rs.ModelError, match="Model.init: latent"):
        phi_rs.Model.init(dataset_dir, latent=0)
    with pytest.raises(phi_rs.ModelError, match="Model.init: boundary_horizon"):
        phi_rs.Model.init(dataset_dir, boundary_horizon=0.0)


def test_model_init_boundary_horizon(dataset_dir):
    default = phi_rs.Model.init(dataset_dir, **INIT_OPTIONS)
    assert "boundary_horizon" not in default.spec_dict["config"]
    far = phi_rs.Model.init(dataset_dir, boundary_horizon=4.0, **INIT_OPTIONS)
    assert far.spec_dict["config"]["boundary_horizon"] == 4.0


def test_predict_is_the_first_step_of_rollout(model_dir, dataset_dir, cli_rollout):
    model = phi_rs.Model.load(model_dir)
    positions, types = phi_rs.Dataset(dataset_dir)["train", 0]
    c, start = model.input_velocities, int(cli_rollout["start"][0])
    window = positions[start - c:start + 1]
    predicted = model.predict(window, types, kinematic=positions[start + 1])
    assert predicted.dtype == np.float32 and predicted.shape == positions.shape[1:]
    assert np.array_equal(predicted, cli_rollout["predicted_position"][0])
    # Without kinematic positions the obstacles stay where the window leaves them.
    still = model.predict(window, types)
    liquid = types == 1
    assert np.array_equal(still[liquid], predicted[liquid])
    assert np.array_equal(still[~liquid], positions[start][~liquid])
    with pytest.raises(phi_rs.ModelError, match=r"window: shape .* the model reads \[3, N, 2\]"):
        model.predict(positions[:2], types)
    with pytest.raises(phi_rs.ModelError, match="particle_type"):
        model.predict(window, types[:-1])


def test_evaluate_agrees_with_rollout_and_the_metrics(model_dir, dataset_dir):
    model = phi_rs.Model.load(model_dir)
    positions, types = phi_rs.Dataset(dataset_dir)["train", 0]
    c, liquid = model.input_velocities, types == 1
    ev = model.evaluate(positions, types, short_rollout=5, sinkhorn_epsilon=1e-2,
                        sinkhorn_every=1)
    assert ev["start"] == c and ev["failed_step"] is None
    assert ev["liquid_particles"] == liquid.sum()
    # MSE 400 and its curve: the full rollout from frame C against the frames it predicts.
    predicted = model.rollout(positions, types)
    truth = positions[c + 1:]
    assert ev["mse400"] == pytest.approx(phi_rs.position_mse(predicted, truth, types), rel=1e-12)
    assert np.allclose(ev["curves"]["mse"], phi_rs.position_mse(predicted, truth, types,
                                                                per_frame=True), rtol=1e-12)
    # EMD and Sinkhorn divergence per frame over the liquid, averaged.
    emd = [phi_rs.emd(p[liquid], t[liquid]) for p, t in zip(predicted, truth)]
    assert ev["emd"] == pytest.approx(np.mean(emd), rel=1e-9)
    sinkhorn = [phi_rs.sinkhorn(p[liquid], t[liquid], epsilon=1e-2)
                for p, t in zip(predicted, truth)]
    assert ev["sinkhorn"] == pytest.approx(np.mean(sinkhorn), rel=1e-9)
    # MSE 20 (here 5): rollouts from frames C, C + 5, ... while 5 frames follow.
    starts = range(c, positions.shape[0] - 5, 5)
    short = [phi_rs.position_mse(model.rollout(positions, types, steps=5, start=s),
                                 positions[s + 1:s + 6], types) for s in starts]
    assert ev["short_windows"] == len(short)
    assert ev["mse20"] == pytest.approx(np.mean(short), rel=1e-12)
    with pytest.raises(phi_rs.ModelError, match="emd_cost"):
        model.evaluate(positions, types, emd_cost="manhattan")
    assert "plausibility" not in ev and "plausible" not in ev


def swept_left(positions, types, cells_per_frame):
    """The trajectory with its liquid carried left by `cells_per_frame` more every frame: it
    reaches the left wall within a few frames and, rolled out with open walls, goes through."""
    swept = positions.copy()
    frames = np.arange(positions.shape[0], dtype=np.float32)[:, None]
    swept[:, types == 1, 0] -= cells_per_frame * frames
    return swept


def test_clamped_walls_keep_the_rollout_in_the_box(model_dir, dataset_dir):
    ds = phi_rs.Dataset(dataset_dir)
    cell = ds.metadata["position_scale"]
    positions, types = ds["train", 0]
    swept = swept_left(positions, types, 4 * cell)
    model = phi_rs.Model.load(model_dir)
    assert model.walls == "open"
    clamped = model.with_walls("clamp")
    assert clamped.walls == "clamp" and model.walls == "open"
    liquid = types == 1
    open_rollout = model.rollout(swept, types)[:, liquid]
    clamped_rollout = clamped.rollout(swept, types)[:, liquid]
    lo, hi = np.array(ds.metadata["bounds"], dtype=np.float32).T
    outside = ((open_rollout < lo) | (open_rollout > hi)).any(axis=(1, 2))
    assert outside.any()
    assert ((clamped_rollout >= lo) & (clamped_rollout <= hi)).all()
    # The rollouts agree until the open one first leaves the box; at that step the clamped one
    # is the open one's prediction clamped into the box: stopped on the wall, not short of it.
    k = int(np.argmax(outside))
    assert np.array_equal(clamped_rollout[:k], open_rollout[:k])
    assert np.array_equal(clamped_rollout[k], np.clip(open_rollout[k], lo, hi))
    # One step is the open model's, clamped into the box.
    c = model.input_velocities
    assert np.array_equal(clamped.predict(swept[:c + 1], types),
                          np.clip(model.predict(swept[:c + 1], types), lo, hi))
    with pytest.raises(phi_rs.ModelError, match="'bouncy' is not a kind of walls"):
        model.with_walls("bouncy")


def test_pushed_obstacles_keep_the_liquid_out_of_cells_it_enters(model_dir, dataset_dir):
    ds = phi_rs.Dataset(dataset_dir)
    cell = ds.metadata["position_scale"]
    lo, hi = np.array(ds.metadata["bounds"], dtype=np.float64).T
    # A wall three cells thick in the middle of the domain, an obstacle particle at the centre of
    # each of its cells, and a column of liquid left of it moving right at half a cell a frame.
    first = int(0.5 * (hi[0] - lo[0]) / cell)
    rows = int((hi[1] - lo[1]) / cell)
    wall = np.array([[lo[0] + (i + 0.5) * cell, lo[1] + (j + 0.5) * cell]
                     for i in range(first, first + 3) for j in range(4, rows - 4)])
    column = np.array([[lo[0] + (first - 3.2) * cell, lo[1] + (j + 0.3) * cell]
                       for j in range(8, 16)])
    frames = 12
    steps = np.arange(frames, dtype=np.float64)[:, None, None]
    liquid = column[None] + steps * np.array([0.5 * cell, 0.0])
    positions = np.concatenate([np.broadcast_to(wall, (frames,) + wall.shape), liquid],
                               axis=1).astype(np.float32)
    types = np.array([0] * len(wall) + [1] * len(column), dtype=np.int64)

    model = phi_rs.Model.load(model_dir)
    assert model.obstacles == "open"
    pushed = model.with_obstacles("push", cell)
    assert pushed.obstacles == "push" and model.obstacles == "open"
    c = model.input_velocities
    is_liquid, is_solid = types == 1, types == 0

    def entered(rollout):
        """Whether a liquid particle is, at some frame, inside an obstacle particle's cell it
        was not inside at the frame before."""
        f = np.concatenate([positions[c:c + 1], rollout])
        d = np.abs(f[:, is_liquid, None, :] - f[:, None, is_solid, :])
        inside = (d < np.float32(0.5 * cell)).all(axis=-1)
        return (inside[1:] & ~inside[:-1]).any()

    open_rollout = model.rollout(positions, types)
    pushed_rollout = pushed.rollout(positions, types)
    assert entered(open_rollout)
    assert not entered(pushed_rollout)
    # The obstacle particles follow the truth either way.
    assert np.array_equal(pushed_rollout[:, is_solid], positions[c + 1:, is_solid])
    with pytest.raises(phi_rs.ModelError, match="needs the cell_size"):
        model.with_obstacles("push")
    with pytest.raises(phi_rs.ModelError, match="'bounce' is not a kind of obstacles"):
        model.with_obstacles("bounce", cell)
    with pytest.raises(phi_rs.ModelError, match="cell_size"):
        model.with_obstacles("push", 0.0)


def test_evaluate_with_a_container_counts_what_leaves_it(model_dir, dataset_dir):
    ds = phi_rs.Dataset(dataset_dir)
    bounds, cell = ds.metadata["bounds"], ds.metadata["position_scale"]
    positions, types = ds["train", 0]
    swept = swept_left(positions, types, 4 * cell)
    model = phi_rs.Model.load(model_dir)
    ev = model.evaluate(swept, types, sinkhorn_every=0, bounds=bounds, cell_size=cell)
    plausibility = ev["plausibility"]
    # The fractions of the liquid's particle-frames outside the domain and inside a cell
    # that holds an obstacle particle, counted here from the rollout.
    c, liquid = model.input_velocities, types == 1
    predicted = model.rollout(swept, types)
    lo = np.array([b[0] for b in bounds])
    hi = np.array([b[1] for b in bounds])
    outside = ((predicted[:, liquid] < lo) | (predicted[:, liquid] > hi)).any(axis=-1)
    assert outside.mean() > 0
    assert plausibility["outside"] == pytest.approx(outside.mean(), rel=1e-12)
    inside = 0
    for frame, is_out in zip(predicted, outside):
        cells = np.floor((frame.astype(np.float64) - lo) / cell).astype(np.int64)
        solid = {tuple(x) for x in cells[~liquid]}
        inside += sum(tuple(x) in solid for x, o in zip(cells[liquid], is_out) if not o)
    assert plausibility["inside_obstacles"] == pytest.approx(inside / outside.size, rel=1e-12)
    # The centre of mass at the end, in cells, and the verdict.
    centre = predicted[-1, liquid].astype(np.float64).mean(axis=0)
    true_centre = swept[-1, liquid].astype(np.float64).mean(axis=0)
    assert plausibility["final_centre_distance_cells"] == pytest.approx(
        np.linalg.norm(centre - true_centre) / cell, rel=1e-9)
    assert ev["plausible"] is False
    assert ev["start"] == c
    with pytest.raises(phi_rs.ModelError, match="cell_size: must be given with bounds"):
        model.evaluate(swept, types, bounds=bounds)
    with pytest.raises(phi_rs.ModelError, match="bounds: 1 pairs for a 2-dimensional model"):
        model.evaluate(swept, types, bounds=bounds[:1], cell_size=cell)
    with pytest.raises(phi_rs.ModelError, match=r"axis 1 is \(1, 0\)"):
        model.evaluate(swept, types, bounds=[bounds[0], (1, 0)], cell_size=cell)
    with pytest.raises(phi_rs.ModelError, match="axis 0 has 3 values"):
        model.evaluate(swept, types, bounds=[(0, 1, 2), bounds[1]], cell_size=cell)


def test_evaluate_over_a_split_is_phi_eval(phi, model_dir, dataset_dir, tmp_path):
    model = phi_rs.Model.load(model_dir)
    models = {"open": model, "clamped": model.with_walls("clamp")}
    table = phi_rs.evaluate(models, dataset_dir, split="train", short_rollout=5)
    out = tmp_path / "eval"
    phi("eval", "--model", f"open={model_dir}", "--model", f"clamped={model_dir}",
        "--model-walls", "clamped=clamp", "--data", dataset_dir, "--split", "train",
        "--short-rollout", 5, "--sinkhorn-every", 0, "--frame-every", 0, "--out", out,
        "--backend", "ndarray")
    record = json.loads((out / "eval.json").read_text())
    cli = {m["label"]: m["summary"] for m in record["models"]}
    assert set(table["models"]) == set(cli) == {"open", "clamped"}
    for name, summary in table["models"].items():
        assert summary == cli[name], name
    # Each row is Model.evaluate's dict of that trajectory, against the dataset's container.
    ds = phi_rs.Dataset(dataset_dir)
    bounds, cell = ds.metadata["bounds"], ds.metadata["position_scale"]
    for i, row in enumerate(table["trajectories"]["clamped"]):
        positions, types = ds["train", i]
        one = models["clamped"].evaluate(positions, types, short_rollout=5, sinkhorn_every=0,
                                         density_radius=ds.metadata["default_connectivity_radius"],
                                         bounds=bounds, cell_size=cell)
        one.pop("plausible")
        assert row.pop("index") == i and row.pop("seed") != 0
        one.pop("index"), one.pop("seed")
        assert row == one
    assert len(phi_rs.evaluate(models, dataset_dir, split="train",
                               trajectories=1)["trajectories"]["open"]) == 1
    with pytest.raises(phi_rs.DatasetError, match="valid"):
        phi_rs.evaluate(models, dataset_dir, split="valid")


def test_ctrl_c_interrupts_a_rollout(model_dir, dataset_dir):
    model = phi_rs.Model.load(model_dir)
    positions, types = phi_rs.Dataset(dataset_dir)["train", 0]
    # A trajectory long enough to run for seconds: the first frame held still.
    still = np.repeat(positions[:1], 20_000, axis=0)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            model.rollout(still, types)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)


def test_rollout_of_a_window_with_kinematic_frames(model_dir, dataset_dir):
    model = phi_rs.Model.load(model_dir)
    positions, types = phi_rs.Dataset(dataset_dir)["train", 0]
    c = model.input_velocities
    # The window and the ground truth's later frames as `kinematic`: the trajectory's rollout.
    window, later = positions[:c + 1], positions[c + 1:]
    assert np.array_equal(model.rollout(window, types, kinematic=later),
                          model.rollout(positions, types))
    # Obstacles held where the window leaves them; the liquid's rows of `kinematic` unread.
    still = np.repeat(window[-1:], 4, axis=0)
    scrambled = still.copy()
    scrambled[:, types == 1] = 123.0
    held = model.rollout(window, types, kinematic=still)
    assert held.shape == (4, types.shape[0], 2)
    assert np.array_equal(held, model.rollout(window, types, kinematic=scrambled))
    assert np.array_equal(held[:, types == 0], still[:, types == 0])
    with pytest.raises(phi_rs.ModelError, match=r"kinematic: shape \(4, 3, 2\)"):
        model.rollout(window, types, kinematic=still[:, :3])
