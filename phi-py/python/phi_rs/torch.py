"""phi's FLIP as a PyTorch operation: initial particle positions and velocities in, the state
after ``steps`` steps out, with a ``grad_fn`` whose backward pass is phi's own gradient
(``phi_rs.FlipGradient.vjp``, differentiated through the steps on the Burn backend).

A PyTorch loss and optimiser can then drive phi's simulator, as ``phi optimize`` does with
gradient descent (the thesis's section 4.3)::

    import numpy as np
    import torch
    import phi_rs.torch

    flip = phi_rs.FlipGradient("scenes/small32.toml", steps=10)
    v0 = torch.tensor(flip.velocities)
    moved = flip.positions + np.float32([3, 2])
    target = torch.tensor(flip.run(moved, flip.velocities)[0])
    x0 = torch.tensor(flip.positions, requires_grad=True)
    optimiser = torch.optim.Adam([x0], lr=0.25)
    for _ in range(14):
        optimiser.zero_grad()
        x, v = phi_rs.torch.simulate(flip, x0, v0)
        loss = ((x - target) ** 2).mean()
        loss.backward()
        optimiser.step()

The simulation runs in float32 on the CPU; results and gradients come back in the dtype and on
the device of the input tensors.
"""

import os
from typing import Optional, Tuple, Union

try:
    import torch
except ImportError as error:  # pragma: no cover - depends on the environment
    raise ImportError(
        f"phi_rs.torch needs PyTorch (pip install torch): {error}"
    ) from error

from ._phi_rs import FlipGradient

__all__ = ["FlipFunction", "simulate"]


def _to_numpy(tensor: torch.Tensor):
    """A float32 C-contiguous NumPy copy of ``tensor``'s values."""
    return tensor.detach().to(device="cpu", dtype=torch.float32).contiguous().numpy()


def _like(array, reference: torch.Tensor) -> torch.Tensor:
    """``array`` as a tensor with ``reference``'s dtype and device."""
    return torch.from_numpy(array).to(device=reference.device, dtype=reference.dtype)


class FlipFunction(torch.autograd.Function):
    """``FlipFunction.apply(flip, positions, velocities)``: ``flip.run`` forward,
    ``flip.vjp`` backward. ``flip`` is a ``phi_rs.FlipGradient``; ``positions`` and
    ``velocities`` are ``[N, d]`` tensors. Returns the final ``(positions, velocities)``.

    The backward pass runs the steps once more, recording them (the forward keeps no graph in
    phi), so it costs about two forward runs; it can be called any number of times (e.g. with
    ``retain_graph=True``). It is not itself differentiable (no second derivatives)."""

    @staticmethod
    def forward(ctx, flip, positions, velocities):
        initial = (_to_numpy(positions), _to_numpy(velocities))
        final_positions, final_velocities = flip.run(*initial)
        ctx.flip = flip
        ctx.initial = initial
        ctx.references = (positions.detach(), velocities.detach())
        return _like(final_positions, positions), _like(final_velocities, velocities)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad_positions, grad_velocities):
        if not any(ctx.needs_input_grad[1:]):
            return None, None, None
        gradients = ctx.flip.vjp(
            *ctx.initial, _to_numpy(grad_positions), _to_numpy(grad_velocities)
        )
        return (None,) + tuple(
            _like(g, ref) if needed else None
            for g, ref, needed in zip(gradients, ctx.references, ctx.needs_input_grad[1:])
        )


def simulate(
    scene: Union[FlipGradient, str, "os.PathLike[str]"],
    positions,
    velocities,
    steps: Optional[int] = None,
) -> Tuple[torch.Tensor, torch.Tensor]:
    """Runs FLIP ``steps`` steps of ``scene`` from ``positions`` and ``velocities``
    (``[N, d]`` tensors, or anything ``torch.as_tensor`` takes) and returns the final
    ``(positions, velocities)`` ``[N_T, d]``, differentiable with respect to both inputs.

    ``scene`` is a ``phi_rs.FlipGradient`` (reused across calls: build it once in an
    optimisation loop), or a scene file or TOML text, built anew each call. ``steps`` defaults
    to the ``FlipGradient``'s, or the scene's ``simulation.steps``; a ``FlipGradient`` with other
    steps is refused (``ValueError``).

    Raises ``SimulationError`` for arrays that are not ``[N, d]`` or a failed step, and
    ``SceneError`` for a scene that does not build."""
    if isinstance(scene, FlipGradient):
        if steps is not None and steps != scene.steps:
            raise ValueError(
                f"phi_rs.torch.simulate: steps={steps}, but the FlipGradient runs "
                f"{scene.steps} steps; build one with FlipGradient(scene, steps={steps})"
            )
        flip = scene
    else:
        flip = FlipGradient(scene, steps)
    positions = torch.as_tensor(positions)
    velocities = torch.as_tensor(velocities)
    return FlipFunction.apply(flip, positions, velocities)
