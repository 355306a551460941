#!/usr/bin/env bash
# Builds phi (release, default backends) and simulates every example scene in scenes/ on the
# default ndarray backend. Each run writes out/<scene>/: trajectory.npz, run.json, frames/ and
# simulation.gif. Extra arguments go to every `phi simulate` call (e.g. --backend burn).
# Then the learned simulator shipped in experiments/levers/two-step-r040-impacts-8000 (the
# CPU-scale model of docs/gns.md, "What limits learning", with clamped walls and liquid pushed
# out of obstacles) rolls out test scene 4 of the thesis's dataset next to its FLIP ground truth:
# out/gns-rollout/test_4/rollout.gif.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

cargo build --release --quiet
for scene in scenes/*.toml; do
    name="$(basename "$scene" .toml)"
    target/release/phi simulate "$scene" --out "out/$name" --frame-every 2 --force "$@"
    echo
done
# The first five test scenes of table 5.1 (the same as in `phi dataset generate --split all`).
target/release/phi dataset generate --out out/gns-test --split test --trajectories 5
target/release/phi rollout --model experiments/levers/two-step-r040-impacts-8000 --data out/gns-test --trajectory 4 \
    --out out/gns-rollout --frame-every 2 --force
echo
echo "GIFs:"
ls -1 out/*/simulation.gif out/gns-rollout/test_4/rollout.gif
