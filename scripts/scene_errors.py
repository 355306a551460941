"""How far a ten-scene mean can be trusted: each model's EMD and MSE 400 per test scene, read as
the mean, the median and the mean without the scenes that swing, beside a base model.

    python scripts/scene_errors.py BASE_CACHE [NAME=CACHE ...] [--leave-out 5,6]

A CACHE is a `phi eval` cache folder of one model (`OUT/cache/MODEL`, one `test_K.json` per
scene). For the base and each NAME=CACHE this prints, in 10⁻² stored units², the mean, the median
and the mean over the scenes not left out of the EMD and of MSE 400, and on how many scenes the
model is lower than the base (EMD / MSE 400). Both folders must hold the same scenes.

The ten test scenes are few, and some of them are bistable (liquid thrown at a thin wall ends on
one side or the other): one scene can move the mean by more than a lever does. The median and the
mean without such scenes say whether a difference of the means is the lever's or the scene's.

Needs the Python standard library only.
"""

import argparse
import json
import os
import statistics
import sys


def scene_errors(cache):
    """{scene index: (EMD, MSE 400)} in 10⁻² stored units² from a `phi eval` cache folder."""
    errors = {}
    try:
        names = os.listdir(cache)
    except OSError as e:
        sys.exit(f"error: {cache}: cannot read the folder ({e.strerror})")
    for name in names:
        if not (name.endswith(".json") and "_" in name):
            continue
        path = os.path.join(cache, name)
        with open(path) as f:
            try:
                evaluation = json.load(f)["evaluation"]
                index, emd, mse400 = evaluation["index"], evaluation["emd"], evaluation["mse400"]
            except (KeyError, TypeError, json.JSONDecodeError) as e:
                sys.exit(f"error: {path}: not a phi eval cache file ({e})")
        if emd is None or mse400 is None:
            sys.exit(f"error: {path}: the rollout of scene {index} has no EMD or MSE 400 (blown up?)")
        errors[index] = (100.0 * emd, 100.0 * mse400)
    if not errors:
        sys.exit(f"error: {cache}: no phi eval cache files (test_K.json)")
    return errors


def summary(errors, base, leave_out):
    """One line of figures: per metric the mean, median and mean without `leave_out`, then the
    scenes below `base` (None for the base itself)."""
    kept = [k for k in sorted(errors) if k not in leave_out]
    if not kept:
        sys.exit("error: --leave-out leaves no scene")
    cells = []
    for m in range(2):
        values = [errors[k][m] for k in sorted(errors)]
        cells += [
            statistics.mean(values),
            statistics.median(values),
            statistics.mean(errors[k][m] for k in kept),
        ]
    text = "\t".join(f"{v:.2f}" for v in cells)
    if base is None:
        return text + "\t"
    below = [sum(errors[k][m] < base[k][m] for k in errors) for m in range(2)]
    return text + f"\t{below[0]} / {below[1]}"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("base", help="the base model's phi eval cache folder")
    parser.add_argument("models", nargs="*", help="NAME=CACHE of the models to read beside it")
    parser.add_argument(
        "--leave-out", default="5,6", help="scenes left out of the third mean (default 5,6)"
    )
    args = parser.parse_args()
    try:
        leave_out = {int(k) for k in args.leave_out.split(",") if k.strip()}
    except ValueError:
        sys.exit(f"error: --leave-out {args.leave_out!r}: not a comma-separated list of scenes")

    base = scene_errors(args.base)
    rows = [(args.base, base, None)]
    for item in args.models:
        name, sep, cache = item.partition("=")
        if not sep or not name or not cache:
            sys.exit(f"error: {item!r}: expected NAME=CACHE")
        errors = scene_errors(cache)
        if set(errors) != set(base):
            sys.exit(f"error: {cache}: scenes {sorted(errors)}, the base has {sorted(base)}")
        rows.append((name, errors, base))

    left = ",".join(str(k) for k in sorted(leave_out))
    print(
        f"model\tEMD mean\tmedian\twithout {left}\tMSE 400 mean\tmedian\twithout {left}"
        "\tscenes below the base (EMD / MSE 400)"
    )
    for name, errors, against in rows:
        print(f"{name}\t{summary(errors, against, leave_out)}")


if __name__ == "__main__":
    main()
