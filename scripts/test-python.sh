#!/usr/bin/env bash
# Builds the Python module `phi_rs` (phi-py/) into the virtual environment .venv-py and runs its
# tests (pytest, phi-py/tests), which compare it with the `phi` command line built here.
# Arguments go to pytest. PYTHON picks the interpreter that makes the environment (>= 3.9).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

if [ ! -x .venv-py/bin/python ]; then
    "${PYTHON:-python3}" -m venv .venv-py
fi
export PATH="$PWD/.venv-py/bin:$PATH"
pip install --quiet -r phi-py/requirements-test.txt
# PyTorch for `phi_rs.torch`'s tests (about 3 GB with the CUDA libraries it loads; see the file).
# PHI_PY_TORCH=0 leaves it out, and those tests are skipped.
if [ "${PHI_PY_TORCH:-1}" != 0 ]; then
    pip install --quiet --no-deps --no-cache-dir -r phi-py/requirements-torch.txt
fi
# One target folder for the module and the `phi` binary: they share the compiled crates.
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/target}"
cargo build --release --bin phi
pip install --quiet --no-build-isolation --force-reinstall --no-deps ./phi-py
pytest phi-py/tests "$@"
