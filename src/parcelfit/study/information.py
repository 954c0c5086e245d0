"""The linear-Gaussian experimental design behind ``parcelfit design``
(`parcelfit.study.design`, whose docstring states the formulas): the information of real runs
of a case, the expected interval shares it leaves, the runs needed, the greedy order of
candidates and the t value an effect must reach to count. Parameters are in interval units
(each parameter's current interval mapped to [0, 1])."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from parcelfit.study.predict import QUANTITIES
from parcelfit.study.spread import FALSE_EFFECTS, t_threshold

MAX_RUNS = 100  # the most real runs a candidate is asked for
PRIOR_PRECISION = 12.0  # of a uniform distribution on [0, 1]


def information(
    J: np.ndarray, scatter: np.ndarray, runs: int = 1, model: np.ndarray | None = None
) -> np.ndarray:
    """The information of ``runs`` real runs of a case fitted against simulations (module
    docstring of `parcelfit.study.design`): J^T (S / n + M)^-1 J, ``J`` (quantities x
    parameters, the changes over the intervals), ``scatter`` s_q (per quantity, same units),
    ``model`` m_q the variance of the simulated mean over the fit's placements (same units
    squared; None: 0, the simulations' mean taken as exact); parameters x parameters, in
    interval units. Without ``model`` it is ``runs`` times one run's J^T S^-1 J; with it,
    it stops growing at J^T M^-1 J however many runs are added."""
    scatter = np.asarray(scatter, float)
    if model is None:
        Js = np.asarray(J, float) / scatter[:, None]
        return runs * (Js.T @ Js)
    Js = np.asarray(J, float) / np.sqrt(scatter**2 / runs + np.asarray(model, float))[:, None]
    return Js.T @ Js


def shares_of(gained: np.ndarray, known: np.ndarray | None = None) -> np.ndarray:
    """Per parameter the expected interval as a share of today's (at most 1): the posterior
    standard deviation with the information ``known`` (what the fitted cases tell; None:
    nothing) plus ``gained`` (the new runs'), over that with ``known`` alone; both with the
    uniform prior over today's intervals (precision 12 in interval units)."""
    gained = np.asarray(gained, float)
    d = gained.shape[0]
    base = PRIOR_PRECISION * np.eye(d) + (0.0 if known is None else np.asarray(known, float))
    before = np.diag(np.linalg.inv(base))
    after = np.diag(np.linalg.inv(base + gained))
    ratio = np.maximum(after, 0.0) / np.maximum(before, 1e-300)
    return np.minimum(1.0, np.sqrt(ratio))


def expected_width(
    J: np.ndarray,
    scatter: np.ndarray,
    runs: int,
    known: np.ndarray | None = None,
    model: np.ndarray | None = None,
) -> np.ndarray:
    """w_p(n) of the module docstring for every parameter: ``J`` (quantities x parameters, the
    changes over the intervals), ``scatter`` s_q (per quantity, same units), ``runs`` n,
    ``known`` the information the fitted cases hold (None: nothing), ``model`` the simulated
    mean's variance m_q (`information`); a share of the current interval (at most 1)."""
    return shares_of(information(J, scatter, runs, model), known)


def runs_needed(
    J: np.ndarray,
    scatter: np.ndarray,
    target: np.ndarray,
    known: np.ndarray | None = None,
    model: np.ndarray | None = None,
) -> list[int | None]:
    """Per parameter, the fewest real runs (1 to `MAX_RUNS`) after which the expected width
    share (with the information ``known`` of the fitted cases and the simulated mean's
    variance ``model``, `information`) is at most ``target`` (a share of the current
    interval); None when never."""
    out: list[int | None] = [None] * J.shape[1]
    for n in range(1, MAX_RUNS + 1):
        w = shares_of(information(J, scatter, n, model), known)
        for p in range(J.shape[1]):
            if out[p] is None and w[p] <= target[p]:
                out[p] = n
        if all(v is not None for v in out):
            break
    return out


def greedy_sequence(
    infos: Sequence[np.ndarray], known: np.ndarray | None, open_: Sequence[int]
) -> list[tuple[int, float]]:
    """The candidates in the greedy order of `parcelfit.study.design`'s docstring: ``infos``
    the information of each one's real runs (`information`), ``known`` the fitted cases', ``open_`` the indices
    of the open parameters; each step takes the candidate whose runs, added to those of the
    ones taken before, leave the smallest mean share over the open parameters (ties: the
    earlier candidate). Returns (candidate index, that mean share) in order."""
    if not infos:
        return []
    idx = list(open_)
    taken = np.zeros_like(np.asarray(infos[0], float))
    left = list(range(len(infos)))
    out: list[tuple[int, float]] = []
    while left:
        means = [float(np.mean(shares_of(taken + infos[c], known)[idx])) for c in left]
        k = int(np.argmin(np.round(means, 12)))
        out.append((left[k], means[k]))
        taken = taken + infos[left[k]]
        left.pop(k)
    return out


def resolved_t(n_sets: int, n_parameters: int) -> float:
    """The t value an effect must reach to count (module docstring): `t_threshold` over the
    quantities of `parcelfit.study.predict`."""
    return t_threshold(n_sets, n_parameters, len(QUANTITIES))


__all__ = [
    "FALSE_EFFECTS",
    "MAX_RUNS",
    "PRIOR_PRECISION",
    "expected_width",
    "greedy_sequence",
    "information",
    "resolved_t",
    "runs_needed",
    "shares_of",
]
