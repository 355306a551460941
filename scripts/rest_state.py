"""Does a model leave liquid at rest alone? Rollouts of a still scene (`scenes/rest/`) read as drift.

    phi dataset generate --split test --scenes scenes/rest --out data/rest
    phi rollout --model MODEL --walls clamp --data data/rest --split test --all --frame-every 0 --out rest-MODEL
    python scripts/rest_state.py data/rest test rest-MODEL [rest-OTHER ...]

FLIP leaves a pool at rest where it is (its particles move by 1e-6 stored units in 400 frames).
A learned simulator has no such guarantee: its per-particle acceleration errors at rest, however
small, integrate into motion, and nothing in the network pulls a compressed region apart again.
Per rollout directory and trajectory this prints, from the model's frames:

- the mean number of liquid neighbours within R of a liquid particle over FLIP's (the evaluation's
  density ratio), averaged over the second half of the rollout and in its last frame;
- the 90th percentile of the neighbour counts in the last frame over the first frame's (packing
  inside the liquid, where a particle has neighbours all round);
- the RMS displacement of the particles from where they started, in cells (`position_scale`);
- the RMS speed over the last 50 frames, in cells a frame.

Needs numpy only (`benches/anchors/gns/requirements.txt` pins it).
"""

import json
import os
import sys

import numpy as np

from late_kinetic_energy import liquid_type  # the scripts folder is on the path when run
from neighbour_counts import neighbour_counts


def rest_state(predicted, true, radius, cell):
    """The drift figures of one rollout: `predicted` and `true` are [T, N, dim] liquid positions."""
    half = len(predicted) // 2
    frames = range(half, len(predicted), max(1, (len(predicted) - half) // 20))
    ratios = [
        neighbour_counts(predicted[t], radius).mean() / neighbour_counts(true[t], radius).mean()
        for t in frames
    ]
    last = neighbour_counts(predicted[-1], radius)
    first = neighbour_counts(true[0], radius)
    last_ratio = last.mean() / neighbour_counts(true[-1], radius).mean()
    displacement = np.sqrt(((predicted[-1] - true[0]) ** 2).sum(-1).mean()) / cell
    velocity = np.diff(predicted[-51:], axis=0)
    speed = np.sqrt((velocity**2).sum(-1).mean()) / cell
    return (
        float(np.mean(ratios)),
        float(last_ratio),
        float(np.percentile(last, 90) / np.percentile(first, 90)),
        float(displacement),
        float(speed),
    )


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    data, split, rollouts = sys.argv[1], sys.argv[2], sys.argv[3:]
    with open(os.path.join(data, "metadata.json")) as f:
        metadata = json.load(f)
    radius = metadata["default_connectivity_radius"]
    cell = metadata["position_scale"]
    liquid = liquid_type(metadata)
    print(f"a pool at rest against FLIP's ({data}, split {split}; R = {radius}, cell = {cell})")
    print("rollouts\ttrajectory\tdensity, 2nd half\tdensity, last\tp90 last/first\t"
          "RMS displacement (cells)\tRMS speed, last 50 (cells/frame)")
    for folder in rollouts:
        runs = sorted(d for d in os.listdir(folder) if d.startswith(f"{split}_"))
        if not runs:
            sys.exit(f"{folder}: no {split}_* rollout (run `phi rollout --all --out {folder}`)")
        for run in runs:
            path = os.path.join(folder, run, "rollout.npz")
            try:
                r = np.load(path)
                kind = r["particle_type"]
                predicted, true = r["predicted_position"], r["true_position"]
            except (OSError, KeyError, ValueError) as e:
                sys.exit(f"{path}: not a phi rollout.npz: {e}")
            mask = kind == liquid
            figures = rest_state(predicted[:, mask], true[:, mask], radius, cell)
            print(f"{folder}\t{run}\t" + "\t".join(f"{v:.2f}" for v in figures))


if __name__ == "__main__":
    main()
