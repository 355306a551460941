"""Times POT's exact EMD (ot.dist + ot.emd2) on the cases of the fixture that the emd bench reads.

    python3 -m venv /tmp/pot && /tmp/pot/bin/pip install pot numpy
    OMP_NUM_THREADS=1 /tmp/pot/bin/python phi-core/benches/emd_pot.py [REPEATS]

Prints, per case and ground cost, the median and the best of REPEATS (default 30) timings of
ot.dist(a, b, metric) followed by ot.emd2 with uniform weights, the same work as
`phi_core::point_sets::earth_movers_distance`. numItermax is raised so that the network simplex
reaches the optimum (POT's default, 100,000, stops early on the 1,300-point cases).
"""

import pathlib
import statistics
import sys
import time

import numpy as np
import ot

FIXTURE = pathlib.Path(__file__).parents[1] / "tests/fixtures/emd_pot.txt"
CASES = ["rollout_1300", "uniform_1300"]


def read_cases():
    lines = FIXTURE.read_text().splitlines()
    cases = {}
    for k in range(0, len(lines), 3):
        _, name, n, d, *_ = lines[k].split()
        n, d = int(n), int(d)
        a = np.array(lines[k + 1].split()[1:], dtype=np.float32).astype(np.float64).reshape(n, d)
        b = np.array(lines[k + 2].split()[1:], dtype=np.float32).astype(np.float64).reshape(n, d)
        cases[name] = (a, b)
    return cases


def main():
    repeats = int(sys.argv[1]) if len(sys.argv) > 1 else 30
    cases = read_cases()
    print(f"POT {ot.__version__}, numpy {np.__version__}, {repeats} repeats")
    for name in CASES:
        a, b = cases[name]
        w = np.full(len(a), 1.0 / len(a))
        for metric in ["sqeuclidean", "euclidean"]:
            times = []
            for _ in range(repeats):
                start = time.perf_counter()
                value = ot.emd2(w, w, ot.dist(a, b, metric=metric), numItermax=10_000_000)
                times.append(time.perf_counter() - start)
            print(
                f"{name} {metric}: median {1e3 * statistics.median(times):.2f} ms, "
                f"best {1e3 * min(times):.2f} ms (EMD {value:.9g})"
            )


if __name__ == "__main__":
    main()
