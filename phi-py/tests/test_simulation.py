"""phi_rs.Simulation: a scene stepped on demand against phi_rs.simulate's frames, its
arguments and errors, Ctrl-C inside a long step(n), and two simulations at once."""

import _thread
import signal
import threading

import numpy as np
import pytest

import phi_rs
from conftest import ROOT

SCENE = ROOT / "scenes" / "small32.toml"
STEPS = 5

INFLOW_SCENE = """
[domain]
resolution = [16, 16]

[simulation]
dt = 0.05
steps = 10

[[liquid]]
geometry = { type = "box", lower = [0, 0], upper = [16, 2] }

[[inflow]]
geometry = { type = "box", lower = [2, 12], upper = [4, 14] }
velocity = [2, 0]
every = 2
until_step = 6
"""


@pytest.fixture(scope="module")
def recorded():
    return phi_rs.simulate(SCENE, steps=STEPS)


def assert_state_is_frame(sim, run, frame):
    """`sim`'s state equals frame `frame` of the `simulate` result `run`, bit for bit."""
    count = run["particle_count"][frame]
    positions, velocities = sim.positions, sim.velocities
    assert positions.dtype == np.float32 and velocities.dtype == np.float32
    assert positions.shape == (count, run["positions"].shape[2])
    assert velocities.shape == positions.shape
    assert np.isfinite(positions).all() and np.isfinite(velocities).all()
    assert np.array_equal(positions, run["positions"][frame, :count])
    assert np.array_equal(velocities, run["velocities"][frame, :count])
    assert sim.steps == frame
    assert sim.time == run["time"][frame]
    assert np.array_equal(sim.particle_type, run["particle_type"][:count])


def test_step_by_step_equals_simulate_bit_for_bit(recorded):
    sim = phi_rs.Simulation(SCENE)
    assert_state_is_frame(sim, recorded, 0)
    for frame in range(1, STEPS + 1):
        sim.step()
        assert_state_is_frame(sim, recorded, frame)


def test_one_step_of_many_equals_many_steps_of_one(recorded):
    at_once = phi_rs.Simulation(SCENE)
    at_once.step(STEPS)
    assert_state_is_frame(at_once, recorded, STEPS)

    split = phi_rs.Simulation(SCENE.read_text())
    split.step(2)
    assert_state_is_frame(split, recorded, 2)
    split.step(0)
    assert_state_is_frame(split, recorded, 2)
    split.step(n=STEPS - 2)
    assert_state_is_frame(split, recorded, STEPS)


def test_growing_inflow_has_no_padding():
    run = phi_rs.simulate(INFLOW_SCENE, steps=6)
    assert run["particle_count"][6] > run["particle_count"][0]
    sim = phi_rs.Simulation(INFLOW_SCENE)
    for frame in range(1, 7):
        sim.step()
        assert_state_is_frame(sim, run, frame)


def test_properties_and_repr():
    sim = phi_rs.Simulation(str(SCENE))
    assert sim.backend == "ndarray"
    assert sim.dim == 2
    assert sim.dt == pytest.approx(0.05)
    assert isinstance(sim.time, float) and sim.time == 0.0
    assert isinstance(sim.steps, int) and sim.steps == 0
    assert sim.particle_type.dtype == np.int32
    assert repr(sim) == "Simulation(steps=0, time=0, particles=1024, backend='ndarray')"


def test_burn_agrees_with_ndarray():
    ndarray = phi_rs.Simulation(SCENE)
    burn = phi_rs.Simulation(SCENE, backend="burn")
    ndarray.step(2)
    burn.step(2)
    assert burn.backend == "burn"
    assert burn.steps == 2 and burn.time == ndarray.time
    np.testing.assert_allclose(burn.positions, ndarray.positions, atol=1e-3)


def test_bad_scene_names_the_file_and_the_key(tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text(SCENE.read_text().replace("resolution", "resolutoin"))
    with pytest.raises(phi_rs.SceneError) as info:
        phi_rs.Simulation(scene)
    assert "bad.toml" in str(info.value)
    assert "resolutoin" in str(info.value)
    with pytest.raises(phi_rs.SceneError, match="nowhere.toml"):
        phi_rs.Simulation(tmp_path / "nowhere.toml")
    with pytest.raises(phi_rs.SceneError, match="simulation.dt"):
        phi_rs.Simulation(SCENE.read_text().replace("dt = 0.05", "dt = -1.0"))


def test_unknown_backend_is_a_phi_error():
    with pytest.raises(phi_rs.PhiError, match="'tpu' is not a backend"):
        phi_rs.Simulation(SCENE, backend="tpu")


def test_bad_step_counts_are_refused_and_change_nothing():
    sim = phi_rs.Simulation(SCENE)
    with pytest.raises(ValueError, match="at least 0; got -1"):
        sim.step(-1)
    with pytest.raises(TypeError):
        sim.step(1.5)
    with pytest.raises(TypeError):
        sim.step("2")
    assert sim.steps == 0
    assert sim.time == 0.0


def test_ctrl_c_interrupts_a_long_step_at_a_completed_step():
    sim = phi_rs.Simulation(SCENE)
    # Python's own Ctrl-C handler, even where the test runner was started with SIGINT ignored
    # (a background job of a shell), in which case `interrupt_main` would do nothing.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            sim.step(10**9)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    done = sim.steps
    assert 0 < done < 10**9
    run = phi_rs.simulate(SCENE, steps=done)
    assert_state_is_frame(sim, run, done)
    sim.step()
    assert sim.steps == done + 1


def test_ctrl_c_interrupts_simulate():
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            phi_rs.simulate(SCENE, steps=10**5)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)


def test_two_simulations_step_in_two_threads():
    expected = phi_rs.simulate(SCENE, steps=3)
    sims = [phi_rs.Simulation(SCENE) for _ in range(2)]
    errors = []

    def run(sim):
        try:
            sim.step(3)
        except Exception as e:  # reported below
            errors.append(e)

    threads = [threading.Thread(target=run, args=(sim,)) for sim in sims]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
    assert not any(t.is_alive() for t in threads)
    assert errors == []
    for sim in sims:
        assert_state_is_frame(sim, expected, 3)
