"""The model's numerical error at a predicted design: the estimate from matched pairs of the
model and the refined model, and `parcelfit predict` widening the band of a real run by it (on
the analytic test simulator, whose refined model turns the parcel by less:
``FAKE_SIM_MESH_ERROR``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parcelfit.study.numerical_error import (
    NUMERICAL_RUNS,
    NumericalError,
    estimate_numerical_error,
    numerical_note,
)
from parcelfit.study.predict import MODEL_ITERATION, REFINED_ITERATION, predict, shown_value
from parcelfit.study.run_scatter import real_run_band
from parcelfit.study.store import Store

from .predict_helpers import write_finished_study, write_rig_q

K = 1.482602218505602  # the MAD of normal scatter times K is its sd


def _run(transit: float, rotation: float, heading: float) -> dict[str, float | None]:
    return {
        "transit_time": transit,
        "rotation": rotation,
        "exit_x": 1.0,
        "exit_y": 0.0,
        "exit_heading": heading,
    }


def test_the_error_is_the_median_shift_and_the_robust_spread_of_the_pairs():
    model = [_run(2.0, 0.1, 0.1 * i) for i in range(5)]
    shifts = [0.010, 0.020, 0.030, 0.040, 0.050]
    refined = [_run(2.0 * 1.01, 0.1, 0.1 * i + d) for i, d in enumerate(shifts)]
    err = estimate_numerical_error(model, refined, 2)
    d = np.array(shifts)
    spread = K * float(np.median(np.abs(d - np.median(d))))
    assert err.sd["exit_heading"] == pytest.approx(math.hypot(0.03, spread))
    assert err.sd["transit_time"] == pytest.approx(0.01)  # relative: a share of the value
    assert err.sd["rotation"] == 0 and err.sd["exit_y"] == 0
    assert (err.pairs, err.changed, err.refinement, err.reason) == (5, 0, 2, None)
    assert numerical_note(err) is None


def test_a_pair_that_changes_outcome_is_counted_and_does_not_set_the_band():
    model = [_run(2.0, 0.2, 0.2) for _ in range(5)]
    refined = [_run(2.0, 0.21, 0.21) for _ in range(4)] + [_run(2.5, 3.2, 3.2)]  # one spins
    err = estimate_numerical_error(model, refined, 2)
    assert err.changed == 1 and err.pairs == 5
    assert err.sd["rotation"] == pytest.approx(0.01)  # the median pair's, not the spin's turn
    note = numerical_note(err)
    assert note is not None and "at 1 of 5 placements" in note and "not converged" in note


def test_failed_runs_leave_their_pair_out_and_none_left_says_why():
    model = [_run(2.0, 0.1, 0.1), None, _run(2.0, 0.1, 0.1)]
    refined = [_run(2.0, 0.1, 0.2), _run(2.0, 0.1, 5.0), None]
    err = estimate_numerical_error(model, refined, 3)
    assert err.pairs == 1 and err.sd["exit_heading"] == pytest.approx(0.1)
    none = estimate_numerical_error([None], [_run(2.0, 0.1, 0.1)], 2)
    assert none.sd == {} and none.reason == "no placement ended ok on both models"
    assert "not estimated (no placement ended ok" in (numerical_note(none) or "")
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


def test_predict_widens_the_band_of_a_real_run_by_the_numerical_error(study, tmp_path, monkeypatch):
    monkeypatch.setenv("FAKE_SIM_MESH_ERROR", "0.4")  # the refined model turns 0.2 rad less
    p = _predict(study, tmp_path, "p")
    err = p.numerical
    assert err is not None and err.reason is None
    assert (err.pairs, err.refinement, err.changed) == (NUMERICAL_RUNS, 2, 0)
    store = Store(tmp_path / "p" / "predict.sqlite", readonly=True)
    try:
        rows = store.evaluations("screen")
    finally:
        store.close()
    model = sorted((e for e in rows if e.iteration == MODEL_ITERATION), key=lambda e: e.slot)
    refined = sorted((e for e in rows if e.iteration == REFINED_ITERATION), key=lambda e: e.slot)
    assert [e.seed for e in model] == [e.seed for e in refined]  # matched placements
    assert len(model) == NUMERICAL_RUNS and len(set(e.seed for e in model)) == NUMERICAL_RUNS
    d = [
        b.details.quantities["exit_heading"] - a.details.quantities["exit_heading"]
        for a, b in zip(model, refined, strict=True)
    ]
    # the mesh error the simulator adds: 0.4 / refinement (1 - exp(-2 t)); the difference at
    # the run's end is -0.2 (1 - exp(-2 t_end)), about -0.2 for runs of a second or more
    assert all(-0.2 <= x < -0.18 for x in d), d
    assert err.sd["exit_heading"] == pytest.approx(abs(float(np.median(d))), rel=0.05)
    assert err.sd["exit_y"] == 0  # the mesh error turns, it does not move
    by = {s.quantity: s for s in p.summaries}
    h = by["exit_heading"]
    # no fitted run in this study: the band of a real run is the model's runs joined by draws
    # of the error alone (E_Pa's wide effect on the heading makes the model's band wide, so the
    # widening at its ends is less than the error's own 5-95 % half-width)
    values = p.runs["exit_heading"].tolist()
    band = real_run_band(values, "exit_heading", None, 0, {"exit_heading": err.sd["exit_heading"]})
    assert (h.run_q05, h.run_q95) == pytest.approx(band)
    assert h.run_q05 < h.q05 - 0.1 and h.run_q95 > h.q95 + 0.1
    # the refined model's runs at the recommended (here the plausible medians') parameters lie
    # inside the widened band, not all inside the model's own
    heads = [e.details.quantities["exit_heading"] for e in refined]
    assert all(h.run_q05 <= x <= h.run_q95 for x in heads)
    y = by["exit_y"]
    assert (y.run_q05, y.run_q95) == pytest.approx((y.q05, y.q95))
    from parcelfit.report.prediction import prediction_view, write_prediction_page

    view = prediction_view(p)
    row = next(r for r in view["summary"] if r["quantity"] == "exit heading")
    assert row["numerical"] == shown_value("exit_heading", err.sd["exit_heading"], 2)
    assert f"estimated from {NUMERICAL_RUNS} placement(s)" in view["numerical"]
    page = write_prediction_page(p, tmp_path / "p" / "page.html").read_text()
    assert "numerical error (sd)" in page and "refined 2 times over" in page
    # a rerun resumes: nothing simulated again, the same error
    again = _predict(study, tmp_path, "p")
    assert again.numerical == err


def test_no_numerical_error_when_switched_off_and_the_note_says_so(study, tmp_path, monkeypatch):
    monkeypatch.setenv("FAKE_SIM_MESH_ERROR", "0.4")
    p = _predict(study, tmp_path, "off", numerical_runs=0)
    assert p.numerical == NumericalError({}, 2, reason="switched off: --numerical-runs 0")
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
    from parcelfit.errors import ParcelfitError

    with pytest.raises(ParcelfitError, match="--numerical-runs -1"):
        _predict(study, tmp_path, "bad", numerical_runs=-1)
