#!/usr/bin/env bash
# The thesis's learning experiments at CPU scale (docs/gns.md, "Experiments at CPU scale"):
# generates the datasets, trains the five configs/gns/cpu presets one after another, then
# evaluates them on the test scenes and on the taller domain of fig. 5.9. Every stage resumes:
# run the script again after a stop, a kill or a new sitting and it goes on where it was (a
# training run from its newest checkpoint, bit for bit).
#
#   scripts/cpu-experiments.sh [STAGE...]     stages: data train eval (default: all three)
#
# PHI (default target/release/phi), DATA (default data) and RUNS (default experiments/cpu) move
# the binary, the datasets and the training directories.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

phi=${PHI:-target/release/phi}
data=${DATA:-data}
runs=${RUNS:-experiments/cpu}
stages=("$@")
[ ${#stages[@]} -gt 0 ] || stages=(data train eval)
variants=(1s 1sn 1snb 2ss 2si)

if [ ! -x "$phi" ]; then
    echo "$phi not found: cargo build --release --bin phi (or set PHI)" >&2
    exit 1
fi

wants() {
    local s
    for s in "${stages[@]}"; do [ "$s" = "$1" ] && return 0; done
    return 1
}

# A dataset is finished once metadata.json is written (generation writes it last).
dataset() {
    local out=$1
    shift
    [ -f "$out/metadata.json" ] || "$phi" dataset generate --out "$out" "$@"
}

if wants data; then
    dataset "$data/flip" --split all
    dataset "$data/flip-walls" --split all --variant walls
    dataset "$data/tall" --split test --scenes scenes/generalisation --position-scale 0.025
    dataset "$data/tall-walls" --split test --scenes scenes/generalisation --position-scale 0.025 \
        --variant walls
fi

if wants train; then
    for v in "${variants[@]}"; do
        out=$runs/$v
        if [ -f "$out/train.json" ]; then
            "$phi" train --resume --out "$out"
            continue
        fi
        case $v in
            1snb) set -- --data "$data/flip-walls" ;;
            2si) set -- --data "$data/flip" --init-from "$runs/1s/best" ;;
            *) set -- --data "$data/flip" ;;
        esac
        "$phi" train --config "configs/gns/cpu/$v.toml" --out "$out" "$@"
    done
fi

if wants eval; then
    models=()
    for v in 1s 1sn 2ss 2si; do models+=(--model "$v=$runs/$v"); done
    "$phi" eval "${models[@]}" --data "$data/flip" --split test --out "$runs/eval"
    "$phi" eval --model "1snb=$runs/1snb" --data "$data/flip-walls" --split test \
        --out "$runs/eval-walls"
    # 1sn on the taller domain, its boundary features against the real walls and against the
    # walls it was trained with.
    "$phi" eval --model "1sn=$runs/1sn" --data "$data/tall" --split test --bounds data \
        --out "$runs/eval-tall"
    "$phi" eval --model "1sn=$runs/1sn" --data "$data/tall" --split test --bounds model \
        --out "$runs/eval-tall-model-walls"
    "$phi" eval --model "1snb=$runs/1snb" --data "$data/tall-walls" --split test \
        --out "$runs/eval-tall-walls"
fi
