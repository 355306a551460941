#!/usr/bin/env bash
# Builds phi (release, default backends) and simulates every example scene in scenes/ on the
# default ndarray backend. Each run writes out/<scene>/: trajectory.npz, run.json, frames/ and
# simulation.gif. Extra arguments go to every `phi simulate` call (e.g. --backend burn).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

cargo build --release --quiet
for scene in scenes/*.toml; do
    name="$(basename "$scene" .toml)"
    target/release/phi simulate "$scene" --out "out/$name" --frame-every 2 "$@"
    echo
done
echo "GIFs:"
ls -1 out/*/simulation.gif
