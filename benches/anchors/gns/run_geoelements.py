"""GNS inference with geoelements/gns on phi's input and weights: the anchor of
docs/benchmarks.md's "GNS inference against geoelements/gns".

The input is the .npz of `target/release/examples/gns_step --write-input in.npz --write-model
model` (keys `position` [N, C+1, dim], `particle_type` [N], `senders`/`receivers` [E], `bounds`,
`radius`, `vel_mean`/`vel_std`/`acc_mean`/`acc_std`); the weights are that model directory's
`model.safetensors` (its `model.json` beside it). A step is geoelements'
`LearnedSimulator.predict_positions` under `torch.no_grad()`: radius graph, features, the
network, Euler integration, as phi's `gns_step` times it. The script

1. checks the normalised accelerations of the window against phi's (`acc` of
   `gns_step --write-acc acc.npz`, passed as `--phi-acc acc.npz`, or of the input itself): the
   maximum absolute difference over the largest magnitude of phi's;
2. times `--repeats` steps after `--warmup` and prints their median and best;
3. with `--rollout-steps S`, rolls the window out S steps (a cKDTree graph each step, kinematic
   particles held at their latest positions) and prints the wall time, the time in the graphs,
   the median step, the mean edge count and the peak resident memory.

`--graph input` gives geoelements the input's edges (phi's graph of the window) for the check
and the timed steps; `--graph kdtree` (the default) builds its own (strictly within R, see
`geoelements.KdTreeRadiusGraph`). Rollouts always build their own.

    VENV/bin/python benches/anchors/gns/run_geoelements.py --gns-src GNS_SRC --input in.npz \\
        --weights model/model.safetensors --phi-acc acc.npz --threads 1 --repeats 10
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np
import torch

import geoelements as g


def arguments() -> argparse.Namespace:
    """The shared arguments and the inference ones."""
    p = g.parser(__doc__.split("\n\n")[0])
    p.add_argument(
        "--phi-acc",
        type=pathlib.Path,
        help="phi's normalised accelerations of the window (`acc` of gns_step --write-acc); "
        "without it the input's own `acc`, if any",
    )
    p.add_argument(
        "--graph",
        choices=("kdtree", "input"),
        default="kdtree",
        help="the graph of the check and the timed steps: geoelements' contract on cKDTree, "
        "or the input's edges",
    )
    p.add_argument(
        "--rollout-steps", type=int, default=0, help="then roll the window out this many steps"
    )
    return p.parse_args()


def phi_accelerations(args: argparse.Namespace, data: dict[str, np.ndarray]) -> np.ndarray | None:
    """phi's normalised accelerations of the window, if given."""
    if args.phi_acc is not None:
        with np.load(args.phi_acc) as acc:
            return acc["acc"]
    return data["acc"] if "acc" in data else None


def normalised_acceleration(
    simulator: torch.nn.Module, window: torch.Tensor, per_example: torch.Tensor, types: torch.Tensor
) -> torch.Tensor:
    """The network's output on the window: `predict_positions` without the integration."""
    with torch.no_grad():
        nodes, edge_index, edges = simulator._encoder_preprocessor(window, per_example, types)
        return simulator._encode_process_decode(nodes, edge_index, edges)


def step(
    simulator: torch.nn.Module, window: torch.Tensor, per_example: torch.Tensor, types: torch.Tensor
) -> torch.Tensor:
    """One inference step as geoelements' rollout takes it: the next positions."""
    with torch.no_grad():
        return simulator.predict_positions(
            window, nparticles_per_example=per_example, particle_types=types
        )


def rollout(
    simulator: torch.nn.Module,
    window: torch.Tensor,
    types: torch.Tensor,
    kinematic: torch.Tensor,
    steps: int,
) -> list[float]:
    """`steps` predictions from `window`, each fed back as geoelements' rollout does; kinematic
    particles keep their latest positions (phi's obstacles do not move). Seconds per step."""
    per_example = torch.tensor([window.shape[0]])
    current = window
    times = []
    for _ in range(steps):
        start = time.perf_counter()
        predicted = step(simulator, current, per_example, types)
        predicted = torch.where(kinematic[:, None], current[:, -1], predicted)
        current = torch.cat([current[:, 1:], predicted[:, None]], dim=1)
        times.append(time.perf_counter() - start)
    return times


def main() -> None:
    args = arguments()
    g.set_threads(args.threads)
    geo = g.import_geoelements(args.gns_src)
    simulator, spec = g.load_simulator(geo, args.weights)
    simulator.eval()

    with np.load(args.input) as npz:
        data = {k: npz[k] for k in npz.files}
    g.check_input(data, spec)
    position = data["position"].astype(np.float32)
    particle_type = data["particle_type"].astype(np.int64)
    n = position.shape[0]
    kinematic = g.kinematic_mask(particle_type, spec["kinematic_types"])
    window = torch.from_numpy(position)
    types = torch.from_numpy(particle_type)
    per_example = torch.tensor([n])

    kdtree = g.KdTreeRadiusGraph()
    graph: g.KdTreeRadiusGraph | g.FixedRadiusGraph = kdtree
    if args.graph == "input":
        graph = g.FixedRadiusGraph(data["senders"], data["receivers"], n)
    g.use_radius_graph(geo, graph)

    acc = normalised_acceleration(simulator, window, per_example, types).numpy()
    edges = graph.stats.edges_per_call[-1]
    print(
        f"graph ({args.graph}): {edges} edges; phi's graph of the input: {len(data['senders'])} "
        f"edges (inclusive of R)"
    )
    reference = phi_accelerations(args, data)
    if reference is None:
        print("no phi accelerations to check against (gns_step --write-acc acc.npz, --phi-acc)")
    else:
        if reference.shape != acc.shape:
            sys.exit(f"phi's accelerations are {reference.shape}, geoelements' {acc.shape}")
        difference = np.abs(acc.astype(np.float64) - reference.astype(np.float64))
        scale = np.abs(reference).max()
        print(
            f"normalised accelerations against phi's: max |difference| {difference.max():.3e}, "
            f"relative to max |phi| ({scale:.4g}): {difference.max() / scale:.3e}"
        )

    for _ in range(args.warmup):
        step(simulator, window, per_example, types)
    times = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        step(simulator, window, per_example, types)
        times.append((time.perf_counter() - start) * 1e3)
    if times:
        print(
            f"geoelements ({geo.learned_simulator.__name__} of {args.gns_src}): {n} particles "
            f"({int((~kinematic).sum())} not kinematic), {edges} edges, {args.threads} threads: "
            f"step median {g.median(times):.1f} ms, best {min(times):.1f} ms "
            f"({len(times)} steps, torch {torch.__version__})"
        )

    if args.rollout_steps > 0:
        g.use_radius_graph(geo, kdtree)
        kdtree.stats.reset()
        if not np.allclose(position[kinematic], position[kinematic][:, -1:, :]):
            print("warning: kinematic particles move in the window; the rollout holds them still")
        start = time.perf_counter()
        steps = rollout(simulator, window, types, torch.from_numpy(kinematic), args.rollout_steps)
        wall = time.perf_counter() - start
        graphs = kdtree.stats
        print(
            f"rollout: {len(steps)} steps in {wall:.2f} s (model {wall - graphs.seconds:.2f} s, "
            f"cKDTree graphs {graphs.seconds:.2f} s), step median {g.median(steps) * 1e3:.1f} ms, "
            f"mean {wall / len(steps) * 1e3:.1f} ms; {graphs.edges / graphs.calls:.0f} edges a "
            f"step; peak RSS {g.peak_rss_mib():.0f} MiB"
        )
    else:
        print(f"peak RSS {g.peak_rss_mib():.0f} MiB")


if __name__ == "__main__":
    main()
