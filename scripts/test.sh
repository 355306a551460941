#!/usr/bin/env bash
# Installs what the tests need (libtorch 2.11.0 into .venv-torch, for the tch backend) and runs every
# test of the workspace on every backend: ndarray, Burn and tch, then the Python module's tests
# (scripts/test-python.sh). Ends with the totals over all test binaries and pytest.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

bash scripts/setup-libtorch.sh >/dev/null
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
status=0
cargo test --workspace --features tch --no-fail-fast "$@" 2>&1 | tee "$log" || status=$?
# The Python module (phi-py/, outside the workspace): built and tested by pytest.
bash scripts/test-python.sh 2>&1 | tee -a "$log" || status=$?
# Cargo's `test result:` lines, and pytest's closing line (`=== 3 passed, 1 skipped in 2.0s ===`).
awk '/^test result:/ { passed += $4; failed += $6; ignored += $8 }
     /^=+ .* in [0-9.]+s/ {
         for (i = 2; i < NF; i++) {
             word = $(i + 1); gsub(/[,=]/, "", word)
             if (word == "passed") passed += $i
             else if (word == "failed" || word == "error" || word == "errors") failed += $i
             else if (word == "skipped" || word == "xfailed" || word == "deselected") ignored += $i
         }
     }
     END { printf "\ntotal: %d passed, %d failed, %d skipped\n", passed, failed, ignored }' "$log"
exit "$status"
