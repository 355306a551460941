"""What calling phi through Python costs over the command line: whole processes, timed in
alternating pairs (CLI, Python, CLI, ...), so that a drift of the machine's speed hits both.

    python benches/python/overhead.py [--phi target/release/phi] [--runs 7]

Run it with the interpreter that has `phi_rs` installed (scripts/test-python.sh installs it into
.venv-torch). Three cases:

- start-up: `phi --version` against `python -c "import phi_rs"` (the interpreter, NumPy and
  the extension module), the fixed cost of every Python call below;
- FLIP: `phi simulate SCENE --steps S` (no frames; the trajectory written once, at the end)
  against `phi_rs.simulate(SCENE, steps=S)`, which returns the same arrays;
- rollout: `phi rollout` of a model on one trajectory (no frames; `rollout.npz` written once)
  against `Model.load(...).rollout(...)` on the same trajectory.

Prints each command's median wall time and the median of the per-pair ratios Python / CLI.
"""

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def wall(command):
    start = time.perf_counter()
    subprocess.run(command, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def compare(name, cli, python, runs):
    wall(cli), wall(python)  # warm the page cache and the binaries
    pairs = [(wall(cli), wall(python)) for _ in range(runs)]
    cli_s = statistics.median(c for c, _ in pairs)
    py_s = statistics.median(p for _, p in pairs)
    ratio = statistics.median(p / c for c, p in pairs)
    spread = (min(p / c for c, p in pairs), max(p / c for c, p in pairs))
    print(f"| {name} | {cli_s:.3f} | {py_s:.3f} | {ratio:.3f} ({spread[0]:.3f}-{spread[1]:.3f}) |",
          flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--phi", default=str(ROOT / "target/release/phi"))
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--scene", default="scenes/block_pool.toml")
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--model", default="experiments/levers/mirror-average-clamp")
    parser.add_argument("--data", default="data/flip")
    parser.add_argument("--split", default="test")
    parser.add_argument("--trajectory", type=int, default=4)
    parser.add_argument("--rollout-steps", type=int, default=100)
    args = parser.parse_args()
    print("| case | CLI (s) | Python (s) | Python / CLI (min-max) |")
    print("|---|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        compare("start-up", [args.phi, "--version"], [sys.executable, "-c", "import phi_rs"],
                args.runs)
        compare(
            f"FLIP: {args.scene}, {args.steps} steps",
            [args.phi, "-q", "simulate", args.scene, "--steps", str(args.steps),
             "--frame-every", "0", "--checkpoint-every", str(args.steps),
             "--out", f"{tmp}/simulate", "--force"],
            [sys.executable, "-c",
             f"import phi_rs; phi_rs.simulate({args.scene!r}, steps={args.steps})"],
            args.runs,
        )
        compare(
            f"rollout: {args.model}, {args.split} {args.trajectory}, {args.rollout_steps} steps",
            [args.phi, "-q", "rollout", "--model", args.model, "--data", args.data,
             "--split", args.split, "--trajectory", str(args.trajectory),
             "--steps", str(args.rollout_steps), "--frame-every", "0",
             "--checkpoint-every", str(args.rollout_steps), "--out", f"{tmp}/rollout",
             "--force"],
            [sys.executable, "-c",
             "import phi_rs\n"
             f"model = phi_rs.Model.load({args.model!r})\n"
             f"positions, types = phi_rs.Dataset({args.data!r})[{args.split!r}, "
             f"{args.trajectory}]\n"
             f"model.rollout(positions, types, steps={args.rollout_steps})\n"],
            args.runs,
        )


if __name__ == "__main__":
    main()
