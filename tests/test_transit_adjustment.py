"""Transit times adjusted for the belt speeds a run rode at (parcelfit.metrics.transit_adjustment)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parcelfit.metrics.comparison import Comparison
from parcelfit.metrics.transit_adjustment import (
    fit_transit_adjustment,
    ridden_speeds,
    window_speed,
)
from parcelfit.runs import Run, TestCase, Trajectory
from parcelfit.study.precision import run_statistics

CASE = TestCase("E1", "KPBW", 3)
RATE = 60.0  # Hz


def _belt_run(run_id: str, v1: float, v2: float, transit: float | None) -> Run:
    """A parcel riding belt 1 at ``v1`` for 1 s, then belt 2 at ``v2`` for 1 s, at 30 degrees
    to the belts' direction [m/s, s]."""
    t = np.arange(0.0, 2.0 + 0.5 / RATE, 1.0 / RATE)
    s = np.where(t <= 1.0, v1 * t, v1 + v2 * (t - 1.0))
    heading = math.radians(30.0)
    return Run(
        run_id,
        CASE,
        Trajectory(t, s * math.cos(heading), s * math.sin(heading), np.zeros_like(t)),
        transit,
    )


def test_the_speed_of_a_window_is_its_least_squares_velocity() -> None:
    t = np.linspace(0.0, 0.25, 16)
    xy = np.column_stack([0.3 + 0.6 * t, -0.1 + 0.8 * t])
    assert window_speed(t, xy) == pytest.approx(1.0, abs=1e-12)
    assert math.isnan(window_speed(t[:2], xy[:2]))  # two samples: no speed
    assert math.isnan(window_speed(np.zeros(4), np.zeros((4, 2))))  # no time passes


def test_ridden_speeds_are_the_first_and_the_last_belts() -> None:
    v_start, v_end = ridden_speeds(_belt_run("r", 0.62, 1.57, 1.0).trajectory)
    assert v_start == pytest.approx(0.62, abs=1e-9)
    assert v_end == pytest.approx(1.57, abs=1e-9)
    # a window shorter than the sampling interval holds one sample: no speed
    track = _belt_run("r", 0.62, 1.57, 1.0).trajectory
    assert all(math.isnan(v) for v in ridden_speeds(track, window=0.5 / RATE))


def test_the_adjustment_removes_what_the_belt_speeds_explain() -> None:
    rng = np.random.default_rng(3)
    v1 = 0.62 * (1 + rng.uniform(-0.03, 0.03, 10))
    v2 = 1.57 * (1 + rng.uniform(-0.03, 0.03, 10))
    specimen = rng.normal(0.0, 0.002, 10)  # s: what the parcels themselves scatter
    # riding 0.48 s on belt 1 and 0.64 s on belt 2: T = 0.48 * 0.62 / v1 + 0.64 * 1.57 / v2
    transit = 0.48 * 0.62 / v1 + 0.64 * 1.57 / v2 + specimen
    runs = [_belt_run(f"r{i}", v1[i], v2[i], transit[i]) for i in range(10)]
    adj = fit_transit_adjustment(runs)
    assert adj.active and adj.runs == 10
    # the coefficients are the derivatives -t_ride / v of the riding times
    assert adj.coefficients[0] == pytest.approx(-0.48 / 0.62, rel=0.15)
    assert adj.coefficients[1] == pytest.approx(-0.64 / 1.57, rel=0.15)
    assert adj.sd_before > 4 * adj.sd_after
    adjusted = np.array([adj.adjust_run(r) for r in runs])
    assert adjusted.std(ddof=1) == pytest.approx(specimen.std(ddof=1), rel=0.3)
    # at the real runs' mean speeds nothing changes; a run without a transit time has none
    assert adj.adjust(1.234, adj.mean_speeds) == pytest.approx(1.234, abs=1e-15)
    assert adj.adjust_run(_belt_run("n", 0.62, 1.57, None)) is None
    # a speed the track could not give leaves the transit time as it is
    assert adj.adjust(1.234, (math.nan, 1.6)) == 1.234
    assert "sd" in adj.describe() and "adjusted" in adj.describe()
    # the precision check's statistic is the adjusted transit time
    stats = run_statistics(runs[0], Comparison(rate=None), adj)
    assert stats is not None and stats[0] == pytest.approx(adjusted[0], abs=1e-15)


def test_speeds_that_explain_nothing_or_too_few_runs_leave_the_transit_time_alone() -> None:
    rng = np.random.default_rng(5)
    v1 = 0.62 * (1 + rng.uniform(-0.03, 0.03, 8))
    v2 = 1.57 * (1 + rng.uniform(-0.03, 0.03, 8))
    design = np.column_stack([np.ones(8), v1 - v1.mean(), v2 - v2.mean()])
    noise = rng.normal(0.0, 0.01, 8)
    # residual of the noise after projecting out the speeds: exactly uncorrelated with them
    noise -= design @ np.linalg.lstsq(design, noise, rcond=None)[0]
    runs = [_belt_run(f"r{i}", v1[i], v2[i], 1.2 + noise[i]) for i in range(8)]
    adj = fit_transit_adjustment(runs)
    assert not adj.active
    assert adj.sd_after == adj.sd_before
    assert adj.adjust_run(runs[0]) == runs[0].transit_time
    assert "not adjusted" in adj.describe()
    few = fit_transit_adjustment(
        [_belt_run(f"r{i}", 0.62 + 0.01 * i, 1.57, 1.2 - 0.01 * i) for i in range(4)]
    )
    assert not few.active and few.runs == 4
    assert fit_transit_adjustment([]).runs == 0
