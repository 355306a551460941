"""phi_rs.FlipGradient: its run equals phi_rs.simulate's on the Burn backend, its
vector-Jacobian product matches central finite differences of the run, and its errors."""

import numpy as np
import pytest

import phi_rs

# A block falling in a closed 8 × 8 box: small enough for finite differences of every element.
TINY = """
[domain]
resolution = [8, 8]

[simulation]
dt = 0.05
steps = 4
particles_per_cell = 3

[[liquid]]
geometry = { type = "box", lower = [3, 3], upper = [5, 5] }
velocity = [0.5, -1.0]
"""

H = 1e-2


def projection(flip, positions, velocities, u, w):
    """u·x_T + w·v_T after the run, accumulated in float64."""
    x, v = flip.run(positions, velocities)
    return float(np.dot(x.astype(np.float64).ravel(), u.ravel())
                 + np.dot(v.astype(np.float64).ravel(), w.ravel()))


def central_differences(flip, positions, velocities, u, w, h):
    """∂(u·x_T + w·v_T)/∂(x₀, v₀) by central differences with step h, as [2, N, d]."""
    initial = np.stack([positions, velocities]).astype(np.float32)
    gradient = np.zeros(initial.shape)
    for index in np.ndindex(*initial.shape):
        plus, minus = initial.copy(), initial.copy()
        plus[index] += h
        minus[index] -= h
        step = float(plus[index]) - float(minus[index])
        gradient[index] = (projection(flip, *plus, u, w) - projection(flip, *minus, u, w)) / step
    return gradient


def test_run_equals_simulate_on_burn_bit_for_bit():
    flip = phi_rs.FlipGradient(TINY)
    assert flip.steps == 4 and flip.dim == 2 and flip.dt == pytest.approx(0.05)
    recorded = phi_rs.simulate(TINY, backend="burn")
    assert np.array_equal(flip.positions, recorded["positions"][0])
    assert np.array_equal(flip.velocities, recorded["velocities"][0])
    x, v = flip.run(flip.positions, flip.velocities)
    assert x.dtype == np.float32 and x.shape == flip.positions.shape
    assert np.array_equal(x, recorded["positions"][-1])
    assert np.array_equal(v, recorded["velocities"][-1])
    # Fewer steps than the scene's.
    two = phi_rs.FlipGradient(TINY, steps=2)
    assert np.array_equal(two.run(two.positions, two.velocities)[0],
                          recorded["positions"][2])


def test_vjp_matches_central_differences():
    flip = phi_rs.FlipGradient(TINY)
    x0, v0 = flip.positions, flip.velocities
    rng = np.random.default_rng(7)
    u = rng.uniform(0.5, 1.5, x0.shape)
    w = 0.1 * rng.uniform(0.5, 1.5, x0.shape)
    analytic = np.stack(flip.vjp(x0, v0, u.astype(np.float32), w.astype(np.float32)))
    assert analytic.shape == (2, *x0.shape) and analytic.dtype == np.float32
    fd = central_differences(flip, x0, v0, u, w, H)
    fd_half = central_differences(flip, x0, v0, u, w, H / 2)
    # Compared where the stencil lies on one smooth piece of the run (no particle crosses a
    # face or cell line inside it): there the two difference quotients agree.
    smooth = np.abs(fd - fd_half) <= 2e-3 + 1e-2 * np.abs(fd)
    assert smooth.mean() >= 0.8, f"only {smooth.sum()} of {smooth.size} elements are smooth"
    error = np.abs(analytic - fd)[smooth]
    assert (error <= 5e-3 + 5e-3 * np.abs(fd[smooth])).all(), error.max()
    # Gradients with respect to both positions and velocities are there.
    assert np.abs(analytic[0]).max() > 0.1 and np.abs(analytic[1]).max() > 0.01


def test_vjp_without_velocity_gradients_is_with_zeros():
    flip = phi_rs.FlipGradient(TINY, steps=2)
    x0, v0 = flip.positions, flip.velocities
    u = np.ones_like(x0)
    without = flip.vjp(x0, v0, u)
    zeros = flip.vjp(x0, v0, u, np.zeros_like(v0))
    for a, b in zip(without, zeros):
        assert np.array_equal(a, b)


def test_flip_gradient_errors():
    with pytest.raises(phi_rs.SceneError, match="resolutoin"):
        phi_rs.FlipGradient(TINY.replace("resolution", "resolutoin"))
    flip = phi_rs.FlipGradient(TINY, steps=1)
    x0, v0 = flip.positions, flip.velocities
    with pytest.raises(phi_rs.SimulationError, match=r"run: positions: shape \(.*\): expected \[N, 2\]"):
        flip.run(x0[:, :1], v0)
    with pytest.raises(phi_rs.SimulationError, match="must have the same shape"):
        flip.run(x0, v0[:-1])
    with pytest.raises(phi_rs.SimulationError, match="grad_positions"):
        flip.vjp(x0, v0, x0[:-1])
    with pytest.raises(phi_rs.SimulationError, match="not an array of float32"):
        flip.run("not an array", v0)


def test_phi_rs_torch_without_pytorch_says_what_is_missing():
    # A fresh interpreter in which `import torch` fails: the package imports, and asking for
    # phi_rs.torch raises an ImportError that says PyTorch is needed.
    import subprocess
    import sys
    code = (
        "import sys; sys.modules['torch'] = None\n"
        "import phi_rs\n"
        "try:\n"
        "    phi_rs.torch\n"
        "except ImportError as e:\n"
        "    print(e)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True)
    assert "phi_rs.torch needs PyTorch" in result.stdout
