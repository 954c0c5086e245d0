"""A stricter validation criterion: the simulated run must stay inside the real runs' band.

The published criteria (section 8) compare mean DTW distances, which a simulation can pass while
drifting visibly away from every real run (the polybag of the published work). This test is
pointwise. On the prepared trajectories (`Comparison`: resampled, relative, cropped), every run's
lateral position y and heading theta are read as functions of the travelled distance along x,
x_mono = running maximum of x (parcels are conveyed forward), on a common grid over the x span
that all runs cover. At each grid point the band is

    [min over real runs - tolerance, max over real runs + tolerance]

(tolerances: ``tol_xy`` = 3 mm, the published tracking accuracy, and ``tol_theta`` = 1 deg). The
simulation passes when y and theta are inside their bands at no less than ``min_inside`` (95 %)
of the grid points. The check reports both fractions inside and the largest excursions outside.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.runs import Trajectory

DEFAULT_TOL_XY = 0.003  # m
DEFAULT_TOL_THETA = math.radians(1.0)  # rad


@dataclass(frozen=True)
class EnvelopeCheck:
    """Share of the path inside the real runs' band, largest excursions [m], [rad], verdict."""

    inside_y: float
    inside_theta: float
    worst_y: float
    worst_theta: float
    min_inside: float
    passed: bool


def _on_grid(traj: Trajectory, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = np.maximum.accumulate(traj.x)
    # keep the first sample of each plateau so the abscissa is strictly increasing
    keep = np.concatenate([[True], np.diff(x) > 0])
    return np.interp(grid, x[keep], traj.y[keep]), np.interp(grid, x[keep], traj.theta[keep])


@dataclass(frozen=True)
class EnvelopeBand:
    """The real runs' band along x and the simulated run on the same grid (m, rad)."""

    grid: np.ndarray  # x [m]
    real_y: np.ndarray  # (runs, points) [m]
    real_theta: np.ndarray  # (runs, points) [rad]
    sim_y: np.ndarray
    sim_theta: np.ndarray
    tol_xy: float
    tol_theta: float

    @property
    def y_low(self) -> np.ndarray:
        """Lower edge of the lateral band [m]."""
        return self.real_y.min(axis=0) - self.tol_xy

    @property
    def y_high(self) -> np.ndarray:
        """Upper edge of the lateral band [m]."""
        return self.real_y.max(axis=0) + self.tol_xy

    @property
    def theta_low(self) -> np.ndarray:
        """Lower edge of the heading band [rad]."""
        return self.real_theta.min(axis=0) - self.tol_theta

    @property
    def theta_high(self) -> np.ndarray:
        """Upper edge of the heading band [rad]."""
        return self.real_theta.max(axis=0) + self.tol_theta


def envelope_band(
    simulated: Trajectory,
    real: Sequence[Trajectory],
    *,
    tol_xy: float = DEFAULT_TOL_XY,
    tol_theta: float = DEFAULT_TOL_THETA,
    points: int = 200,
) -> EnvelopeBand:
    """y and theta of the real runs and the simulated run on a common grid along x."""
    if len(real) < 2:
        raise ParcelfitError("the envelope test needs at least two real runs")
    runs = [*real, simulated]
    lo = max(float(np.min(t.x)) for t in runs)
    hi = min(float(np.max(t.x)) for t in runs)
    if not hi > lo:
        raise ParcelfitError(
            "the runs share no stretch along x", fix="check the regions of interest"
        )
    grid = np.linspace(lo, hi, points)
    real_y, real_th = zip(*(_on_grid(t, grid) for t in real), strict=True)
    sim_y, sim_th = _on_grid(simulated, grid)
    return EnvelopeBand(grid, np.array(real_y), np.array(real_th), sim_y, sim_th, tol_xy, tol_theta)


def envelope_check(
    simulated: Trajectory,
    real: Sequence[Trajectory],
    *,
    tol_xy: float = DEFAULT_TOL_XY,
    tol_theta: float = DEFAULT_TOL_THETA,
    min_inside: float = 0.95,
    points: int = 200,
) -> EnvelopeCheck:
    """Is the (prepared) simulated run inside the band of the (prepared) real runs along x?"""
    band = envelope_band(simulated, real, tol_xy=tol_xy, tol_theta=tol_theta, points=points)
    out_y = np.maximum(band.y_low - band.sim_y, band.sim_y - band.y_high)
    out_t = np.maximum(band.theta_low - band.sim_theta, band.sim_theta - band.theta_high)
    inside_y = float(np.mean(out_y <= 0))
    inside_t = float(np.mean(out_t <= 0))
    return EnvelopeCheck(
        inside_y,
        inside_t,
        float(max(out_y.max(), 0.0)),
        float(max(out_t.max(), 0.0)),
        min_inside,
        bool(inside_y >= min_inside and inside_t >= min_inside),
    )
