#!/usr/bin/env bash
# Installs libtorch 2.11.0 (the version tch 0.24 links against) into a project-local virtual
# environment, `.venv-torch/`, from the PyPI wheel `torch==2.11.0`.
#
# The wheel is installed without its dependencies: `libtorch_cpu.so` only needs `libcudart.so.13`
# and `libcupti.so.13` at load time (its NEEDED entries), which two small packages provide, at the
# versions the wheel's `cuda-toolkit==13.0.2` requirement pins. Both land in
# `site-packages/nvidia/cu13/lib`, which the wheel's libraries already carry in their rpath. This
# avoids the multi-gigabyte CUDA stack (cuBLAS, cuDNN, NCCL, ...) on machines without a GPU:
# `libtorch_cuda.so` is installed but never loaded by a default build.
#
# Idempotent: a second run checks the installed versions and returns at once.
# Prints the libtorch directory (`.../site-packages/torch`) on its last line.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${PHI_TORCH_VENV:-$root/.venv-torch}"
python="${PYTHON:-python3}"

torch_version="2.11.0"
cuda_runtime_version="13.0.96"
cuda_cupti_version="13.0.85"

installed_version() {
    "$venv/bin/python" - <<'PY' 2>/dev/null
import importlib.metadata as m
try:
    print(m.version("torch"), m.version("nvidia-cuda-runtime"), m.version("nvidia-cuda-cupti"))
except m.PackageNotFoundError:
    print("missing")
PY
}

if [ ! -x "$venv/bin/python" ]; then
    echo "creating virtual environment $venv" >&2
    "$python" -m venv "$venv"
fi

if [ "$(installed_version)" != "$torch_version $cuda_runtime_version $cuda_cupti_version" ]; then
    echo "installing torch==$torch_version (about 530 MB download) into $venv" >&2
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps \
        "torch==$torch_version" "nvidia-cuda-runtime==$cuda_runtime_version" \
        "nvidia-cuda-cupti==$cuda_cupti_version"
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
