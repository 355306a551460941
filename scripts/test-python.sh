#!/usr/bin/env bash
# Builds the Python module `phi_rs` (phi-py/) and runs its tests (pytest, phi-py/tests), which
# compare it with the `phi` command line built here. Arguments go to pytest.
#
# The module is installed into the virtual environment that scripts/setup-libtorch.sh makes for the
# tch backend (.venv-torch, or PHI_TORCH_VENV), which already holds PyPI's torch 2.11.0 wheel: one
# copy of torch serves both, and the tests of `phi_rs.torch` only need the CUDA libraries that
# `import torch` loads (phi-py/requirements-torch.txt, about 2.3 GB). They are installed one
# package at a time, so that no more than one wheel waits on disk. PHI_PY_TORCH=0 leaves them out:
# `import torch` then fails and those tests are skipped. PYTHON picks the interpreter that makes
# the environment (>= 3.9).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

bash scripts/setup-libtorch.sh >/dev/null
venv="${PHI_TORCH_VENV:-$PWD/.venv-torch}"
export PATH="$venv/bin:$PATH"
pip install --quiet --disable-pip-version-check -r phi-py/requirements-test.txt
if [ "${PHI_PY_TORCH:-1}" != 0 ]; then
    grep -v -e '^#' -e '^$' phi-py/requirements-torch.txt | while read -r requirement; do
        pip install --quiet --disable-pip-version-check --no-deps --no-cache-dir "$requirement"
    done
fi
# One target folder for the module and the `phi` binary: they share the compiled crates.
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/target}"
cargo build --release --bin phi
pip install --quiet --disable-pip-version-check --no-build-isolation --force-reinstall --no-deps \
    ./phi-py
pytest phi-py/tests "$@"
