"""Reading a phi dataset from the scripts: its `metadata.json` and one trajectory's `.npz`, with
errors that name the file. Imported by the scripts in this folder (it is on the path when one
of them runs); needs numpy."""

import json
import os
import sys

import numpy as np


def read_metadata(data):
    """(metadata dict, path) of the dataset folder `data`; exits naming the file if unreadable."""
    path = os.path.join(data, "metadata.json")
    try:
        with open(path) as f:
            return json.load(f), path
    except (OSError, json.JSONDecodeError) as e:
        sys.exit(f"error: {path}: cannot read the dataset's metadata ({e})")


def read_trajectory(data, split, index):
    """(positions [T, N, dim] as float64, particle types [N], path) of trajectory `index` of
    `split`; exits naming the file if it is missing or lacks either array."""
    path = os.path.join(data, split, f"traj_{index:05d}.npz")
    try:
        with np.load(path) as d:
            return d["position"].astype(np.float64), d["particle_type"], path
    except (OSError, KeyError, ValueError) as e:
        sys.exit(f"error: {path}: cannot read position and particle_type ({e})")
