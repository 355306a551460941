#!/usr/bin/env python3
"""Training losses of two `phi train` runs that drew the same batches, row by row.

Two runs with the same `training.seed`, batch size and data draw the same windows in the same
order, so the difference of their logged losses at one step is the difference the lever made on
those batches, free of the batch-to-batch spread (a mean over 100 steps moves by 2-3x from one
row to the next when a batch holds a wall impact). For every `train.csv` row the two runs share,
the log of the ratio `B / A`; reported per block of steps and over all of them as the mean log
ratio turned back into a percentage, with the number of rows where B is lower.

    python3 scripts/compare_losses.py A/train.csv B/train.csv [--from 100] [--to 4000] [--block 1000]

Standard library only. Exits with an error naming the file when a file is not a `train.csv`.
"""

import argparse
import csv
import math
import sys


def read_losses(path):
    """`{step: loss}` of a train.csv; rows without a loss (screening only) are skipped."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        sys.exit(f"{path}: cannot read: {e.strerror}")
    if not rows or "step" not in rows[0] or "loss" not in rows[0]:
        sys.exit(f"{path}: not a train.csv (needs the columns step and loss)")
    losses = {}
    for line, row in enumerate(rows, start=2):
        if not row["loss"]:
            continue
        try:
            step, loss = int(row["step"]), float(row["loss"])
        except ValueError:
            sys.exit(f"{path}:{line}: step {row['step']!r} or loss {row['loss']!r} is not a number")
        if not loss > 0 or not math.isfinite(loss):
            sys.exit(f"{path}:{line}: loss {loss} is not a positive finite number")
        losses[step] = loss
    return losses


def summary(pairs):
    """(percentage change of B against A, rows where B is lower, rows) of `[(a, b), ...]`."""
    mean_log = sum(math.log(b / a) for a, b in pairs) / len(pairs)
    lower = sum(b < a for a, b in pairs)
    return 100.0 * (math.exp(mean_log) - 1.0), lower, len(pairs)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("a", help="the baseline run's train.csv")
    parser.add_argument("b", help="the lever's train.csv")
    parser.add_argument("--from", dest="first", type=int, default=0, help="first step compared")
    parser.add_argument("--to", dest="last", type=int, default=None, help="last step compared")
    parser.add_argument("--block", type=int, default=1000, help="steps per reported block")
    args = parser.parse_args()
    if args.block <= 0:
        sys.exit(f"--block {args.block}: must be positive")

    a, b = read_losses(args.a), read_losses(args.b)
    steps = sorted(
        s for s in a.keys() & b.keys()
        if s >= args.first and (args.last is None or s <= args.last)
    )
    if not steps:
        sys.exit(f"{args.a} and {args.b} share no logged step in the range asked for")

    print("steps\tB against A\tB lower")
    blocks = {}
    for s in steps:
        blocks.setdefault((s - 1) // args.block, []).append((a[s], b[s]))
    for key in sorted(blocks):
        pairs = blocks[key]
        change, lower, n = summary(pairs)
        print(f"{key * args.block + 1}-{(key + 1) * args.block}\t{change:+.2f} %\t{lower} of {n}")
    change, lower, n = summary([(a[s], b[s]) for s in steps])
    print(f"{steps[0]}-{steps[-1]}\t{change:+.2f} %\t{lower} of {n}")


if __name__ == "__main__":
    main()
