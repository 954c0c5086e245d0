"""The state of a study folder, running or finished, as one typed record (`StudyStatus`):
what ``parcelfit status`` prints (and ``status --json`` writes), what ``calibrate`` prints when
it stops and what the report's calibration section reads. It reads the store and the stored
results; it simulates and writes nothing.

Iterations are numbered one way everywhere: 0 is the initial design, k >= 1 the k-th batch the
optimiser chose. Parameter values are SI, in the unit `StudyStatus.units` gives per parameter.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, field_serializer

from parcelfit.errors import ParcelfitError
from parcelfit.runs import is_synthetic
from parcelfit.study.details import CaseCost
from parcelfit.study.results import read_results
from parcelfit.study.store import STORE_FILE, CaseRecord, SourceRecord, Store, StudyRecord
from parcelfit.study.verdict import Verdict, study_verdict


class _Record(BaseModel):
    """A status record: frozen, its fields exactly the keys of its JSON form."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    def to_json(self) -> dict[str, Any]:
        """The JSON-ready form (``status --json``): the fields under their own names."""
        return self.model_dump()


class PointStatus(_Record):
    """One evaluated parameter set (SI, fitted parameters only) with its cost [-], the
    iteration it was evaluated in (None when not found among the fitting evaluations) and
    ``parts``: the per-case cost parts of a joint or ensemble study (None otherwise)."""

    params: dict[str, float]
    cost: float
    iteration: int | None
    parts: list[CaseCost] | None

    @field_serializer("parts")
    def _parts_json(self, parts: list[CaseCost] | None) -> list[dict[str, Any]] | None:
        """The parts in their stored form (the keys of the chosen cost only)."""
        return None if parts is None else [p.to_json() for p in parts]


class ValidationStatus(_Record):
    """One stored validation: the iteration it followed, its case (None in a one-case study),
    the simulation's status and its verdict (None while pending or when it failed)."""

    after_iteration: int
    case: str | None
    status: str
    passed: bool | None


class StudyStatus(_Record):
    """A summary of a study folder (`study_status`).

    ``study``: its description (`record_summary`); ``dataset`` and ``synthetic`` (True for
    SYNTHETIC data, None when the dataset is not recorded); ``reference_run``; ``stop_reason``
    (None while running); ``evaluations``, ``pending`` and ``by_status`` (fitting evaluations
    per status); ``last_iteration`` (None before the first); ``recommended`` (the parameters
    the study validates and reports, set when it stops); ``lowest_cost`` (the evaluation with
    the lowest single cost); ``cases`` (a joint study's test cases: label, role
    fit/validation/transfer, weight, dataset, reference run, acceptance threshold; None for a
    one-case study); ``validations``; ``verdict`` (the overall verdict with its checks,
    `parcelfit.study.verdict`, as JSON); ``units`` (SI unit per parameter, and the cost's)."""

    study: dict[str, Any] | None
    dataset: str | None
    synthetic: bool | None
    reference_run: str | None
    stop_reason: str | None
    evaluations: int
    pending: int
    by_status: dict[str, int]
    last_iteration: int | None
    recommended: PointStatus | None
    lowest_cost: PointStatus | None
    cases: list[CaseRecord] | None
    validations: list[ValidationStatus]
    verdict: dict[str, Any]
    units: dict[str, str]

    @field_serializer("cases")
    def _cases_json(self, cases: list[CaseRecord] | None) -> list[dict[str, Any]] | None:
        """The cases in their stored form."""
        return None if cases is None else [c.to_json() for c in cases]

    @property
    def shown(self) -> PointStatus | None:
        """The parameters to show: the recommended ones, or while the study runs the lowest-cost
        ones so far."""
        return self.recommended if self.recommended is not None else self.lowest_cost


def record_summary(record: StudyRecord) -> dict[str, Any]:
    """A study record as JSON (bounds SI), its optimiser as ``optimizer``: ``sampler``,
    ``settings`` (BOSettings fields, None without a GP), ``recorded`` (False for a store of an
    earlier version: the defaults stand in) and ``note`` (None, or what stands in)."""
    doc = record.to_json()
    del doc["sampler"], doc["bo_settings"]
    doc["optimizer"] = {**record.optimizer.to_json(), "note": record.optimizer.note}
    return doc


def study_folder(folder: str | Path) -> Path:
    """``folder`` if it holds a study store, else its ``calibration/`` subfolder when that does
    (as ``parcelfit demo`` writes); ``folder`` unchanged otherwise (the caller refuses it)."""
    folder = Path(folder)
    inner = folder / "calibration"
    return (
        inner if not (folder / STORE_FILE).is_file() and (inner / STORE_FILE).is_file() else folder
    )


def study_status(folder: str | Path) -> StudyStatus:
    """The state of the study in ``folder`` (running or finished), read from its store and
    stored results (`StudyStatus`); a folder without a store is refused, naming the
    ``calibration/`` subfolder when the study is there (the demo's)."""
    from parcelfit.sim.params import si_unit

    folder = Path(folder)
    path = folder / STORE_FILE
    if not path.is_file():
        inner = folder / "calibration" / STORE_FILE
        raise ParcelfitError(
            f"no {STORE_FILE} here"
            + ("; the study is in the calibration/ subfolder" if inner.is_file() else ""),
            file=folder,
            fix=f"point at {inner.parent}"
            if inner.is_file()
            else "point at a study's output folder",
        )
    store = Store(path, readonly=True)
    try:
        fits = store.evaluations("fit")
        vals = store.evaluations("validation")
        record, source = store.read_study(), store.read_source() or SourceRecord()
        reference_run, stop_reason = store.get_meta("reference_run"), store.get_meta("stop_reason")
        cases = store.read_cases()
        recommended = store.read_recommended()
    finally:
        store.close()
    ok = [e for e in fits if e.status == "ok" and e.cost is not None and math.isfinite(e.cost)]
    lowest = min(ok, key=lambda e: e.cost) if ok else None  # type: ignore[arg-type, return-value]
    names = list(record.parameters if record else (lowest.params if lowest else []))
    return StudyStatus(
        study=None if record is None else record_summary(record),
        dataset=source.dataset,
        synthetic=is_synthetic(source.dataset) if source.dataset else None,
        reference_run=reference_run,
        stop_reason=stop_reason,
        evaluations=len(fits),
        pending=sum(e.status == "pending" for e in fits),
        by_status={s: sum(e.status == s for e in fits) for s in sorted({e.status for e in fits})},
        last_iteration=max((e.iteration for e in fits), default=None),
        recommended=None
        if recommended is None
        else PointStatus(
            params=recommended.params,
            cost=recommended.cost,
            iteration=next((e.iteration for e in fits if e.params == recommended.params), None),
            parts=next((e.details.cases for e in fits if e.params == recommended.params), None),
        ),
        lowest_cost=None
        if lowest is None or lowest.cost is None
        else PointStatus(
            params=lowest.params,
            cost=lowest.cost,
            iteration=lowest.iteration,
            parts=lowest.details.cases,
        ),
        cases=cases,
        validations=[
            ValidationStatus(
                after_iteration=v.iteration,
                case=v.details.case,
                status=v.status,
                passed=v.details.passed,
            )
            for v in vals
        ],
        verdict=_verdict(folder, cases, stop_reason).to_json(),
        units={**{n: si_unit(n) for n in names}, "cost": "-"},
    )


def _verdict(folder: Path, cases: list[CaseRecord] | None, stop_reason: str | None) -> Verdict:
    """The verdict of the study's stored results (a damaged results file counts as none)."""
    try:
        results = read_results(folder)
    except ParcelfitError:
        results = None
    return study_verdict(results, cases, stop_reason is not None)


def folder_verdict(folder: str | Path) -> Verdict:
    """The overall verdict of a study folder with its checks (`parcelfit.study.verdict`): what
    ``calibrate``, ``status`` and the report say. ``folder`` is a study folder or a folder
    holding ``calibration/`` (the demo's)."""
    folder = Path(folder)
    inner = folder / "calibration"
    if not (folder / STORE_FILE).is_file() and (inner / STORE_FILE).is_file():
        folder = inner
    store = Store(folder / STORE_FILE, readonly=True)
    try:
        cases, stop_reason = store.read_cases(), store.get_meta("stop_reason")
    finally:
        store.close()
    return _verdict(folder, cases, stop_reason)
