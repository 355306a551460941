"""phi_rs.torch: FLIP as a PyTorch operation. Its gradients match central finite differences
of a PyTorch loss, gradcheck passes on a smooth run, and torch.optim lowers an L2 loss to a
target (the thesis's section 4.3). Skipped only where PyTorch is not installed."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import phi_rs  # noqa: E402
import phi_rs.torch  # noqa: E402
from test_gradient import TINY  # noqa: E402


@pytest.fixture(scope="module")
def flip():
    return phi_rs.FlipGradient(TINY)


def test_forward_equals_flip_gradient_run(flip):
    x0 = torch.tensor(flip.positions, requires_grad=True)
    v0 = torch.tensor(flip.velocities, requires_grad=True)
    x, v = phi_rs.torch.simulate(flip, x0, v0)
    assert x.grad_fn is not None and v.grad_fn is not None
    assert x.dtype == torch.float32 and x.shape == x0.shape
    expected = flip.run(flip.positions, flip.velocities)
    assert np.array_equal(x.detach().numpy(), expected[0])
    assert np.array_equal(v.detach().numpy(), expected[1])
    # float64 in, float64 out (computed in float32).
    x64, _ = phi_rs.torch.simulate(flip, x0.double(), v0.double())
    assert x64.dtype == torch.float64
    assert np.array_equal(x64.detach().numpy(), expected[0].astype(np.float64))


def loss_of(flip, x0, v0, target):
    """A PyTorch loss of the final state: L2 to a target plus a kinetic-energy term."""
    x, v = phi_rs.torch.simulate(flip, x0, v0)
    return ((x - target) ** 2).sum() + 0.1 * (v ** 2).sum()


def test_gradients_match_central_differences_of_the_loss(flip):
    x0 = torch.tensor(flip.positions, dtype=torch.float64, requires_grad=True)
    v0 = torch.tensor(flip.velocities, dtype=torch.float64, requires_grad=True)
    target = torch.tensor(flip.positions, dtype=torch.float64) + torch.tensor([0.5, 0.2])
    loss_of(flip, x0, v0, target).backward()
    analytic = torch.stack([x0.grad, v0.grad]).numpy()

    def differences(h):
        initial = torch.stack([x0.detach(), v0.detach()])
        gradient = np.zeros(tuple(initial.shape))
        with torch.no_grad():
            for index in np.ndindex(*initial.shape):
                plus, minus = initial.clone(), initial.clone()
                plus[index] += h
                minus[index] -= h
                # The simulation reads float32: difference over the steps it really takes.
                step = float(plus[index].float()) - float(minus[index].float())
                gradient[index] = (loss_of(flip, *plus, target).item()
                                   - loss_of(flip, *minus, target).item()) / step
        return gradient

    fd, fd_half = differences(1e-2), differences(5e-3)
    smooth = np.abs(fd - fd_half) <= 2e-3 + 1e-2 * np.abs(fd)
    assert smooth.mean() >= 0.8, f"only {smooth.sum()} of {smooth.size} elements are smooth"
    error = np.abs(analytic - fd)[smooth]
    assert (error <= 1e-2 + 5e-3 * np.abs(fd[smooth])).all(), error.max()


def test_gradcheck_on_a_smooth_run():
    # Particles 0.1–0.4 cells off every face and centre line, moving slowly for two steps, so
    # that every stencil of gradcheck's differences stays on one smooth piece.
    flip = phi_rs.FlipGradient(TINY, steps=2)
    cells = [(3, 3), (4, 3), (3, 4), (4, 4)]
    offsets = [(0.2, 0.3), (0.7, 0.15), (0.35, 0.8)]
    x0 = torch.tensor([[i + a, j + b] for i, j in cells for a, b in offsets],
                      dtype=torch.float64, requires_grad=True)
    v0 = torch.tensor([[0.3 * np.sin(0.7 * y), -0.5 + 0.2 * np.cos(0.9 * x)]
                       for x, y in x0.tolist()], dtype=torch.float64, requires_grad=True)
    # The forward map is float32 inside: differences need a step well above its round-off.
    assert torch.autograd.gradcheck(
        lambda x, v: phi_rs.torch.simulate(flip, x, v),
        (x0, v0), eps=1e-2, atol=1e-2, rtol=1e-2)


def test_torch_optimiser_lowers_an_l2_loss_to_a_target(flip):
    # The target is the run from the block moved by (0.6, 0.4): its initial positions are an
    # optimum, which Adam approaches from the scene's own block.
    v0 = torch.tensor(flip.velocities)
    shifted = flip.positions + np.float32([0.6, 0.4])
    target = torch.tensor(flip.run(shifted, flip.velocities)[0])
    x0 = torch.tensor(flip.positions, requires_grad=True)
    optimiser = torch.optim.Adam([x0], lr=0.05)
    losses = []
    for _ in range(12):
        optimiser.zero_grad()
        x, _ = phi_rs.torch.simulate(flip, x0, v0)
        loss = ((x - target) ** 2).sum()
        loss.backward()
        optimiser.step()
        losses.append(loss.item())
    assert losses[-1] < 0.25 * losses[0], losses
    # The initial positions moved towards the optimum.
    before = np.abs(flip.positions - shifted).mean()
    after = np.abs(x0.detach().numpy() - shifted).mean()
    assert after < 0.5 * before, (before, after)


def test_simulate_from_a_scene_and_its_errors(flip):
    x0, v0 = torch.tensor(flip.positions), torch.tensor(flip.velocities)
    # A scene's TOML text is built on the spot; the run is the same.
    x, _ = phi_rs.torch.simulate(TINY, x0, v0, steps=4)
    assert torch.equal(x, phi_rs.torch.simulate(flip, x0, v0)[0])
    with pytest.raises(ValueError, match="runs 4 steps"):
        phi_rs.torch.simulate(flip, x0, v0, steps=3)
    with pytest.raises(phi_rs.SimulationError, match=r"expected \[N, 2\]"):
        phi_rs.torch.simulate(flip, x0[:, :1], v0)
    # Only the inputs that need gradients get them.
    x0.requires_grad_(True)
    x, v = phi_rs.torch.simulate(flip, x0, v0)
    (x.sum() + v.sum()).backward()
    assert x0.grad is not None and v0.grad is None


def test_torch_module_is_reached_from_the_package():
    import importlib
    assert importlib.import_module("phi_rs").torch is phi_rs.torch
    assert phi_rs.torch.FlipFunction.apply is not None
