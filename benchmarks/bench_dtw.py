"""DTW speed: parcelfit's numba kernel against dtw-python, measured in the same run.

    python benchmarks/bench_dtw.py [--length 600] [--repeats 20]

Prints, for one pair of 2-D series of the given length, the median time per pair of
dtw-python (distance only, its fastest mode) and of parcelfit, and their ratio; then the time
for a 10 x 10 distance matrix (45 pairs) with parcelfit on one thread, on all cores, and with
dtw-python in a loop. Needs the test extras (dtw-python).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import dtw as dtw_python
import numba
import numpy as np

from parcelfit.metrics import dtw_distance, pairwise_dtw


def median_time(func, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        func()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--length", type=int, default=600)
    ap.add_argument("--repeats", type=int, default=20)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    n = args.length
    a = rng.normal(size=(n, 2)).cumsum(axis=0)
    b = rng.normal(size=(n, 2)).cumsum(axis=0)
    assert abs(
        dtw_distance(a, b) - dtw_python.dtw(a, b, distance_only=True).distance
    ) < 1e-9 * dtw_distance(a, b)

    t_ref = median_time(lambda: dtw_python.dtw(a, b, distance_only=True), args.repeats)
    t_ours = median_time(lambda: dtw_distance(a, b), args.repeats)
    print(f"one pair, {n} x {n} samples, 2-D (median of {args.repeats}):")
    print(f"  dtw-python (distance_only) {t_ref * 1e3:8.2f} ms")
    print(f"  parcelfit                  {t_ours * 1e3:8.2f} ms")
    print(f"  speed-up                   {t_ref / t_ours:8.1f} x")

    series = [
        rng.normal(size=(n + int(rng.integers(-50, 50)), 2)).cumsum(axis=0) for _ in range(10)
    ]
    pairwise_dtw(series)  # compile the parallel kernel
    cores = numba.config.NUMBA_NUM_THREADS
    numba.set_num_threads(1)
    t_one = median_time(lambda: pairwise_dtw(series), max(3, args.repeats // 4))
    numba.set_num_threads(cores)
    t_all = median_time(lambda: pairwise_dtw(series), max(3, args.repeats // 4))
    t_loop = median_time(
        lambda: [
            dtw_python.dtw(series[i], series[j], distance_only=True)
            for i in range(10)
            for j in range(i + 1, 10)
        ],
        max(3, args.repeats // 4),
    )
    print(f"10 x 10 distance matrix (45 pairs of ~{n} samples), {os.cpu_count()} cores:")
    print(f"  dtw-python loop            {t_loop * 1e3:8.1f} ms")
    print(f"  parcelfit, 1 thread        {t_one * 1e3:8.1f} ms")
    print(
        f"  parcelfit, {cores} threads       {t_all * 1e3:8.1f} ms  (x{t_one / t_all:.2f} over 1 thread)"
    )
    print(f"  speed-up over dtw-python   {t_loop / t_all:8.1f} x")


if __name__ == "__main__":
    main()
