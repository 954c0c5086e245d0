import sqlite3

import pytest

from parcelfit import ParcelfitError
from parcelfit.study.store import Store


def test_pending_then_finished_and_persistent(tmp_path):
    path = tmp_path / "study.sqlite"
    store = Store(path)
    store.set_meta("seed", 7)
    ids = store.add_pending("fit", 0, [{"mu": 0.4}, {"mu": 0.5}], speed_setting=1, seeds=[11, 12])
    assert [e.status for e in store.evaluations()] == ["pending", "pending"]
    store.finish(
        ids[1],
        status="ok",
        cost=0.25,
        dtw_xy=0.1,
        dtw_theta=0.2,
        transit_time=1.3,
        wall_time=2.5,
        run_file="runs/fit-0-1.csv",
        details={"message": "ok"},
    )
    store.close()
    again = Store(path)
    assert again.get_meta("seed") == 7 and again.get_meta("missing") is None
    rows = again.evaluations("fit")
    assert [r.status for r in rows] == ["pending", "ok"]
    done = rows[1]
    assert (done.params, done.cost, done.seed, done.run_file) == (
        {"mu": 0.5},
        0.25,
        12,
        "runs/fit-0-1.csv",
    )
    assert done.details == {"message": "ok"} and done.finished_at >= done.asked_at
    assert again.evaluations("validation") == []
    mode = sqlite3.connect(path).execute("PRAGMA journal_mode").fetchone()[0]
    assert mode == "wal"


def test_a_batch_slot_is_recorded_once_and_results_need_a_final_status(tmp_path):
    store = Store(tmp_path / "s.sqlite")
    ids = store.add_pending("fit", 3, [{"a": 1.0}], speed_setting=1, seeds=[1])
    with pytest.raises(sqlite3.IntegrityError):
        store.add_pending("fit", 3, [{"a": 2.0}], speed_setting=1, seeds=[1])
    assert len(store.evaluations()) == 1  # the failed batch left nothing behind
    with pytest.raises(ParcelfitError, match="final status"):
        store.finish(ids[0], status="pending")
    with pytest.raises(ParcelfitError, match="no evaluation with id 99"):
        store.finish(99, status="ok")


def test_damaged_database_is_reported(tmp_path):
    bad = tmp_path / "s.sqlite"
    bad.write_bytes(b"this is not a database" * 100)
    with pytest.raises(ParcelfitError, match="cannot open the study database"):
        Store(bad)


def test_the_meta_records_round_trip_by_type(tmp_path):
    from parcelfit.study.store import (
        OptimizerRecord,
        RecommendedRecord,
        SourceRecord,
        StudyRecord,
    )

    study = StudyRecord(
        name="s",
        parameters=("mu_d_BePa", "E_Pa"),
        bounds=((0.3, 0.6), (2e8, 1.6e9)),
        log=(False, True),
        batch_size=3,
        seed=5,
        fit_setting=1,
        validation_setting=2,
        optimizer=OptimizerRecord("published", {"batch": "kmeans", "noise": "fixed"}),
    )
    source = SourceRecord("/s/study.yaml", "/s/data", "E3", "KPBW")
    best = RecommendedRecord({"mu_d_BePa": 0.45, "E_Pa": 9e8}, 0.25)
    store = Store(tmp_path / "study.sqlite")
    assert store.read_study() is None and store.read_recommended() is None
    store.write_study(study)
    store.write_source(source)
    store.write_recommended(best)
    store.close()
    again = Store(tmp_path / "study.sqlite", readonly=True)
    assert again.read_study() == study and again.read_study().optimizer.note is None
    assert again.read_source() == source and again.read_recommended() == best
    # one writer and one reader: the records are not read or written as raw values
    with pytest.raises(ParcelfitError, match=r"read_study\(\)"):
        again.get_meta("study")
    again.close()
    with pytest.raises(ParcelfitError, match=r"write_recommended\(\)"):
        Store(tmp_path / "study.sqlite").set_meta("recommended", {})


def test_an_old_study_record_reads_with_default_optimizer_settings_and_says_so(tmp_path):
    from .helpers import old_meta

    store = Store(tmp_path / "study.sqlite")
    old_meta(
        store,
        study={"name": "old", "parameters": ["mu_d_BePa"], "bounds": [[0.3, 0.6]], "seed": 2},
        source={"dataset": "/d"},
    )
    record = store.read_study()
    assert record.parameters == ("mu_d_BePa",) and record.log == (False,) and record.seed == 2
    assert record.batch_size == 4 and record.validation_setting is None
    opt = record.optimizer
    assert not opt.recorded and opt.settings is None and "earlier parcelfit" in opt.note
    assert store.read_source().dataset == "/d" and store.read_source().rig is None
    old_meta(store, study="not a record")
    with pytest.raises(ParcelfitError, match="'study' record is damaged"):
        store.read_study()
    store.close()
