#!/usr/bin/env bash
# Checks a CUDA build of phi on a machine with an NVIDIA GPU and PyTorch 2.11 installed in its
# Python, but no Rust toolchain (the binary is built elsewhere and copied over), then trains the
# thesis-size models for the time that is left. One run, about 9 minutes, whose numbers
# docs/gns.md ("Training on a GPU") and docs/benchmarks.md report.
#
# On the build machine:
#   bash scripts/setup-libtorch.sh
#   cargo build --release --features tch,cuda --bin phi
#   strip -o phi-cuda target/release/phi
# On the GPU machine, from the repository root:
#   BUDGET=560 scripts/gpu-check.sh [PHI_BINARY]     # default target/release/phi
#
# It finds libtorch in the Python's site-packages (torch/lib and the nvidia/*/lib folders of the
# CUDA wheels) and puts it on LD_LIBRARY_PATH, since the rpath baked in at build time points at
# the build machine's copy. Then, each step bounded by `timeout`:
#   1. a dataset made by the binary itself (seed 0: the first 400 training and 20 validation
#      trajectories of `phi dataset generate --split all`);
#   2. correctness: 20 steps of `phi train --backend tch` at the thesis scale
#      (configs/gns/1sn.toml, batch 2) on `--device cpu` and on `--device cuda`, losses per step;
#   3. speed: 300 steps of the same on CUDA beside the PyTorch reference trainer
#      (benches/anchors/gns/train_reference.py) on the same GPU, configuration and batch, and
#      inference: `phi rollout --device cuda` beside the reference's one-step predictions;
#   4. the thesis-size runs of configs/gns/gpu/*.toml side by side on the GPU until BUDGET seconds
#      (from the start of this script) less two minutes, stopped by SIGINT (a checkpoint each);
#   5. each run's last checkpoint screened on the GPU by the reference implementation (the same
#      network as phi's, to 3e-8: phi-gns/tests/model/pytorch.rs) on 20 validation trajectories.
# Everything it measures goes to $OUT (or a temporary folder): gpu-check.log, small.tar (CSV and
# JSON files), and per run run-NAME.tar (model, state, train.csv) plus the optimiser state of the
# first run (resumable there with `phi train --resume`).
set -uo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

phi="$(realpath "${1:-target/release/phi}")"
python="${PYTHON:-python3}"
budget="${BUDGET:-560}"
runs="${RUNS:-1sn 1s 1sn-b8}"
out="${OUT:-$(mktemp -d)}"
mkdir -p "$out"
work="$(mktemp -d)"
small="$work/small"
mkdir -p "$small"
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
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version \
    --format=csv,noheader
nproc
echo "== $phi"
ls -l "$phi"
if ldd "$phi" | grep -E 'not found'; then
    echo "error: $phi has unresolved libraries (above)"
    exit 1
fi
ldd "$phi" | grep -E 'libtorch|libc10' | sed 's/ (0x.*//'

echo "== dataset (400 train, 20 valid) [${SECONDS}s]"
data="$work/data"
timeout 150 "$phi" -q dataset generate --out "$data" --split train --trajectories 400 --seed 0 || exit 1
timeout 60 "$phi" -q dataset generate --out "$data" --split valid --trajectories 20 --seed 0 || exit 1
cp "$data/metadata.json" "$small/metadata.json"

train() { # name, device, steps, log_every, timeout, config
    timeout "$5" "$phi" -q train --backend tch --device "$2" --data "$data" --config "$6" \
        --out "$work/run-$1" --steps "$3" --log-every "$4" --screen-every 0 --checkpoint-every "$3"
    local rc=$?
    cp "$work/run-$1/train.csv" "$small/train-$1.csv" 2>/dev/null
    return $rc
}

echo "== correctness: 20 steps at the thesis scale, cpu and cuda [${SECONDS}s]"
train check-cpu cpu 20 1 150 configs/gns/1sn.toml
train check-cuda cuda 20 1 90 configs/gns/1sn.toml
awk -F, '
    FNR == 1 { next }
    FILENAME ~ /check-cpu/ { cpu[$1] = $2 }
    FILENAME ~ /check-cuda/ { gpu[$1] = $2 }
    END {
        worst = 0
        for (s = 1; s <= 20; s++) {
            if (!(s in cpu) || !(s in gpu)) { print "step " s ": missing"; continue }
            d = gpu[s] - cpu[s]; if (d < 0) d = -d
            r = d / cpu[s]; if (r > worst) worst = r
            printf "step %2d: loss cpu %.7e, cuda %.7e, relative difference %.1e\n", s, cpu[s], gpu[s], r
        }
        printf "largest relative difference over 20 steps: %.1e\n", worst
    }' "$small/train-check-cpu.csv" "$small/train-check-cuda.csv"

echo "== speed: phi train, 300 steps on cuda [${SECONDS}s]"
train speed-cuda cuda 300 100 120 configs/gns/1sn.toml
tail -n 3 "$small/train-speed-cuda.csv"
echo "== speed: reference trainer, 300 steps on cuda [${SECONDS}s]"
PYTHONUNBUFFERED=1 timeout 120 "$python" benches/anchors/gns/train_reference.py --data "$data" \
    --config configs/gns/1sn.toml --steps 300 --log-every 100 --device cuda --out "$work/ref-speed" \
    && cp "$work/ref-speed/train.csv" "$small/train-ref-speed.csv"
echo "== inference: reference, 300 one-step predictions on cuda [${SECONDS}s]"
PYTHONUNBUFFERED=1 timeout 60 "$python" benches/anchors/gns/train_reference.py --data "$data" \
    --config configs/gns/1sn.toml --device cuda --bench-inference 300 \
    --init-from "$work/run-speed-cuda/checkpoints/step-0000000300"
echo "== inference: phi rollout, 300 steps on cuda [${SECONDS}s]"
timeout 90 "$phi" -q rollout --backend tch --device cuda --data "$data" --split valid --trajectory 0 \
    --model "$work/run-speed-cuda/checkpoints/step-0000000300" --steps 300 --frame-every 0 \
    --out "$work/rollout-cuda" && cp "$work/rollout-cuda"/*/rollout.json "$small/rollout-cuda.json"
grep -E '"(wall|model)_seconds"' "$small/rollout-cuda.json"

long=$((budget - SECONDS - 170))
echo "== thesis-size runs side by side ($runs) for ${long}s [${SECONDS}s]"
if [ "$long" -gt 30 ]; then
    # `wait` with the PIDs: a bare `wait` would also wait for the `tee` of the log, for ever.
    pids=()
    for name in $runs; do
        timeout -s INT -k 60 "$long" "$phi" -q train --backend tch --device cuda --data "$data" \
            --config "configs/gns/gpu/$name.toml" --out "$work/gpu-$name" \
            > "$work/gpu-$name.log" 2>&1 &
        pids+=($!)
    done
    wait "${pids[@]}"
    for name in $runs; do
        tail -n 2 "$work/gpu-$name.log"
        tail -n 1 "$work/gpu-$name/train.csv"
    done
fi

echo "== screening the last checkpoints on 20 validation trajectories, side by side [${SECONDS}s]"
pids=()
for name in $runs; do
    last="$(ls -d "$work/gpu-$name"/checkpoints/step-* 2>/dev/null | tail -n 1)"
    [ -n "$last" ] || continue
    PYTHONUNBUFFERED=1 timeout 150 "$python" -W ignore benches/anchors/gns/train_reference.py \
        --data "$data" --config "configs/gns/gpu/$name.toml" --device cuda --init-from "$last" \
        --screen-only 20 > "$work/screen-$name.log" 2>&1 &
    pids+=($!)
done
wait "${pids[@]}"
for name in $runs; do
    last="$(ls -d "$work/gpu-$name"/checkpoints/step-* 2>/dev/null | tail -n 1)"
    [ -n "$last" ] || continue
    echo "-- $name, $(basename "$last"): $(tail -n 1 "$work/screen-$name.log")"
    cp "$work/screen-$name.log" "$small/"
    tar -cf "$out/run-$name.tar" -C "$work/gpu-$name" train.csv config.toml \
        -C "$last" model.json model.safetensors state.json
    if [ "$name" = "${runs%% *}" ]; then
        cp "$last/optimizer.safetensors" "$out/optimizer-$name.safetensors"
    fi
done
tar -cf "$out/small.tar" -C "$small" .
echo "done in ${SECONDS}s; files in $out"
