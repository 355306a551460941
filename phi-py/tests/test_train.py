"""phi_rs.train against `phi train` on the same preset: the same loss curve and weights, an
exact resume, the progress callback, a stop from it, and the refusals."""

import csv

import pytest

import phi_rs

PRESET = """description = "a tiny test model"

[model]
input_velocities = 3
latent_size = 8
hidden_size = 8
hidden_layers = 1
message_passing_steps = 1
embedding_size = 4
boundary_features = true
noise_std = 1e-3
seed = 3

[training]
steps = 6
batch_size = 2
seed = 11
extra_steps = 0
log_every = 1

[optimizer]
beta1 = 0.9
beta2 = 0.999
eps = 1e-8

[optimizer.learning_rate]
initial = 1e-3
final_rate = 1e-5
decay_steps = 100

[checkpoints]
every = 2
keep = 10

[screening]
every = 3
split = "train"
trajectories = 1
window_stride = 5
rollout_steps = 6
select_by = "rollout_mse"

[data]
split = "train"
cache_mib = 1
read_ahead = 2
"""


@pytest.fixture(scope="module")
def preset(tmp_path_factory):
    path = tmp_path_factory.mktemp("preset") / "tiny.toml"
    path.write_text(PRESET)
    return path


def losses(out):
    """(step, loss, learning_rate) of every row of train.csv."""
    with open(out / "train.csv") as f:
        return [(row["step"], row["loss"], row["learning_rate"]) for row in csv.DictReader(f)]


def weights(out, step):
    return (out / "checkpoints" / f"step-{step:010d}" / "model.safetensors").read_bytes()


@pytest.fixture(scope="module")
def cli_run(phi, dataset_dir, preset, tmp_path_factory):
    out = tmp_path_factory.mktemp("train") / "cli"
    phi("train", "--data", dataset_dir, "--config", preset, "--out", out, "--backend", "burn")
    return out


def test_train_equals_phi_train(cli_run, dataset_dir, preset, tmp_path):
    calls = []
    result = phi_rs.train(tmp_path / "py", data=dataset_dir, config=preset,
                          progress=lambda *args: calls.append(args))
    assert result["step"] == 6 and result["best"] is not None
    assert [c[0] for c in calls] == [1, 2, 3, 4, 5, 6] and all(c[1] == 6 for c in calls)
    assert calls[-1][2] == pytest.approx(result["loss"])
    assert losses(tmp_path / "py") == losses(cli_run)
    assert len(losses(cli_run)) == 6
    assert weights(tmp_path / "py", 6) == weights(cli_run, 6)


def test_resume_continues_as_an_uninterrupted_run(cli_run, dataset_dir, preset, tmp_path):
    out = tmp_path / "resumed"

    def stop_after_four(step, total, loss, learning_rate):
        if step == 4:
            raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        phi_rs.train(out, data=dataset_dir, config=preset, progress=stop_after_four)
    assert (out / "checkpoints" / f"step-{4:010d}").is_dir()
    result = phi_rs.train(out, resume=True)
    assert result["step"] == 6
    assert losses(out) == losses(cli_run)
    assert weights(out, 6) == weights(cli_run, 6)
    # At the total already: nothing to do.
    assert phi_rs.train(out, resume=True)["loss"] is None


def test_train_refusals(dataset_dir, preset, tmp_path):
    with pytest.raises(phi_rs.TrainingError, match="a preset is needed"):
        phi_rs.train(tmp_path / "a", data=dataset_dir)
    bad = tmp_path / "bad.toml"
    bad.write_text(PRESET.replace("latent_size", "latent_sise"))
    with pytest.raises(phi_rs.TrainingError, match="latent_sise"):
        phi_rs.train(tmp_path / "b", data=dataset_dir, config=bad)
    with pytest.raises(phi_rs.TrainingError, match="init_from"):
        phi_rs.train(tmp_path / "c", resume=True, init_from=tmp_path)
    with pytest.raises(phi_rs.DatasetError, match="no-data"):
        phi_rs.train(tmp_path / "d", data=tmp_path / "no-data", config=preset)
    with pytest.raises(phi_rs.TrainingError, match="not a screening metric"):
        phi_rs.train(tmp_path / "e", data=dataset_dir, config=preset, select_by="emd2")
    with pytest.raises(phi_rs.TrainingError, match="screening.emd_every"):
        phi_rs.train(tmp_path / "f", data=dataset_dir, config=preset, select_by="emd")
