#!/usr/bin/env python3
"""Does liquid go through the obstacles? The largest share of the liquid inside obstacle cells in
any one frame of a rollout, against FLIP's, from `phi eval`'s per-trajectory cache.

`phi eval`'s plausibility criterion counts the liquid particle-frames inside obstacle cells over
the whole rollout. A block that passes through a thin obstacle is inside it for a few frames of
several hundred, so it reads under 1 % there although most of the block went through. The
per-frame curves in `OUT/cache/MODEL/SPLIT_I.json` (`inside_obstacles`, `inside_obstacles_true`:
liquid particles inside obstacle cells, per frame) show the passage: per trajectory this prints
the peak share of the liquid inside obstacle cells (model, FLIP), the frame of the model's peak,
and the number of frames in which more than `--above` (default 5 %) of the liquid is inside.

    python3 scripts/obstacle_passage.py NAME=OUT/cache/MODEL [NAME=...] [--above 0.05]

The last line of each model is the mean over the trajectories that have obstacles (FLIP's liquid
touches their cells at some frame, or the model's does). Standard library only.
"""

import argparse
import glob
import json
import os
import sys


def passage(path, above):
    """(index, peak share, FLIP's peak share, frame of the peak, frames above `above`), or None
    for a trajectory whose liquid never touches an obstacle cell, model's or FLIP's."""
    try:
        with open(path) as f:
            evaluation = json.load(f)["evaluation"]
        curves = evaluation["curves"]
        liquid = evaluation["liquid_particles"]
        frames, model, truth = (
            curves["frame"],
            curves["inside_obstacles"],
            curves["inside_obstacles_true"],
        )
    except (OSError, KeyError, TypeError, json.JSONDecodeError) as e:
        sys.exit(f"error: {path}: not a phi eval cache file with obstacle curves ({e})")
    if not liquid or not frames or len(model) != len(frames) or len(truth) != len(frames):
        sys.exit(f"error: {path}: the obstacle curves do not match the frames")
    if max(model) == 0 and max(truth) == 0:
        return None
    peak = max(range(len(frames)), key=lambda i: model[i])
    return (
        evaluation["index"],
        model[peak] / liquid,
        max(truth) / liquid,
        frames[peak],
        sum(1 for v in model if v / liquid > above),
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("caches", nargs="+", help="NAME=CACHE: a phi eval cache folder of one model")
    parser.add_argument(
        "--above", type=float, default=0.05, help="count the frames above this share (default 0.05)"
    )
    args = parser.parse_args()
    if not 0.0 <= args.above < 1.0:
        sys.exit(f"error: --above {args.above}: not a share in [0, 1)")

    for item in args.caches:
        name, sep, cache = item.partition("=")
        if not sep or not name or not cache:
            sys.exit(f"error: {item!r}: expected NAME=CACHE")
        paths = sorted(
            glob.glob(os.path.join(cache, "*_*.json")),
            key=lambda p: int(os.path.basename(p).rsplit("_", 1)[1].split(".")[0]),
        )
        if not paths:
            sys.exit(f"error: {cache}: no phi eval cache files (SPLIT_I.json)")
        print(f"## {name} ({cache})")
        print(f"trajectory\tpeak inside\tFLIP's peak\tat frame\tframes above {args.above:.0%}")
        rows = []
        for path in paths:
            row = passage(path, args.above)
            if row is None:
                continue
            rows.append(row)
            index, share, truth, frame, count = row
            print(f"{index}\t{share:.1%}\t{truth:.1%}\t{frame}\t{count}")
        if rows:
            mean = lambda k: sum(r[k] for r in rows) / len(rows)
            print(f"mean of {len(rows)}\t{mean(1):.1%}\t{mean(2):.1%}\t\t{mean(4):.1f}")
        else:
            print("no trajectory has obstacles")
        print()


if __name__ == "__main__":
    main()
