"""The real runs' own scatter (`parcelfit.study.run_scatter`): the excess variance, the band of a
real run, and the estimate from a finished calibration on the analytic test simulator."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from parcelfit.runs import TestCase, load_dataset
from parcelfit.study.calibration import Calibration
from parcelfit.study.run_scatter import (
    RunScatter,
    estimate_run_scatter,
    quantities,
    real_run_band,
    scatter_note,
    variance_difference,
)
from parcelfit.study.studyfile import load_study

from .helpers import intervals_of, write_study
from .predict_helpers import write_rig_q

K = 1.482602218505602  # 1 / Phi^-1(3/4): the MAD of normal scatter times K is its sd


def test_the_difference_is_the_real_variance_beyond_the_model_s():
    # robust variances (K MAD)^2: real [1, 2, 3] -> MAD 1; model [2, 2.5] -> MAD 0.25
    assert variance_difference([1.0, 2.0, 3.0], [2.0, 2.5]) == pytest.approx(K**2 * (1 - 0.0625))
    # the model spreads more: negative (model [0, 10] -> MAD 5), kept for the mean over cases
    assert variance_difference([1.0, 2.0, 3.0], [0.0, 10.0]) == pytest.approx(K**2 * (1 - 25))
    assert variance_difference([1.0, 2.0, 3.0], [5.0]) == pytest.approx(K**2)  # one simulation
    assert variance_difference([2.0, 4.0], [], relative=True) == pytest.approx(K**2 / 9.0)
    assert variance_difference([1.0], [1.0, 2.0]) is None  # one real run says nothing
    # for normal scatter it is the variance
    rng = np.random.default_rng(0)
    big = rng.normal(0.0, 0.3, 20000)
    assert variance_difference(big, []) == pytest.approx(0.09, rel=0.03)


def test_cases_that_scatter_like_the_model_add_no_excess_on_average():
    """The differences are averaged before the cut at 0: twenty cases whose ten real runs and
    ten model runs scatter alike give a mean difference near 0, where cutting each case first
    would add about a third of the variance."""
    rng = np.random.default_rng(5)
    diffs = [
        variance_difference(rng.normal(0, 1.0, 10), rng.normal(0, 1.0, 10)) for _ in range(400)
    ]
    assert abs(np.mean(diffs)) < 0.1
    assert np.mean(np.maximum(diffs, 0.0)) > 0.25  # the cut per case's bias


def test_a_split_between_outcomes_is_not_counted_as_scatter():
    # six runs slide (about 0.4 rad), four spin (about 1.9 rad); the model at the recommended
    # parameters spins at 2 of 10: the sample variance's excess would be the split's
    real = [0.40, 0.41, 0.39, 0.42, 0.38, 0.40, 1.90, 1.92, 1.88, 1.91]
    model = [0.40, 0.42, 0.38, 0.41, 0.39, 0.40, 0.41, 0.39, 1.90, 1.91]
    assert np.var(real, ddof=1) - np.var(model, ddof=1) > 0.15  # an sd of 0.44 rad
    e = variance_difference(real, model)
    # the scatter within the slides (0.01-0.03 rad), not the split's 0.45 rad
    assert e is not None and math.sqrt(e) < 0.05


def test_the_band_of_a_real_run_widens_the_model_s_by_the_scatter():
    scatter = RunScatter({"transit_time": 0.1, "exit_y": 0.01, "rotation": 1.0}, ("R/P/1",), 2)
    lo, hi = real_run_band([2.0] * 50, "transit_time", scatter, seed=0)  # relative
    assert lo == pytest.approx(2.0 * (1 - 1.645 * 0.1), rel=0.02)
    assert hi == pytest.approx(2.0 * (1 + 1.645 * 0.1), rel=0.02)
    lo, hi = real_run_band([0.5] * 50, "exit_y", scatter, seed=0)  # absolute
    assert (lo, hi) == (
        pytest.approx(0.5 - 0.01645, abs=5e-4),
        pytest.approx(0.5 + 0.01645, abs=5e-4),
    )
    lo, hi = real_run_band([0.0] * 50, "rotation", scatter, seed=0)  # |N(0, 1)|: folded
    assert lo == pytest.approx(0.063, abs=0.01) and hi == pytest.approx(1.96, abs=0.05)
    values = list(np.linspace(0.0, 1.0, 101))
    assert real_run_band(values, "exit_heading", scatter, seed=0) == pytest.approx((0.05, 0.95))
    assert real_run_band(values, "exit_y", scatter, 3) == real_run_band(
        values, "exit_y", scatter, 3
    )
    assert all(math.isnan(x) for x in real_run_band([], "exit_y", scatter, 0))


def test_the_estimate_from_a_calibration_with_one_run_per_evaluation(tmp_path):
    path = write_study(tmp_path, budget=8, validation={"speed_setting": None}, executor="serial")
    Calibration(load_study(path), tmp_path / "study", figures=False, key_frames=False).run()
    scatter = estimate_run_scatter(tmp_path / "study", load_study(path))
    assert scatter is not None and scatter.cases == ("R/P/1",) and scatter.simulations == 1
    runs = load_dataset(tmp_path / "data")[TestCase("R", "P", 1)].runs
    real = [quantities(r.trajectory, r.transit_time) for r in runs]
    t = np.array([v["transit_time"] for v in real])
    y = np.array([v["exit_y"] for v in real])
    # one simulation per evaluation: the model's variance is 0, the excess all the real runs'
    assert scatter.sd["transit_time"] == pytest.approx(_robust_sd(t) / t.mean(), rel=1e-12)
    assert scatter.sd["exit_y"] == pytest.approx(_robust_sd(y), rel=1e-12)
    # the twin's transit times carry 1 % noise (tests/fake_sim.py)
    assert 0.004 < scatter.sd["transit_time"] < 0.02
    # such a scatter holds the placements' too, and the prediction says so
    note = scatter_note(scatter)
    assert note is not None and "one simulation per fitted case" in note
    assert scatter_note(RunScatter(scatter.sd, scatter.cases, 2)) is None
    assert scatter_note(None) is None


def test_a_prediction_s_band_of_a_real_run_holds_the_model_s_band():
    from parcelfit.study.predict import summarise_prediction

    rng = np.random.default_rng(2)
    sets = [{"mu_d_BePa": float(v)} for v in rng.uniform(0.3, 0.5, 6)]
    rows = [
        {
            "set": i,
            "placement": j,
            "transit_time": 1.5 + s["mu_d_BePa"] + 0.001 * j,
            "rotation": 0.2,
            "exit_y": 0.01 * j,
            "exit_heading": 0.2,
        }
        for i, s in enumerate(sets)
        for j in range(4)
    ]
    ident = intervals_of(["mu_d_BePa"], 0.3, 0.5, "determined")
    scatter = RunScatter({"transit_time": 0.02}, ("R/P/1",), 2)
    summaries, _, _ = summarise_prediction(ident, sets, [0, 1, 2, 3], pd.DataFrame(rows), scatter)
    by = {s.quantity: s for s in summaries}
    t = by["transit_time"]
    assert t.run_q05 < t.q05 and t.run_q95 > t.q95  # widened by the scatter
    y = by["exit_y"]  # no scatter known for it: the model's band
    assert (y.run_q05, y.run_q95) == (y.q05, y.q95)


def test_predict_simulates_the_recommended_parameters_for_the_scatter(tmp_path):
    from parcelfit.study.predict import SCATTER_RUNS, predict
    from parcelfit.study.store import Store

    path = write_study(tmp_path, budget=8, validation={"speed_setting": None}, executor="serial")
    Calibration(load_study(path), tmp_path / "study", figures=False, key_frames=False).run()
    out, rig = tmp_path / "pred", str(write_rig_q(tmp_path))
    p = predict(
        tmp_path / "study", rig, "KPBW", 1, sets=2, placements=3, executor="serial", out=out
    )
    # the prediction's own runs: sets x placements; the scatter's apart, on the fitted case
    assert len(p.runs) == 2 * 3
    assert p.scatter is not None and p.scatter.simulations == SCATTER_RUNS
    assert p.scatter.cases == ("R/P/1",)
    store = Store(out / "predict.sqlite", readonly=True)
    try:
        rows = [e for e in store.evaluations("screen") if e.iteration == 1]
    finally:
        store.close()
    assert len(rows) == SCATTER_RUNS and len({e.seed for e in rows}) == SCATTER_RUNS
    assert all(e.status == "ok" and e.speed_setting == 1 for e in rows)
    study_store = Store(tmp_path / "study" / "study.sqlite", readonly=True)
    try:
        recommended = study_store.read_recommended()
    finally:
        study_store.close()
    assert recommended is not None and recommended.params
    for e in rows:
        assert {k: e.params[k] for k in recommended.params} == pytest.approx(recommended.params)
    # the placements' scatter is now the model's: the excess is what the real runs add beyond
    real = [quantities(r.trajectory, r.transit_time) for r in _runs(tmp_path)]
    y_real = _robust_sd([v["exit_y"] for v in real]) ** 2
    y_model = _robust_sd([e.details.quantities["exit_y"] for e in rows]) ** 2
    assert p.scatter.sd["exit_y"] == pytest.approx(math.sqrt(max(0.0, y_real - y_model)))
    # the analytic simulator cannot run its drives off their mean speed, and the note says so
    assert any("--speed-deviation is ignored" in n for n in p.notes)
    # a rerun resumes: nothing left to simulate, the same tables
    again = predict(
        tmp_path / "study", rig, "KPBW", 1, sets=2, placements=3, executor="serial", out=out
    )
    assert again.scatter == p.scatter
    pd.testing.assert_frame_equal(again.runs, p.runs)


def _runs(tmp_path):
    return load_dataset(tmp_path / "data")[TestCase("R", "P", 1)].runs


def _robust_sd(values) -> float:
    v = np.asarray(values, float)
    return K * float(np.median(np.abs(v - np.median(v))))
