#!/usr/bin/env bash
# The thesis's learning experiments at CPU scale (docs/gns.md, "Experiments at CPU scale"):
# generates the datasets, trains the five configs/gns/cpu presets one after another, then
# evaluates them on the test scenes and on the taller domain of fig. 5.9, and solves the inverse
# problem of thesis section 4.3 through FLIP and through two of the models. Every stage resumes:
# run the script again after a stop, a kill or a new sitting and it goes on where it was (a
# training run from its newest checkpoint, bit for bit).
#
#   scripts/cpu-experiments.sh [STAGE...]     stages: data train eval optimize (default: all)
#
# PHI (default target/release/phi), DATA (default data) and RUNS (default experiments/cpu) move
# the binary, the datasets and the training directories. VARIANTS (default "1s 1sn 1snb 2ss 2si")
# trains some of the variants only; Burn trains on one core, so a 2-core machine runs
# two lanes at once, e.g.
#   VARIANTS="1s 1sn 2ss" scripts/cpu-experiments.sh train &
#   VARIANTS="1snb" scripts/cpu-experiments.sh train; wait; VARIANTS=2si scripts/cpu-experiments.sh train
#
# The budget is the same for every variant in model passes: 4,000 steps of the one-step loss, and
# 2,000 of the two-step loss (each step two passes and their gradients), screened every 2,000 and
# 1,000 steps, so at the same passes (STEPS_ONE and STEPS_TWO change the budget). 2si starts from
# 1s/best, as in the thesis.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

phi=${PHI:-target/release/phi}
data=${DATA:-data}
runs=${RUNS:-experiments/cpu}
stages=("$@")
[ ${#stages[@]} -gt 0 ] || stages=(data train eval optimize)
read -r -a variants <<<"${VARIANTS:-1s 1sn 1snb 2ss 2si}"
steps_one=${STEPS_ONE:-4000}
steps_two=${STEPS_TWO:-2000}

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
        case $v in
            2ss | 2si) steps=$steps_two ;;
            *) steps=$steps_one ;;
        esac
        if [ -f "$out/train.json" ]; then
            # The run keeps its dataset and preset; the budget is given again as the total.
            "$phi" train --resume --out "$out" --steps "$steps"
            continue
        fi
        case $v in
            1snb) set -- --data "$data/flip-walls" ;;
            2ss) set -- --data "$data/flip" --screen-every $((steps / 2)) ;;
            2si) set -- --data "$data/flip" --init-from "$runs/1s/best" --screen-every $((steps / 2)) ;;
            *) set -- --data "$data/flip" ;;
        esac
        "$phi" train --config "configs/gns/cpu/$v.toml" --out "$out" --steps "$steps" "$@"
    done
fi

if wants eval; then
    # --force: an evaluation made before is written anew from its cache, recomputing only the
    # trajectories of models whose weights changed since.
    # Table B.1: all five on the test scenes, 1snb on their walls variant.
    models=()
    for v in 1s 1sn 1snb 2ss 2si; do models+=(--model "$v=$runs/$v"); done
    "$phi" eval "${models[@]}" --data "$data/flip" --model-data "1snb=$data/flip-walls" \
        --split test --out "$runs/eval" --force
    # Fig. 5.9: 1sn with its boundary features against the taller domain's walls, 1snb with the
    # walls as particles; then 1sn measuring the walls it was trained with.
    "$phi" eval --model "1sn=$runs/1sn" --model "1snb=$runs/1snb" --data "$data/tall" \
        --model-data "1snb=$data/tall-walls" --split test --bounds data --out "$runs/eval-tall" \
        --force
    "$phi" eval --model "1sn=$runs/1sn" --data "$data/tall" --split test --bounds model \
        --out "$runs/eval-tall-model-walls" --force
fi

if wants optimize; then
    # Thesis fig. 4.5's problem through FLIP and through the 1s and 2si models (Burn, CPU); a run
    # with its summary.json is done; one without it was cut short and is replaced.
    problem=scenes/optimize/two_spheres.toml
    optimize() {
        local out=$runs/optimize/$1
        shift
        [ -f "$out/summary.json" ] || "$phi" optimize "$problem" --out "$out" --backend burn \
            --force "$@"
    }
    optimize flip
    optimize gns-1s --simulator gns --model "$runs/1s/best"
    optimize gns-2si --simulator gns --model "$runs/2si/best"
fi
