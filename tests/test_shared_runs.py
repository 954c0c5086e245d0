"""Simulations shared between the predictions of one study (`parcelfit.study.shared_runs`), on
the analytic test simulator: a second prediction takes the real runs' scatter runs from the
first instead of simulating them, and a second prediction of the same design the numerical
error's (and its own runs where they are the same simulations); it gets the same values a
fresh run gets, and takes nothing from a prediction with other placements, of another study or
of another design (a rig file edited counts as another)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from parcelfit.progress import ProgressEvent
from parcelfit.study import shared_runs
from parcelfit.study.calibration import Calibration
from parcelfit.study.predict import SCATTER_RUNS, predict
from parcelfit.study.shared_runs import (
    DESIGN,
    REUSED_RECORD,
    SCATTER,
    SCATTER_RECORD,
    candidate_stores,
    reused_ids,
)
from parcelfit.study.store import Store
from parcelfit.study.studyfile import load_study

from .helpers import write_study
from .predict_helpers import write_finished_study, write_rig_q


def _scatter_rows(out: Path) -> list:
    store = Store(out / "predict.sqlite", readonly=True)
    try:
        return sorted(
            (e for e in store.evaluations("screen") if e.iteration > 0),
            key=lambda e: (e.iteration, e.slot),
        )
    finally:
        store.close()


def _reused(out: Path) -> tuple[set[int], object]:
    store = Store(out / "predict.sqlite", readonly=True)
    try:
        return reused_ids(store, [SCATTER]), store.get_meta(REUSED_RECORD)
    finally:
        store.close()


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory) -> tuple[Path, str]:
    tmp = tmp_path_factory.mktemp("reuse")
    path = write_study(tmp, budget=8, validation={"speed_setting": None}, executor="serial")
    Calibration(load_study(path), tmp / "study", figures=False, key_frames=False).run()
    return tmp, str(write_rig_q(tmp))


def _predict(tmp: Path, rig: str, out: Path, setting: int = 1, seed: int = 0, study="study"):
    events: list[ProgressEvent] = []
    p = predict(
        tmp / study,
        rig,
        "KPBW",
        setting,
        sets=2,
        placements=2,
        seed=seed,
        numerical_runs=0,
        executor="serial",
        out=out,
        progress=events.append,
    )
    return p, [e.message for e in events]


def test_a_second_prediction_takes_the_scatter_runs_of_the_first(calibrated):
    tmp, rig = calibrated
    first, said = _predict(tmp, rig, tmp / "preds" / "a")
    assert any(f"0 of {SCATTER_RUNS} simulations stored" in m for m in said), said
    assert _reused(tmp / "preds" / "a") == (set(), None)
    # another design, the same study and seed: nothing of the scatter is simulated again
    second, said = _predict(tmp, rig, tmp / "preds" / "b", setting=2)
    assert any(f"{SCATTER_RUNS} simulations taken from a" in m for m in said), said
    assert any(f"{SCATTER_RUNS} of {SCATTER_RUNS} simulations stored, 0 to run" in m for m in said)
    a, b = _scatter_rows(tmp / "preds" / "a"), _scatter_rows(tmp / "preds" / "b")
    ids, record = _reused(tmp / "preds" / "b")
    assert ids == {e.id for e in b} and record["from"] == [str((tmp / "preds" / "a").resolve())]
    assert [(e.params, e.seed, e.transit_time, e.details.quantities) for e in b] == [
        (e.params, e.seed, e.transit_time, e.details.quantities) for e in a
    ]
    assert second.scatter == first.scatter
    # the same as simulating them afresh (a folder with no prediction beside it)
    fresh, _ = _predict(tmp, rig, tmp / "alone" / "c", setting=2)
    shutil.rmtree(tmp / "alone")
    assert fresh.scatter == second.scatter
    assert fresh.runs.drop(columns="wall_time").equals(second.runs.drop(columns="wall_time"))


def test_other_placements_or_another_study_take_nothing(calibrated, tmp_path):
    tmp, rig = calibrated
    _predict(tmp, rig, tmp / "other" / "a")
    # another seed: other placements, so every scatter run is simulated
    _, said = _predict(tmp, rig, tmp / "other" / "b", seed=1)
    assert not any("taken from" in m for m in said)
    assert _reused(tmp / "other" / "b") == (set(), None)
    # another study beside it (its own calibration): its runs are not this study's
    path = write_study(tmp_path, budget=8, validation={"speed_setting": None}, executor="serial")
    Calibration(load_study(path), tmp_path / "study", figures=False, key_frames=False).run()
    _, said = _predict(tmp_path, rig, tmp / "other" / "c")
    assert not any("taken from" in m for m in said)


def test_the_stores_searched(tmp_path):
    study, out = tmp_path / "study", tmp_path / "elsewhere" / "mine"
    for folder in (study / "predict-E1-KPBW-1", study / "notes", tmp_path / "elsewhere" / "x", out):
        folder.mkdir(parents=True)
        (folder / "predict.sqlite").write_bytes(b"")
    found = candidate_stores(study, out)
    assert found == sorted(
        p.resolve()
        for p in (
            study / "predict-E1-KPBW-1" / "predict.sqlite",
            tmp_path / "elsewhere" / "x" / "predict.sqlite",
        )
    )


def test_a_crash_while_copying_resumes_with_every_copied_run_listed(calibrated, monkeypatch):
    tmp, rig = calibrated
    _predict(tmp, rig, tmp / "crash" / "a")
    real_finish = Store.finish
    calls = {"n": 0}

    def finish_then_crash(self, row_id, **kw):
        calls["n"] += 1
        if calls["n"] == 4 and kw.get("wall_time") is not None:
            raise KeyboardInterrupt  # the process stops in the middle of copying
        return real_finish(self, row_id, **kw)

    monkeypatch.setattr(Store, "finish", finish_then_crash)
    with pytest.raises(KeyboardInterrupt):
        _predict(tmp, rig, tmp / "crash" / "b", setting=2)
    monkeypatch.setattr(Store, "finish", real_finish)
    copied = {e.id for e in _scatter_rows(tmp / "crash" / "b") if e.status == "ok"}
    assert len(copied) == 3 and len(_reused(tmp / "crash" / "b")[0]) == SCATTER_RUNS
    # the source is gone: the rest are simulated here, and only the copied three are listed
    shutil.rmtree(tmp / "crash" / "a")
    _, said = _predict(tmp, rig, tmp / "crash" / "b", setting=2)
    assert any(f"3 of {SCATTER_RUNS} simulations stored" in m for m in said), said
    rows = _scatter_rows(tmp / "crash" / "b")
    assert all(e.status == "ok" for e in rows)
    ids, record = _reused(tmp / "crash" / "b")
    assert ids == copied and record["rows"] == 3


def test_runs_of_another_version_or_of_a_store_without_its_record_are_not_taken(
    calibrated, monkeypatch
):
    tmp, rig = calibrated
    _predict(tmp, rig, tmp / "version" / "a")
    monkeypatch.setattr(shared_runs, "__version__", "0.0.0-other")
    _, said = _predict(tmp, rig, tmp / "version" / "b")
    assert not any("taken from" in m for m in said)
    monkeypatch.undo()
    # a store whose runs finished before it had a record (an older parcelfit) is not a source
    store = Store(tmp / "version" / "b" / "predict.sqlite")
    try:
        store._db.execute("DELETE FROM meta WHERE key = ?", (SCATTER_RECORD,))  # as before
        assert store.get_meta(SCATTER_RECORD) is None
    finally:
        store.close()
    shutil.rmtree(tmp / "version" / "a")
    _predict(tmp, rig, tmp / "version" / "b")  # resumed with today's version: nothing to run
    _, said = _predict(tmp, rig, tmp / "version" / "c")
    assert not any("taken from" in m for m in said)
    store = Store(tmp / "version" / "b" / "predict.sqlite", readonly=True)
    try:
        assert store.get_meta(SCATTER_RECORD) is None  # not vouched for after the fact
    finally:
        store.close()


def test_an_unreadable_or_foreign_folder_beside_the_output_is_passed_over(calibrated):
    tmp, rig = calibrated
    beside = tmp / "foreign"
    (beside / "junk").mkdir(parents=True)
    (beside / "junk" / "predict.sqlite").write_text("not a database")
    (beside / "empty").mkdir()
    (beside / "empty" / "predict.sqlite").write_bytes(b"")
    p, said = _predict(tmp, rig, beside / "mine")
    assert p.scatter is not None and not any("taken from" in m for m in said)


# the design's runs: the numerical error's and the prediction's own


@pytest.fixture
def unfitted(tmp_path, monkeypatch) -> tuple[Path, Path]:
    """A study whose store holds no fit (so no scatter runs), rig Q beside it, and the log of
    every simulation started."""
    folder = write_finished_study(tmp_path)
    write_rig_q(tmp_path)
    log = tmp_path / "started.log"
    monkeypatch.setenv("FAKE_SIM_LOG", str(log))
    monkeypatch.setenv("FAKE_SIM_MESH_ERROR", "0.4")
    return folder, log


def _predict_q(study: Path, out: Path, setting: int = 1, **kw):
    events: list[ProgressEvent] = []
    options = {"sets": 3, "placements": 2, "numerical_runs": 3, **kw}
    p = predict(
        study,
        str(study.parent / "Q.yaml"),
        "KPBW",
        setting,
        executor="serial",
        out=out,
        progress=events.append,
        **options,
    )
    return p, [e.message for e in events]


def _started(log: Path) -> list[str]:
    return log.read_text().splitlines() if log.is_file() else []


def _design_rows(out: Path) -> list:
    store = Store(out / "predict.sqlite", readonly=True)
    try:
        return [e for e in store.evaluations("screen") if e.iteration <= 0]
    finally:
        store.close()


def test_a_design_predicted_again_with_more_sets_takes_the_numerical_error_runs(unfitted, tmp_path):
    study, log = unfitted
    first, _ = _predict_q(study, tmp_path / "preds" / "a")
    assert first.numerical is not None and first.numerical.pairs == 3
    before = _started(log)
    assert sum(r.startswith("numerical-") for r in before) == 6
    second, said = _predict_q(study, tmp_path / "preds" / "b", sets=5)
    started = _started(log)[len(before) :]
    store = Store(tmp_path / "preds" / "b" / "predict.sqlite", readonly=True)
    try:
        record = store.get_meta(DESIGN.reused)
        taken = reused_ids(store, [DESIGN])
    finally:
        store.close()
    rows = {e.id: e for e in _design_rows(tmp_path / "preds" / "b")}
    own_taken = sum(rows[i].iteration == 0 for i in taken)  # sets drawn in both
    # the 6 runs of the numerical error are not simulated again; of the 5 x 2 own runs, those
    # of the sets both draws hold are not either
    assert not any(r.startswith("numerical-") for r in started)
    assert len(started) + own_taken == 10 and all(r.startswith("predict-set") for r in started)
    assert {rows[i].iteration for i in taken} >= {-1, -2} and record["rows"] == 6 + own_taken
    assert any(f"the design's runs: {6 + own_taken} simulations taken from a" in m for m in said)
    assert second.numerical == first.numerical
    # the same as estimating it afresh (no prediction beside it)
    fresh, said = _predict_q(study, tmp_path / "alone" / "c", sets=5)
    assert not any("taken from" in m for m in said)
    assert fresh.numerical == second.numerical
    assert fresh.runs.drop(columns="wall_time").equals(second.runs.drop(columns="wall_time"))


def test_the_same_sets_and_placements_take_the_design_s_own_runs_too(unfitted, tmp_path):
    study, log = unfitted
    _predict_q(study, tmp_path / "same" / "a")
    before = _started(log)
    # other inputs in another folder, the same simulations (the study has no scatter runs)
    p, said = _predict_q(study, tmp_path / "same" / "b", scatter_runs=4)
    assert _started(log) == before  # nothing simulated
    assert any("the design's runs: 12 simulations taken from a" in m for m in said), said
    assert all(e.status == "ok" for e in _design_rows(tmp_path / "same" / "b"))
    assert len(p.runs) == 6


def test_another_design_or_an_edited_rig_file_takes_none_of_the_design_s_runs(unfitted, tmp_path):
    study, log = unfitted
    _predict_q(study, tmp_path / "other" / "a")
    # the other speed setting: another design
    _, said = _predict_q(study, tmp_path / "other" / "b", setting=2)
    assert not any("taken from" in m for m in said)
    # the rig file edited under the same name: another design, though its label is the same
    rig = study.parent / "Q.yaml"
    rig.write_text(rig.read_text() + "\n# edited\n")
    before = _started(log)
    _, said = _predict_q(study, tmp_path / "other" / "c")
    assert not any("taken from" in m for m in said)
    assert sum(r.startswith("numerical-") for r in _started(log)[len(before) :]) == 6


def test_another_refinement_takes_none_of_the_numerical_error_runs(unfitted, tmp_path):
    study, log = unfitted
    first, _ = _predict_q(study, tmp_path / "refine" / "a")
    # the study's refinement is left out of its fingerprint (a finished study may be checked at
    # another): the refined runs at 4 are not those at 2
    path = tmp_path / "study.yaml"
    doc = yaml.safe_load(path.read_text())
    doc["validation"] = {**(doc.get("validation") or {}), "refinement": 4}
    path.write_text(yaml.safe_dump(doc))
    before = _started(log)
    second, said = _predict_q(study, tmp_path / "refine" / "b")
    assert not any("taken from" in m for m in said)
    assert sum(r.startswith("numerical-") for r in _started(log)[len(before) :]) == 6
    assert second.numerical.refinement == 4 and second.numerical != first.numerical
    fresh, _ = _predict_q(study, tmp_path / "alone" / "c")
    assert fresh.numerical == second.numerical


def test_a_prediction_resumed_under_another_record_vouches_for_none_of_its_runs(
    unfitted, tmp_path, monkeypatch
):
    from . import fake_sim

    study, log = unfitted
    rig = study.parent / "Q.yaml"
    original = rig.read_text()
    monkeypatch.setattr(fake_sim, "started", 0)
    monkeypatch.setenv("FAKE_SIM_INTERRUPT_AFTER", "2")
    with pytest.raises(KeyboardInterrupt):
        _predict_q(study, tmp_path / "resumed" / "a")
    monkeypatch.delenv("FAKE_SIM_INTERRUPT_AFTER")
    # resumed with the rig file edited: the rest of its runs are not what its record says
    rig.write_text(original + "\n# edited\n")
    _predict_q(study, tmp_path / "resumed" / "a")
    store = Store(tmp_path / "resumed" / "a" / "predict.sqlite", readonly=True)
    try:
        assert store.get_meta(DESIGN.record) == shared_runs.WITHDRAWN
    finally:
        store.close()
    # the file as it was: the resumed store is no source, although part of it was made so
    rig.write_text(original)
    before = _started(log)
    _, said = _predict_q(study, tmp_path / "resumed" / "b")
    assert not any("taken from" in m for m in said)
    assert len(_started(log)) - len(before) == 3 * 2 + 6
