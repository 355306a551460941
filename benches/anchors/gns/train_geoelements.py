"""A GNS training step with geoelements/gns from phi's initial weights on phi's batch: the anchor
of docs/benchmarks.md's "GNS training step against geoelements/gns".

The input is the .npz of `target/release/examples/gns_train_step --write-input train.npz
--write-model model` (keys `position` [N, C+1, dim], the clean windows of the batch one after
the other; `next_position` [N, dim]; `noise` [N, C+1, dim], phi's position noise of its first
step; `particle_type`, `n_particles_per_example`, `kinematic_types`; `noise_std`; `loss`, phi's
first loss; the normalisation, bounds and radius); the weights are that model directory's
`model.safetensors`.

A step is the body of geoelements' train.py loop: its random-walk noise
(`noise_utils.get_random_walk_noise_for_position_sequence`) zeroed on kinematic particles,
`LearnedSimulator.predict_accelerations` on the concatenated batch (a radius graph per example,
here on cKDTree, inside the step), the squared error summed over dimensions and averaged over the
non-kinematic particles, `zero_grad`, `backward`, `torch.optim.Adam.step` and its learning-rate
update. The first step takes phi's stored noise instead of drawing one, so its loss is phi's
first loss up to rounding; it is printed against phi's. Then `--repeats` timed steps (after
`--warmup` untimed ones, the first of them that comparison), their median and best, and the
process's peak resident memory.

    VENV/bin/python benches/anchors/gns/train_geoelements.py --gns-src GNS_SRC --input train.npz \\
        --weights model/model.safetensors --threads 1 --repeats 3
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np
import torch

import geoelements as g

# geoelements' train.py defaults (its flags lr_init, lr_decay, lr_decay_steps).
LR_INIT = 1e-4
LR_DECAY = 0.1
LR_DECAY_STEPS = 5e6


def arguments() -> argparse.Namespace:
    """The shared arguments and the training ones."""
    p = g.parser(__doc__.split("\n\n")[0])
    p.add_argument("--seed", type=int, default=0, help="torch.manual_seed of geoelements' noise")
    return p.parse_args()


@dataclass
class Batch:
    """The batch as geoelements' data loader hands it to the loop, plus phi's first noise."""

    position: torch.Tensor  # [N, C+1, dim], clean
    next_position: torch.Tensor  # [N, dim]
    particle_type: torch.Tensor  # [N]
    per_example: torch.Tensor  # [B]
    non_kinematic: torch.Tensor  # [N], bool
    phi_noise: torch.Tensor  # [N, C+1, dim]


def read_batch(data: dict[str, np.ndarray], kinematic_types: list[int]) -> Batch:
    """The batch of phi's train.npz."""
    particle_type = data["particle_type"].astype(np.int64)
    return Batch(
        position=torch.from_numpy(data["position"].astype(np.float32)),
        next_position=torch.from_numpy(data["next_position"].astype(np.float32)),
        particle_type=torch.from_numpy(particle_type),
        per_example=torch.from_numpy(data["n_particles_per_example"].astype(np.int64)),
        non_kinematic=torch.from_numpy(~g.kinematic_mask(particle_type, kinematic_types)),
        phi_noise=torch.from_numpy(data["noise"].astype(np.float32)),
    )


def acceleration_loss(
    predicted: torch.Tensor, target: torch.Tensor, non_kinematic: torch.Tensor
) -> torch.Tensor:
    """geoelements' loss: squared error summed over dimensions, kinematic particles zeroed, the
    sum divided by the count of non-kinematic particles."""
    per_particle = ((predicted - target) ** 2).sum(dim=-1)
    per_particle = torch.where(non_kinematic, per_particle, torch.zeros_like(per_particle))
    return per_particle.sum() / non_kinematic.sum()


def train_step(
    geo: g.Geoelements,
    simulator: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    batch: Batch,
    noise_std: float,
    step: int,
    noise: torch.Tensor | None = None,
) -> float:
    """One iteration of geoelements' training loop; `noise` replaces its drawn noise. The loss."""
    if noise is None:
        noise = geo.noise_utils.get_random_walk_noise_for_position_sequence(
            batch.position, noise_std_last_step=noise_std
        )
    else:
        noise = noise.clone()
    noise *= batch.non_kinematic.view(-1, 1, 1)
    predicted, target = simulator.predict_accelerations(
        next_positions=batch.next_position,
        position_sequence_noise=noise,
        position_sequence=batch.position,
        nparticles_per_example=batch.per_example,
        particle_types=batch.particle_type,
    )
    loss = acceleration_loss(predicted, target, batch.non_kinematic)
    value = loss.item()
    optimizer.zero_grad()
    loss.backward()
    optimizer.step()
    rate = LR_INIT * LR_DECAY ** (step / LR_DECAY_STEPS)
    for group in optimizer.param_groups:
        group["lr"] = rate
    return value


def main() -> None:
    args = arguments()
    if args.warmup + args.repeats < 1:
        raise SystemExit("nothing to run: --warmup 0 --repeats 0")
    g.set_threads(args.threads)
    torch.manual_seed(args.seed)
    geo = g.import_geoelements(args.gns_src)
    simulator, spec = g.load_simulator(geo, args.weights)
    simulator.train()
    graph = g.KdTreeRadiusGraph()
    g.use_radius_graph(geo, graph)

    with np.load(args.input) as npz:
        data = {k: npz[k] for k in npz.files}
    g.check_input(data, spec)
    noise_std = float(data["noise_std"])
    if noise_std != spec["config"]["noise_std"]:
        print(
            f"warning: the batch's noise_std {noise_std} is not model.json's "
            f"{spec['config']['noise_std']} (the normalisation's)"
        )
    batch = read_batch(data, spec["kinematic_types"])
    optimizer = torch.optim.Adam(simulator.parameters(), lr=LR_INIT)

    times: list[float] = []
    first_loss = None
    for i in range(args.warmup + args.repeats):
        start = time.perf_counter()
        loss = train_step(
            geo,
            simulator,
            optimizer,
            batch,
            noise_std,
            step=i,
            noise=batch.phi_noise if i == 0 else None,
        )
        seconds = time.perf_counter() - start
        if i >= args.warmup:
            times.append(seconds)
        if i == 0:
            first_loss = loss
            phi_loss = float(data["loss"])
            print(
                f"first step (phi's noise): geoelements loss {loss:.7f}, phi loss {phi_loss:.7f}, "
                f"difference {loss - phi_loss:.3e} ({abs(loss - phi_loss) / abs(phi_loss):.3e} "
                f"relative); edges {graph.stats.edges_per_call[-1]} (phi: {len(data['senders'])}, "
                f"inclusive of R)"
            )
    counts = " + ".join(str(int(c)) for c in batch.per_example)
    summary = (
        f"step median {g.median(times):.3f} s, best {min(times):.3f} s ({len(times)} steps)"
        if times
        else "no timed steps"
    )
    print(
        f"geoelements: batch of {len(batch.per_example)} ({counts} particles), "
        f"{graph.stats.edges_per_call[-1]} edges, {args.threads} threads: first loss "
        f"{first_loss:.6f}, {summary}, peak RSS {g.peak_rss_mib():.0f} MiB "
        f"(torch {torch.__version__})"
    )


if __name__ == "__main__":
    main()
