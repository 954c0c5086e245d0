"""How precisely can a set of test cases determine each parameter, before calibrating?

A calibration can only pin a parameter as far as the real runs' own scatter allows: if moving a
parameter over its whole range changes what the runs show by less than the uncertainty of the
real runs' mean, no optimiser and no cost function can tell the values apart. This module turns
simulated sensitivities and the real runs' scatter into the precision the data allow, per
parameter, for one test case or several jointly, so that the test cases can be chosen before
the compute is spent (`scripts/precision_check.py`).

**Statistics.** Each run (real or simulated) is summarised on its case's regions of interest,
prepared as every comparison in parcelfit (`parcelfit.metrics.comparison`: resampled, relative
to the start, cropped), by

    s = (T, |theta_end - theta_0|, y_end - y_0)   [s, rad, m]

the transit time, the net rotation and the lateral drift. Optionally T is the transit time
adjusted for the belt speeds each run rode at (`parcelfit.metrics.transit_adjustment`: fitted on
the case's real runs, applied alike to real and simulated runs), which takes the belts' speed
deviation out of the real runs' scatter.

**Sensitivity.** With u_j = (p_j - low_j) / (high_j - low_j) the parameter's share of its range,
the Jacobian column of parameter j is the change of the mean statistics of K seeded placements
between the low and the high end of its range (every other parameter at the point of interest),

    J_:j = mean_K s(u_j = 1) - mean_K s(u_j = 0),

a secant over the whole range (a response that is not monotone over the range is understated).
Both ends share the placement seeds (matched pairs), so J's standard error is the standard
error of the mean paired difference, sd(d) / sqrt(K); an entry below twice its standard error
is not resolved by K placements (`resolved`). **An entry that is not resolved carries no
information** (it is set to 0 in F below): neither its size nor its sign is known, and where
the real runs scatter less than the placements' outcomes (the placements spin at some seeds,
the real runs all slide) an unresolved secant would claim a precision no calibration reaches.
Measured so: at the bundled twin's truth E_Pa moved E3 setting 1's mean rotation by 0.15 +-
0.16 rad against the real runs' sd of 0.02 rad, which counted as information gave E_Pa +-8 %
alone. The check names such parameters (`Precision.unresolved`), so that more placements can
settle them.

**Information.** The real runs of case c (n_c of them) estimate the mean statistics with the
covariance Sigma_c / n_c. Sigma_c is their correlation (Ledoit-Wolf shrinkage, scikit-learn, on
the statistics scaled by their standard deviations: ten runs do not estimate a 3 x 3 covariance
well) scaled by the population's standard deviation per statistic,

    sd_k = max(sd_real,k, sd_model,k, 1e-3),

the larger of the real runs' sample sd and the placements' sd at the point (the sample sd of K
placements simulated at the point itself, `CaseSensitivity.model_sd`). If the model is right at
the point, its placements and the real runs sample one population; ten real runs can miss an
outcome the placements show at some seeds (a spin), and their sample sd then understates the
scatter their mean has. Measured so: the bundled twin's ten E3/KPBW/1 runs all slid (rotation
sd 0.02 rad) where the placements spun at some seeds (their sd 0.79 rad), and the belt friction came
out at +-1 % from the rotation alone; with the placements' scatter, +-21 %
(docs/research/precision-check.md). Without runs at the point (`sensitivity`'s ``at_point``) the
placements' sd is pooled over the parameters' ends (the root mean of the sample variances at
each end), which overstates the scatter at the point where one end spins far more often.
The floor of 1e-3 in each unit is a tracked run's resolution (1 ms, 1 mrad, 1 mm) for a
statistic every run shows alike. This is the data's limit: a calibration that simulates K
placements per evaluation adds the scatter of its own mean on top. In the linear, Gaussian
approximation the Fisher information of the shares u is

    F = sum_c J_c^T (Sigma_c / n_c)^-1 J_c,

and with a prior of the uniform's variance 1/12 on each share (information 12 I: what is known
without any data) the approximate posterior covariance is C = (F + 12 I)^-1. The precision
reported per parameter j is the 95 % half-width h_j = 1.96 sqrt(C_jj) as a share of the range,
jointly (other parameters free, so confounded parameters share the information) and alone
(1.96 / sqrt(F_jj + 12): all other parameters known). h_j <= 0.10 means the data could
determine the parameter within 10 % of its range; with no information h_j = 1.96 / sqrt(12) =
0.57 (undetermined).

**Which parameters to calibrate.** A calibration fits a few parameters and fixes the rest. For
a subset S of the parameters, fitted while the others are fixed at the point's values, the
information is F restricted to S (others known), and the half-widths are 1.96 sqrt(diag((F_SS +
12 I)^-1)). `best_subsets` ranks every subset of a given size by how many of its parameters
would be determined within `WITHIN` (then by the largest half-width, smaller first): what the
screening's "at most four, by effect size" means when the effect is measured against the real
runs' scatter. It assumes the fixed parameters are right; a wrong fixed value biases the fit.

This is an estimate, not a bound: the linear secant and the Gaussian approximation can be off
either way (a threshold response such as spin or slide is neither linear nor Gaussian), and the
three statistics do not hold everything the DTW comparison sees. What it does show reliably is
the case where a parameter's whole-range effect is small against the real runs' scatter: then
the parameter cannot be recovered from those cases, whatever the calibration does.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from sklearn.covariance import LedoitWolf

from parcelfit.errors import ParcelfitError
from parcelfit.metrics.comparison import Comparison
from parcelfit.metrics.transit_adjustment import TransitAdjustment
from parcelfit.runs import Run

STATISTICS = ("transit [s]", "rotation [rad]", "lateral drift [m]")
PRIOR_INFORMATION = 12.0  # 1 / variance of a uniform share on [0, 1]
Z95 = 1.959963984540054  # two-sided 95 % normal quantile
WITHIN = 0.10  # share of the range within which a parameter counts as determined (recovery's 10 %)


def run_statistics(
    run: Run, comparison: Comparison, adjustment: TransitAdjustment | None = None
) -> np.ndarray | None:
    """The statistics s = (T [s], net rotation [rad], lateral drift [m]) of a run on its case's
    prepared regions of interest, T adjusted for the belt speeds the run rode at when an
    ``adjustment`` is given (`parcelfit.metrics.transit_adjustment`); None without a transit
    time or with fewer than two samples in the regions."""
    if run.transit_time is None:
        return None
    traj = comparison.prepare(run.trajectory)
    if len(traj.t) < 2:
        return None
    theta = np.unwrap(np.asarray(traj.theta, dtype=float))
    xy = np.asarray(traj.xy, dtype=float)
    transit = run.transit_time if adjustment is None else adjustment.adjust_run(run)
    return np.array([transit, abs(theta[-1] - theta[0]), xy[-1, 1] - xy[0, 1]])


@dataclass(frozen=True)
class CaseSensitivity:
    """What one test case tells about the parameters: the Jacobian of its mean statistics over
    the parameters' ranges (rows STATISTICS, columns ``names``; units of the statistic per whole
    range) with its standard errors, and its real runs' statistics (n x 3)."""

    label: str
    names: tuple[str, ...]
    jacobian: np.ndarray
    jacobian_se: np.ndarray
    real: np.ndarray
    # the placements' standard deviation per statistic at the point (or, without runs there,
    # pooled over the parameter ends); None: not known, the real runs' scatter alone counts
    model_sd: np.ndarray | None = None

    @property
    def real_sd(self) -> np.ndarray:
        """The real runs' sample standard deviation per statistic [s, rad, m]; NaN with fewer
        than two runs."""
        real = np.asarray(self.real, dtype=float).reshape(-1, len(STATISTICS))
        if len(real) < 2:
            return np.full(len(STATISTICS), np.nan)
        return real.std(axis=0, ddof=1)

    @property
    def scatter(self) -> np.ndarray:
        """The population's standard deviation per statistic (module docstring): the larger of
        the real runs' and the placements' [s, rad, m], at least 1e-3 in each unit."""
        sd = self.real_sd
        if self.model_sd is not None:
            sd = np.maximum(sd, np.nan_to_num(np.asarray(self.model_sd, dtype=float)))
        # a statistic every run shows alike carries no scatter to compare against; give it the
        # resolution of a tracked run (1 ms, 1 mrad, 1 mm) so it cannot claim infinite information
        return np.maximum(sd, 1e-3)

    @property
    def resolved(self) -> np.ndarray:
        """Entries of the Jacobian larger than twice their standard error."""
        return np.abs(self.jacobian) > 2.0 * self.jacobian_se

    def information(self, resolved_only: bool = True) -> np.ndarray:
        """The Fisher information of the parameters' shares from this case's real runs
        (module docstring): J^T (Sigma / n)^-1 J, with the entries of J the placements do not
        resolve set to 0 unless ``resolved_only`` is False."""
        jac = np.asarray(self.jacobian, dtype=float)
        if resolved_only:
            jac = np.where(self.resolved, jac, 0.0)
        return jac.T @ np.linalg.solve(self._mean_covariance, jac)

    @cached_property
    def _mean_covariance(self) -> np.ndarray:
        """Sigma / n, the covariance of the real runs' mean statistics (module docstring); one
        Ledoit-Wolf fit per case, shared by every information the case gives."""
        real = np.asarray(self.real, dtype=float)
        n = real.shape[0]
        if n < 2:
            raise ParcelfitError(
                f"test case {self.label} has {n} usable real run(s); the scatter needs two or more",
                fix="add real runs of this case, or leave it out",
            )
        own = np.maximum(self.real_sd, 1e-3)
        z = (real - real.mean(axis=0)) / own
        # the real runs' correlations, shrunk: with every column standardised Ledoit-Wolf's
        # diagonal is (n - 1) / n for each; made exactly 1, also for a statistic every real run
        # shows alike (a zero column), then rescaled by the population's sd
        shrunk = LedoitWolf().fit(z).covariance_
        d = np.sqrt(np.diag(shrunk))
        d[d == 0] = 1.0
        corr = shrunk / np.outer(d, d)
        np.fill_diagonal(corr, 1.0)
        scale = self.scatter
        return corr * np.outer(scale, scale) / n


def sensitivity(
    label: str,
    names: Sequence[str],
    low: Mapping[str, Sequence[np.ndarray | None]],
    high: Mapping[str, Sequence[np.ndarray | None]],
    real: Sequence[np.ndarray | None],
    at_point: Sequence[np.ndarray | None] | None = None,
) -> CaseSensitivity:
    """A case's sensitivity from the statistics of its simulated runs at each parameter's low
    and high end (``low[name][i]`` and ``high[name][i]`` share placement i; None where a run
    failed, dropped with its partner) and of its real runs (None: not usable); the placements'
    scatter from the runs ``at_point`` (placements at the point itself, two or more usable), or
    else pooled over the pairs' ends."""
    jac = np.zeros((len(STATISTICS), len(names)))
    se = np.zeros_like(jac)
    variances = []  # the placements' sample variance at each parameter end
    for j, name in enumerate(names):
        pairs = [
            (a, b)
            for a, b in zip(low[name], high[name], strict=True)
            if a is not None and b is not None
        ]
        if not pairs:
            raise ParcelfitError(
                f"no placement of {label} gave runs at both ends of {name}'s range",
                fix="check the simulations' status (parcelfit simulate) or widen the placements",
            )
        d = np.array([b - a for a, b in pairs])
        jac[:, j] = d.mean(axis=0)
        se[:, j] = d.std(axis=0, ddof=1) / math.sqrt(len(d)) if len(d) > 1 else np.inf
        if len(pairs) > 1:
            ends = (np.array([a for a, _ in pairs]), np.array([b for _, b in pairs]))
            variances += [np.var(end, axis=0, ddof=1) for end in ends]
    rows = [s for s in real if s is not None]
    model_sd = np.sqrt(np.mean(variances, axis=0)) if variances else None
    point = [s for s in at_point or () if s is not None]
    if len(point) >= 2:
        model_sd = np.std(np.array(point), axis=0, ddof=1)
    return CaseSensitivity(
        label, tuple(names), jac, se, np.array(rows).reshape(-1, len(STATISTICS)), model_sd
    )


@dataclass(frozen=True)
class Precision:
    """95 % half-widths [share of the range] per parameter: ``joint`` (others free) and
    ``alone`` (others known), from the cases in ``labels``; ``alone_unresolved`` is ``alone``
    with the entries the placements do not resolve counted as if they were real."""

    labels: tuple[str, ...]
    names: tuple[str, ...]
    joint: np.ndarray
    alone: np.ndarray
    alone_unresolved: np.ndarray

    def unresolved(self, share: float = WITHIN) -> tuple[str, ...]:
        """The parameters that would be determined within ``share`` of their range alone if
        the effects the placements do not resolve were real, and are not without them: more
        placements would tell."""
        return tuple(
            n
            for n, a, u in zip(self.names, self.alone, self.alone_unresolved, strict=True)
            if u <= share < a
        )

    def determined(self, share: float = WITHIN) -> dict[str, bool]:
        """Whether each parameter could be determined within ``share`` of its range (joint)."""
        return {n: bool(h <= share) for n, h in zip(self.names, self.joint, strict=True)}


def precision(cases: Sequence[CaseSensitivity]) -> Precision:
    """The precision the real runs of ``cases`` allow together (module docstring)."""
    if not cases:
        raise ParcelfitError("no test cases to judge", fix="give at least one case")
    names = cases[0].names
    if any(c.names != names for c in cases):
        raise ParcelfitError("the cases' sensitivities cover different parameters")
    info = sum(c.information() for c in cases)
    prior = PRIOR_INFORMATION * np.eye(len(names))
    cov = np.linalg.inv(info + prior)
    joint = Z95 * np.sqrt(np.diag(cov))
    alone = Z95 / np.sqrt(np.diag(info) + PRIOR_INFORMATION)
    info_all = sum(c.information(resolved_only=False) for c in cases)
    alone_all = Z95 / np.sqrt(np.diag(info_all) + PRIOR_INFORMATION)
    return Precision(tuple(c.label for c in cases), names, joint, alone, alone_all)


@dataclass(frozen=True)
class Subset:
    """A set of parameters to calibrate with the others fixed, and the 95 % half-widths
    [share of the range] the cases would allow each of them."""

    names: tuple[str, ...]
    half_widths: np.ndarray

    @property
    def determined(self) -> int:
        """How many of the subset's parameters would be determined within `WITHIN`."""
        return int(np.sum(self.half_widths <= WITHIN))

    def widths_text(self) -> str:
        """Each parameter with its half-width, as `half_width_text` writes it."""
        return ", ".join(
            f"{n} {half_width_text(h)}" for n, h in zip(self.names, self.half_widths, strict=True)
        )


def best_subsets(cases: Sequence[CaseSensitivity], size: int, top: int = 5) -> list[Subset]:
    """The ``top`` subsets of ``size`` parameters that ``cases`` would determine best, each
    fitted with the other parameters fixed (module docstring): most parameters within
    `WITHIN` first, then the smaller largest half-width."""
    if not cases:
        raise ParcelfitError("no test cases to judge", fix="give at least one case")
    names = cases[0].names
    if not 1 <= size <= len(names):
        raise ParcelfitError(
            f"a subset of {size} from {len(names)} parameter(s)",
            fix=f"choose a size from 1 to {len(names)}",
        )
    info = sum(c.information() for c in cases)
    prior = PRIOR_INFORMATION * np.eye(size)
    # every subset: C(16, 4) = 1820 inversions of 4 x 4 matrices, instant; no library ranks
    # parameter subsets by a Fisher information, so the loop is ours
    found = []
    for idx in itertools.combinations(range(len(names)), size):
        sub = info[np.ix_(idx, idx)]
        widths = Z95 * np.sqrt(np.diag(np.linalg.inv(sub + prior)))
        found.append(Subset(tuple(names[i] for i in idx), widths))
    found.sort(key=lambda s: (-s.determined, float(s.half_widths.max()), s.names))
    return found[:top]


def half_width_text(h: float) -> str:
    """A 95 % half-width [share of the range] as a percentage, starred where <= `WITHIN`."""
    return f"{100 * h:.0f} %" + (" *" if h <= WITHIN else "")


__all__ = [
    "STATISTICS",
    "WITHIN",
    "CaseSensitivity",
    "Precision",
    "Subset",
    "best_subsets",
    "half_width_text",
    "precision",
    "run_statistics",
    "sensitivity",
]
