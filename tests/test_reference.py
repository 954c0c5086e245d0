import numpy as np
import pytest

from parcelfit.metrics import Comparison, calibration_cost, select_reference, validate
from parcelfit.metrics.validation import mean_distance_check, transit_time_check
from parcelfit.runs import Box, CaseData, Run, TestCase, Trajectory

from .helpers import reference_dtw

CASE = TestCase("E3", "KPBW", 1)


def _traj(y_drift: float, turn: float, n: int = 60, x0: float = 0.0) -> Trajectory:
    t = np.arange(n) / 60
    return Trajectory(t=t, x=x0 + 0.6 * t, y=y_drift * t**2, theta=turn * t)


def _case(drifts, turns, times, regions=(), margin=0.0):
    runs = tuple(
        Run(f"r{i}", CASE, _traj(d, w, x0=0.01 * i), tt)
        for i, (d, w, tt) in enumerate(zip(drifts, turns, times, strict=True))
    )
    return CaseData(CASE, runs, regions, margin)


def test_matrices_follow_section_4_by_hand():
    cd = _case([0.0, 0.05, 0.10, 0.30], [0.0, 0.1, 0.2, 0.9], [1.0, 1.1, 1.2, 1.6])
    sel = select_reference(cd)
    # independent computation with dtw-python on the relative trajectories
    xy = [(r.trajectory.xy - r.trajectory.xy[0]) for r in cd.runs]
    th = [r.trajectory.theta - r.trajectory.theta[0] for r in cd.runs]
    d_xy = np.array([[reference_dtw(a, b) ** 2 for b in xy] for a in xy])
    d_th = np.array([[reference_dtw(a, b) ** 2 for b in th] for a in th])
    tt = np.array([1.0, 1.1, 1.2, 1.6])
    d_time = (tt[:, None] - tt[None]) ** 2
    assert np.allclose(sel.d_xy, d_xy, rtol=1e-9, atol=1e-15)
    assert np.allclose(sel.d_theta, d_th, rtol=1e-9, atol=1e-15)
    assert np.allclose(sel.d_time, d_time)
    assert sel.max_time == pytest.approx(0.36)
    expected = d_time / d_time.max() + d_xy / d_xy.max() + d_th / d_th.max()
    assert np.allclose(sel.d_combined, expected)
    assert np.allclose(sel.row_sums, expected.sum(axis=1))
    assert sel.index == int(np.argmin(expected.sum(axis=1)))
    assert sel.reference_id in ("r1", "r2")  # never an extreme run
    assert sel.uses_time
    d = sel.to_dict()
    assert d["reference_run"] == sel.reference_id and len(d["d_xy_m2"]) == 4


def test_missing_transit_time_leaves_d_time_out():
    cd = _case([0.0, 0.05, 0.3], [0.0, 0.1, 0.9], [1.0, None, 1.3])
    sel = select_reference(cd)
    assert not sel.uses_time
    assert np.all(sel.d_time == 0)
    assert sel.reference_id == "r1"


def test_identical_runs_and_single_run():
    runs = tuple(Run(f"r{i}", CASE, _traj(0.1, 0.2), 1.0) for i in range(2))
    sel = select_reference(CaseData(CASE, runs))
    assert sel.max_xy == 0 and np.all(sel.d_combined == 0) and sel.index == 0
    assert select_reference(_case([0.1], [0.2], [1.0])).reference_id == "r0"


def test_regions_crop_before_comparison():
    # runs differ only beyond x = 0.5 m; a region x < 0.3 m sees no difference in heading
    cd = _case([0.0, 0.0, 0.0], [0.0, 0.2, 0.4], [1, 1, 1], regions=(Box(xmax=0.3),))
    sel = select_reference(cd)
    full = select_reference(cd, Comparison())
    assert sel.max_theta < full.max_theta
    assert all(len(s) < 60 for s in sel.theta_series)


def test_cost_is_equation_3():
    cd = _case([0.0, 0.05, 0.10, 0.30], [0.0, 0.1, 0.2, 0.9], [1.0, 1.1, 1.2, 1.6])
    sel = select_reference(cd)
    ref = cd.runs[sel.index].trajectory
    assert calibration_cost(ref, sel).value == 0.0
    cand = cd.runs[3].trajectory
    c = calibration_cost(cand, sel, w_xy=1.0, w_theta=2.0)
    i = sel.index
    assert c.term_xy == pytest.approx(sel.d_xy[i, 3] / sel.max_xy, rel=1e-12)
    assert c.term_theta == pytest.approx(2 * sel.d_theta[i, 3] / sel.max_theta, rel=1e-12)
    assert c.value == pytest.approx(c.term_xy + c.term_theta)
    assert c.dtw_xy == pytest.approx(np.sqrt(sel.d_xy[i, 3]))
    with pytest.raises(ValueError, match="weights"):
        calibration_cost(cand, sel, w_xy=-1)


def test_mean_distance_check_by_hand():
    real = np.array([[0.0, 1.0, 4.0], [1.0, 0.0, 9.0], [4.0, 9.0, 0.0]])
    check = mean_distance_check("xy", real, np.array([2.0, 2.0, 2.0]))
    # means over the 3 others: r0 (1+4+2)/3, r1 (1+9+2)/3, r2 (4+9+2)/3, sim (2+2+2)/3
    assert check.real_means == pytest.approx((7 / 3, 4.0, 5.0))
    assert check.simulated_mean == pytest.approx(2.0)
    assert check.largest_real_mean == pytest.approx(5.0) and check.passed
    assert not mean_distance_check("xy", real, np.array([20.0, 20.0, 20.0])).passed


def test_transit_time_check():
    assert transit_time_check(1.1, (1.0, None, 1.2)).passed
    c = transit_time_check(1.25, (1.0, 1.2))
    assert (c.low, c.high, c.passed) == (1.0, 1.2, False)
    assert not transit_time_check(None, (1.0, 1.2)).passed
    with pytest.raises(ValueError, match="no real run"):
        transit_time_check(1.0, (None, None))


def test_validation_passes_a_typical_run_and_fails_an_outlier():
    cd = _case([0.0, 0.05, 0.10, 0.15], [0.0, 0.1, 0.2, 0.3], [1.0, 1.1, 1.2, 1.3])
    sel = select_reference(cd)
    good = validate(_traj(0.07, 0.15), 1.15, sel)
    assert good.passed and good.xy.passed and good.theta.passed and good.transit_time.passed
    bad = validate(_traj(0.6, 1.5), 1.15, sel)
    assert not bad.passed
    assert not bad.xy.passed and not bad.theta.passed and bad.transit_time.passed
    assert bad.xy.simulated_mean > bad.xy.largest_real_mean
