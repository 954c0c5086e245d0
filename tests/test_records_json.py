"""Stored records read back and write the same bytes: tests/data/records holds a
``results.json`` and store meta records as an earlier parcelfit wrote them (before the records
became pydantic models)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from parcelfit.study.identify import Advice, Identifiability, ParameterInterval
from parcelfit.study.results import (
    BandRecord,
    DependenceCurve,
    KeyFramesRecord,
    ReferenceRecord,
    StudyResults,
    SurrogateRecord,
    ValidationRecord,
)
from parcelfit.study.store import OptimizerRecord, RecommendedRecord, SourceRecord, StudyRecord

DATA = Path(__file__).parent / "data" / "records"
RESULTS = (DATA / "results.json").read_text()
META = json.loads((DATA / "meta.json").read_text())
# study records as written before they became pydantic models, and what that code read from and
# wrote for records of earlier versions (no sampler, missing or null keys, an empty name)
STUDY = json.loads((DATA / "study.json").read_text())


def same(kind, doc) -> None:
    """``doc`` read as ``kind`` writes the same JSON text."""
    assert json.dumps(kind.from_json(doc).to_json()) == json.dumps(doc)


def test_a_results_file_reads_back_and_writes_the_same_bytes():
    assert json.dumps(StudyResults.from_json(json.loads(RESULTS)).to_json()) == RESULTS


@pytest.mark.parametrize(
    ("kind", "part"),
    [
        (KeyFramesRecord, lambda d: d["key_frames"]),
        (SurrogateRecord, lambda d: d["surrogate"]),
        (OptimizerRecord, lambda d: d["surrogate"]["optimizer"]),
        (DependenceCurve, lambda d: d["surrogate"]["curves"][0]),
        (BandRecord, lambda d: d["validations"][0]["band"]),
        (Advice, lambda d: d["advice"]),
        (ReferenceRecord, lambda d: d["references"]["fit"]),
        (ReferenceRecord, lambda d: d["references"]["validation"]),
        (ValidationRecord, lambda d: d["validations"][0]),
        (ValidationRecord, lambda d: d["transfer"][0]),
        (Identifiability, lambda d: d["identifiability"]),
        (ParameterInterval, lambda d: d["identifiability"]["parameters"][0]),
        (ParameterInterval, lambda d: d["identifiability"]["parameters"][1]),
    ],
)
def test_a_results_record_reads_back_and_writes_the_same(kind, part):
    same(kind, part(json.loads(RESULTS)))


@pytest.mark.parametrize(
    ("kind", "key"),
    [
        (SourceRecord, "source"),
        (SourceRecord, "source_partial"),
        (RecommendedRecord, "recommended"),
        (OptimizerRecord, "optimizer"),
    ],
)
def test_a_store_record_reads_back_and_writes_the_same(kind, key):
    same(kind, META[key])


def test_records_read_what_earlier_versions_left_out():
    assert SourceRecord.from_json({}) == SourceRecord()
    frames = KeyFramesRecord.from_json({"case": "R/P/2", "params": None})
    assert (frames.params, frames.image, frames.note) == ({}, None, None)
    best = RecommendedRecord.from_json({"params": {"E_Pa": 9e8}, "cost": 1})
    assert best.cost == 1.0 and isinstance(best.cost, float)
    assert json.dumps(best.to_json()) == '{"params": {"E_Pa": 900000000.0}, "cost": 1.0}'
    advice = Advice.from_json({"changes": {"R/P/2": {"E_Pa": 1}}, "best": None})
    assert (advice.parameters, advice.params, advice.changes) == ((), {}, {"R/P/2": {"E_Pa": 1.0}})


def test_a_parameter_interval_reads_integers_as_floats():
    doc = {"name": "E_Pa", "low": 2, "high": 16, "interval": [3, 15], "median": 9}
    iv = ParameterInterval.from_json({**doc, "verdict": "narrowed", "rhat": 1})
    assert iv.interval == (3.0, 15.0) and isinstance(iv.interval[0], float)
    assert json.dumps(iv.to_json()) == (
        '{"name": "E_Pa", "low": 2.0, "high": 16.0, "interval": [3.0, 15.0], "median": 9.0, '
        '"verdict": "narrowed", "rhat": 1.0}'
    )


def test_identifiability_reads_an_empty_sample_and_earlier_defaults():
    doc = json.loads(RESULTS)["identifiability"]
    earlier = ("level", "reached", "supported", "best_acceptance")
    old = {k: v for k, v in doc.items() if k not in earlier}
    ident = Identifiability.from_json({**old, "sample": []})
    assert ident.sample.shape == (0, 2) and ident.correlation.shape == (2, 2)
    assert (ident.level, ident.reached, ident.supported, ident.best_acceptance) == (
        0.95,
        True,
        True,
        1.0,
    )
    assert json.dumps(ident.to_json()["sample"]) == "[]"


def test_a_reference_record_reads_integers_as_floats_and_keeps_missing_times():
    doc = json.loads(RESULTS)["references"]["fit"]
    n = len(doc["run_ids"])
    ref = ReferenceRecord.from_json({**doc, "transit_times_s": [None, *range(1, n)]})
    assert ref.transit_times == (None, *(float(t) for t in range(1, n)))
    assert json.dumps(ref.to_json()["transit_times_s"]) == json.dumps(
        [None, *map(float, range(1, n))]
    )
    assert ref.reference_id == doc["reference_run"] == doc["run_ids"][doc["index"]]
    assert ref.xy_series[0].shape == (len(doc["prepared_runs"][0]["x_m"]), 2)
    assert list(ref.to_json()) == list(doc)


def test_a_validation_record_reads_a_failed_run_with_only_its_case_and_status():
    failed = ValidationRecord.from_json({"case": "R/P/2", "status": "failed", "params": None})
    assert (failed.verdict, failed.sim_xy, failed.band, failed.passed) == (None, None, None, False)
    assert json.dumps(failed.to_json()) == (
        '{"case": "R/P/2", "after_iteration": null, "params": {}, "status": "failed", '
        '"message": null, "transit_time_s": null, "run_file": null, "verdict": null, '
        '"simulated": null, "band": null}'
    )
    doc = json.loads(RESULTS)["validations"][0]
    ok = ValidationRecord.from_json({**doc, "after_iteration": 3.0, "transit_time_s": 1})
    assert (
        ok.after_iteration == 3 and ok.transit_time == 1.0 and ok.passed == doc["verdict"]["passed"]
    )
    assert ok.sim_xy.shape == (len(doc["simulated"]["x_m"]), 2)


def test_a_results_file_of_an_earlier_version_reads_and_keeps_each_cases_keys():
    doc = json.loads(RESULTS)
    for key in ("stop_reason", "transfer", "advice", "identifiability", "surrogate"):
        del doc[key]
    doc["figures"] = None
    doc["key_frames"] = {"case": "R/P/2"}
    doc["cases"] = [
        {"case": "R/P/2", "role": "fit"},
        {"case": "R/P/1", "role": "validation", "weight": 2},
    ]
    old = StudyResults.from_json(doc)
    assert (old.stop_reason, old.transfer, old.figures, old.advice) == (None, (), (), None)
    assert old.key_frames.params == {} and old.surrogate is None and old.identifiability is None
    out = old.to_json()
    assert list(out) == list(json.loads(RESULTS))
    assert out["cases"] == [
        {"case": "R/P/2", "role": "fit"},
        {"case": "R/P/1", "role": "validation", "weight": 2.0},
    ]
    assert json.dumps(out["key_frames"]) == (
        '{"case": "R/P/2", "params": {}, "image": null, "animation": null, "note": null}'
    )
    assert json.dumps(out["references"]) == json.dumps(json.loads(RESULTS)["references"])


@pytest.mark.parametrize("doc", STUDY["written"])
def test_a_study_record_reads_back_and_writes_the_same(doc):
    same(StudyRecord, doc)
    assert StudyRecord.from_json(doc).optimizer.recorded


@pytest.mark.parametrize("old", STUDY["earlier"])
def test_a_study_record_of_an_earlier_store_reads_as_before(old):
    record = StudyRecord.from_json(old["stored"])
    assert json.dumps(record.to_json()) == json.dumps(old["written"])
    assert record.optimizer == OptimizerRecord(recorded=False)
    assert StudyRecord.from_json(old["written"]).optimizer.recorded
