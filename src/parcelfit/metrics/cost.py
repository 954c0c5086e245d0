"""The calibration cost of a candidate run against the reference run (method.md eq. 3).

    c = w_xy * DTW_xy(ref, sim)^2 / max(D_xy) + w_theta * DTW_theta(ref, sim)^2 / max(D_theta)

DTW_xy is the DTW distance [m] of the prepared centre trajectories, DTW_theta that [rad] of the
prepared headings, max(D_xy) [m^2] and max(D_theta) [rad^2] the largest entries of the real
runs' matrices of the test case (section 4), so a cost of 1 per term means "as far from the
reference as the two most different real runs are from each other". Default weights are 1.
A zero scale (all real runs identical) leaves the term unnormalised.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.metrics.dtw import dtw_distance
from parcelfit.metrics.reference import ReferenceSelection
from parcelfit.runs import Trajectory


@dataclass(frozen=True)
class Cost:
    """Cost of one candidate (dimensionless) with its parts: DTW distances [m], [rad]."""

    value: float
    dtw_xy: float
    dtw_theta: float
    term_xy: float
    term_theta: float


def calibration_cost(
    candidate: Trajectory,
    reference: ReferenceSelection,
    w_xy: float = 1.0,
    w_theta: float = 1.0,
) -> Cost:
    """Equation (3) for ``candidate`` against the reference run of ``reference``'s test case."""
    if w_xy < 0 or w_theta < 0:
        raise ParcelfitError(f"weights must be >= 0, got w_xy={w_xy}, w_theta={w_theta}")
    prepared = reference.comparison.prepare(candidate)
    i = reference.index
    window = reference.comparison.window
    dtw_xy = dtw_distance(reference.xy_series[i], prepared.xy, window)
    dtw_theta = dtw_distance(reference.theta_series[i], prepared.theta, window)
    term_xy = w_xy * dtw_xy**2 / (reference.max_xy if reference.max_xy > 0 else 1.0)
    term_theta = w_theta * dtw_theta**2 / (reference.max_theta if reference.max_theta > 0 else 1.0)
    return Cost(term_xy + term_theta, dtw_xy, dtw_theta, term_xy, term_theta)


def real_run_costs(
    reference: ReferenceSelection, w_xy: float = 1.0, w_theta: float = 1.0
) -> np.ndarray:
    """Equation (3) of every real run other than the reference run, against the reference run
    (dimensionless): what a simulation as good as one more real run would score. Read off the
    selection's matrices, D_xy(i*, j) / max(D_xy) and D_theta(i*, j) / max(D_theta)."""
    i = reference.index
    sx = reference.max_xy if reference.max_xy > 0 else 1.0
    st = reference.max_theta if reference.max_theta > 0 else 1.0
    c = w_xy * reference.d_xy[i] / sx + w_theta * reference.d_theta[i] / st
    return np.delete(np.asarray(c, float), i)
