"""Generates a dataset of random FLIP scenes in shards over a pool of worker processes, then
merges the shards: the dataset `phi dataset generate` writes in one run, byte for byte.

    python phi-py/examples/generate_in_parallel.py OUT [--workers N] [--trajectories T]
        [--steps S] [--seed SEED]

Each worker runs `phi_rs.generate_dataset(shard=(k, n), threads=1)` into `OUT.shards/k-of-n`;
a shard that was interrupted is continued when the script runs again (`resume=True`). The same
function maps over any executor with `map`: `concurrent.futures.ProcessPoolExecutor` here, a
`dask.distributed.Client.map` or a Ray pool across machines that share a file system (each
worker then writes its shard where the merging process can read it).
"""

import argparse
import concurrent.futures
import multiprocessing
import os
from pathlib import Path

import phi_rs


def shard_dir(out, k, n):
    return Path(f"{out}.shards") / f"{k}-of-{n}"


def generate_shard(out, k, n, trajectories, steps, seed):
    """One worker's share: the trajectories `i` with `i mod n = k` of every split."""
    return phi_rs.generate_dataset(shard_dir(out, k, n), trajectories=trajectories, steps=steps,
                                   seed=seed, shard=(k, n), threads=1, resume=True)


def generate_in_parallel(out, workers, trajectories=None, steps=None, seed=0, executor=None):
    """Generates the `workers` shards over `executor` (a process pool of `workers` processes if
    None) and merges them into `out`. Returns `phi_rs.merge_dataset`'s summary."""
    shards = range(workers)
    args = ([out] * workers, shards, [workers] * workers, [trajectories] * workers,
            [steps] * workers, [seed] * workers)
    if executor is None:
        # Fresh interpreters ("spawn"): a forked child would inherit the parent's thread pools.
        context = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as pool:
            list(pool.map(generate_shard, *args))
    else:
        list(executor.map(generate_shard, *args))
    return phi_rs.merge_dataset(out, [shard_dir(out, k, workers) for k in shards])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out")
    parser.add_argument("--workers", type=int, default=os.cpu_count())
    parser.add_argument("--trajectories", type=int, default=None,
                        help="per split (default: table 5.1's 2000, 20 and 10)")
    parser.add_argument("--steps", type=int, default=None, help="per trajectory (default 400)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    summary = generate_in_parallel(args.out, args.workers, args.trajectories, args.steps,
                                   args.seed)
    print(f"{args.out}: {summary['counts']} from {args.workers} shards")


if __name__ == "__main__":
    main()
