"""How the spread of a prediction splits between the parameters and the placements, and how far
each parameter moves it: a quantity q simulated at n parameter sets drawn from a calibration's
plausible set S times the same K seeded placements (`parcelfit.study.predict`,
`parcelfit.study.design`).

**Parameters versus placements** (a two-way decomposition, the law of total variance). With
q_ij the run of set i at placement j, n_i the runs of set i that have q, N = sum_i n_i, the
set means m_i = (1/n_i) sum_j q_ij and the grand mean m = (1/N) sum_ij q_ij:

    V = (1/N) sum_ij (q_ij - m)^2                      total variance
    B = (1/N) sum_i n_i (m_i - m)^2                    variance of the per-set means
    W = (1/N) sum_i sum_j (q_ij - m_i)^2               mean within-set variance
    V = B + W,   parameter share = B / V,   placement share = W / V.

The parameter share needs two sets at least (NaN with one). W (divisor N) is what the shares
add up with; as an estimate of one run's scatter about its set's mean it is biased low by the
set means fitted to the same runs, and `Decomposition.run_variance` is the unbiased one,

    s^2 = (1/(N - n_sets)) sum_i sum_j (q_ij - m_i)^2     (NaN when N <= n_sets),

which `parcelfit design` uses (with K = 5 placements W alone is 0.8 of it).

With every run ok (n_i = K) B is the variance of the per-set means and W the mean of the
within-set variances (both with divisor n, resp. K). Because every set sees the same K
placements, a quantity that is a sum of a parameter part and a placement part,
q_ij = a_i + b_j, splits exactly: B = var(a), W = var(b). An interaction of parameters and
placements counts as placement spread (W); B also holds 1/K of the placements' scatter of each
set mean when the parts do not add, so with few placements the parameter share is an upper
estimate.

**How far each parameter moves a prediction** (from the draws, no further simulation): the
per-set means m_i of q are regressed (ordinary least squares, with an intercept) on all
calibrated parameters at once, each scaled to its plausible interval, z = (p - a) / (b - a)
for the interval [a, b]. The coefficient of a parameter is then the change of the predicted
mean over its plausible interval with the other parameters varying over the plausible set as
they do in use (so a parameter correlated with another in S is credited only with its own
part), and its standard error is the regression's. A one-at-a-time sweep was not chosen: it
costs 2 x K more simulations per parameter and moves the parameter from one calibrated set that
may lie outside S at the interval's ends. An effect counts as resolved when its t value
(effect / standard error, nonzero) reaches Student's two-sided quantile with N - d - 1 degrees
of freedom for a 5 % chance that any of a case's quantities x parameters shows an effect it
does not have (Bonferroni, `t_threshold`; 3.5 with 20 sets, 4 parameters and 4 quantities; N the
sets with a mean of that quantity). With N sets and d parameters the regression needs N > d + 1;
for parameters spread evenly over their intervals and uncorrelated, the standard error is about
s sqrt(12 / N), s the scatter of the set means about the fit: 0.77 s with the default 20 sets.
The standard error is the regression's: it holds the placements' scatter of the set means and
whatever the linear fit in all parameters leaves unexplained.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

FALSE_EFFECTS = 0.05  # the chance that a case shows any effect it does not have (t-test)
# run-to-run measurement floor per quantity (SI): the band test's 3 mm and 1 degree, 2 ms
FLOOR = {
    "transit_time": 0.002,
    "exit_y": 0.003,
    "rotation": math.radians(1.0),
    "exit_heading": math.radians(1.0),
}


def t_threshold(n_sets: int, n_parameters: int, n_quantities: int) -> float:
    """The t value an effect must reach to count (module docstring): the two-sided quantile of
    Student's t (n_sets - n_parameters - 1 degrees of freedom, at least 1) at `FALSE_EFFECTS`
    shared over every quantity and parameter of a case (Bonferroni)."""
    from scipy.stats import t

    tests = max(n_quantities * n_parameters, 1)
    dof = max(n_sets - n_parameters - 1, 1)
    return float(t.ppf(1.0 - FALSE_EFFECTS / (2 * tests), dof))


@dataclass(frozen=True)
class Decomposition:
    """The two-way split of the module docstring: total variance V, between-set B and
    within-set W (units of the quantity squared), runs N and sets counted."""

    total: float
    between: float
    within: float
    runs: int
    sets: int

    @property
    def split(self) -> bool:
        """Whether the spread can be split: two sets with a value and some set with two runs
        (with one run per set W is 0 by construction, whatever the placements do)."""
        return self.total > 0 and self.sets >= 2 and self.runs > self.sets

    @property
    def parameter_share(self) -> float:
        """B / V (NaN when V is 0, nothing was measured, fewer than two sets have a value or no
        set has two runs: `split`)."""
        return self.between / self.total if self.split else math.nan

    @property
    def run_variance(self) -> float:
        """One run's variance about its set's mean, unbiased (module docstring): W N / (N -
        n_sets); NaN when no set has two runs."""
        if not self.runs > self.sets:
            return math.nan
        return self.within * self.runs / (self.runs - self.sets)

    @property
    def placement_share(self) -> float:
        """W / V (NaN when V is 0, nothing was measured or no set has two runs; with one set
        it is 1: all the spread is the placements')."""
        return self.within / self.total if self.total > 0 and self.runs > self.sets else math.nan


def decompose(values: np.ndarray) -> Decomposition:
    """The decomposition of ``values`` (n sets x K placements; NaN where a run has no value)
    into the variance of the per-set means and the mean within-set variance (module
    docstring)."""
    q = np.asarray(values, float)
    ok = np.isfinite(q)
    n_i = ok.sum(axis=1)
    N = int(n_i.sum())
    if N == 0:
        return Decomposition(math.nan, math.nan, math.nan, 0, 0)
    grand = float(q[ok].mean())
    have = n_i > 0
    means = np.where(have, np.nansum(np.where(ok, q, 0.0), axis=1) / np.maximum(n_i, 1), np.nan)
    between = float(np.sum(n_i[have] * (means[have] - grand) ** 2) / N)
    dev = np.where(ok, q - means[:, None], 0.0)
    within = float(np.sum(dev[have] ** 2) / N)
    total = float(np.sum((q[ok] - grand) ** 2) / N)
    return Decomposition(total, between, within, N, int(have.sum()))


@dataclass(frozen=True)
class Effect:
    """How far one parameter moves one quantity's predicted mean over the parameter's
    plausible interval [low, high] (SI), with its standard error (module docstring) and the t
    value it must reach to count (`t_threshold`); NaN when the regression has too few sets."""

    parameter: str
    verdict: str
    quantity: str
    low: float
    high: float
    effect: float
    se: float
    threshold: float

    @property
    def estimated(self) -> bool:
        """False when the regression had too few sets to estimate the effect."""
        return math.isfinite(self.effect)

    @property
    def resolved(self) -> bool:
        """True when the effect is nonzero and at least `threshold` standard errors."""
        return (
            math.isfinite(self.effect)
            and self.effect != 0.0
            and abs(self.effect) >= self.threshold * self.se
        )

    @property
    def negligible(self) -> bool:
        """True when even |effect| + `threshold` standard errors, the largest effect the data
        do not rule out, stays below the quantity's measurement floor (`FLOOR`): whatever its
        size, no run could show it."""
        return (
            math.isfinite(self.effect)
            and math.isfinite(self.se)
            and abs(self.effect) + self.threshold * self.se < FLOOR[self.quantity]
        )


def effects_of(
    means: np.ndarray, X: np.ndarray, intervals: Sequence[tuple[float, float]]
) -> tuple[np.ndarray, np.ndarray]:
    """OLS of the per-set means (n,) on the parameters X (n, d; SI) scaled to their
    ``intervals``: each parameter's effect over its interval and its standard error (NaN
    where the regression cannot be made: fewer than d + 2 sets with a mean)."""
    means = np.asarray(means, float)
    X = np.asarray(X, float)
    d = X.shape[1]
    nan = np.full(d, math.nan)
    ok = np.isfinite(means)
    if ok.sum() < d + 2:
        return nan, nan.copy()
    lo = np.array([a for a, _ in intervals], float)
    width = np.array([b - a for a, b in intervals], float)
    Z = (X[ok] - lo) / np.where(width > 0, width, 1.0)
    A = np.column_stack([np.ones(int(ok.sum())), Z])
    y = means[ok]
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    dof = len(y) - A.shape[1]
    resid = y - A @ coef
    s2 = float(resid @ resid) / dof
    cov = s2 * np.linalg.pinv(A.T @ A)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    effect, se = coef[1:], se[1:]
    flat = width <= 0  # a parameter the sample holds at one value moves nothing
    return np.where(flat, 0.0, effect), np.where(flat, 0.0, se)


__all__ = [
    "FALSE_EFFECTS",
    "Decomposition",
    "Effect",
    "decompose",
    "effects_of",
    "t_threshold",
]
