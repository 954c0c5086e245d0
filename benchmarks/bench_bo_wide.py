"""The optimisers on a wide set of standard test functions, split into a tuning half and a
held-out half before anything runs.

    python -m pip install -e ".[optuna,botorch]"   # torch from its CPU wheel index first
    python benchmarks/bench_bo_wide.py [--seeds 10] [--jobs 2] [--out bench-bo-wide]
        [--samplers gp,published,tpe,optuna-gp,botorch] [--problems Branin,Levy4,...]
        [--half fresh|heldout|tuning|both] [--no-timing] [--summary-only] [--check-minima]

Problems (21, 2-8 dimensions; `PROBLEMS`), in four categories: smooth (Branin, Six-hump
camel, Hartmann 3 and 6, Rosenbrock 4, Styblinski-Tang 4, an ill-conditioned ellipsoid in 8-D
with condition number 1e6), multimodal (Levy 4 and 6, Ackley 3 and 5, Michalewicz 5, Shekel 4
with m = 10, Rastrigin 3), rough like the parcel cost (Rough4 of benchmarks/bench_bo.py and a
3-D and a 6-D one built the same way) and noisy (Hartmann 3 and 6 with Gaussian observation
noise of sd 0.05 and 0.2, seeded by the evaluated point; the regret is of the noise-free value).

A second held-out half, ``fresh`` (12 more problems, `FRESH`: Goldstein-Price 2, Dixon-Price
4, Zakharov 6, Powell 8; Drop-wave 2, Schwefel 3, Shekel 4 with m = 7, Griewank 5; a 2-D and a
5-D rough one; Hartmann 4 with noise of sd 0.05 and Michalewicz 2 with noise of sd 0.2), fixed
on 2026-12-07 before any sampler ran on it, because the first held-out half had been used to
choose the default's acquisition among variants; ``--half fresh`` runs it and the summary
gives it a table of its own. ``--check-minima`` checks its global minima.

The split (`split`, printed and written to ``<out>/split.csv``), stratified by category: the
default ``gp`` was tuned on the problems of benchmarks/bench_bo.py (`TUNED`), so they go to the
tuning half; within each category the other problems are drawn in a seeded random order
(``SPLIT_SEED``) into the tuning half until it holds half the category (rounded down), the
rest is the held-out half. Nothing else is random at import.

Each run: batches of 4, 16 initial points (each sampler's own initial design: Latin hypercube
for gp, published and botorch; Optuna's random startup for tpe and optuna-gp, ``n_startup_trials``
16), ``--budget`` evaluations in all (default 64). Result: the final simple regret (the best
noise-free value among the evaluated points minus the global minimum) and the CPU seconds of
the run (one BLAS/torch thread per worker), appended to ``<out>/results.csv`` as each run ends;
a rerun skips the (problem, sampler, seed) rows already there. The held-out half runs first.

Summary (``<out>/summary.md``, also printed): per half, the median final regret per problem and
sampler, and per sampler the share of the half's problems on which its median final regret is
the lowest or within 10 % of the lowest. Timing: the median CPU seconds of ``ask(4)`` after 200
observations in 4-D, one thread, per sampler (``<out>/timing.csv``).
"""

from __future__ import annotations

import argparse
import csv
import math
import multiprocessing
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from machine_load import installed, processor

SPLIT_SEED = 57
BATCH = 4
N_INITIAL = 16
SAMPLERS = ("gp", "published", "tpe", "optuna-gp", "botorch")
VERSIONED = ("numpy", "scipy", "scikit-learn", "optuna", "torch", "botorch", "gpytorch")

Objective = Callable[[np.ndarray], float]


# -- test functions (x in the problem's own box) ----------------------------------------------
def branin(x: np.ndarray) -> float:
    x1, x2 = x
    b, c, t = 5.1 / (4 * math.pi**2), 5 / math.pi, 1 / (8 * math.pi)
    return float((x2 - b * x1**2 + c * x1 - 6) ** 2 + 10 * (1 - t) * math.cos(x1) + 10)


def six_hump_camel(x: np.ndarray) -> float:
    x1, x2 = x
    return float((4 - 2.1 * x1**2 + x1**4 / 3) * x1**2 + x1 * x2 + (-4 + 4 * x2**2) * x2**2)


_H3_A = np.array([[3.0, 10, 30], [0.1, 10, 35], [3.0, 10, 30], [0.1, 10, 35]])
_H3_P = 1e-4 * np.array(
    [[3689, 1170, 2673], [4699, 4387, 7470], [1091, 8732, 5547], [381, 5743, 8828]]
)
_H6_A = np.array(
    [
        [10, 3, 17, 3.5, 1.7, 8],
        [0.05, 10, 17, 0.1, 8, 14],
        [3, 3.5, 1.7, 10, 17, 8],
        [17, 8, 0.05, 10, 0.1, 14],
    ]
)
_H6_P = 1e-4 * np.array(
    [
        [1312, 1696, 5569, 124, 8283, 5886],
        [2329, 4135, 8307, 3736, 1004, 9991],
        [2348, 1451, 3522, 2883, 3047, 6650],
        [4047, 8828, 8732, 5743, 1091, 381],
    ]
)
_H_ALPHA = np.array([1.0, 1.2, 3.0, 3.2])


def hartmann3(x: np.ndarray) -> float:
    return float(-np.sum(_H_ALPHA * np.exp(-np.sum(_H3_A * (x - _H3_P) ** 2, axis=1))))


def hartmann6(x: np.ndarray) -> float:
    return float(-np.sum(_H_ALPHA * np.exp(-np.sum(_H6_A * (x - _H6_P) ** 2, axis=1))))


def rosenbrock(x: np.ndarray) -> float:
    return float(np.sum(100 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[:-1]) ** 2))


def styblinski_tang(x: np.ndarray) -> float:
    return float(0.5 * np.sum(x**4 - 16 * x**2 + 5 * x))


_ELL_SHIFT = np.array([1.3, -2.1, 0.7, 3.1, -0.4, -3.3, 2.2, 0.9])


def ellipsoid(x: np.ndarray) -> float:
    """Axis-aligned ellipsoid with condition number 1e6, minimum 0 away from the centre."""
    d = len(x)
    w = 10.0 ** (6 * np.arange(d) / (d - 1))
    return float(np.sum(w * (x - _ELL_SHIFT[:d]) ** 2))


def levy(x: np.ndarray) -> float:
    w = 1 + (x - 1) / 4
    return float(
        math.sin(math.pi * w[0]) ** 2
        + np.sum((w[:-1] - 1) ** 2 * (1 + 10 * np.sin(math.pi * w[:-1] + 1) ** 2))
        + (w[-1] - 1) ** 2 * (1 + math.sin(2 * math.pi * w[-1]) ** 2)
    )


def ackley(x: np.ndarray) -> float:
    d = len(x)
    return float(
        -20 * math.exp(-0.2 * math.sqrt(np.sum(x**2) / d))
        - math.exp(np.sum(np.cos(2 * math.pi * x)) / d)
        + 20
        + math.e
    )


def michalewicz(x: np.ndarray) -> float:
    i = np.arange(1, len(x) + 1)
    return float(-np.sum(np.sin(x) * np.sin(i * x**2 / math.pi) ** 20))


_SHEKEL_C = 0.1 * np.array([1, 2, 2, 4, 4, 6, 3, 7, 5, 5])
_SHEKEL_A = np.array(
    [
        [4, 4, 4, 4],
        [1, 1, 1, 1],
        [8, 8, 8, 8],
        [6, 6, 6, 6],
        [3, 7, 3, 7],
        [2, 9, 2, 9],
        [5, 5, 3, 3],
        [8, 1, 8, 1],
        [6, 2, 6, 2],
        [7, 3.6, 7, 3.6],
    ],
    dtype=float,
)


def shekel(x: np.ndarray) -> float:
    return float(-np.sum(1 / (np.sum((x - _SHEKEL_A) ** 2, axis=1) + _SHEKEL_C)))


def rastrigin(x: np.ndarray) -> float:
    return float(10 * len(x) + np.sum(x**2 - 10 * np.cos(2 * math.pi * x)))


def _rough(d: int, seed: int) -> Objective:
    """A d-D cost built like benchmarks/bench_bo.py's Rough4 (and equal to it for d = 4, seed
    2024): a smooth bowl plus deterministic roughness of at most 0.04 with a wavelength of
    about 1 % of a parameter's range, zero at the optimum (global minimum 0)."""
    if d == 4:
        centre, weights = np.array([0.31, 0.62, 0.47, 0.74]), np.array([1.0, 0.6, 0.35, 0.15])
    else:
        r = np.random.default_rng(seed + 100)
        centre, weights = r.uniform(0.2, 0.8, d), np.geomspace(1.0, 0.15, d)
    dirs = np.random.default_rng(seed).standard_normal((8, d))
    freq = np.random.default_rng(seed + 1).uniform(40.0, 120.0, 8)

    def f(x: np.ndarray) -> float:
        u = x - centre
        bowl = float(np.sum(weights * u**2)) / 0.6
        return bowl + 0.04 * float(np.mean(np.sin(np.pi * freq * (dirs @ u)) ** 2))

    return f


def _noisy(f: Objective, sd: float) -> Objective:
    """``f`` plus Gaussian noise of sd ``sd``, seeded by the point itself (the same for every
    sampler that evaluates the same point)."""

    def g(x: np.ndarray) -> float:
        key = np.frombuffer(np.asarray(x, dtype=float).tobytes(), dtype=np.uint32).tolist()
        return f(x) + sd * float(np.random.default_rng(key).standard_normal())

    return g


# name -> (category, bounds per dimension, observed function, true function, global minimum)
Problem = tuple[str, list[tuple[float, float]], Objective, Objective, float]
_RO3, _RO4, _RO6 = _rough(3, 2030), _rough(4, 2024), _rough(6, 2026)
_U3, _U6 = [(0.0, 1.0)] * 3, [(0.0, 1.0)] * 6
PROBLEMS: dict[str, Problem] = {
    "Branin": ("smooth", [(-5.0, 10.0), (0.0, 15.0)], branin, branin, 0.397887),
    "SixHumpCamel": (
        "smooth",
        [(-3.0, 3.0), (-2.0, 2.0)],
        six_hump_camel,
        six_hump_camel,
        -1.031628,
    ),
    "Hartmann3": ("smooth", _U3, hartmann3, hartmann3, -3.86278),
    "Hartmann6": ("smooth", _U6, hartmann6, hartmann6, -3.32237),
    "Rosenbrock4": ("smooth", [(-2.048, 2.048)] * 4, rosenbrock, rosenbrock, 0.0),
    "StyblinskiTang4": ("smooth", [(-5.0, 5.0)] * 4, styblinski_tang, styblinski_tang, -156.66466),
    "Ellipsoid8": ("smooth", [(-5.0, 5.0)] * 8, ellipsoid, ellipsoid, 0.0),
    "Levy4": ("multimodal", [(-10.0, 10.0)] * 4, levy, levy, 0.0),
    "Levy6": ("multimodal", [(-10.0, 10.0)] * 6, levy, levy, 0.0),
    # Ackley on [-5, 10]^d: the usual [-32.768, 32.768]^d leaves a needle no 64-point budget
    # finds, and a box centred on the minimum favours samplers that try the centre
    "Ackley3": ("multimodal", [(-5.0, 10.0)] * 3, ackley, ackley, 0.0),
    "Ackley5": ("multimodal", [(-5.0, 10.0)] * 5, ackley, ackley, 0.0),
    "Michalewicz5": ("multimodal", [(0.0, math.pi)] * 5, michalewicz, michalewicz, -4.687658),
    "Shekel4": ("multimodal", [(0.0, 10.0)] * 4, shekel, shekel, -10.536410),
    "Rastrigin3": ("multimodal", [(-5.12, 5.12)] * 3, rastrigin, rastrigin, 0.0),
    "Rough3": ("rough", _U3, _RO3, _RO3, 0.0),
    "Rough4": ("rough", [(0.0, 1.0)] * 4, _RO4, _RO4, 0.0),
    "Rough6": ("rough", _U6, _RO6, _RO6, 0.0),
    "Hartmann3+n0.05": ("noisy", _U3, _noisy(hartmann3, 0.05), hartmann3, -3.86278),
    "Hartmann3+n0.2": ("noisy", _U3, _noisy(hartmann3, 0.2), hartmann3, -3.86278),
    "Hartmann6+n0.05": ("noisy", _U6, _noisy(hartmann6, 0.05), hartmann6, -3.32237),
    "Hartmann6+n0.2": ("noisy", _U6, _noisy(hartmann6, 0.2), hartmann6, -3.32237),
}
# the problems of benchmarks/bench_bo.py, on which the default was tuned (Hartmann6+n0.05 is
# its Hartmann6+n)
TUNED = ("Branin", "Hartmann6", "Hartmann6+n0.05", "Rough4")


def split(seed: int = SPLIT_SEED) -> dict[str, str]:
    """Problem -> "tuning" or "heldout": within each category, the problems in a seeded random
    order, the tuned ones first, fill the tuning half up to half the category (rounded down);
    the rest is held out."""
    rng = np.random.default_rng(seed)
    halves = {}
    for category in ("smooth", "multimodal", "rough", "noisy"):
        names = [n for n, pr in PROBLEMS.items() if pr[0] == category]
        drawn = [names[i] for i in rng.permutation(len(names))]
        order = [n for n in drawn if n in TUNED] + [n for n in drawn if n not in TUNED]
        for i, n in enumerate(order):
            halves[n] = "tuning" if i < len(names) // 2 else "heldout"
    return {n: halves[n] for n in PROBLEMS}


HALVES = split()  # drawn before anything else runs


# -- a second held-out half -----------------------------------------------------------------------
# The first held-out half was used to choose the default's acquisition (noisy EI) among
# variants (docs/research/bo-wide/tuning-variants.md), so it no longer judges the default on
# problems nothing was chosen on. These 12 ("fresh") were fixed on 2026-12-07 before any
# sampler ran on them: the same four categories, 2-8 dimensions, none a function of either
# earlier half at its dimension (module docstring). Boxes that would centre a minimum are
# shifted, as Ackley's. Global minima from the literature where it gives them to enough digits,
# else by a fine local optimisation from the known minimiser; `--check-minima` checks each
# against a dense random sample and local optimisations from its best points.


def goldstein_price(x: np.ndarray) -> float:
    x1, x2 = x
    a = 1 + (x1 + x2 + 1) ** 2 * (19 - 14 * x1 + 3 * x1**2 - 14 * x2 + 6 * x1 * x2 + 3 * x2**2)
    b = 30 + (2 * x1 - 3 * x2) ** 2 * (
        18 - 32 * x1 + 12 * x1**2 + 48 * x2 - 36 * x1 * x2 + 27 * x2**2
    )
    return float(a * b)


def dixon_price(x: np.ndarray) -> float:
    i = np.arange(2, len(x) + 1)
    return float((x[0] - 1) ** 2 + np.sum(i * (2 * x[1:] ** 2 - x[:-1]) ** 2))


def zakharov(x: np.ndarray) -> float:
    s = float(np.sum(0.5 * np.arange(1, len(x) + 1) * x))
    return float(np.sum(x**2) + s**2 + s**4)


def powell(x: np.ndarray) -> float:
    a, b, c, d = x[0::4], x[1::4], x[2::4], x[3::4]
    return float(
        np.sum((a + 10 * b) ** 2 + 5 * (c - d) ** 2 + (b - 2 * c) ** 4 + 10 * (a - d) ** 4)
    )


def drop_wave(x: np.ndarray) -> float:
    r2 = float(np.sum(x**2))
    return float(-(1 + math.cos(12 * math.sqrt(r2))) / (0.5 * r2 + 2))


def schwefel(x: np.ndarray) -> float:
    return float(418.9829 * len(x) - np.sum(x * np.sin(np.sqrt(np.abs(x)))))


def shekel7(x: np.ndarray) -> float:
    """Shekel's function with m = 7: the first seven of the ten terms of `shekel` (Dixon and
    Szego's centres, the seventh (5, 5, 3, 3); some libraries give (5, 3, 5, 3))."""
    a, c = _SHEKEL_A[:7], _SHEKEL_C[:7]
    return float(-np.sum(1 / (np.sum((x - a) ** 2, axis=1) + c)))


def griewank(x: np.ndarray) -> float:
    i = np.arange(1, len(x) + 1)
    return float(np.sum(x**2) / 4000 - np.prod(np.cos(x / np.sqrt(i))) + 1)


# Hartmann 6's coefficients on its first four inputs
_H4_A, _H4_P = _H6_A[:, :4], _H6_P[:, :4]


def hartmann4(x: np.ndarray) -> float:
    """The 4-D Hartmann function (the 6-D one's coefficients on the first four inputs, scaled
    as Picheny et al. 2013: (1.1 - sum) / 0.839)."""
    inner = np.sum(_H4_A * (x - _H4_P) ** 2, axis=1)
    return float((1.1 - np.sum(_H_ALPHA * np.exp(-inner))) / 0.839)


def _schwefel_min(d: int) -> float:
    """Schwefel's minimum in d dimensions: d times the minimum of its 1-D term (separable)."""
    from scipy.optimize import minimize_scalar

    term = minimize_scalar(
        lambda t: 418.9829 - t * math.sin(math.sqrt(abs(t))),
        bounds=(400.0, 440.0),
        method="bounded",
        options={"xatol": 1e-12},
    )
    return d * float(term.fun)


def _refined(f: Objective, x0: list[float]) -> float:
    """The minimum of ``f`` by a fine local optimisation from the known minimiser ``x0``."""
    from scipy.optimize import minimize

    res = minimize(
        f,
        np.array(x0, float),
        method="Nelder-Mead",
        options={"xatol": 1e-12, "fatol": 1e-15, "maxiter": 20000},
    )
    return float(min(res.fun, f(np.array(x0, float))))


_RO2, _RO5 = _rough(2, 2031), _rough(5, 2032)
_U2, _U4, _U5 = [(0.0, 1.0)] * 2, [(0.0, 1.0)] * 4, [(0.0, 1.0)] * 5
_H4_MIN = _refined(hartmann4, [0.1873, 0.1906, 0.5566, 0.2647])
_M2_MIN = _refined(michalewicz, [2.20290552, 1.57079633])
_S7_MIN = _refined(shekel7, [4.00057, 4.00069, 3.99949, 3.99961])

# name -> (category, bounds per dimension, observed function, true function, global minimum)
FRESH: dict[str, Problem] = {
    "GoldsteinPrice2": ("smooth", [(-2.0, 2.0)] * 2, goldstein_price, goldstein_price, 3.0),
    "DixonPrice4": ("smooth", [(-10.0, 10.0)] * 4, dixon_price, dixon_price, 0.0),
    "Zakharov6": ("smooth", [(-5.0, 10.0)] * 6, zakharov, zakharov, 0.0),
    "Powell8": ("smooth", [(-4.0, 5.0)] * 8, powell, powell, 0.0),
    "DropWave2": ("multimodal", [(-3.0, 5.12)] * 2, drop_wave, drop_wave, -1.0),
    "Schwefel3": ("multimodal", [(-500.0, 500.0)] * 3, schwefel, schwefel, _schwefel_min(3)),
    "Shekel7": ("multimodal", [(0.0, 10.0)] * 4, shekel7, shekel7, _S7_MIN),
    "Griewank5": ("multimodal", [(-8.0, 12.0)] * 5, griewank, griewank, 0.0),
    "Rough2": ("rough", _U2, _RO2, _RO2, 0.0),
    "Rough5": ("rough", _U5, _RO5, _RO5, 0.0),
    "Hartmann4+n0.05": ("noisy", _U4, _noisy(hartmann4, 0.05), hartmann4, _H4_MIN),
    "Michalewicz2+n0.2": (
        "noisy",
        [(0.0, math.pi)] * 2,
        _noisy(michalewicz, 0.2),
        michalewicz,
        _M2_MIN,
    ),
}


def check_fresh_minima(samples: int = 200_000, starts: int = 30, seed: int = 0) -> None:
    """Print, per problem, the minimum used and the lowest value found by a dense random sample
    and local optimisations from its best points (never below the minimum used)."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(seed)
    for name, (_, bounds, _, f, optimum) in FRESH.items():
        lo, hi = np.array(bounds).T
        x = lo + (hi - lo) * rng.random((samples, len(bounds)))
        vals = np.array([f(p) for p in x])
        best = float(vals.min())
        for i in np.argsort(vals)[:starts]:
            res = minimize(f, x[i], method="L-BFGS-B", bounds=bounds)
            best = min(best, float(res.fun))
        flag = "OK" if best >= optimum - 1e-9 * max(1.0, abs(optimum)) else "BELOW"
        print(f"{name:<20} minimum used {optimum:.10g}  lowest found {best:.10g}  {flag}")


HALVES.update(dict.fromkeys(FRESH, "fresh"))
ALL_PROBLEMS: dict[str, Problem] = {**PROBLEMS, **FRESH}


# -- runs ---------------------------------------------------------------------------------------
def _sampler(name: str, bounds: list[tuple[float, float]], seed: int):
    from parcelfit.optimize import Space
    from parcelfit.optimize.sampler import make_sampler

    space = Space.from_bounds({f"x{i}": b for i, b in enumerate(bounds)})
    options = {"n_startup_trials": N_INITIAL} if name == "tpe" else None
    base, settings = _variant(name)
    return make_sampler(
        base,
        space,
        batch_size=BATCH,
        seed=seed,
        n_initial=N_INITIAL,
        settings=settings,
        options=options,
    )


def _variant(name: str):
    """``gp:key=value:...`` -> ("gp", the default's `BOSettings` with those keys changed), as
    a study file's optimizer keys are read; any other name -> (name, None)."""
    from bench_bo import variant_settings

    base = name.split(":")[0]
    if base == name:
        return base, None
    return base, variant_settings(name, n_initial=N_INITIAL)


def _one_thread() -> None:
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass


def run_one(job: tuple[str, str, int, int]) -> dict[str, object]:
    """One (problem, sampler, seed) run: the final regret and CPU seconds."""
    problem, sampler, seed, budget = job
    _, bounds, f, truth, optimum = ALL_PROBLEMS[problem]
    t0 = time.process_time()
    try:
        opt = _sampler(sampler, bounds, seed)
    except Exception as exc:  # a sampler whose extra is not installed
        return {"problem": problem, "sampler": sampler, "seed": seed, "error": str(exc)}
    best = math.inf
    n = 0
    while n < budget:
        for p in opt.ask(min(BATCH, budget - n)):
            x = np.array([p[f"x{i}"] for i in range(len(bounds))])
            best = min(best, truth(x))
            opt.tell(p, f(x))
            n += 1
    return {
        "problem": problem,
        "half": HALVES[problem],
        "sampler": sampler,
        "seed": seed,
        "dims": len(bounds),
        "budget": budget,
        "final_regret": max(best - optimum, 0.0),
        "cpu_s": time.process_time() - t0,
    }


def ask_time(sampler: str, n_obs: int = 200, dims: int = 4, repeats: int = 3) -> dict[str, object]:
    """Median CPU seconds of ask(4) after ``n_obs`` observations in ``dims`` dimensions, one
    thread (the initial design is used up first, so every timed ask fits its model)."""
    rng = np.random.default_rng(0)
    try:
        opt = _sampler(sampler, [(0.0, 1.0)] * dims, 0)
    except Exception as exc:
        return {"sampler": sampler, "error": str(exc)}

    def cost(p: dict[str, float]) -> float:
        return float(sum((v - 0.4) ** 2 for v in p.values()) + 0.01 * rng.standard_normal())

    for p in opt.ask(N_INITIAL):
        opt.tell(p, cost(p))
    for _ in range(n_obs - N_INITIAL):
        p = {f"x{i}": float(rng.random()) for i in range(dims)}
        opt.tell(p, cost(p))
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        batch = opt.ask(4)
        times.append(time.process_time() - t0)
        for p in batch:
            opt.tell(p, cost(p))
    return {
        "sampler": sampler,
        "n_obs": n_obs,
        "dims": dims,
        "ask4_cpu_s": statistics.median(times),
    }


# -- output -------------------------------------------------------------------------------------
FIELDS = ["problem", "half", "sampler", "seed", "dims", "budget", "final_regret", "cpu_s"]


def _read(path: Path) -> list[dict[str, str]]:
    if not path.exists():
        return []
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def summary(rows: list[dict[str, str]], samplers: list[str]) -> str:
    """The per-half tables (see the module docstring) as Markdown. Per problem only the seeds
    that every sampler has finished count, so that the samplers are compared on the same seeds."""
    out = []
    for half in ("fresh", "heldout", "tuning"):
        regret: dict[tuple[str, str, int], float] = {}
        cpu: dict[str, list[float]] = {s: [] for s in samplers}
        for r in rows:
            if r["half"] == half and r["sampler"] in samplers:
                regret[r["problem"], r["sampler"], int(r["seed"])] = float(r["final_regret"])
        common = {
            p: sorted(
                set.intersection(*({k[2] for k in regret if k[:2] == (p, s)} for s in samplers))
            )
            for p in ALL_PROBLEMS
            if HALVES[p] == half
        }
        probs = [p for p, seeds in common.items() if seeds]
        if not probs:
            continue
        for r in rows:
            if (
                r["half"] == half
                and r["sampler"] in samplers
                and int(r["seed"]) in common.get(r["problem"], [])
            ):
                cpu[r["sampler"]].append(float(r["cpu_s"]))
        n_seeds = sorted({len(common[p]) for p in probs})
        out.append(
            f"\n### {half} half: median final regret ({len(probs)} problems; seeds per problem, "
            f"the same for every sampler: {', '.join(map(str, n_seeds))})\n"
        )
        out.append("| problem | seeds | " + " | ".join(samplers) + " |")
        out.append("|---" * (len(samplers) + 2) + "|")
        good = dict.fromkeys(samplers, 0)
        lowest = dict.fromkeys(samplers, 0)
        for p in probs:
            med = {s: statistics.median(regret[p, s, k] for k in common[p]) for s in samplers}
            lo = min(med.values())
            cells = []
            for s in samplers:
                ok = med[s] <= 1.1 * lo
                good[s] += ok
                lowest[s] += med[s] == lo
                cells.append(f"**{med[s]:.3g}**" if ok else f"{med[s]:.3g}")
            out.append(f"| {p} | {len(common[p])} | " + " | ".join(cells) + " |")
        n = len(probs)
        out.append(
            "| lowest or within 10 % | | "
            + " | ".join(f"{good[s]}/{n} ({good[s] / n:.0%})" for s in samplers)
            + " |"
        )
        out.append("| lowest | | " + " | ".join(f"{lowest[s]}/{n}" for s in samplers) + " |")
        out.append(
            "| median CPU s per run | | "
            + " | ".join(f"{statistics.median(cpu[s]):.1f}" for s in samplers)
            + " |"
        )
    return "\n".join(out)


def timing_table(path: Path) -> str:
    """The ask(4) CPU seconds of ``<out>/timing.csv`` as Markdown."""
    rows = _read(path)
    if not rows:
        return ""
    lines = ["\n### CPU s of ask(4) after 200 observations in 4-D, one thread (median of 3)\n"]
    lines.append("| sampler | CPU s |")
    lines.append("|---|---|")
    for r in rows:
        value = r["ask4_cpu_s"] and f"{float(r['ask4_cpu_s']):.3g}"
        lines.append(f"| {r['sampler']} | {value or r['error']} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--budget", type=int, default=64)
    ap.add_argument("--jobs", type=int, default=2, choices=(1, 2))
    ap.add_argument("--out", type=Path, default=Path("bench-bo-wide"))
    ap.add_argument("--samplers", default=",".join(SAMPLERS))
    ap.add_argument("--problems", default=",".join(ALL_PROBLEMS))
    ap.add_argument("--half", choices=("fresh", "heldout", "tuning", "both"), default="both")
    ap.add_argument("--no-timing", action="store_true")
    ap.add_argument("--summary-only", action="store_true")
    ap.add_argument("--check-minima", action="store_true")
    args = ap.parse_args()
    if args.check_minima:
        check_fresh_minima()
        return
    samplers = args.samplers.split(",")
    # results can differ between machines and installs (docs/research/bo-wide/replication.md)
    print(f"processor: {processor()}", flush=True)
    print(f"installed: {installed(VERSIONED)}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    with (args.out / "split.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["problem", "category", "dims", "half", "split_seed"])
        for p, (fam, bounds, *_) in ALL_PROBLEMS.items():
            w.writerow([p, fam, len(bounds), HALVES[p], SPLIT_SEED])
    for half in ("fresh", "heldout", "tuning"):
        print(f"{half}: {', '.join(p for p in ALL_PROBLEMS if HALVES[p] == half)}", flush=True)
    results = args.out / "results.csv"
    if not args.summary_only:
        done = {(r["problem"], r["sampler"], int(r["seed"])) for r in _read(results)}
        # "both": the first two halves, as before the fresh one existed
        order = ["heldout", "tuning"] if args.half == "both" else [args.half]
        problems = args.problems.split(",")
        jobs = [
            (p, s, seed, args.budget)
            for half in order
            for seed in range(args.seeds)  # all problems of a half at a seed before the next
            for p in problems
            if HALVES[p] == half
            for s in samplers
            if (p, s, seed) not in done
        ]
        print(f"{len(done)} runs done before, {len(jobs)} to run", flush=True)
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[var] = "1"  # inherited by the spawned workers before they load BLAS
        ctx = multiprocessing.get_context("spawn")
        with ctx.Pool(args.jobs, initializer=_one_thread, maxtasksperchild=20) as pool:
            if not args.no_timing:
                with (args.out / "timing.csv").open("w", newline="") as fh:
                    w = csv.DictWriter(fh, ["sampler", "n_obs", "dims", "ask4_cpu_s", "error"])
                    w.writeheader()
                    for t in pool.imap(ask_time, samplers):
                        w.writerow(t)
                        print(f"ask(4), 200 observations, 4-D, one thread: {t}", flush=True)
            new = not results.exists()
            with results.open("a", newline="") as fh:
                w = csv.DictWriter(fh, FIELDS)
                if new:
                    w.writeheader()
                t0 = time.time()
                for i, r in enumerate(pool.imap_unordered(run_one, jobs), 1):
                    if "error" in r:
                        print(f"{r['problem']} {r['sampler']} seed {r['seed']}: {r['error']}")
                        continue
                    w.writerow(r)
                    fh.flush()
                    print(
                        f"[{i}/{len(jobs)} {time.time() - t0:.0f} s] {r['half']} {r['problem']} "
                        f"{r['sampler']} seed {r['seed']}: regret {r['final_regret']:.3g}, "
                        f"{r['cpu_s']:.1f} CPU s",
                        flush=True,
                    )
    text = summary(_read(results), samplers) + "\n" + timing_table(args.out / "timing.csv")
    (args.out / "summary.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
