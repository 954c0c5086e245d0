"""The ensemble cost: a set of simulated runs against the set of real runs of a test case.

Equation (3) compares one simulation with one reference run, so its value at the true
parameters is as random as the placement of that one simulation and the choice of that one real
run. The ensemble cost compares K simulations of one parameter set (K seeded placements) with
all n real runs instead. With the prepared runs (`parcelfit.metrics.comparison`), the squared
DTW distances normalised as in equation (3),

    D(s, r) = w_xy DTW_xy(s, r)^2 / max(D_xy) + w_theta DTW_theta(s, r)^2 / max(D_theta)

(max over the real runs' matrices of section 4), the cost of a case is

    c = (1 / (K n)) sum_s sum_r D(s, r)  +  w_T (mean T_sim - mean T_real)^2 / SE^2,
    SE^2 = s_sim^2 / K + s_real^2 / n

with the sample variances s^2 of the transit times [s^2] (s_sim^2 is replaced by s_real^2 when
fewer than two simulations have a transit time: one run tells nothing of the model's scatter).
The first term estimates E[D(S, R)] for a simulated run S and a real run R drawn independently
(unbiased: every pair counts once); the second is the squared Welch statistic of the difference
of the mean transit times, growing with the square of the difference in units of its standard
error. Each side keeps its own variance because the model's runs need not scatter like the
real runs (on E1 the placements scatter the transit time by a tenth of what the real runs'
specimens and belts do; on E3 spins scatter both). With few placements the statistic is far
from chi-square with one degree of freedom: at K = 2, s_sim^2 rests on two runs and is near zero
whenever they cross in about the same time, so its tail is long. That is the cost's own
scatter at the true parameters, and the acceptance threshold of the identifiability analysis
is taken from it (below). The transit term is left out (``transit_term`` None) when the real
runs have fewer than two transit times or no simulation has one.

**Variance of the estimator.** The first term is a two-sample mean over all pairs (a
generalised U-statistic); to first order

    Var(c_traj) ~ var_s(mean_r D(s, r)) / K + var_r(mean_s D(s, r)) / n

(the variances of the row and column means of D); `EnsembleCost.se` is its square root (None with
fewer than two real runs; with one simulation the second part alone). More placements shrink
the first part only; the real runs' part is fixed by the experiment.

**Antithetic placements** (``cost.mirrored``, `parcelfit.study.joint.placement_seeds`). The
simulations then come in units: a placement beside its mirror image, and the nominal placement
alone when K is odd. A unit's mean transit time has no placement scatter to first order (none
where the transit time is linear in the placement), so the K runs' own variance overstates the
variance of their mean. With ``units`` given (the unit of each simulation), the transit term's
simulation part is taken from the units' means instead, over the U units:

    SE^2 = s_units^2 / U + s_real^2 / n

0 with a single unit (K = 2: one pair; what remains is of second order and not estimated).
Where that leaves SE^2 = 0 (real runs that all cross in the same time), or a unit lost a run's
transit time (a lone run of a pair keeps its whole placement scatter), the runs' own variance
over K stands as without units. The mean is still over the runs (the nominal run of an odd K
weighs 1/K, where the units' variance treats the U means alike: a small mismatch, kept). The
trajectory term's standard error keeps the runs' own variance: D is a squared distance, whose
part linear in the placement vanishes near the best fit, and mirroring does not cancel the
quadratic part that remains. The threshold's sets of K real runs (below) are independent runs,
which no real experiment can mirror: with their long-tailed transit statistic (above) against a
mirrored cost whose transit term at the truth is about chi-square with one degree of freedom,
the threshold is the more generous and the plausible sets the wider.

**Adjusted transit times.** With ``cost.transit: adjusted`` the real runs' transit times in the
reference are adjusted for the belt speeds each run rode at
(`parcelfit.metrics.reference.adjusted_reference`) and the simulated runs' times
alike before they reach this module: T above is then T^a, and s_real^2 the adjusted times'
variance (smaller by what the belt speeds explain).

**Real runs on the same scale.** `ensemble_null_costs` scores every set of K real runs (every
one of the C(n, K) sets, or ``max_subsets`` sets drawn with a seed when there are more) as an
ensemble against the other n - K real runs, in the same formula (except that a transit term
with no scatter on either side is 0, not infinite): what an ensemble of K
simulations would score if the simulations were as good as K more real runs (the cost's
distribution at the true parameters, as far as the real runs can show it). Against n - K runs
instead of n it scatters a little more than the cost would, which errs on the side of accepting.
`ensemble_real_costs` is its K = 1 case (each real run against the other n - 1, the transit
term's SE^2 = s^2 (1 + 1 / (n - 1)) with their sample variance). A high quantile of the sets' costs is the
acceptance threshold of the identifiability analysis (`parcelfit.study.joint.threshold`). K is
cut to n - 2 when the real runs are fewer than K + 2, so that the other runs keep a variance.
With ``transit: adjusted`` the real runs' times were adjusted by a fit to all of them, the sets'
included, so the sets score a little better than simulations would, and the threshold is less
generous than stated.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.metrics.dtw import cross_dtw
from parcelfit.metrics.reference import ReferenceSelection
from parcelfit.runs import Trajectory


@dataclass(frozen=True)
class EnsembleCost:
    """The ensemble cost of one case (dimensionless) with its parts: the trajectory term, the
    weighted transit term (None when not computable), the standard error of the trajectory
    term (None with fewer than two real runs; with one simulation the real runs' part of it
    only), the simulations compared, and
    the mean simulated transit time [s] (None without one)."""

    value: float
    trajectory_term: float
    transit_term: float | None
    se: float | None
    n_sims: int
    mean_transit: float | None


def _scales(reference: ReferenceSelection) -> tuple[float, float]:
    return (
        reference.max_xy if reference.max_xy > 0 else 1.0,
        reference.max_theta if reference.max_theta > 0 else 1.0,
    )


def ensemble_cost(
    sims: Sequence[Trajectory],
    transit_times: Sequence[float | None],
    reference: ReferenceSelection,
    w_xy: float = 1.0,
    w_theta: float = 1.0,
    w_transit: float = 1.0,
    units: Sequence[int] | None = None,
) -> EnsembleCost:
    """The ensemble cost (module docstring) of simulated runs ``sims`` (raw trajectories, SI)
    with their transit times [s] against the real runs behind ``reference``; ``units`` (one per
    simulation) groups antithetic placements, whose units' means carry the simulations' part of
    the transit term's variance (module docstring)."""
    if not sims:
        raise ParcelfitError("an ensemble cost needs at least one simulated run")
    if min(w_xy, w_theta, w_transit) < 0:
        raise ParcelfitError("the weights of the ensemble cost must be >= 0")
    comparison = reference.comparison
    prepared = [comparison.prepare(t) for t in sims]
    window = comparison.window
    sx, st = _scales(reference)
    d = (
        w_xy * cross_dtw([p.xy for p in prepared], reference.xy_series, window) ** 2 / sx
        + w_theta * cross_dtw([p.theta for p in prepared], reference.theta_series, window) ** 2 / st
    )
    k, n = d.shape
    if units is not None and len(units) != k:
        raise ParcelfitError("an ensemble cost needs one unit per simulated run")
    traj = float(d.mean())
    se = None
    if k >= 2 and n >= 2:  # the trajectory term's SE: the runs' own variance (docstring)
        se = math.sqrt(d.mean(axis=1).var(ddof=1) / k + d.mean(axis=0).var(ddof=1) / n)
    elif n >= 2:  # one simulation: the real runs' part of the variance only
        se = math.sqrt(d.mean(axis=0).var(ddof=1) / n)
    timed = [
        (t, u)
        for t, u in zip(transit_times, units if units is not None else range(k), strict=True)
        if t is not None and math.isfinite(t)
    ]
    sim_t = [t for t, _ in timed]
    timed_units = None
    if units is not None:
        timed_units = [u for _, u in timed]
        whole, kept = Counter(units), Counter(timed_units)
        if any(kept[u] != whole[u] for u in kept):
            timed_units = None  # a unit lost a run's time: its lone run is not a pair's mean
    real_t = [t for t in reference.transit_times if t is not None]
    transit = None
    mean_t = float(np.mean(sim_t)) if sim_t else None
    if sim_t and len(real_t) >= 2 and w_transit > 0:
        transit = w_transit * transit_statistic(sim_t, real_t, units=timed_units)
    value = traj + (transit or 0.0)
    return EnsembleCost(value, traj, transit, se, k, mean_t)


def _unit_means(values: np.ndarray, units: Sequence[int]) -> np.ndarray:
    """The mean of ``values`` per unit (antithetic placements), in the units' first order."""
    order = list(dict.fromkeys(units))
    return np.array([values[[i for i, u in enumerate(units) if u == g]].mean() for g in order])


def transit_statistic(
    sim_times: Sequence[float],
    real_times: Sequence[float],
    *,
    constant: float = math.inf,
    units: Sequence[int] | None = None,
) -> float:
    """The squared Welch statistic of the mean transit times [s] (module docstring;
    dimensionless): SE^2 = s_sim^2 / K + s_real^2 / n, s_sim^2 = s_real^2 with one simulated
    time; with ``units`` (antithetic placements) the simulations' part from the units' means,
    0 with one unit, unless that leaves SE^2 = 0. Needs a simulated and two real times; when
    SE^2 is 0 it is 0 for equal means and ``constant`` otherwise."""
    m, n = len(sim_times), len(real_times)
    if m < 1 or n < 2:
        raise ParcelfitError("a transit statistic needs a simulated and two real transit times")
    var_real = float(np.var(real_times, ddof=1))
    var_sim = float(np.var(sim_times, ddof=1)) if m >= 2 else var_real
    sim_part = var_sim / m
    if units is not None:
        means = _unit_means(np.asarray(sim_times, float), units)
        paired = float(np.var(means, ddof=1)) / len(means) if len(means) >= 2 else 0.0
        if paired + var_real / n > 0:  # else the runs' own variance, as without units
            sim_part = paired
    se2 = sim_part + var_real / n
    diff2 = (float(np.mean(sim_times)) - float(np.mean(real_times))) ** 2
    return diff2 / se2 if se2 > 0 else (0.0 if diff2 == 0 else constant)


def ensemble_null_costs(
    reference: ReferenceSelection,
    k: int = 1,
    w_xy: float = 1.0,
    w_theta: float = 1.0,
    w_transit: float = 1.0,
    *,
    max_subsets: int = 2000,
    seed: int = 0,
) -> np.ndarray:
    """The ensemble cost of sets of ``k`` real runs against the other real runs (module
    docstring), from the selection's matrices (dimensionless, one per set: all C(n, k) sets in
    lexicographic order, or ``max_subsets`` drawn with ``seed`` when there are more; ``k`` cut
    as `effective_set_size` says). The transit term counts the runs that have a transit time,
    as the cost does."""
    n = len(reference.run_ids)
    if n < 2:
        raise ParcelfitError(
            f"test case {reference.case.label} has {n} real run: too few to compare sets"
        )
    if k < 1:
        raise ParcelfitError(f"an ensemble has at least one run, got {k}")
    k = effective_set_size(n, k)
    sx, st = _scales(reference)
    d = w_xy * reference.d_xy / sx + w_theta * reference.d_theta / st
    t = np.array([math.nan if x is None else float(x) for x in reference.transit_times])
    if math.comb(n, k) <= max_subsets:
        subsets = [list(c) for c in itertools.combinations(range(n), k)]
    else:
        rng = np.random.default_rng([seed, n, k])
        subsets = [sorted(rng.choice(n, k, replace=False)) for _ in range(max_subsets)]
    out = np.empty(len(subsets))
    for i, chosen in enumerate(subsets):
        others = [r for r in range(n) if r not in chosen]
        out[i] = d[np.ix_(chosen, others)].mean()
        sim_t = t[chosen][np.isfinite(t[chosen])]
        real_t = t[others][np.isfinite(t[others])]
        if w_transit > 0 and len(sim_t) and len(real_t) >= 2:  # as `ensemble_cost` has it
            # runs that all took one transit time: no scatter to judge by, so no term (not inf)
            out[i] += w_transit * transit_statistic(sim_t, real_t, constant=0.0)
    return out


def effective_set_size(n: int, k: int) -> int:
    """The size of the sets of real runs `ensemble_null_costs` scores for ``k`` placements and
    ``n`` real runs: k, cut to n - 2 (at least 1) so that the other runs keep a variance."""
    return max(1, min(k, n - 2))


def ensemble_real_costs(
    reference: ReferenceSelection,
    w_xy: float = 1.0,
    w_theta: float = 1.0,
    w_transit: float = 1.0,
) -> np.ndarray:
    """The ensemble cost of every real run as a one-member ensemble against the other real runs
    (module docstring), from the selection's matrices (dimensionless, one per real run)."""
    return ensemble_null_costs(reference, 1, w_xy, w_theta, w_transit)


__all__ = [
    "EnsembleCost",
    "effective_set_size",
    "ensemble_cost",
    "ensemble_null_costs",
    "ensemble_real_costs",
    "transit_statistic",
]
