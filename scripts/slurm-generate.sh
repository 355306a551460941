#!/usr/bin/env bash
# A dataset generated on a SLURM cluster: one array task per shard, then one merge.
#
#   scripts/slurm-generate.sh OUT N [phi dataset generate options...]
#
# submits an array job of N tasks, task k running
#
#   phi dataset generate --out OUT.shards/shard-k --shard k/N --threads $SLURM_CPUS_PER_TASK ...
#
# and a job that runs after every task has succeeded,
#
#   phi dataset merge --out OUT OUT.shards/shard-0 ... OUT.shards/shard-(N-1)
#
# The shards lie beside OUT, not in it: `phi dataset merge` writes into a new or empty folder.
# Every option after N goes to each `phi dataset generate` (--split, --trajectories, --seed,
# --variant, --config, --steps, --scenes, --position-scale; not --out, --shard or --threads,
# which the script sets). A task that fails or is killed is resumed by running it again
# (`sbatch --array=k ... task`, or the whole command again): its finished trajectories are kept.
# The merged dataset has the same bytes as one unsharded run.
#
# Environment:
#   PHI          the phi binary (default: phi on PATH, else target/release/phi)
#   SBATCH_ARGS  extra sbatch options for both jobs (e.g. "--partition=cpu --time=04:00:00")
#   CPUS         CPUs per array task (default 8)
#
# The script runs itself inside the jobs: `task OUT N ...` in an array task, `merge OUT N` in
# the merge job; both modes also run by hand (with SLURM_ARRAY_TASK_ID set for `task`).
set -euo pipefail

script=$(realpath "$0")
phi=${PHI:-$(command -v phi || echo "$(dirname "$script")/../target/release/phi")}

usage() {
    echo "usage: $0 OUT N [phi dataset generate options...]" >&2
    exit 2
}

shard_dir() { echo "$1.shards/shard-$2"; }

case "${1:-}" in
task)
    shift
    [[ $# -ge 2 ]] || usage
    out=$1 n=$2
    shift 2
    k=${SLURM_ARRAY_TASK_ID:?"the task mode runs in a SLURM array job (SLURM_ARRAY_TASK_ID)"}
    exec "$phi" dataset generate --out "$(shard_dir "$out" "$k")" --shard "$k/$n" \
        --threads "${SLURM_CPUS_PER_TASK:-1}" "$@"
    ;;
merge)
    shift
    [[ $# -eq 2 ]] || usage
    out=$1 n=$2
    shards=()
    for ((k = 0; k < n; k++)); do
        shards+=("$(shard_dir "$out" "$k")")
    done
    exec "$phi" dataset merge --out "$out" "${shards[@]}"
    ;;
esac

[[ $# -ge 2 ]] || usage
out=$1 n=$2
shift 2
[[ $n =~ ^[1-9][0-9]*$ ]] || { echo "N must be a positive number of shards, got '$n'" >&2; exit 2; }
for option in "$@"; do
    case $option in
    --out | --out=* | --shard | --shard=* | --threads | --threads=*)
        echo "$option is set by the script; leave it out" >&2
        exit 2
        ;;
    esac
done
command -v sbatch > /dev/null || { echo "sbatch not found: run this on a SLURM login node" >&2; exit 1; }
mkdir -p "$out.shards/logs"
read -r -a extra <<< "${SBATCH_ARGS:-}"
array=$(sbatch --parsable "${extra[@]}" --job-name=phi-generate --array="0-$((n - 1))" \
    --cpus-per-task="${CPUS:-8}" --output="$out.shards/logs/shard-%a.log" \
    "$script" task "$out" "$n" "$@")
merge=$(sbatch --parsable "${extra[@]}" --job-name=phi-merge --dependency="afterok:${array%%;*}" \
    --cpus-per-task=1 --output="$out.shards/logs/merge.log" \
    "$script" merge "$out" "$n")
echo "submitted: array job $array ($n shards into $out.shards), merge job $merge (into $out)"
