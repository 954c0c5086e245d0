import sqlite3

import pytest

from parcelfit import ParcelfitError
from parcelfit.optimize.store import Store


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
