#!/usr/bin/env bash
# Installs what the tests need (libtorch 2.9.0 into .venv-torch, for the tch backend) and runs every
# test of the workspace on every backend: ndarray, Burn and tch.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

bash scripts/setup-libtorch.sh >/dev/null
cargo test --workspace --features tch "$@"
