"""Transit times adjusted for the speeds each run's belts ran at.

Real belts run up to 3 % off their mean speed (method.md section 2), and a parcel riding a belt
for a time t_ride at a speed v off by dv/v arrives about t_ride dv/v earlier or later: on E1
(0.5 s on belt 1, 0.6 s on belt 2) a uniform +-3 % deviation alone scatters the transit time by
about 15 ms, most of what ten real runs show. That scatter hides the parameters' effects on the
transit time; it is not a property of the parcel. Each run's own track shows the speeds it rode
at, so the transit time can be compared at common belt speeds.

**Ridden speeds.** For a track (t_k, x_k, y_k) the speed over a window of ``window`` seconds is
the length of the least-squares velocity,

    v = |(sum (t_k - tbar)(p_k - pbar)) / sum (t_k - tbar)^2|   [m/s],

over the samples of the first window (the parcel riding the first conveyor it was placed on)
and of the last window (riding the last one towards the second light barrier): u = (v_start,
v_end). No rig geometry is needed, so the same holds for any rig and solver.

**Adjustment.** Over the n real runs with a transit time, ordinary least squares

    T_i = b_0 + a^T (u_i - ubar) + e_i,

ubar the real runs' mean speeds, gives the coefficients a [s per m/s]; the adjusted transit time
of any run, real or simulated, is

    T^a = T - a^T (u - ubar)   [s],

one fixed function of a track, the same on both sides of a comparison, so adjusting cannot bias
a comparison: it only removes the part of the real runs' scatter their belt speeds explain. The
adjustment is kept only when it explains something, i.e. when the residual variance with the
regression's degrees of freedom, sum e_i^2 / (n - 3), is below the plain sample variance (an
adjusted R^2 above 0), and only with n >= 5 (two residual degrees of freedom at least);
otherwise a = 0 and T^a = T. Speeds a track cannot give (a window with fewer than three
samples) leave the run's transit time unadjusted.

Caveats. The real belts' deviation is short-term (method.md section 2): a speed measured at the
start and end of a run stands for the whole run only as far as the deviation is slow against a
transit time. The regression also absorbs whatever part of the end speed the parameters set (a
parcel still slipping on the last belt): the adjusted transit time then responds less to those
parameters, which a sensitivity computed with the same adjustment (`parcelfit.study.precision`)
shows.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from parcelfit.runs import Run, Trajectory

WINDOW = 0.25  # s: long enough for a 1 mm tracking noise to give the speed to about 0.5 %
MIN_RUNS = 5  # real runs needed to fit two coefficients and an intercept with 2 dof to spare


def window_speed(t: np.ndarray, xy: np.ndarray) -> float:
    """The length of the least-squares velocity [m/s] of positions ``xy`` [m] (n x 2) at times
    ``t`` [s]; NaN with fewer than three samples."""
    t = np.asarray(t, dtype=float)
    if t.size < 3:
        return math.nan
    dt = t - t.mean()
    denom = float(dt @ dt)
    if denom <= 0:
        return math.nan
    velocity = dt @ (np.asarray(xy, dtype=float) - np.asarray(xy, dtype=float).mean(axis=0))
    return float(np.hypot(*(velocity / denom)))


def ridden_speeds(trajectory: Trajectory, window: float = WINDOW) -> tuple[float, float]:
    """The parcel's speed [m/s] over the first and the last ``window`` seconds of its track
    (module docstring); NaN where a window holds fewer than three samples."""
    t = np.asarray(trajectory.t, dtype=float)
    xy = np.asarray(trajectory.xy, dtype=float)
    if t.size == 0:
        return math.nan, math.nan
    first = t <= t[0] + window
    last = t >= t[-1] - window
    return window_speed(t[first], xy[first]), window_speed(t[last], xy[last])


@dataclass(frozen=True)
class TransitAdjustment:
    """The adjustment of the module docstring: coefficients ``a`` [s per m/s] on (v_start,
    v_end), the real runs' mean speeds ``mean_speeds`` [m/s], the real runs' transit-time
    standard deviation before and after [s], and the window [s]. ``a`` all 0: not adjusted."""

    coefficients: tuple[float, float]
    mean_speeds: tuple[float, float]
    sd_before: float
    sd_after: float
    runs: int
    window: float = WINDOW

    @property
    def active(self) -> bool:
        """Whether the adjustment changes anything (the belt speeds explained some scatter)."""
        return any(c != 0.0 for c in self.coefficients)

    def adjust(self, transit_time: float, speeds: Sequence[float]) -> float:
        """The adjusted transit time [s] of a run with transit time [s] and ridden speeds
        (v_start, v_end) [m/s]; unadjusted where a speed is not finite."""
        u = np.asarray(speeds, dtype=float)
        if not self.active or not np.all(np.isfinite(u)):
            return float(transit_time)
        return float(transit_time - np.dot(self.coefficients, u - np.asarray(self.mean_speeds)))

    def adjust_track(self, transit_time: float | None, trajectory: Trajectory) -> float | None:
        """The adjusted transit time [s] of a run with ``transit_time`` [s] (None: none) and
        track ``trajectory``, its speeds read over this adjustment's window."""
        if transit_time is None:
            return None
        return self.adjust(transit_time, ridden_speeds(trajectory, self.window))

    def adjust_run(self, run: Run) -> float | None:
        """The adjusted transit time [s] of ``run`` (None without a transit time)."""
        return self.adjust_track(run.transit_time, run.trajectory)

    def describe(self) -> str:
        """One line for a report: what the adjustment did to the real runs' scatter."""
        if not self.active:
            return (
                f"transit times not adjusted (the belt speeds explain none of the scatter of "
                f"{self.runs} real runs, sd {self.sd_before * 1e3:.1f} ms)"
            )
        return (
            f"transit times adjusted to the real runs' mean ridden speeds: sd "
            f"{self.sd_before * 1e3:.1f} ms -> {self.sd_after * 1e3:.1f} ms over {self.runs} "
            f"real runs"
        )


def fit_transit_adjustment(runs: Sequence[Run], window: float = WINDOW) -> TransitAdjustment:
    """Fit the adjustment of the module docstring on ``runs`` (the real runs of one test case;
    runs without a transit time or without finite speeds are left out of the fit)."""
    rows = []
    for run in runs:
        if run.transit_time is None or not math.isfinite(run.transit_time):
            continue
        u = ridden_speeds(run.trajectory, window)
        if all(math.isfinite(v) for v in u):
            rows.append((run.transit_time, *u))
    n = len(rows)
    if n < 2:
        return TransitAdjustment((0.0, 0.0), (math.nan, math.nan), math.nan, math.nan, n, window)
    data = np.asarray(rows, dtype=float)
    times, speeds = data[:, 0], data[:, 1:]
    mean_speeds = speeds.mean(axis=0)
    sd_before = float(times.std(ddof=1))
    keep = (0.0, 0.0)
    sd_after = sd_before
    if n >= MIN_RUNS:
        design = np.column_stack([np.ones(n), speeds - mean_speeds])
        coef, *_ = np.linalg.lstsq(design, times, rcond=None)
        resid = times - design @ coef
        sd_resid = float(math.sqrt(resid @ resid / (n - design.shape[1])))
        if sd_resid < sd_before:
            keep = (float(coef[1]), float(coef[2]))
            sd_after = sd_resid
    return TransitAdjustment(
        keep, (float(mean_speeds[0]), float(mean_speeds[1])), sd_before, sd_after, n, window
    )


__all__ = [
    "WINDOW",
    "TransitAdjustment",
    "fit_transit_adjustment",
    "ridden_speeds",
    "window_speed",
]
