#!/usr/bin/env python3
"""A rollout's liquid density over time against FLIP's, from `phi eval`'s per-trajectory cache.

`phi eval --out OUT` keeps, for every model and trajectory, `OUT/cache/MODEL/SPLIT_I.json` with the
curves `density_predicted` and `density_true`: the mean number of liquid neighbours within the
density radius of a liquid particle, per frame. Their ratio is the final-density criterion at the
last frame; here it is read along the rollout, to tell a pool compressed at its first impact from
one that packs together slowly while it rests:

- `peak`: the largest ratio up to frame `--impact-until` (100), and the frame where it occurs;
- the ratio at the frames given with `--frames` (default 50 100 200 300, and the last frame).

    python3 scripts/density_over_time.py NAME=OUT/cache/MODEL [NAME=...] [--frames 50 100 200 300]

Per trajectory and the mean over the trajectories of each cache. Standard library only.
"""

import argparse
import glob
import json
import os
import sys


def load_curves(path):
    """(frames, ratio per frame) of one cached trajectory."""
    try:
        with open(path) as f:
            doc = json.load(f)
    except (OSError, json.JSONDecodeError) as e:
        sys.exit(f"{path}: cannot read a phi eval cache file: {e}")
    if doc.get("format") != "phi-eval-trajectory":
        sys.exit(f"{path}: format is {doc.get('format')!r}, not 'phi-eval-trajectory'")
    try:
        curves = doc["evaluation"]["curves"]
        frames = curves["frame"]
        predicted, true = curves["density_predicted"], curves["density_true"]
    except (KeyError, TypeError) as e:
        sys.exit(f"{path}: evaluation.curves lacks {e}")
    if not frames or len(predicted) != len(frames) or len(true) != len(frames):
        sys.exit(f"{path}: evaluation.curves.frame and the density curves differ in length")
    if any(t is None or t <= 0 for t in true) or any(p is None for p in predicted):
        sys.exit(f"{path}: a density curve holds a missing or non-positive value")
    return frames, [p / t for p, t in zip(predicted, true)]


def trajectory_key(path):
    """Sort `test_10.json` after `test_9.json`."""
    stem = os.path.splitext(os.path.basename(path))[0]
    split, _, index = stem.rpartition("_")
    return (split, int(index)) if index.isdigit() else (stem, -1)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("caches", nargs="+", metavar="NAME=DIR", help="a model's cache folder")
    parser.add_argument("--frames", type=int, nargs="+", default=[50, 100, 200, 300])
    parser.add_argument("--impact-until", type=int, default=100)
    args = parser.parse_args()

    header = ["trajectory", "peak", "peak frame"] + [f"@{f}" for f in args.frames] + ["last"]
    for spec in args.caches:
        name, sep, folder = spec.partition("=")
        if not sep or not name or not folder:
            sys.exit(f"{spec!r}: expected NAME=DIR")
        files = sorted(glob.glob(os.path.join(folder, "*.json")), key=trajectory_key)
        if not files:
            sys.exit(f"{folder}: no cached trajectory (*.json)")
        print(f"## {name} ({folder})")
        print("\t".join(header))
        rows = []
        for path in files:
            frames, ratio = load_curves(path)
            early = [i for i, f in enumerate(frames) if f <= args.impact_until]
            if not early:
                sys.exit(f"{path}: no frame up to --impact-until {args.impact_until}")
            peak = max(early, key=lambda i: ratio[i])
            at = []
            for f in args.frames:
                if f not in frames:
                    sys.exit(f"{path}: frame {f} is not in the rollout ({frames[0]}-{frames[-1]})")
                at.append(ratio[frames.index(f)])
            rows.append([ratio[peak]] + at + [ratio[-1]])
            label = os.path.splitext(os.path.basename(path))[0]
            values = [f"{v:.2f}" for v in rows[-1]]
            print("\t".join([label, values[0], str(frames[peak])] + values[1:]))
        means = [sum(column) / len(rows) for column in zip(*rows)]
        print("\t".join(["mean", f"{means[0]:.2f}", ""] + [f"{v:.2f}" for v in means[1:]]))
        print()


if __name__ == "__main__":
    main()
