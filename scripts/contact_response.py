#!/usr/bin/env python3
"""Does a model stop liquid that touches an obstacle? Its one-step vertical acceleration of the
liquid near obstacles, against FLIP's, from one-step rollouts started at FLIP's own frames.

    for s in $(seq 18 2 38); do
        phi rollout --model MODEL --data DATA --trajectory I --start $s --steps 1 \\
            --frame-every 0 --out steps/s$s
    done
    python3 scripts/contact_response.py DATA test I steps/s*

Each rollout folder holds `SPLIT_I/rollout.npz` with one predicted frame after its start frame
`s` (FLIP's frames up to `s` are the input). For the liquid particles within R of an obstacle
particle in FLIP's frame `s` this prints the mean vertical acceleration `p[s+1] - 2 p[s] + p[s-1]`
of FLIP's next frame and of the model's, in units of gravity (`--gravity`, cells per second²,
9.81 as the random scenes and `phi model probe` have it, times dt² and the position scale of the
metadata), and the same for the liquid farther than 3 R from every obstacle. A model that stops liquid at obstacles as FLIP does reads FLIP's numbers
near them: a positive (upward) acceleration of several g at first contact.

With `--bands 0,1,3,5,10` it prints a second table: the same means for the liquid whose distance
to the nearest obstacle particle lies in each band (in units of R), FLIP's and the model's. FLIP's
pressure stops a whole falling block within a frame or two of its first contact; a network with
`M` message-passing steps sees at most `M` R from a particle, so a model that stops the block far
from the obstacle in the same frame as FLIP needs that reach.

Needs numpy (`benches/anchors/gns/requirements.txt` pins it).
"""

import argparse
import os
import sys

import numpy as np

# The scripts folder is on the path when one of its scripts runs.
from dataset_files import read_metadata, read_trajectory
from late_kinetic_energy import liquid_type


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", help="the phi dataset the rollouts started from")
    parser.add_argument("split")
    parser.add_argument("trajectory", type=int)
    parser.add_argument("rollouts", nargs="+", help="phi rollout --steps 1 output folders")
    parser.add_argument("--gravity", type=float, default=9.81, help="cells per second² (9.81)")
    parser.add_argument(
        "--bands",
        help="band edges of the distance to the obstacles in units of R, e.g. 0,1,3,5,10",
    )
    args = parser.parse_args()

    meta, meta_path = read_metadata(args.data)
    try:
        radius = float(meta["default_connectivity_radius"])
        gravity = args.gravity * float(meta["dt"]) ** 2 * float(meta["position_scale"])
    except (KeyError, TypeError, ValueError) as e:
        sys.exit(f"error: {meta_path}: cannot read the radius, dt or position_scale ({e})")
    if gravity <= 0.0:
        sys.exit(f"error: --gravity {args.gravity}: gravity must be > 0 to scale by")
    edges = []
    if args.bands is not None:
        try:
            edges = [float(e) for e in args.bands.split(",")]
        except ValueError as e:
            sys.exit(f"error: --bands {args.bands}: not a list of numbers ({e})")
        if len(edges) < 2 or any(b <= a for a, b in zip(edges, edges[1:])) or edges[0] < 0:
            sys.exit(f"error: --bands {args.bands}: needs two or more increasing edges from 0 up")
    liquid = liquid_type(meta)
    obstacle = [int(k) for k, v in meta.get("particle_types", {}).items() if v == "obstacle"]
    name = f"{args.split}_{args.trajectory}"
    truth, types, path = read_trajectory(args.data, args.split, args.trajectory)
    obstacles = truth[0, np.isin(types, obstacle)]
    if len(obstacles) == 0:
        sys.exit(f"error: {path}: the trajectory has no obstacle particles")
    is_liquid = types == liquid

    rows = []
    for folder in args.rollouts:
        rollout = os.path.join(folder, name, "rollout.npz")
        try:
            with np.load(rollout) as r:
                predicted = r["predicted_position"][0].astype(np.float64)
                start = int(r["start"][0])
        except (OSError, KeyError, ValueError, IndexError) as e:
            sys.exit(f"error: {rollout}: not a phi rollout of {name} ({e})")
        if predicted.shape != truth.shape[1:] or not 1 <= start < len(truth) - 1:
            sys.exit(f"error: {rollout}: start {start} or shape {predicted.shape} does not fit {path}")
        before, now = truth[start - 1], truth[start]
        true_acc = truth[start + 1] - 2 * now + before
        model_acc = predicted - 2 * now + before
        distance = np.sqrt(((now[:, None, :] - obstacles[None]) ** 2).sum(-1)).min(1)
        near = is_liquid & (distance <= radius)
        far = is_liquid & (distance > 3 * radius)
        rows.append((start, near, far, true_acc, model_acc, distance))

    print(f"{path}: vertical acceleration in units of g; near: liquid within R of an obstacle")
    print("start\tnear\tFLIP near\tmodel near\tFLIP far\tmodel far")
    mean = lambda a, m: f"{a[m, -1].mean() / gravity:.2f}" if m.any() else "–"
    rows.sort(key=lambda r: r[0])
    for start, near, far, true_acc, model_acc, _ in rows:
        print(
            f"{start}\t{int(near.sum())}\t{mean(true_acc, near)}\t{mean(model_acc, near)}"
            f"\t{mean(true_acc, far)}\t{mean(model_acc, far)}"
        )
    if not edges:
        return
    bands = list(zip(edges, edges[1:]))
    print(f"\nby distance to the nearest obstacle particle (units of R), FLIP / model (particles)")
    print("start\t" + "\t".join(f"{a:g}-{b:g} R" for a, b in bands))
    for start, _, _, true_acc, model_acc, distance in rows:
        cells = []
        for a, b in bands:
            band = is_liquid & (distance >= a * radius) & (distance < b * radius)
            cells.append(f"{mean(true_acc, band)} / {mean(model_acc, band)} ({int(band.sum())})")
        print(f"{start}\t" + "\t".join(cells))


if __name__ == "__main__":
    main()
