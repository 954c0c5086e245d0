"""Sample efficiency of the batch BO against its peers on analytic functions, in one run.

    python -m venv --system-site-packages .bench && .bench/bin/pip install -e . arm-mango optuna
    .bench/bin/python benchmarks/bench_bo.py [--seeds 20] [--budget 100] [--jobs 2]

Branin (2-D) and Hartmann 6 (6-D), batch size 4, ``--budget`` evaluations, ``--seeds`` seeds.
For each method: the median number of evaluations until the simple regret (best value found
minus the global minimum) is at most 0.01, counting seeds that never get there as "more than the
budget", and the share of seeds that get there. Methods:

* ``parcelfit``: `BatchBO` with its defaults (Latin hypercube of 16, GP Matern 5/2 with one
  length scale per input, alpha = 0.35^2 on the standardised cost, MC UCB, k-means batches);
* ``parcelfit-log``: the same with the cost log-warped before standardising (``transform: log``);
* ``mango``: the Mango library as in the published work (batch 4, 16 random initial points);
* ``optuna``: Optuna's default sampler (TPE), batches of 4 by ask/tell;
* ``random``: uniform random search.

Then the overhead of one ``ask(4)`` with 200 observations in 4-D on one core (median of 5).

Mango and Optuna are not dependencies of parcelfit: install them in the benchmark's own
environment as above.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import random
import statistics
import time
from collections.abc import Callable

import numpy as np

from parcelfit.optimize import BatchBO, BOSettings, Space

Function = tuple[str, dict[str, tuple[float, float]], Callable[[dict[str, float]], float], float]


def branin(p: dict[str, float]) -> float:
    x1, x2 = p["x1"], p["x2"]
    b, c, t = 5.1 / (4 * math.pi**2), 5 / math.pi, 1 / (8 * math.pi)
    return (x2 - b * x1**2 + c * x1 - 6) ** 2 + 10 * (1 - t) * math.cos(x1) + 10


_A = np.array(
    [
        [10, 3, 17, 3.5, 1.7, 8],
        [0.05, 10, 17, 0.1, 8, 14],
        [3, 3.5, 1.7, 10, 17, 8],
        [17, 8, 0.05, 10, 0.1, 14],
    ]
)
_P = 1e-4 * np.array(
    [
        [1312, 1696, 5569, 124, 8283, 5886],
        [2329, 4135, 8307, 3736, 1004, 9991],
        [2348, 1451, 3522, 2883, 3047, 6650],
        [4047, 8828, 8732, 5743, 1091, 381],
    ]
)
_ALPHA = np.array([1.0, 1.2, 3.0, 3.2])


def hartmann6(p: dict[str, float]) -> float:
    x = np.array([p[f"x{i}"] for i in range(6)])
    return float(-np.sum(_ALPHA * np.exp(-np.sum(_A * (x - _P) ** 2, axis=1))))


FUNCTIONS: list[Function] = [
    ("Branin", {"x1": (-5.0, 10.0), "x2": (0.0, 15.0)}, branin, 0.397887),
    ("Hartmann6", {f"x{i}": (0.0, 1.0) for i in range(6)}, hartmann6, -3.32237),
]


def run_parcelfit(bounds, f, seed, budget, transform="none"):
    bo = BatchBO(
        Space.from_bounds(bounds), batch_size=4, seed=seed, settings=BOSettings(transform=transform)
    )
    values = []
    while len(values) < budget:
        for p in bo.ask(min(4 if values else 16, budget - len(values))):
            v = f(p)
            bo.tell(p, v)
            values.append(v)
    return values


def run_random(bounds, f, seed, budget):
    rng = np.random.default_rng(seed)
    return [
        f({k: lo + (hi - lo) * rng.random() for k, (lo, hi) in bounds.items()})
        for _ in range(budget)
    ]


def run_optuna(bounds, f, seed, budget):
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=seed))
    values = []
    while len(values) < budget:
        trials = [study.ask() for _ in range(min(4, budget - len(values)))]
        for tr in trials:
            v = f({k: tr.suggest_float(k, lo, hi) for k, (lo, hi) in bounds.items()})
            study.tell(tr, v)
            values.append(v)
    return values


def run_mango(bounds, f, seed, budget):
    from mango import Tuner
    from scipy.stats import uniform

    random.seed(seed)
    np.random.seed(seed)
    values = []

    def objective(batch):
        out = [f(p) for p in batch]
        values.extend(out)
        return out

    space = {k: uniform(lo, hi - lo) for k, (lo, hi) in bounds.items()}
    conf = {"batch_size": 4, "initial_random": 16, "num_iteration": (budget - 16) // 4}
    Tuner(space, objective, conf).minimize()
    return values[:budget]


METHODS = {
    "parcelfit": run_parcelfit,
    "parcelfit-log": lambda b, f, s, n: run_parcelfit(b, f, s, n, "log"),
    "mango": run_mango,
    "optuna": run_optuna,
    "random": run_random,
}


def evals_to_regret(values, optimum, tol=0.01):
    best = np.minimum.accumulate(values)
    hit = np.flatnonzero(best - optimum <= tol)
    return int(hit[0]) + 1 if hit.size else None


def one(job):
    fname, method, seed, budget = job
    _, bounds, f, opt = next(fn for fn in FUNCTIONS if fn[0] == fname)
    t0 = time.perf_counter()
    try:
        values = METHODS[method](bounds, f, seed, budget)
    except ImportError as exc:
        return fname, method, seed, "missing", str(exc), 0.0
    return (
        fname,
        method,
        seed,
        evals_to_regret(values, opt),
        min(values) - opt,
        time.perf_counter() - t0,
    )


def ask_overhead(n_obs: int = 200, dims: int = 4, repeats: int = 5) -> float:
    """Median seconds of ask(4) after n_obs observations in dims dimensions, one BLAS thread."""
    from threadpoolctl import threadpool_limits

    rng = np.random.default_rng(0)
    space = Space.from_bounds({f"x{i}": (0.0, 1.0) for i in range(dims)})
    bo = BatchBO(space, batch_size=4, seed=0, settings=BOSettings(n_initial=1))
    bo.tell(bo.ask(1)[0], 1.0)  # use up the initial design, so every timed ask() fits the GP
    for _ in range(n_obs - 1):
        p = {f"x{i}": float(rng.random()) for i in range(dims)}
        bo.tell(p, float(sum((v - 0.4) ** 2 for v in p.values()) + 0.01 * rng.standard_normal()))
    times = []
    with threadpool_limits(1):
        for _ in range(repeats):
            t0 = time.perf_counter()
            batch = bo.ask(4)
            times.append(time.perf_counter() - t0)
            for p in batch:  # keep the history growing as in a study
                bo.tell(p, 0.1)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--budget", type=int, default=100)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--overhead-only", action="store_true")
    args = ap.parse_args()
    if args.overhead_only:
        print(
            f"ask(4) with 200 observations in 4-D, one core: {ask_overhead():.2f} s (target: < 2 s)"
        )
        return
    methods = args.methods.split(",")
    print(
        f"batch size 4, budget {args.budget}, {args.seeds} seeds; evaluations to regret <= 0.01",
        flush=True,
    )
    print(
        f"{'function':<11}{'method':<15}{'median evals':>13}{'reached':>9}{'median final regret':>21}{'s/run':>7}"
    )
    with multiprocessing.get_context("spawn").Pool(args.jobs) as pool:
        for fname, *_ in FUNCTIONS:  # one function at a time, printed as soon as it is done
            jobs = [(fname, m, s, args.budget) for m in methods for s in range(args.seeds)]
            results = pool.map(one, jobs, chunksize=1)
            for m in methods:
                rows = [r for r in results if r[1] == m]
                if any(r[3] == "missing" for r in rows):
                    print(f"{fname:<11}{m:<15}  not installed: {rows[0][4]}")
                    continue
                hits = [r[3] if r[3] is not None else math.inf for r in rows]
                med = statistics.median(hits)
                med_txt = f">{args.budget}" if math.isinf(med) else f"{med:g}"
                reached = sum(h != math.inf for h in hits) / len(hits)
                final = statistics.median(r[4] for r in rows)
                secs = statistics.median(r[5] for r in rows)
                print(
                    f"{fname:<11}{m:<15}{med_txt:>13}{reached:>9.0%}{final:>21.4f}{secs:>7.1f}",
                    flush=True,
                )
    print(f"ask(4) with 200 observations in 4-D, one core: {ask_overhead():.2f} s (target: < 2 s)")


if __name__ == "__main__":
    main()
