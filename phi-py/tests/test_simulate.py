"""phi_rs.simulate against `phi simulate`, its errors, and two runs at once."""

import threading

import numpy as np
import pytest

import phi_rs
from conftest import ROOT

SCENE = ROOT / "scenes" / "small32.toml"
STEPS = 4


@pytest.fixture(scope="module")
def cli_trajectory(phi, tmp_path_factory):
    out = tmp_path_factory.mktemp("simulate") / "run"
    phi("simulate", SCENE, "--out", out, "--steps", STEPS, "--frame-every", 0,
        "--backend", "ndarray")
    with np.load(out / "trajectory.npz") as npz:
        return {key: npz[key] for key in npz.files}


def test_simulate_equals_cli_bit_for_bit(cli_trajectory):
    result = phi_rs.simulate(SCENE, steps=STEPS)
    assert set(result) == set(cli_trajectory)
    for key, expected in cli_trajectory.items():
        got = result[key]
        assert got.dtype == expected.dtype, key
        assert got.shape == expected.shape, key
        assert np.array_equal(got, expected, equal_nan=True), key
    assert result["positions"].shape[0] == STEPS + 1
    assert result["steps_completed"][0] == STEPS


def test_arrays_come_back_without_a_copy(model_dir, dataset_dir):
    # A returned array wraps the buffer the library filled (its base is the Rust container
    # that owns it), C-contiguous and writeable: NumPy copied nothing.
    def wraps_the_library_buffer(array):
        return (not array.flags.owndata and type(array.base).__name__ == "PySliceContainer"
                and array.flags.c_contiguous and array.flags.writeable)

    result = phi_rs.simulate(SCENE, steps=1)
    assert all(wraps_the_library_buffer(result[key]) for key in ("positions", "velocities"))
    model = phi_rs.Model.load(model_dir)
    positions, types = phi_rs.Dataset(dataset_dir)["train", 0]
    assert wraps_the_library_buffer(positions) and wraps_the_library_buffer(types)
    assert wraps_the_library_buffer(model.rollout(positions, types, steps=2))


def test_simulate_takes_toml_text_and_str_paths():
    from_text = phi_rs.simulate(SCENE.read_text(), steps=2)
    from_str = phi_rs.simulate(str(SCENE), steps=2)
    assert np.array_equal(from_text["positions"], from_str["positions"])
    assert np.array_equal(from_text["velocities"], from_str["velocities"])
    # The scene's own step count when none is given.
    short = phi_rs.simulate(SCENE.read_text().replace("steps = 100", "steps = 1"))
    assert short["positions"].shape[0] == 2


def test_simulate_on_burn_agrees_with_ndarray():
    ndarray = phi_rs.simulate(SCENE, steps=2, backend="ndarray")
    burn = phi_rs.simulate(SCENE, steps=2, backend="burn")
    assert burn["positions"].shape == ndarray["positions"].shape
    np.testing.assert_allclose(burn["positions"], ndarray["positions"], atol=1e-3)


def test_missing_scene_file_names_the_file(tmp_path):
    missing = tmp_path / "nowhere.toml"
    with pytest.raises(phi_rs.SceneError, match="nowhere.toml") as info:
        phi_rs.simulate(missing)
    assert isinstance(info.value, phi_rs.PhiError)


def test_unknown_key_names_the_file_and_the_key(tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text(SCENE.read_text().replace("resolution", "resolutoin"))
    with pytest.raises(phi_rs.SceneError) as info:
        phi_rs.simulate(scene)
    message = str(info.value)
    assert "bad.toml" in message
    assert "resolutoin" in message


def test_value_out_of_range_names_the_key():
    text = SCENE.read_text().replace("dt = 0.05", "dt = -1.0")
    with pytest.raises(phi_rs.SceneError, match="simulation.dt"):
        phi_rs.simulate(text)


def test_unknown_backend_is_a_phi_error():
    with pytest.raises(phi_rs.PhiError, match="'tpu' is not a backend"):
        phi_rs.simulate(SCENE, steps=1, backend="tpu")


def test_two_threads_simulate_at_once():
    expected = phi_rs.simulate(SCENE, steps=3)["positions"]
    results, errors = {}, []

    def run(name):
        try:
            results[name] = phi_rs.simulate(SCENE, steps=3)["positions"]
        except Exception as e:  # reported below, with the thread's name
            errors.append((name, e))

    threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
    assert not any(t.is_alive() for t in threads)
    assert errors == []
    assert sorted(results) == [0, 1]
    for positions in results.values():
        assert np.array_equal(positions, expected)
