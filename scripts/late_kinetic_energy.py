"""How much of a FLIP trajectory's late kinetic energy is bulk motion, and how much particle noise.

    python scripts/late_kinetic_energy.py data/flip test          # every trajectory of the split
    python scripts/late_kinetic_energy.py data/flip test 50 16 8  # frames, then cell counts

The evaluation's plausibility criterion compares the liquid's kinetic energy over the last 50
frames with FLIP's. FLIP's particles carry noise of their own (each moves with the grid's velocity
plus its own history), so a model could fail that criterion by not reproducing noise. This splits
FLIP's late kinetic energy (per particle, `½|x_t − x_{t−1}|²` in stored units per frame, as
`phi eval` measures it) into the part carried by the mean velocity of the liquid in each cell of
a coarse grid over the domain's bounds, and the rest. A fraction near 1 at a coarse grid says the
late motion is coherent (sloshing); near 0, that it is particle-level noise.

Needs numpy only (`benches/anchors/gns/requirements.txt` pins it). Reads phi's npz trajectories
and `metadata.json` (the particle type named "liquid").
"""

import json
import os
import sys

import numpy as np


def liquid_type(metadata):
    names = metadata["particle_types"]
    for key, name in names.items():
        if name == "liquid":
            return int(key)
    raise SystemExit(f"metadata.json: particle_types {names} names no 'liquid' type")


def coherent_fraction(positions, velocities, lower, upper, cells):
    """The kinetic energy of the per-cell mean velocity over the total, summed over frames."""
    total, coherent = 0.0, 0.0
    for x, v in zip(positions, velocities):
        index = np.floor((x - lower) / (upper - lower) * cells).astype(np.int64)
        index = np.clip(index, 0, cells - 1)
        key = index[:, 0] * cells + index[:, 1]
        for axis in range(2, x.shape[1]):
            key = key * cells + index[:, axis]
        _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
        mean = np.zeros((counts.size, v.shape[1]))
        np.add.at(mean, inverse, v)
        mean /= counts[:, None]
        total += 0.5 * (v**2).sum()
        coherent += 0.5 * (mean[inverse] ** 2).sum()
    return coherent / total


def main(argv):
    if len(argv) < 3:
        raise SystemExit(__doc__)
    data, split = argv[1], argv[2]
    frames = int(argv[3]) if len(argv) > 3 else 50
    grids = [int(n) for n in argv[4:]] or [32, 16, 8]
    with open(os.path.join(data, "metadata.json")) as f:
        metadata = json.load(f)
    liquid = liquid_type(metadata)
    bounds = np.array(metadata["bounds"], dtype=np.float64)
    lower, upper = bounds[:, 0], bounds[:, 1]
    folder = os.path.join(data, split)
    names = sorted(n for n in os.listdir(folder) if n.endswith(".npz"))
    if not names:
        raise SystemExit(f"{folder}: no .npz trajectories")
    print("trajectory     late KE    " + "  ".join(f"1/{n} cells" for n in grids) + "  centre of mass")
    fractions = {n: [] for n in grids}
    for name in names:
        with np.load(os.path.join(folder, name)) as npz:
            x = npz["position"].astype(np.float64)
            mask = npz["particle_type"] == liquid
        if x.shape[0] <= frames:
            raise SystemExit(f"{name}: {x.shape[0]} frames, not more than {frames}")
        x = x[:, mask]
        v = x[-frames:] - x[-frames - 1 : -1]
        total = 0.5 * (v**2).sum(axis=2).mean()
        centre = 0.5 * (v.mean(axis=1) ** 2).sum(axis=1).mean() / total
        row = []
        for n in grids:
            fraction = coherent_fraction(x[-frames:], v, lower, upper, n)
            fractions[n].append(fraction)
            row.append(f"{fraction:10.2f}")
        print(f"{name:<14} {total:.3e}  " + "  ".join(row) + f"  {centre:13.3f}")
    print("range" + " " * 21 + "  ".join(
        f"{min(fractions[n]):.2f}–{max(fractions[n]):.2f}".rjust(10) for n in grids))


if __name__ == "__main__":
    main(sys.argv)
