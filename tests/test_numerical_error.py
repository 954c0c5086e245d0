"""The model's numerical error at a predicted design: the estimate from matched pairs of the
model and the refined model, and `parcelfit predict` widening the band of a real run by it (on
the analytic test simulator, whose refined model turns the parcel by less:
``FAKE_SIM_MESH_ERROR``)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from parcelfit.errors import ParcelfitError
from parcelfit.study.numerical_error import (
    NUMERICAL_RUNS,
    NumericalError,
    estimate_numerical_error,
    numerical_notes,
)
from parcelfit.study.predict import MODEL_ITERATION, REFINED_ITERATION, predict, shown_value
from parcelfit.study.run_scatter import real_run_band
from parcelfit.study.store import Store

from .predict_helpers import BOUNDS, write_finished_study, write_rig_q

K = 1.482602218505602  # the MAD of normal scatter times K is its sd


def _run(transit: float, rotation: float, heading: float) -> dict[str, float | None]:
    return {
        "transit_time": transit,
        "rotation": rotation,
        "exit_x": 1.0,
        "exit_y": 0.0,
        "exit_heading": heading,
    }


def test_the_error_is_the_median_and_robust_spread_of_the_differences_scaled_to_the_model():
    model = [_run(2.0, 0.1, 0.1 * i) for i in range(5)]
    shifts = [0.010, 0.020, 0.030, 0.040, 0.050]
    refined = [_run(2.0 * 1.01, 0.1, 0.1 * i + d) for i, d in enumerate(shifts)]
    err = estimate_numerical_error(model, refined, 2)
    d = np.array(shifts)
    spread = K * float(np.median(np.abs(d - np.median(d))))
    # at refinement 2 the model's first-order error is twice what refining removed
    assert err.sd["exit_heading"] == pytest.approx(2 * math.hypot(0.03, spread))
    assert err.sd["transit_time"] == pytest.approx(0.02)  # relative: a share of the value
    assert err.sd["rotation"] == 0 and err.sd["exit_y"] == 0
    assert (err.pairs, err.runs, err.changed, err.refinement, err.reason) == (5, 5, 0, 2, None)
    assert numerical_notes(err) == []
    # refined three times over, the model's error is 3/2 of what refining removed
    assert estimate_numerical_error(model, refined, 3).sd["exit_heading"] == pytest.approx(
        1.5 * math.hypot(0.03, spread)
    )
    with pytest.raises(ValueError, match="refinement 1"):
        estimate_numerical_error(model, refined, 1)


def test_a_pair_that_changes_outcome_is_counted_and_does_not_set_the_band():
    model = [_run(2.0, 0.2, 0.2) for _ in range(5)]
    refined = [_run(2.0, 0.21, 0.21) for _ in range(4)] + [_run(2.5, 3.2, 3.2)]  # one spins
    err = estimate_numerical_error(model, refined, 2)
    assert err.changed == 1 and err.pairs == 5
    assert err.sd["rotation"] == pytest.approx(0.02)  # the median pair's, not the spin's turn
    (note,) = numerical_notes(err)
    assert "at 1 of 5 placements" in note and "robust to them" in note


def test_from_half_the_pairs_changing_outcome_the_note_says_the_sd_is_the_outcomes_spread():
    model = [_run(2.0, 0.2, 0.2) for _ in range(6)]
    refined = [_run(2.0, 0.21, 0.21) for _ in range(3)] + [_run(2.5, 3.2, 3.2)] * 3
    err = estimate_numerical_error(model, refined, 2)
    assert err.changed == 3 and err.sd["rotation"] > 1.0  # no longer robust
    (note,) = numerical_notes(err)
    assert "at 3 of 6 placements" in note and "the spread between outcomes" in note


def test_failed_runs_leave_their_pair_out_and_none_left_says_why():
    model = [_run(2.0, 0.1, 0.1), None, _run(2.0, 0.1, 0.1)]
    refined = [_run(2.0, 0.1, 0.2), _run(2.0, 0.1, 5.0), None]
    err = estimate_numerical_error(model, refined, 3, at="medians")
    assert err.pairs == 1 and err.runs == 3 and err.at == "medians"
    assert err.sd["exit_heading"] == pytest.approx(0.15)  # 0.1 x 3 / 2, no spread from one
    notes = numerical_notes(err)
    assert any("rests on 1 of 3 placements" in n for n in notes)
    assert any("a rough estimate" in n for n in notes)
    none = estimate_numerical_error([None], [_run(2.0, 0.1, 0.1)], 2)
    assert none.sd == {} and none.reason == "no placement ended ok on both models"
    (note,) = numerical_notes(none)
    assert "not estimated (no placement ended ok" in note
    with pytest.raises(ValueError):
        estimate_numerical_error([None], [], 2)


@pytest.fixture
def study(tmp_path):
    folder = write_finished_study(tmp_path)
    write_rig_q(tmp_path)
    return folder


def _predict(study, tmp_path, name, **kw):
    return predict(
        study,
        str(tmp_path / "Q.yaml"),
        "KPBW",
        1,
        sets=4,
        placements=3,
        executor="serial",
        out=tmp_path / name,
        **kw,
    )


def _pairs(folder):
    store = Store(folder / "predict.sqlite", readonly=True)
    try:
        rows = store.evaluations("screen")
    finally:
        store.close()
    model = sorted((e for e in rows if e.iteration == MODEL_ITERATION), key=lambda e: e.slot)
    refined = sorted((e for e in rows if e.iteration == REFINED_ITERATION), key=lambda e: e.slot)
    return model, refined


def test_predict_widens_the_band_of_a_real_run_by_the_numerical_error(study, tmp_path, monkeypatch):
    log = tmp_path / "started.log"
    monkeypatch.setenv("FAKE_SIM_LOG", str(log))
    monkeypatch.setenv("FAKE_SIM_MESH_ERROR", "0.4")  # the model turns 0.4 rad more, refined 0.2
    p = _predict(study, tmp_path, "p")
    err = p.numerical
    assert err is not None and err.reason is None
    assert (err.pairs, err.runs, err.refinement, err.changed) == (NUMERICAL_RUNS,) * 2 + (2, 0)
    assert err.at == "medians"  # this study's store holds no fit
    model, refined = _pairs(tmp_path / "p")
    assert [e.seed for e in model] == [e.seed for e in refined]  # matched placements
    assert len(model) == NUMERICAL_RUNS and len({e.seed for e in model}) == NUMERICAL_RUNS
    medians = {name: float(np.mean(b)) for name, b in BOUNDS.items()}  # uniform sample's median
    for e in model + refined:
        assert {k: e.params[k] for k in medians} == pytest.approx(medians, rel=0.02)
    d = np.array(
        [
            b.details.quantities["exit_heading"] - a.details.quantities["exit_heading"]
            for a, b in zip(model, refined, strict=True)
        ]
    )
    # the mesh error the simulator adds: 0.4 / refinement (1 - exp(-2 t)); the difference at
    # the run's end is -0.2 (1 - exp(-2 t_end)), about -0.2 for runs of a second or more
    assert np.all((d >= -0.2) & (d < -0.18)), d
    # the model's own error (against a model without mesh error) is twice that: 0.4
    assert err.sd["exit_heading"] == pytest.approx(2 * abs(float(np.median(d))), rel=0.05)
    assert err.sd["exit_y"] == 0  # the mesh error turns, it does not move
    by = {s.quantity: s for s in p.summaries}
    h = by["exit_heading"]
    assert h.numerical_sd == err.sd["exit_heading"]
    # no fitted run in this study: the band of a real run is the model's widened by the error
    assert h.run_q05 < h.q05 - 0.2 and h.run_q95 > h.q95 + 0.2
    # a converged model's runs (no mesh error) at the same parameters and placements lie inside
    # the widened band
    converged = [
        a.details.quantities["exit_heading"] + 2 * x for a, x in zip(model, d, strict=True)
    ]
    assert all(h.run_q05 <= x <= h.run_q95 for x in converged)
    y = by["exit_y"]
    assert (y.run_q05, y.run_q95) == pytest.approx((y.q05, y.q95))
    from parcelfit.report.prediction import prediction_view, terminal_table, write_prediction_page

    view = prediction_view(p)
    row = next(r for r in view["summary"] if r["quantity"] == "exit heading")
    assert row["numerical"] == shown_value("exit_heading", err.sd["exit_heading"], 2)
    assert (
        f"estimated from {NUMERICAL_RUNS} placement(s) of the plausible set's medians"
        in (view["numerical"])
    )
    assert "numerical error (sd)" in [c.header for c in terminal_table(p).columns]
    page = write_prediction_page(p, tmp_path / "p" / "page.html").read_text()
    assert "numerical error (sd)" in page and "refined 2 times over" in page
    # the real runs' scatter is not estimated here, but the band is not called the model's
    assert "not estimated, the calibration holding no fitted run" in page
    assert "run is the model's\n" not in page and "real run is the model's</" not in page
    summary = pd.read_csv(tmp_path / "p" / "summary.csv").set_index("quantity")
    assert summary.loc["exit_heading", "numerical_sd"] == pytest.approx(err.sd["exit_heading"])
    # a rerun resumes: nothing simulated again, the same error
    started = log.read_text().splitlines()
    assert sum(r.startswith("numerical-") for r in started) == 2 * NUMERICAL_RUNS
    again = _predict(study, tmp_path, "p")
    assert log.read_text().splitlines() == started
    assert again.numerical == err
    # other numerical inputs in the same folder are refused; none at all is not
    with pytest.raises(ParcelfitError, match="numerical error with other inputs"):
        _predict(study, tmp_path, "p", numerical_runs=3)
    off = _predict(study, tmp_path, "p", numerical_runs=0)
    assert off.numerical is not None and "switched off" in (off.numerical.reason or "")
    assert log.read_text().splitlines() == started


def test_with_a_fitted_study_the_error_joins_the_real_runs_scatter(tmp_path, monkeypatch):
    from parcelfit.study.calibration import Calibration
    from parcelfit.study.studyfile import load_study

    from .helpers import write_study

    monkeypatch.setenv("FAKE_SIM_MESH_ERROR", "0.4")
    path = write_study(tmp_path, budget=8, validation={"speed_setting": None}, executor="serial")
    Calibration(load_study(path), tmp_path / "study", figures=False, key_frames=False).run()
    write_rig_q(tmp_path)
    p = _predict(tmp_path / "study", tmp_path, "p")
    err, scatter = p.numerical, p.scatter
    assert err is not None and err.at == "recommended" and err.sd["exit_heading"] > 0.3
    assert scatter is not None and scatter.sd
    store = Store(tmp_path / "study" / "study.sqlite", readonly=True)
    try:
        recommended = store.read_recommended()
    finally:
        store.close()
    assert recommended is not None
    model, refined = _pairs(tmp_path / "p")
    for e in [*model, *refined]:
        assert {k: e.params[k] for k in recommended.params} == pytest.approx(recommended.params)
    for s in p.summaries:
        values = p.runs[s.quantity].tolist()
        alone = real_run_band(values, s.quantity, scatter, 0)  # the real runs' scatter only
        s_q, s_num = scatter.sd.get(s.quantity, 0.0), err.sd.get(s.quantity, 0.0)
        if s_num > 0:  # wider than the scatter alone gives, on both sides
            assert s.run_q05 < alone[0] and s.run_q95 > alone[1], s.quantity
        else:
            assert (s.run_q05, s.run_q95) == pytest.approx(alone), s.quantity
        if s_q > 0 and s_num > 0:  # the two in quadrature: the same draws with the joint sd
            both = real_run_band(values, s.quantity, None, 0, {s.quantity: math.hypot(s_q, s_num)})
            assert (s.run_q05, s.run_q95) == pytest.approx(both)


def test_no_numerical_error_when_switched_off_and_the_note_says_so(study, tmp_path, monkeypatch):
    monkeypatch.setenv("FAKE_SIM_MESH_ERROR", "0.4")
    p = _predict(study, tmp_path, "off", numerical_runs=0)
    assert p.numerical == NumericalError({}, 2, reason="switched off: --numerical-runs 0")
    assert p.summaries[0].numerical_sd != p.summaries[0].numerical_sd  # NaN: not estimated
    assert any("numerical error was not estimated (switched off" in n for n in p.notes)
    h = {s.quantity: s for s in p.summaries}["exit_heading"]
    assert (h.run_q05, h.run_q95) == (h.q05, h.q95)
    store = Store(tmp_path / "off" / "predict.sqlite", readonly=True)
    try:
        assert all(e.iteration == 0 for e in store.evaluations("screen"))
    finally:
        store.close()


def test_a_study_that_switches_the_refinement_off_predicts_without_it(tmp_path):
    folder = write_finished_study(tmp_path, validation={"refinement": 1})
    write_rig_q(tmp_path)
    p = _predict(folder, tmp_path, "p")
    assert p.numerical is not None and "validation.refinement is 1" in (p.numerical.reason or "")


def test_a_bad_count_is_refused(study, tmp_path):
    with pytest.raises(ParcelfitError, match="--numerical-runs -1"):
        _predict(study, tmp_path, "bad", numerical_runs=-1)


def test_the_prediction_s_phases_share_one_executor(study, tmp_path, monkeypatch):
    """The design's runs and the numerical error's model and refined runs: one executor, made
    once and closed once."""
    import parcelfit.study.predict as predict_module

    from .helpers import CountedExecutors

    counted = CountedExecutors(predict_module.open_executor)
    monkeypatch.setattr(predict_module, "open_executor", counted)
    p = _predict(study, tmp_path, "p")
    assert p.numerical is not None and p.numerical.pairs == NUMERICAL_RUNS
    assert (counted.made, counted.closed) == (1, 1)
    # sized for every phase's simulations (all pending in a new folder), not the first phase's
    store = Store(tmp_path / "p" / "predict.sqlite", readonly=True)
    try:
        rows = store.evaluations("screen")
    finally:
        store.close()
    sized = [args[3] for args in counted.calls]  # open_executor(kind, workers, scheduler, items)
    assert sized == [len(rows)] and len(rows) >= 4 * 3 + 2 * NUMERICAL_RUNS
