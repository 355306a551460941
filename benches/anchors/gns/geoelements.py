"""geoelements/gns's `LearnedSimulator` with the weights of a phi model directory.

Shared by `run_geoelements.py` (inference) and `train_geoelements.py` (a training step). The
anchor is geoelements/gns at commit 3b8fb5c (https://github.com/geoelements/gns), a checkout
that is not part of this repository: `--gns-src DIR` puts it on `sys.path`, and only its modules
`gns.learned_simulator`, `gns.graph_network` and `gns.noise_utils` are imported.

What changes against geoelements:

- `torch_geometric.nn.radius_graph`, which needs `torch_cluster` (no CPU wheel on PyPI), is
  replaced in `gns.learned_simulator` by `KdTreeRadiusGraph` (scipy's `cKDTree`, the same
  contract: pairs of one example strictly closer than R, self-loops kept, at most 128 neighbours
  per receiver, the nearest kept if more) or by `FixedRadiusGraph` (the edges of an input file).
- Nothing else: the features, the network, the integration, the noise and the loss pieces are
  geoelements' own code.

The weights (`model.safetensors`, PyTorch names and `[out, in]` layout, see
`phi-gns/tests/fixtures/gns_reference.py`) map onto geoelements' modules as follows:

| phi | geoelements (`_encode_process_decode.` below) |
|---|---|
| `embedding.weight` | `_particle_type_embedding.weight` |
| `encoder.{node,edge}.{i}` / `.ln` | `_encoder.{node,edge}_fn.0.NN-{i}` / `_encoder.{node,edge}_fn.1` |
| `processor.{k}.{edge,node}.{i}` / `.ln` | `_processor.gnn_stacks.{k}.{edge,node}_fn.0.NN-{i}` / `...fn.1` |
| `decoder.{i}` | `_decoder.node_fn.NN-{i}` |

The node and edge features have the same columns in both. The first layers of the processor's
MLPs read concatenations in different orders, so their weight columns are permuted:

- edge MLP: phi reads `[e, v_sender, v_receiver]`, geoelements `[x_i, x_j, e]` with `x_i` the
  receiver (PyG's target, `edge_index[1]`) and `x_j` the sender;
- node MLP: phi reads `[v, sum of messages]`, geoelements `[aggregated messages, x]`.

The normalisation scales are phi's (and geoelements' train.py's) `sqrt(std^2 + noise_std^2)`
with `noise_std` from `model.json`.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import resource
import sys
import time
from dataclasses import dataclass, field
from types import ModuleType
from typing import Callable

import numpy as np
import torch
from safetensors.torch import load_file
from scipy.spatial import cKDTree

GEOELEMENTS_COMMIT = "3b8fb5c"
# geoelements' `_compute_graph_connectivity` asks `radius_graph` for at most this many neighbours.
MAX_NEIGHBOURS = 128


def parser(description: str) -> argparse.ArgumentParser:
    """The arguments both anchor scripts take; each adds its own."""
    p = argparse.ArgumentParser(
        description=description, formatter_class=argparse.ArgumentDefaultsHelpFormatter
    )
    p.add_argument(
        "--gns-src",
        type=pathlib.Path,
        required=True,
        help=f"a checkout of github.com/geoelements/gns at commit {GEOELEMENTS_COMMIT} "
        "(the directory holding its `gns` package)",
    )
    p.add_argument(
        "--input", type=pathlib.Path, required=True, help="the .npz that phi's example wrote"
    )
    p.add_argument(
        "--weights",
        type=pathlib.Path,
        required=True,
        help="model.safetensors of a phi model directory (its model.json is read next to it)",
    )
    p.add_argument("--threads", type=int, default=1, help="torch.set_num_threads")
    p.add_argument("--repeats", type=int, default=10, help="timed steps")
    p.add_argument("--warmup", type=int, default=1, help="untimed steps first")
    return p


def set_threads(threads: int) -> None:
    """Intra-op threads of torch (the anchors' `--threads`)."""
    torch.set_num_threads(threads)


def peak_rss_mib() -> float:
    """The process's peak resident set in MiB (`ru_maxrss` is in KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def median(values: list[float]) -> float:
    """The median as phi's examples take it: the upper middle of the sorted values."""
    ordered = sorted(values)
    return ordered[len(ordered) // 2] if ordered else float("nan")


# ---------------------------------------------------------------------------------------------
# Radius graphs standing in for torch_cluster's
# ---------------------------------------------------------------------------------------------


@dataclass
class GraphStats:
    """What the radius graphs of a run cost: calls, seconds and edges."""

    calls: int = 0
    seconds: float = 0.0
    edges: int = 0
    edges_per_call: list[int] = field(default_factory=list)

    def record(self, seconds: float, edges: int) -> None:
        self.calls += 1
        self.seconds += seconds
        self.edges += edges
        self.edges_per_call.append(edges)

    def reset(self) -> None:
        self.calls, self.seconds, self.edges = 0, 0.0, 0
        self.edges_per_call = []


def kdtree_edges(
    positions: np.ndarray, radius: float, loop: bool = True, max_neighbours: int = MAX_NEIGHBOURS
) -> tuple[np.ndarray, np.ndarray]:
    """Directed (senders, receivers) of one example: every pair strictly closer than `radius`.

    The contract of torch_cluster's `radius_graph` as geoelements calls it: `|p_s - p_r| < R`
    (squared distances compared in the positions' precision), self-loops when `loop`, and at most
    `max_neighbours` senders per receiver (the nearest; torch_cluster keeps the first it finds,
    which differs only when a receiver has more, not the case at these densities). Sorted by
    receiver, then sender.
    """
    n = positions.shape[0]
    tree = cKDTree(positions.astype(np.float64))
    # query_pairs is inclusive and float64; widen it a little and decide `<` afterwards.
    pairs = tree.query_pairs(radius * (1.0 + 1e-6), output_type="ndarray")
    d = positions[pairs[:, 0]] - positions[pairs[:, 1]]
    squared = (d * d).sum(axis=1)
    pairs = pairs[squared < positions.dtype.type(radius) * positions.dtype.type(radius)]
    senders = [pairs[:, 0], pairs[:, 1]]
    receivers = [pairs[:, 1], pairs[:, 0]]
    if loop:
        senders.append(np.arange(n))
        receivers.append(np.arange(n))
    s = np.concatenate(senders).astype(np.int64)
    r = np.concatenate(receivers).astype(np.int64)
    if n and np.bincount(r, minlength=n).max() > max_neighbours:
        distance = np.linalg.norm(positions[s] - positions[r], axis=1)
        order = np.lexsort((distance, r))
        s, r = s[order], r[order]
        starts = np.searchsorted(r, np.arange(n))
        keep = np.arange(len(r)) - starts[r] < max_neighbours
        s, r = s[keep], r[keep]
    order = np.lexsort((s, r))
    return s[order], r[order]


class KdTreeRadiusGraph:
    """A stand-in for `torch_geometric.nn.radius_graph` on scipy's cKDTree, per example.

    Called as geoelements calls it: `(x, r, batch, loop, max_num_neighbors)`; returns
    `edge_index = [senders; receivers]` (PyG's source-to-target flow), as `[2, E]` int64. The time
    and size of every graph go to `stats`.
    """

    def __init__(self) -> None:
        self.stats = GraphStats()

    def __call__(
        self,
        x: torch.Tensor,
        r: float,
        batch: torch.Tensor | None = None,
        loop: bool = False,
        max_num_neighbors: int = 32,
        **_: object,
    ) -> torch.Tensor:
        start = time.perf_counter()
        positions = x.detach().cpu().numpy()
        ids = (
            np.zeros(len(positions), dtype=np.int64)
            if batch is None
            else batch.detach().cpu().numpy()
        )
        senders, receivers = [], []
        # Examples are contiguous runs of `batch` (geoelements builds it so).
        bounds = np.flatnonzero(np.diff(ids)) + 1
        for lo, hi in zip(np.r_[0, bounds], np.r_[bounds, len(ids)]):
            s, rr = kdtree_edges(positions[lo:hi], r, loop, max_num_neighbors)
            senders.append(s + lo)
            receivers.append(rr + lo)
        edge_index = torch.from_numpy(
            np.stack([np.concatenate(senders), np.concatenate(receivers)])
        )
        self.stats.record(time.perf_counter() - start, edge_index.shape[1])
        return edge_index.to(x.device)


class FixedRadiusGraph:
    """A stand-in for `radius_graph` that returns given edges (those of the input file).

    For the one-step comparison on the graph phi used; it checks that it is asked about as many
    particles as the edges were made for.
    """

    def __init__(self, senders: np.ndarray, receivers: np.ndarray, particles: int) -> None:
        self.edge_index = torch.from_numpy(
            np.stack([senders.astype(np.int64), receivers.astype(np.int64)])
        )
        self.particles = particles
        self.stats = GraphStats()

    def __call__(self, x: torch.Tensor, r: float, **_: object) -> torch.Tensor:
        if x.shape[0] != self.particles:
            raise ValueError(
                f"the input's edges are for {self.particles} particles, not {x.shape[0]}"
            )
        self.stats.record(0.0, self.edge_index.shape[1])
        return self.edge_index


# ---------------------------------------------------------------------------------------------
# geoelements and phi's model directory
# ---------------------------------------------------------------------------------------------


@dataclass
class Geoelements:
    """The imported geoelements modules."""

    learned_simulator: ModuleType
    noise_utils: ModuleType


def import_geoelements(src: pathlib.Path) -> Geoelements:
    """Imports geoelements' `gns` package from the checkout `src`."""
    if not (src / "gns" / "learned_simulator.py").is_file():
        sys.exit(f"{src} has no gns/learned_simulator.py: pass a checkout of geoelements/gns")
    sys.path.insert(0, str(src.resolve()))
    from gns import learned_simulator, noise_utils  # noqa: E402 (the checkout is now importable)

    return Geoelements(learned_simulator, noise_utils)


def use_radius_graph(geo: Geoelements, graph: Callable[..., torch.Tensor]) -> None:
    """Makes `LearnedSimulator` build its graphs with `graph` (the name it imported at load)."""
    geo.learned_simulator.radius_graph = graph


def read_spec(weights: pathlib.Path) -> dict:
    """`model.json` of the model directory holding `weights`."""
    path = weights.parent / "model.json"
    spec = json.loads(path.read_text())
    if spec.get("format") != "phi-gns-model":
        sys.exit(f"{path} is not a phi model ({spec.get('format')!r})")
    config = spec["config"]
    if not config["boundary_features"]:
        sys.exit(f"{path}: geoelements always has boundary features; this model has none")
    if config.get("boundary_horizon", 1.0) != 1.0:
        sys.exit(f"{path}: geoelements clips the boundary features at the radius; this model's "
                 f"boundary_horizon is {config['boundary_horizon']}")
    if (config["particle_types"] > 1) != (config["embedding_size"] > 0):
        sys.exit(f"{path}: geoelements embeds the particle type exactly when there are several")
    return spec


def normalisation_stats(spec: dict) -> dict[str, dict[str, torch.Tensor]]:
    """geoelements' `normalization_stats` for phi's spec: scales widened by the noise."""
    norm, noise = spec["normalisation"], spec["config"]["noise_std"]

    def scale(std: list[float]) -> torch.Tensor:
        return torch.sqrt(torch.tensor(std, dtype=torch.float32) ** 2 + noise**2)

    return {
        "acceleration": {
            "mean": torch.tensor(norm["acc_mean"], dtype=torch.float32),
            "std": scale(norm["acc_std"]),
        },
        "velocity": {
            "mean": torch.tensor(norm["vel_mean"], dtype=torch.float32),
            "std": scale(norm["vel_std"]),
        },
    }


def build_simulator(geo: Geoelements, spec: dict) -> torch.nn.Module:
    """A `LearnedSimulator` with the sizes of phi's `spec` (weights still geoelements' own)."""
    c = spec["config"]
    dim = c["dim"]
    embedding = c["embedding_size"] if c["particle_types"] > 1 else 0
    return geo.learned_simulator.LearnedSimulator(
        particle_dimensions=dim,
        nnode_in=c["input_velocities"] * dim + 2 * dim + embedding,
        nedge_in=dim + 1,
        latent_dim=c["latent_size"],
        nmessage_passing_steps=c["message_passing_steps"],
        nmlp_layers=c["hidden_layers"],
        mlp_hidden_dim=c["hidden_size"],
        connectivity_radius=c["connectivity_radius"],
        boundaries=np.array(spec["bounds"], dtype=np.float64),
        normalization_stats=normalisation_stats(spec),
        nparticle_types=c["particle_types"],
        particle_type_embedding_size=max(embedding, 1),
        boundary_clamp_limit=1.0,
        device="cpu",
    )


def _mlp(phi: str, geo: str, layers: int, layer_norm: bool) -> list[tuple[str, str]]:
    """(phi name, geoelements name) prefixes of one MLP's linear layers and LayerNorm."""
    # geoelements wraps an MLP with a LayerNorm as Sequential(mlp, LayerNorm): `.0.NN-i`, `.1`.
    inner = f"{geo}.0" if layer_norm else geo
    pairs = [(f"{phi}.{i}", f"{inner}.NN-{i}") for i in range(layers + 1)]
    if layer_norm:
        pairs.append((f"{phi}.ln", f"{geo}.1"))
    return pairs


def geoelements_state_dict(
    phi: dict[str, torch.Tensor], spec: dict, own: dict[str, torch.Tensor]
) -> dict[str, torch.Tensor]:
    """phi's weights under geoelements' names, the processor's first-layer columns permuted.

    `own` is the simulator's own state dict: it supplies the particle-type embedding when phi's
    model has none (geoelements then makes one it never reads).
    """
    c = spec["config"]
    layers, latent = c["hidden_layers"], c["latent_size"]
    epd = "_encode_process_decode"
    prefixes = _mlp("encoder.node", f"{epd}._encoder.node_fn", layers, True)
    prefixes += _mlp("encoder.edge", f"{epd}._encoder.edge_fn", layers, True)
    for k in range(c["message_passing_steps"]):
        step = f"{epd}._processor.gnn_stacks.{k}"
        prefixes += _mlp(f"processor.{k}.edge", f"{step}.edge_fn", layers, True)
        prefixes += _mlp(f"processor.{k}.node", f"{step}.node_fn", layers, True)
    prefixes += _mlp("decoder", f"{epd}._decoder.node_fn", layers, False)

    L = latent
    # Columns of geoelements' concatenation, as slices of phi's.
    edge_columns = [slice(2 * L, 3 * L), slice(L, 2 * L), slice(0, L)]  # [v_r, v_s, e]
    node_columns = [slice(L, 2 * L), slice(0, L)]  # [sums, v]

    state: dict[str, torch.Tensor] = {}
    used: set[str] = set()
    for phi_prefix, geo_prefix in prefixes:
        for leaf in ("weight", "bias"):
            name = f"{phi_prefix}.{leaf}"
            tensor = phi[name]
            used.add(name)
            first_layer = phi_prefix.startswith("processor.") and phi_prefix.endswith(".0")
            if leaf == "weight" and first_layer:
                columns = edge_columns if ".edge." in phi_prefix else node_columns
                tensor = torch.cat([tensor[:, s] for s in columns], dim=1)
            state[f"{geo_prefix}.{leaf}"] = tensor.contiguous()
    if "embedding.weight" in phi:
        state["_particle_type_embedding.weight"] = phi["embedding.weight"]
        used.add("embedding.weight")
    else:
        state["_particle_type_embedding.weight"] = own["_particle_type_embedding.weight"]
    unused = sorted(set(phi) - used)
    if unused:
        sys.exit(f"phi tensors with no place in geoelements' model: {unused}")
    return state


def load_simulator(geo: Geoelements, weights: pathlib.Path) -> tuple[torch.nn.Module, dict]:
    """geoelements' simulator with phi's weights from `weights`, and phi's spec."""
    spec = read_spec(weights)
    simulator = build_simulator(geo, spec)
    phi = load_file(str(weights))
    state = geoelements_state_dict(phi, spec, simulator.state_dict())
    simulator.load_state_dict(state, strict=True)
    return simulator, spec


def kinematic_mask(particle_type: np.ndarray, kinematic_types: list[int]) -> np.ndarray:
    """True for the particles whose types move by ground truth (obstacles)."""
    return np.isin(particle_type, np.asarray(kinematic_types, dtype=particle_type.dtype))


def check_input(data: "np.lib.npyio.NpzFile", spec: dict) -> None:
    """Exits when the input's normalisation, bounds or radius are not the model's."""
    norm = spec["normalisation"]
    pairs = [(k, norm[k]) for k in ("vel_mean", "vel_std", "acc_mean", "acc_std")]
    pairs += [("bounds", spec["bounds"]), ("radius", spec["config"]["connectivity_radius"])]
    for key, expected in pairs:
        if key in data and not np.allclose(data[key], np.asarray(expected), rtol=1e-12, atol=0):
            sys.exit(f"the input's {key} is not model.json's: {data[key]} != {expected}")
