#!/usr/bin/env bash
# Installs what the tests need (libtorch 2.11.0 into .venv-torch, for the tch backend) and runs every
# test of the workspace on every backend: ndarray, Burn and tch. Ends with the totals over all test
# binaries.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

bash scripts/setup-libtorch.sh >/dev/null
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
cargo test --workspace --features tch "$@" 2>&1 | tee "$log"
awk '/^test result:/ { passed += $4; failed += $6; ignored += $8 }
     END { printf "\ntotal: %d passed, %d failed, %d skipped\n", passed, failed, ignored }' "$log"
