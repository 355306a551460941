"""How dense the liquid is at the start and at the end of each trajectory, FLIP's and a model's.

    python scripts/neighbour_counts.py data/flip test                  # FLIP alone
    python scripts/neighbour_counts.py data/flip test rollouts         # and `phi rollout --all --out rollouts`
    python scripts/neighbour_counts.py data/flip test rollouts 0.03    # the radius, stored units

The evaluation's final-density criterion divides the mean number of liquid neighbours within R
of a liquid particle in the prediction's last frame by the same in FLIP's. A mean mixes how
tightly the particles are packed with the pool's shape (a particle at a free surface has fewer
neighbours, and a flat pool has more of them). The 90th percentile of the counts reads the
packing inside the liquid, where a particle has neighbours all round. This prints both, for the
first frame (the scene's blocks, as the generator placed them) and for the last, FLIP's and, if
a directory of `phi rollout --all` results is given, the model's; and, over all frames, the
largest share of the liquid lying on a wall (within 1/20 of a cell, `position_scale`, of the
domain's bounds), where clamping into the box stacks it.

Needs numpy only (`benches/anchors/gns/requirements.txt` pins it). Reads phi's npz trajectories,
`metadata.json` (the particle type named "liquid", the connectivity radius) and each rollout's
`rollout.npz` (`predicted_position`, whose last row is the trajectory's last frame).
"""

import json
import os
import sys

import numpy as np

from late_kinetic_energy import liquid_type  # the scripts folder is on the path when run


def neighbour_counts(x, radius):
    """For each point of `x` ([N, dim]), how many others lie within `radius` (brute force)."""
    counts = np.empty(len(x), dtype=np.int64)
    for start in range(0, len(x), 256):
        block = x[start : start + 256]
        d2 = ((block[:, None, :] - x[None, :, :]) ** 2).sum(-1)
        counts[start : start + len(block)] = (d2 <= radius * radius).sum(1) - 1
    return counts


def most_on_walls(x, bounds, cell):
    """The largest fraction, over the frames of `x` ([T, N, dim]), of points within cell / 20 of a wall."""
    gap = np.minimum(x - bounds[:, 0], bounds[:, 1] - x).min(-1)
    return (gap < cell / 20).mean(1).max()


def summary(counts):
    return counts.mean(), np.percentile(counts, 90)


def main(argv):
    if len(argv) < 3:
        raise SystemExit(__doc__)
    data, split = argv[1], argv[2]
    rollouts = argv[3] if len(argv) > 3 else None
    with open(os.path.join(data, "metadata.json")) as f:
        metadata = json.load(f)
    liquid = liquid_type(metadata)
    radius = float(argv[4]) if len(argv) > 4 else float(metadata["default_connectivity_radius"])
    count = metadata["splits"][split]
    bounds = np.array(metadata["bounds"], dtype=np.float64)
    cell = float(metadata["position_scale"])
    header = "traj  first: mean  p90 | FLIP last: mean  p90  p90/first  on walls"
    if rollouts:
        header += " | model last: mean  p90  p90/first  on walls"
    print(f"liquid neighbours within {radius} ({data}, split {split})")
    print(header)
    rows = []
    for i in range(count):
        with np.load(os.path.join(data, split, f"traj_{i:05d}.npz")) as t:
            positions = t["position"].astype(np.float64)
            kinds = t["particle_type"]
        x = positions[:, kinds == liquid]
        first = summary(neighbour_counts(x[0], radius))
        last = summary(neighbour_counts(x[-1], radius))
        walls = most_on_walls(x, bounds, cell)
        row = [first[0], first[1], last[0], last[1], last[1] / first[1], walls]
        line = f"{i:4d}  {first[0]:11.1f} {first[1]:4.0f} | {last[0]:15.1f} {last[1]:4.0f} {last[1] / first[1]:10.2f} {walls:9.0%}"
        if rollouts:
            path = os.path.join(rollouts, f"{split}_{i}", "rollout.npz")
            if not os.path.exists(path):
                raise SystemExit(f"{path}: no rollout of {split} trajectory {i} (run `phi rollout --all`)")
            with np.load(path) as r:
                if r["particle_type"].shape != kinds.shape or (r["particle_type"] != kinds).any():
                    raise SystemExit(f"{path}: its particle types are not those of {split} trajectory {i}")
                predicted = r["predicted_position"][:, kinds == liquid].astype(np.float64)
            model = summary(neighbour_counts(predicted[-1], radius))
            walls = most_on_walls(predicted, bounds, cell)
            row += [model[0], model[1], model[1] / first[1], walls]
            line += f" | {model[0]:16.1f} {model[1]:4.0f} {model[1] / first[1]:10.2f} {walls:9.0%}"
        rows.append(row)
        print(line)
    mean = np.array(rows).mean(0)
    line = f"mean  {mean[0]:11.1f} {mean[1]:4.0f} | {mean[2]:15.1f} {mean[3]:4.0f} {mean[4]:10.2f} {mean[5]:9.0%}"
    if rollouts:
        line += f" | {mean[6]:16.1f} {mean[7]:4.0f} {mean[8]:10.2f} {mean[9]:9.0%}"
    print(line)


if __name__ == "__main__":
    main(sys.argv)
