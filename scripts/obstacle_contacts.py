#!/usr/bin/env python3
"""How much of a dataset's liquid meets an obstacle, against how much meets a wall.

    python3 scripts/obstacle_contacts.py DATA [--split train] [--trajectories 100]

Per liquid particle-frame (frames 1 to T-1, where the acceleration p[t+1] - 2 p[t] + p[t-1] is
defined) this asks whether an obstacle particle lies within the connectivity radius R (the
graph's own reach, so a model can see it) and whether a wall of the domain's bounds does, and
prints for both: the share of particle-frames, the share of the squared normalised acceleration
(what a squared-error loss weighs), and the share of the largest events (normalised acceleration
beyond --big, default 4.7 `acc_std`, the top 1 % of the training split). Obstacles are static, so
their reach is rasterised once per trajectory on a grid of R/4 and the liquid looked up in it.

Needs numpy (`benches/anchors/gns/requirements.txt` pins it).
"""

import argparse
import sys

import numpy as np

# The scripts folder is on the path when one of its scripts runs.
from dataset_files import read_metadata, read_trajectory
from late_kinetic_energy import liquid_type


def obstacle_reach(obstacles, radius, step, cells):
    """A [cells, cells] mask of the grid points (spacing `step`, from 0) within `radius` of an
    obstacle particle."""
    mask = np.zeros((cells, cells), bool)
    grid = np.arange(cells) * step
    for p in obstacles:
        ix = slice(max(0, int((p[0] - radius) / step)), min(cells, int((p[0] + radius) / step) + 2))
        iy = slice(max(0, int((p[1] - radius) / step)), min(cells, int((p[1] + radius) / step) + 2))
        x, y = np.meshgrid(grid[ix], grid[iy], indexing="ij")
        mask[ix, iy] |= (x - p[0]) ** 2 + (y - p[1]) ** 2 <= radius * radius
    return mask


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", help="a phi dataset folder (metadata.json, SPLIT/traj_*.npz)")
    parser.add_argument("--split", default="train")
    parser.add_argument("--trajectories", type=int, default=100, help="the first N (default 100)")
    parser.add_argument("--big", type=float, default=4.7, help="a large event, in acc_std")
    args = parser.parse_args()

    meta, meta_path = read_metadata(args.data)
    try:
        radius = float(meta["default_connectivity_radius"])
        lower = np.array([b[0] for b in meta["bounds"]], float)
        upper = np.array([b[1] for b in meta["bounds"]], float)
        acc_mean, acc_std = np.array(meta["acc_mean"], float), np.array(meta["acc_std"], float)
        count = int(meta["splits"][args.split])
    except (KeyError, TypeError, ValueError) as e:
        sys.exit(f"error: {meta_path}: cannot read the radius, bounds, statistics or split ({e})")
    if len(lower) != 2:
        sys.exit(f"error: {meta_path}: bounds of {len(lower)} dimensions; this script reads 2D data")
    liquid = liquid_type(meta)
    obstacle = [int(k) for k, v in meta.get("particle_types", {}).items() if v == "obstacle"]

    step = radius / 4
    cells = int(np.ceil(float(upper.max()) / step)) + 2
    n = min(args.trajectories, count)
    sums = dict.fromkeys(["frames", "obs", "wall", "big", "big_obs", "big_wall"], 0)
    energy = dict.fromkeys(["all", "obs", "wall"], 0.0)
    with_obstacles = 0
    for i in range(n):
        position, types, _ = read_trajectory(args.data, args.split, i)
        obstacles = position[0, np.isin(types, obstacle)]
        reach = obstacle_reach(obstacles, radius, step, cells)
        with_obstacles += len(obstacles) > 0
        p = position[:, types == liquid]
        acc = (p[2:] - 2 * p[1:-1] + p[:-2] - acc_mean) / acc_std
        size2 = (acc**2).sum(-1)
        at = p[1:-1]
        index = np.clip(np.rint(at / step).astype(int), 0, cells - 1)
        near_obstacle = reach[index[..., 0], index[..., 1]]
        near_wall = ((at - lower) < radius).any(-1) | ((upper - at) < radius).any(-1)
        big = size2 > args.big**2
        sums["frames"] += size2.size
        sums["obs"] += int(near_obstacle.sum())
        sums["wall"] += int(near_wall.sum())
        sums["big"] += int(big.sum())
        sums["big_obs"] += int((big & near_obstacle).sum())
        sums["big_wall"] += int((big & near_wall).sum())
        energy["all"] += float(size2.sum())
        energy["obs"] += float(size2[near_obstacle].sum())
        energy["wall"] += float(size2[near_wall].sum())

    if sums["frames"] == 0 or sums["big"] == 0:
        sys.exit("error: no liquid particle-frames, or none beyond --big, to share out")
    print(
        f"{args.data} {args.split}: {n} trajectories ({with_obstacles} with obstacles), "
        f"{sums['frames']} liquid particle-frames, R = {radius}"
    )
    print("within R of\tparticle-frames\tsquared normalised acceleration\tevents beyond --big")
    for name, key in (("an obstacle", "obs"), ("a wall", "wall")):
        print(
            f"{name}\t{sums[key] / sums['frames']:.1%}\t{energy[key] / energy['all']:.1%}"
            f"\t{sums['big_' + key] / sums['big']:.1%}"
        )


if __name__ == "__main__":
    main()
