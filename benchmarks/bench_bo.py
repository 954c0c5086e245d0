"""Sample efficiency of the batch BO against its peers on analytic functions, in one run.

    python -m pip install -e ".[bench]"          # Optuna and Mango, for this benchmark only
    python benchmarks/bench_bo.py [--seeds 20] [--jobs 2] [--functions Branin@48,Rough4]
        [--methods parcelfit,published,mango-default,mango-published,optuna-tpe,random]
    python benchmarks/bench_bo.py --overhead-only

Problems (batch size 4, the budget after the @): Branin@48 and Branin@100 (2-D), Hartmann6
(6-D, 100), Hartmann6+n (the same with Gaussian observation noise of sd 0.05; the regret is of
the noise-free value) and Rough4 (4-D, 100: a smooth bowl plus deterministic, parameter-dependent
roughness like the parcel cost). For each method: the median number of evaluations until the
simple regret (best true value found minus the global minimum) is at most 0.01, counting seeds
that never get there as "more than the budget", the share of seeds that get there, the median
final regret and the median CPU seconds per run; after each problem, the ratio of our median
final regret to each peer's, measured in the same run. Methods:

* ``parcelfit``: `BatchBO` with its defaults (see docs/research/optimizer-benchmarks.md: noise fitted by marginal
  likelihood, output transform chosen by the warped-GP likelihood, log EI with the posterior-mean
  incumbent polished by L-BFGS-B, kriging-believer batches, one length scale per input);
* ``published``: `BOSettings.published()`, method.md section 7 (fixed noise 0.35^2, MC UCB,
  k-means batches);
* ``mango-default``: the Mango library with its own settings (its GP: Matern 5/2 with
  near-zero noise, 10 restarts; UCB lambda 2; its random-exploration schedule starting at
  probability 1 and decaying by 0.9 per batch; clustering batches) except two: 16 random initial
  points (Mango's default is 2) and 4000 random domain points per batch (Mango's default is
  50,000-500,000, about 4.5 CPU s per batch here, so a 20-seed run would take hours);
* ``mango-published``: Mango configured as published (Latin hypercube of 16, Matern 5/2 with
  noise 0.35^2, clustering batches, no exploration), also with 4000 domain points;
* ``optuna-tpe``: Optuna's TPE with its defaults, batches of 4 by ask/tell;
* ``random``: uniform random search;
* ``pub+noisefit``, ``pub+auto``, ``pub+logei``, ``pub+polish``, ``pub+believer``,
  ``pub+ard+local``: one change of the default at a time on top of ``published``;
* ``gp:key=value:...`` / ``pub:key=value:...``: the default / published with other
  `BOSettings`, e.g. ``gp:transform=none``.

The last column is the median CPU seconds per run of one worker (one BLAS thread), which does
not depend on what else the machine runs.
``--overhead-only`` times one ``ask(4)`` with 200 observations in 4-D on one core (median CPU
seconds of 5).
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import os
import random
import statistics
import time
from collections.abc import Callable

import numpy as np

from parcelfit.optimize import BatchBO, BOSettings, Space


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


def _noisy_hartmann6(p: dict[str, float]) -> float:
    """Hartmann 6 plus Gaussian observation noise (sd 0.05), seeded by the point itself."""
    key = np.frombuffer(np.array([p[f"x{i}"] for i in range(6)]).tobytes(), dtype=np.uint32)
    return hartmann6(p) + 0.05 * float(np.random.default_rng(key.tolist()).standard_normal())


_ROUGH_CENTRE = np.array([0.31, 0.62, 0.47, 0.74])
_ROUGH_WEIGHTS = np.array([1.0, 0.6, 0.35, 0.15])
_ROUGH_DIRS = np.random.default_rng(2024).standard_normal((8, 4))
_ROUGH_FREQ = np.random.default_rng(2025).uniform(40.0, 120.0, 8)


def rough4(p: dict[str, float]) -> float:
    """A 4-D cost built like the parcel cost: a smooth bowl (range about 1 over the cube) plus a
    deterministic, parameter-dependent roughness of at most 0.04 (a few % of the range) whose
    wavelength is about 1 % of a parameter's range, zero at the optimum (global minimum 0)."""
    x = np.array([p[f"x{i}"] for i in range(4)]) - _ROUGH_CENTRE
    bowl = float(np.sum(_ROUGH_WEIGHTS * x**2)) / 0.6
    rough = 0.04 * float(np.mean(np.sin(np.pi * _ROUGH_FREQ * (_ROUGH_DIRS @ x)) ** 2))
    return bowl + rough


Objective = Callable[[dict[str, float]], float]
_B = {"x1": (-5.0, 10.0), "x2": (0.0, 15.0)}
_U6 = {f"x{i}": (0.0, 1.0) for i in range(6)}
# name, bounds, observed function, true function (for the regret), global minimum, budget
FUNCTIONS: list[tuple[str, dict[str, tuple[float, float]], Objective, Objective, float, int]] = [
    ("Branin@48", _B, branin, branin, 0.397887, 48),
    ("Branin@100", _B, branin, branin, 0.397887, 100),
    ("Hartmann6", _U6, hartmann6, hartmann6, -3.32237, 100),
    ("Hartmann6+n", _U6, _noisy_hartmann6, hartmann6, -3.32237, 100),
    ("Rough4", {f"x{i}": (0.0, 1.0) for i in range(4)}, rough4, rough4, 0.0, 100),
]


def run_parcelfit(bounds, f, seed, budget, settings=None):
    bo = BatchBO(
        Space.from_bounds(bounds), batch_size=4, seed=seed, settings=settings or BOSettings()
    )
    n = 0
    while n < budget:
        for p in bo.ask(min(4 if n else 16, budget - n)):
            bo.tell(p, f(p))
            n += 1


def run_random(bounds, f, seed, budget):
    rng = np.random.default_rng(seed)
    for _ in range(budget):
        f({k: lo + (hi - lo) * rng.random() for k, (lo, hi) in bounds.items()})


def run_optuna(bounds, f, seed, budget):
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=seed))
    n = 0
    while n < budget:
        trials = [study.ask() for _ in range(min(4, budget - n))]
        for tr in trials:
            study.tell(tr, f({k: tr.suggest_float(k, lo, hi) for k, (lo, hi) in bounds.items()}))
            n += 1


def run_mango(bounds, f, seed, budget, published=False):
    """Mango with its defaults except 16 random initial points and 4000 domain points, or
    (published=True) configured as method.md section 7: a Latin hypercube of 16, GP Matern 5/2
    with noise 0.35^2, k-means batches, no exploration."""
    from mango import Tuner
    from scipy.stats import qmc, uniform
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import Matern

    random.seed(seed)
    np.random.seed(seed)

    def objective(batch):
        return [f(p) for p in batch]

    space = {k: uniform(lo, hi - lo) for k, (lo, hi) in bounds.items()}
    conf = {
        "batch_size": 4,
        "initial_random": 16,
        "num_iteration": (budget - 16) // 4,
        "log_progress": False,
        # Mango's own domain is 50,000-500,000 random points per batch, which makes a 20-seed
        # run take hours; both variants use 4000 Monte Carlo points, as parcelfit does
        "domain_size": 4000,
    }
    if published:
        lhs = qmc.LatinHypercube(d=len(bounds), scramble=True, seed=seed).random(16)
        names = list(bounds)
        conf |= {
            "initial_custom": [
                {
                    k: bounds[k][0] + u[i] * (bounds[k][1] - bounds[k][0])
                    for i, k in enumerate(names)
                }
                for u in lhs
            ],
            "surrogate": GaussianProcessRegressor(
                kernel=Matern(nu=2.5),
                alpha=0.35**2,
                normalize_y=True,
                n_restarts_optimizer=3,
                random_state=seed,
            ),
            "parallel_strategy": "clustering",
            "exploration": 0.0,
            "alpha": 2.0,
        }
    Tuner(space, objective, conf).minimize()


METHODS = {
    "parcelfit": run_parcelfit,
    "published": lambda b, f, s, n: run_parcelfit(b, f, s, n, BOSettings.published()),
    "mango-default": run_mango,
    "mango-published": lambda b, f, s, n: run_mango(b, f, s, n, published=True),
    "optuna-tpe": run_optuna,
    "random": run_random,
}
# one change at a time against the published configuration (--methods to select)
ABLATIONS = {
    "pub+noisefit": BOSettings.published(noise="fit"),
    "pub+auto": BOSettings.published(transform="auto"),
    "pub+logei": BOSettings.published(acquisition="logei", incumbent="mean"),
    "pub+polish": BOSettings.published(polish=2),
    "pub+believer": BOSettings.published(batch="believer"),
    "pub+ard+local": BOSettings.published(ard=True, amplitude=True, local_fraction=0.25),
}
for _name, _settings in ABLATIONS.items():
    METHODS[_name] = lambda b, f, s, n, _st=_settings: run_parcelfit(b, f, s, n, _st)


def variant_settings(method: str, **base_keys: object) -> BOSettings:
    """The `BOSettings` of ``gp:key=value:...`` (the default with changed settings) or
    ``pub:key=value:...`` / ``published:key=value:...`` (the published preset with changes),
    e.g. ``gp:transform=none`` or ``pub:noise=fit``; ``base_keys`` go in first."""
    base, *pairs = method.split(":")
    make = {"gp": BOSettings, "pub": BOSettings.published, "published": BOSettings.published}
    fields = {f.name: f.type for f in BOSettings.__dataclass_fields__.values()}
    kinds = {"int": int, "float": float, "bool": lambda v: v == "true", "str": str}
    kw = {k: kinds[fields[k]](v) for k, v in (pair.split("=") for pair in pairs)}
    return make[base](**{**base_keys, **kw})


def _variant(method: str):
    """A method running ``variant_settings(method)``."""
    settings = variant_settings(method)
    return lambda b, f, s, n: run_parcelfit(b, f, s, n, settings)


def evals_to_regret(values, optimum, tol=0.01):
    best = np.minimum.accumulate(values)
    hit = np.flatnonzero(best - optimum <= tol)
    return int(hit[0]) + 1 if hit.size else None


def _one_thread() -> None:
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)


def one(job):
    fname, method, seed = job
    _, bounds, f, truth, opt, budget = next(fn for fn in FUNCTIONS if fn[0] == fname)
    true_values: list[float] = []

    def objective(p):
        true_values.append(truth(p))
        return f(p)

    t0 = time.process_time()  # CPU seconds of this worker (one BLAS thread): load-independent
    try:
        run = METHODS[method] if method in METHODS else _variant(method)
        run(bounds, objective, seed, budget)
    except ImportError as exc:
        return fname, method, seed, "missing", str(exc), 0.0
    values = true_values[:budget]
    return (
        fname,
        method,
        seed,
        evals_to_regret(values, opt),
        min(values) - opt,
        time.process_time() - t0,
    )


def ask_overhead(n_obs: int = 200, dims: int = 4, repeats: int = 5) -> float:
    """Median CPU seconds of ask(4) after n_obs observations in dims dimensions, one BLAS
    thread: the time on one core, whatever else the machine runs."""
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
            t0 = time.process_time()
            batch = bo.ask(4)
            times.append(time.process_time() - t0)
            for p in batch:  # keep the history growing as in a study
                bo.tell(p, 0.1)
    return statistics.median(times)


PEERS = ("mango-default", "mango-published", "optuna-tpe", "published")


def _ratios(finals: dict[str, float], ours: str = "parcelfit") -> str:
    """One line: our median final regret over each peer's, all measured in this run."""
    if ours not in finals:
        return ""
    parts = [
        f"{p} {finals[ours] / finals[p]:.3g}" if finals[p] > 0 else f"{p} (peer regret 0)"
        for p in PEERS
        if p in finals
    ]
    return f"{'':<12}{ours} / peer, median final regret: " + ", ".join(parts)


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--functions", default=",".join(fn[0] for fn in FUNCTIONS))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--overhead-only", action="store_true")
    args = ap.parse_args()
    if args.overhead_only:
        print(
            f"ask(4) with 200 observations in 4-D, one core: {ask_overhead():.2f} CPU s (target: <= 2 s)"
        )
        return
    methods = args.methods.split(",")
    functions = args.functions.split(",")
    print(
        f"batch size 4, {args.seeds} seeds; evaluations to regret <= 0.01 (budget after the @)",
        flush=True,
    )
    print(
        f"{'function':<12}{'method':<24}{'median evals':>13}{'reached':>9}{'median final regret':>21}{'cpu s/run':>10}"
    )
    # one BLAS thread per worker: with two workers on a shared machine, multithreaded BLAS
    # oversubscribes the cores and the timings measure contention instead of the methods
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"  # inherited by the spawned workers before they load BLAS
    with multiprocessing.get_context("spawn").Pool(args.jobs, initializer=_one_thread) as pool:
        for fname in functions:  # one function at a time, printed as soon as it is done
            budget = next(fn[5] for fn in FUNCTIONS if fn[0] == fname)
            jobs = [(fname, m, s) for m in methods for s in range(args.seeds)]
            results = pool.map(one, jobs, chunksize=1)
            finals: dict[str, float] = {}
            for m in methods:
                rows = [r for r in results if r[1] == m]
                if any(r[3] == "missing" for r in rows):
                    print(f"{fname:<12}{m:<24}  not installed: {rows[0][4]}")
                    continue
                hits = [r[3] if r[3] is not None else math.inf for r in rows]
                med = statistics.median(hits)
                med_txt = f">{budget}" if math.isinf(med) else f"{med:g}"
                reached = sum(h != math.inf for h in hits) / len(hits)
                final = finals[m] = statistics.median(r[4] for r in rows)
                secs = statistics.median(r[5] for r in rows)
                print(
                    f"{fname:<12}{m:<24}{med_txt:>13}{reached:>9.0%}{final:>21.2e}{secs:>10.1f}",
                    flush=True,
                )
            if ratios := _ratios(finals):
                print(ratios, flush=True)
    print(
        f"ask(4) with 200 observations in 4-D, one core: {ask_overhead():.2f} CPU s (target: <= 2 s)"
    )


if __name__ == "__main__":
    main()
