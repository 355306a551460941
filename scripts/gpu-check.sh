#!/usr/bin/env bash
# Checks a CUDA build of phi on a machine with an NVIDIA GPU and PyTorch 2.11 installed in its
# Python, but no Rust toolchain: the binary is built elsewhere and copied over.
#
# Not yet run on a GPU: this script states the procedure; its numbers belong in docs/gns.md only
# once a run has produced them.
#
# On the build machine:
#   bash scripts/setup-libtorch.sh
#   cargo build --release --features tch,cuda --bin phi
#   strip target/release/phi            # the release binary carries line tables
# On the GPU machine, from the repository root (for configs/gns/1sn.toml):
#   scripts/gpu-check.sh [PHI_BINARY]   # default target/release/phi
#
# It finds libtorch in the system Python's site-packages (torch/lib and the nvidia/*/lib folders of
# the CUDA wheels) and puts it on LD_LIBRARY_PATH, since the rpath baked in at build time points at
# the build machine's copy. Then, each step bounded by `timeout`, about 8 minutes at most in all:
#   1. a small dataset made by the binary itself (6 training trajectories, 1 validation);
#   2. 20 steps of `phi train --backend tch --device cpu` at the thesis scale (configs/gns/1sn.toml);
#   3. 300 steps of the same on `--device cuda`.
# It prints steps/s of both (train.csv's steps_per_second, the last row: warm-up excluded) and their
# ratio, and the relative difference of the two runs' mean losses over their first 20 steps (same
# seed, same batches and noise, so they differ only by float rounding and kernel order).
# Logs and train.csv files go to $OUT if set, else to a temporary folder that is printed.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

phi="$(realpath "${1:-target/release/phi}")"
python="${PYTHON:-python3}"
out="${OUT:-$(mktemp -d)}"
mkdir -p "$out"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
exec > >(tee "$out/gpu-check.log") 2>&1

torch_dir="$("$python" -W ignore -c 'import torch, os; print(os.path.dirname(torch.__file__))')"
site="$(dirname "$torch_dir")"
libs="$torch_dir/lib"
for dir in "$site"/nvidia/*/lib "$site"/nvidia/cu*/lib; do
    if [ -d "$dir" ] && [[ ":$libs:" != *":$dir:"* ]]; then
        libs="$libs:$dir"
    fi
done
export LD_LIBRARY_PATH="$libs${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"

echo "== torch"
"$python" -W ignore -c 'import torch; print("torch", torch.__version__, "| CUDA", torch.version.cuda,
      "| cuda available:", torch.cuda.is_available(), "| devices:", torch.cuda.device_count())'
version="$("$python" -W ignore -c 'import torch; print(torch.__version__.split("+")[0])')"
case "$version" in
    2.11.*) ;;
    *) echo "warning: phi binds libtorch 2.11 (tch 0.24), this Python has torch $version" ;;
esac
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version \
    --format=csv,noheader
ldd --version | head -n 1

echo "== $phi"
ls -l "$phi"
# Every library the binary loads must resolve, libtorch_cuda.so among them.
if ldd "$phi" | grep -E 'not found|version .* not found'; then
    echo "error: $phi has unresolved libraries (above)"
    exit 1
fi
ldd "$phi" | grep -E 'libtorch|libc10|libcudart'

echo "== dataset (6 train, 1 valid)"
timeout 90 "$phi" dataset generate --out "$work/data" --split train --count 6 --seed 0
timeout 30 "$phi" dataset generate --out "$work/data" --split valid --count 1 --seed 0

train() { # device, steps, log_every, timeout
    local run="$work/run-$1"
    timeout "$4" "$phi" train --backend tch --device "$1" --data "$work/data" \
        --config configs/gns/1sn.toml --out "$run" --steps "$2" --log-every "$3" \
        --screen-every 0 --checkpoint-every "$2"
    cp "$run/train.csv" "$out/train-$1.csv"
}

echo "== cpu: 20 steps at the thesis scale"
train cpu 20 10 150
echo "== cuda: 300 steps at the thesis scale"
train cuda 300 10 210

# train.csv: step,loss,learning_rate,steps_per_second,...
awk -F, '
    FNR == 1 { next }
    FILENAME ~ /cpu/ { cpu_rate = $4; if ($1 <= 20) cpu_loss[$1] = $2 }
    FILENAME ~ /cuda/ { cuda_rate = $4; if ($1 <= 20) cuda_loss[$1] = $2 }
    END {
        printf "steps/s: cpu %.2f, cuda %.2f, ratio %.1f\n", cpu_rate, cuda_rate, cuda_rate / cpu_rate
        for (s = 10; s <= 20; s += 10) {
            d = cuda_loss[s] - cpu_loss[s]
            if (d < 0) d = -d
            printf "mean loss of steps %d-%d: cpu %.6e, cuda %.6e, relative difference %.1e\n",
                s - 9, s, cpu_loss[s], cuda_loss[s], d / cpu_loss[s]
        }
    }' "$out/train-cpu.csv" "$out/train-cuda.csv"
echo "logs in $out"
