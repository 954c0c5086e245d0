"""Validation of a simulated run against the real runs of a test case (method.md section 8).

With the simulation added to the n real runs as run n+1:

1. transit time: min_i T_i <= T_sim <= max_i T_i                         [s]
2. x/y: in the (n+1) x (n+1) matrix D_xy(i, j) = DTW(X_i, X_j)^2 [m^2], each run's mean distance
   to the others is m_i = sum_{j != i} D_xy(i, j) / n; pass if m_sim <= max over real runs m_i
3. heading: the same with D_theta [rad^2].

All three must hold. Each criterion returns the numbers behind its verdict.

Beyond the published criteria, `Validation.envelope` holds the stricter pointwise band test of
`parcelfit.metrics.envelope` (reported beside them; ``strict_passed`` requires it too).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.metrics.dtw import cross_dtw
from parcelfit.metrics.envelope import EnvelopeCheck, envelope_check
from parcelfit.metrics.reference import ReferenceSelection
from parcelfit.runs import Trajectory


@dataclass(frozen=True)
class TransitTimeCheck:
    """Criterion 1: the simulated transit time [s] against the real runs' range [s]."""

    simulated: float | None
    low: float
    high: float
    passed: bool


@dataclass(frozen=True)
class MeanDistanceCheck:
    """Criteria 2 and 3: mean squared-DTW distance of the simulation and of each real run."""

    quantity: str  # "xy" [m^2] or "theta" [rad^2]
    simulated_mean: float
    real_means: tuple[float, ...]
    largest_real_mean: float
    passed: bool


@dataclass(frozen=True)
class Validation:
    """The verdict of section 8 with its three criteria."""

    transit_time: TransitTimeCheck
    xy: MeanDistanceCheck
    theta: MeanDistanceCheck
    envelope: EnvelopeCheck | None = None

    @property
    def passed(self) -> bool:
        """True when the three published criteria hold."""
        return self.transit_time.passed and self.xy.passed and self.theta.passed

    @property
    def strict_passed(self) -> bool:
        """True when the published criteria and the envelope test hold."""
        return self.passed and self.envelope is not None and self.envelope.passed


def mean_distance_check(quantity: str, real: np.ndarray, to_sim: np.ndarray) -> MeanDistanceCheck:
    """Criterion 2/3 from the real runs' squared-distance matrix and their squared distances to the simulation."""
    n = real.shape[0]
    if n < 1 or real.shape != (n, n) or to_sim.shape != (n,):
        raise ParcelfitError(
            f"inconsistent shapes: real {real.shape}, to simulation {to_sim.shape}"
        )
    full = np.zeros((n + 1, n + 1))
    full[:n, :n] = real
    full[:n, n] = full[n, :n] = to_sim
    means = full.sum(axis=1) / n
    real_means = tuple(float(v) for v in means[:n])
    largest = max(real_means)
    return MeanDistanceCheck(
        quantity, float(means[n]), real_means, largest, bool(means[n] <= largest)
    )


def transit_time_check(simulated: float | None, real: tuple[float | None, ...]) -> TransitTimeCheck:
    """Criterion 1: is the simulated transit time [s] within the real runs' range?"""
    known = [t for t in real if t is not None]
    if not known:
        raise ParcelfitError(
            "no real run of the validation case has a transit time",
            fix="add transit_time to the runs in dataset.yaml",
        )
    low, high = min(known), max(known)
    ok = simulated is not None and low <= simulated <= high
    return TransitTimeCheck(simulated, low, high, bool(ok))


def validate(
    simulated: Trajectory, simulated_transit_time: float | None, real: ReferenceSelection
) -> Validation:
    """Section 8 verdict for a simulated run against the real runs behind ``real``."""
    prepared = real.comparison.prepare(simulated)
    w = real.comparison.window
    real_prepared = [
        Trajectory(t=np.arange(len(xy)), x=xy[:, 0], y=xy[:, 1], theta=th)
        for xy, th in zip(real.xy_series, real.theta_series, strict=True)
    ]
    to_sim_xy = cross_dtw(real.xy_series, [prepared.xy], w)[:, 0] ** 2
    to_sim_theta = cross_dtw(real.theta_series, [prepared.theta], w)[:, 0] ** 2
    return Validation(
        transit_time=transit_time_check(simulated_transit_time, real.transit_times),
        xy=mean_distance_check("xy", real.d_xy, to_sim_xy),
        theta=mean_distance_check("theta", real.d_theta, to_sim_theta),
        envelope=envelope_check(prepared, real_prepared) if len(real_prepared) >= 2 else None,
    )
