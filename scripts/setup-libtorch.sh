#!/usr/bin/env bash
# Installs libtorch 2.9.0 (the version tch 0.22 links against) into a project-local virtual
# environment, `.venv-torch/`, from the PyPI wheel `torch==2.9.0`.
#
# The wheel is installed without its dependencies: the CPU build of `libtorch_cpu.so` only needs
# `libcudart.so.12` and `libcupti.so.12` at load time, which two small packages provide. This avoids
# the multi-gigabyte CUDA stack on machines without a GPU.
#
# Idempotent: a second run checks the installed versions and returns at once.
# Prints the libtorch directory (`.../site-packages/torch`) on its last line.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${PHI_TORCH_VENV:-$root/.venv-torch}"
python="${PYTHON:-python3}"

torch_version="2.9.0"
cuda_runtime="nvidia-cuda-runtime-cu12==12.8.90"
cuda_cupti="nvidia-cuda-cupti-cu12==12.8.90"

installed_version() {
    "$venv/bin/python" - <<'PY' 2>/dev/null
import importlib.metadata as m
try:
    print(m.version("torch"), m.version("nvidia-cuda-runtime-cu12"), m.version("nvidia-cuda-cupti-cu12"))
except m.PackageNotFoundError:
    print("missing")
PY
}

if [ ! -x "$venv/bin/python" ]; then
    echo "creating virtual environment $venv" >&2
    "$python" -m venv "$venv"
fi

if [ "$(installed_version)" != "$torch_version 12.8.90 12.8.90" ]; then
    echo "installing torch==$torch_version (about 900 MB) into $venv" >&2
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps \
        "torch==$torch_version" "$cuda_runtime" "$cuda_cupti"
fi

site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
libtorch="$site/torch"
if [ ! -f "$libtorch/lib/libtorch_cpu.so" ]; then
    echo "error: $libtorch/lib/libtorch_cpu.so is missing after installing torch==$torch_version" >&2
    exit 1
fi
# A stable path that `.cargo/config.toml` points `LIBTORCH` at, whatever the Python version.
ln -sfn "$libtorch" "$venv/libtorch"
echo "$libtorch"
