import json
import sqlite3

import pytest

from parcelfit import ParcelfitError
from parcelfit.study.details import EvaluationDetails
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
        details=EvaluationDetails(message="ok"),
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
    assert (
        done.details.message == "ok"
        and done.details.to_json() == {"message": "ok"}
        and done.finished_at >= done.asked_at
    )
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
        optimizer=OptimizerRecord(
            sampler="published", settings={"batch": "kmeans", "noise": "fixed"}
        ),
    )
    source = SourceRecord(
        study_file="/s/study.yaml", dataset="/s/data", rig="E3", consignment="KPBW"
    )
    best = RecommendedRecord(params={"mu_d_BePa": 0.45, "E_Pa": 9e8}, cost=0.25)
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


# details as earlier versions stored them: each writer's form, raw JSON in the details column
_OLD_DETAILS = [
    {  # a fitting run's simulator diagnostics, some backend-specific
        "message": "the parcel left the rig's end box",
        "steps": 2400,
        "simulated_time": 2.4,
        "timestep": 0.001,
        "steps_per_second": float("nan"),
        "barrier_times": [0.4, None],
        "hand_friction_steps": 3,
        "worker_restarts": 1,
    },
    {  # a validation in a joint study
        "message": None,
        "passed": True,
        "case": "R-P-2",
        "transit_time": {"simulated": 1.21, "low": 1.1, "high": 1.3, "passed": True},
        "xy": {"simulated_mean": 0.01, "largest_real_mean": 0.02, "passed": True},
        "theta": {"simulated_mean": 0.3, "largest_real_mean": 0.2, "passed": False},
        "envelope": None,
    },
    {  # a joint ensemble evaluation
        "cases": [
            {
                "case": "R-P-1",
                "weight": 0.5,
                "run_files": ["runs/a.csv", "runs/b.csv"],
                "seeds": [1, 2],
                "transit_times": [1.2, None],
                "adjusted_transit_times": [1.25, None],
                "cost": 0.7,
                "trajectory_term": 0.5,
                "transit_term": None,
                "se": 0.05,
                "mean_transit_time": 1.2,
            },
            {
                "case": "R-P-2",
                "weight": 1.0,
                "run_files": ["runs/c.csv"],
                "seeds": [None],
                "transit_times": [1.3],
                "cost": 0.2,
                "dtw_xy": 0.1,
                "dtw_theta": 0.3,
            },
        ]
    },
    {  # a joint evaluation one of whose runs failed
        "cases": [],
        "message": "worker failed: BrokenProcessPool('A child process terminated')",
        "failed_run": {"case": "R-P-1", "placement": 3},
    },
    {"rotation": 0.4, "exit_x": 1.5, "exit_y": -0.02, "exit_heading": 0.1},  # a screened run
    {},
]


def test_details_stored_by_earlier_versions_read_typed_and_write_back_unchanged(tmp_path):
    path = tmp_path / "study.sqlite"
    store = Store(path)
    ids = store.add_pending("fit", 0, [{"mu": 0.4}] * len(_OLD_DETAILS), 1, [0] * len(_OLD_DETAILS))
    con = sqlite3.connect(path, isolation_level=None)
    for row, doc in zip(ids, _OLD_DETAILS, strict=True):
        con.execute(
            "UPDATE evaluations SET status = 'ok', details = ? WHERE id = ?",
            (json.dumps(doc), row),
        )
    con.close()
    diag, val, joint, failed, screened, empty = (e.details for e in store.evaluations("fit"))
    assert diag.steps == 2400 and diag.worker_restarts == 1 and diag.simulated_time == 2.4
    assert diag.diagnostic("hand_friction_steps") == 3 and diag.diagnostic("absent") is None
    assert val.passed is True and val.case == "R-P-2" and val.envelope is None
    assert val.transit is not None and (val.transit.low, val.transit.high) == (1.1, 1.3)
    assert val.theta is not None and val.theta.passed is False
    assert joint.cases is not None and [p.case for p in joint.cases] == ["R-P-1", "R-P-2"]
    ensemble, published = joint.cases
    assert ensemble.is_ensemble and ensemble.se == 0.05 and ensemble.transit_times == [1.2, None]
    assert not published.is_ensemble and published.dtw_theta == 0.3 and published.seeds == [None]
    assert published.adjusted_transit_times is None
    assert failed.failed_run is not None and failed.failed_run.placement == 3
    assert failed.cases == [] and failed.message is not None
    assert screened.quantities == {
        "rotation": 0.4,
        "exit_x": 1.5,
        "exit_y": -0.02,
        "exit_heading": 0.1,
    }
    assert empty == EvaluationDetails() and empty.message is None and empty.to_json() == {}
    # written back (as a resumed study rewrites a row), each reads as it was stored
    for e in store.evaluations("fit"):
        store.finish(e.id, status="ok", details=e.details)
    for e, doc in zip(store.evaluations("fit"), _OLD_DETAILS, strict=True):
        assert json.dumps(e.details.to_json(), sort_keys=True) == json.dumps(doc, sort_keys=True)


def test_damaged_details_are_refused_with_the_file_named(tmp_path):
    path = tmp_path / "study.sqlite"
    store = Store(path)
    (row,) = store.add_pending("fit", 0, [{"mu": 0.4}], 1, [0])
    con = sqlite3.connect(path, isolation_level=None)
    con.execute("UPDATE evaluations SET details = ? WHERE id = ?", ('{"cases": 3}', row))
    con.close()
    with pytest.raises(ParcelfitError, match="details in the study database are damaged"):
        store.evaluations()


def test_claim_meta_stores_the_first_inputs_and_compares_later_ones_as_json(tmp_path):
    store = Store(tmp_path / "s.sqlite")
    try:
        first = {"seed": 3, "placements": (1, 2), "rate": 0.5}
        assert store.claim_meta("job", first)  # nothing stored: stored now
        assert store.get_meta("job") == {"seed": 3, "placements": [1, 2], "rate": 0.5}
        assert store.claim_meta("job", {"rate": 0.5, "placements": [1, 2], "seed": 3})
        assert not store.claim_meta("job", {**first, "seed": 4})
        assert store.get_meta("job")["seed"] == 3  # a refused claim changes nothing
    finally:
        store.close()
