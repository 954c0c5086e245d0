"""What a calibration concluded, written for the report: ``results.json`` in the study folder.

The calibration (`parcelfit.study.calibration`) writes this file after every validation and
when it stops; the report renders it and computes nothing of its own. It holds

* the reference runs the study used (fitting and validation test case): the distance matrices
  behind the choice and the prepared real runs (`ReferenceRecord`);
* every validation: its verdict by the published criteria and the stricter band test, the
  prepared simulated run and the band (`ValidationRecord`);
* the GP surrogate's partial dependence curves, refitted with the optimiser settings the store
  records (`SurrogateRecord`);
* the key frames of the calibrated run (MuJoCo studies, `KeyFramesRecord`) and the figures
  written into ``figures/``;
* what the evaluations determine: every parameter's interval and verdict, the posterior
  correlations and sample (`parcelfit.study.identify.Identifiability`), and which candidate
  test case would help most (`parcelfit.study.joint.Advice`);
* the transfer check: the calibrated parameters judged on other test cases
  (`ValidationRecord` each), and the study's test cases with their roles and weights;
* the convergence check: the calibrated parameters simulated again on every validation and
  transfer case with a refined model (`ConvergenceRecord`).

The file's schema is documented in docs/data.md (Study results); units are SI throughout (m,
rad, s; squared DTW distances in m^2 and rad^2). `read_results` reads it, `write_results`
writes it atomically. The demo's ``stricter-criterion.json`` holds one `ReferenceRecord` and one
`ValidationRecord` in the same form.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PlainSerializer,
    PlainValidator,
    SerializerFunctionWrapHandler,
    model_serializer,
    model_validator,
)

from parcelfit import __version__
from parcelfit.atomic import write_text_atomic
from parcelfit.errors import ParcelfitError
from parcelfit.metrics import (
    MeanDistanceCheck,
    ReferenceSelection,
    TransitTimeCheck,
    Validation,
    validate,
)
from parcelfit.metrics.envelope import EnvelopeCheck, envelope_band
from parcelfit.runs import Trajectory
from parcelfit.study.details import (
    EnvelopeCriterion,
    EvaluationDetails,
    MeanCriterion,
    TransitCriterion,
)
from parcelfit.study.identify import Advice, Identifiability
from parcelfit.study.records import ArrayRecord, FloatArray, float_array, float_list
from parcelfit.study.store import CaseRecord, OptimizerRecord

RESULTS_FILE = "results.json"
FORMAT = "parcelfit-study-results"
VERSION = 1


_list = float_list
_array = float_array


class ReferenceRecord(ArrayRecord):
    """A test case's reference run as the study chose it (method section 4): the run ids, the
    chosen index, the real transit times [s], the squared distance matrices (``d_time`` [s^2],
    ``d_xy`` [m^2], ``d_theta`` [rad^2], ``d_combined`` normalised), their largest entries, and
    the prepared real runs (``xy_series``: (n, 2) arrays [m], ``theta_series`` [rad]; stored
    as ``prepared_runs``, after ``reference_run``, the chosen run's id, which is not read)."""

    case: str
    run_ids: tuple[str, ...]
    index: int
    transit_times: tuple[float | None, ...] = Field(alias="transit_times_s")
    uses_time: bool = Field(alias="uses_transit_time")
    d_time: FloatArray = Field(alias="d_time_s2")
    d_xy: FloatArray = Field(alias="d_xy_m2")
    d_theta: FloatArray = Field(alias="d_theta_rad2")
    d_combined: FloatArray
    max_time: float = Field(alias="max_d_time_s2")
    max_xy: float = Field(alias="max_d_xy_m2")
    max_theta: float = Field(alias="max_d_theta_rad2")
    xy_series: tuple[FloatArray, ...] = Field(exclude=True)
    theta_series: tuple[FloatArray, ...] = Field(exclude=True)

    @property
    def reference_id(self) -> str:
        """Id of the chosen reference run."""
        return self.run_ids[self.index]

    @classmethod
    def from_selection(cls, sel: ReferenceSelection) -> ReferenceRecord:
        """The record of a selection."""
        return cls(
            case=sel.case.label,
            run_ids=tuple(sel.run_ids),
            index=sel.index,
            transit_times=tuple(sel.transit_times),
            uses_time=sel.uses_time,
            d_time=sel.d_time,
            d_xy=sel.d_xy,
            d_theta=sel.d_theta,
            d_combined=sel.d_combined,
            max_time=sel.max_time,
            max_xy=sel.max_xy,
            max_theta=sel.max_theta,
            xy_series=tuple(sel.xy_series),
            theta_series=tuple(sel.theta_series),
        )

    @model_validator(mode="before")
    @classmethod
    def _read_prepared_runs(cls, doc: Any) -> Any:
        """The stored ``prepared_runs`` (``x_m``, ``y_m``, ``theta_rad`` each) as the series."""
        if isinstance(doc, Mapping) and "prepared_runs" in doc:
            runs = doc["prepared_runs"]
            doc = {k: v for k, v in doc.items() if k != "prepared_runs"}
            doc["xy_series"] = tuple(
                np.column_stack([_array(r["x_m"]), _array(r["y_m"])]) for r in runs
            )
            doc["theta_series"] = tuple(_array(r["theta_rad"]) for r in runs)
        return doc

    @model_serializer(mode="wrap")
    def _write_stored_form(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """The fields, the chosen run's id after the run ids, and the prepared runs last."""
        out: dict[str, Any] = {}
        for key, value in handler(self).items():
            out[key] = value
            if key == "run_ids":
                out["reference_run"] = self.reference_id
        out["prepared_runs"] = [
            {"x_m": _list(xy[:, 0]), "y_m": _list(xy[:, 1]), "theta_rad": _list(th)}
            for xy, th in zip(self.xy_series, self.theta_series, strict=True)
        ]
        return out


class BandRecord(ArrayRecord):
    """The stricter criterion's band along the travelled distance: ``grid`` x [m], the lateral
    band ``y_low``..``y_high`` [m] and the heading band ``theta_low``..``theta_high`` [rad]."""

    grid: FloatArray = Field(alias="x_m")
    y_low: FloatArray = Field(alias="y_low_m")
    y_high: FloatArray = Field(alias="y_high_m")
    theta_low: FloatArray = Field(alias="theta_low_rad")
    theta_high: FloatArray = Field(alias="theta_high_rad")


def _mean_criterion(check: MeanDistanceCheck) -> MeanCriterion:
    """Criterion 2 or 3 as stored in a validation row's details."""
    return MeanCriterion(
        simulated_mean=check.simulated_mean,
        largest_real_mean=check.largest_real_mean,
        passed=bool(check.passed),
    )


def _verdict_json(v: Validation) -> dict[str, Any]:
    return {
        "passed": v.passed,
        "transit_time": asdict(v.transit_time),
        "xy": asdict(v.xy),
        "theta": asdict(v.theta),
        "envelope": None if v.envelope is None else asdict(v.envelope),
    }


def _verdict_from_json(doc: Mapping[str, Any]) -> Validation:
    def mean(d: Mapping[str, Any]) -> MeanDistanceCheck:
        return MeanDistanceCheck(
            str(d["quantity"]),
            float(d["simulated_mean"]),
            tuple(float(m) for m in d["real_means"]),
            float(d["largest_real_mean"]),
            bool(d["passed"]),
        )

    env = doc.get("envelope")
    return Validation(
        transit_time=TransitTimeCheck(**doc["transit_time"]),
        xy=mean(doc["xy"]),
        theta=mean(doc["theta"]),
        envelope=None if env is None else EnvelopeCheck(**env),
    )


def _read_verdict(v: Any) -> Validation | None:
    """A stored verdict (or one already read) as a `Validation`; None stays None."""
    return v if v is None or isinstance(v, Validation) else _verdict_from_json(v)


def _write_verdict(v: Validation | None) -> dict[str, Any] | None:
    return None if v is None else _verdict_json(v)


class ValidationRecord(ArrayRecord):
    """One validation (method section 8): the test case, the iteration it followed (None for a
    run that is not a study's), the parameters simulated (SI), the simulation's status and
    message, its transit time [s] and run file (relative to the folder holding the record),
    the verdict (None when the run failed or could not be compared), and the curves the report
    plots: the prepared simulated run (``sim_xy`` (n, 2) [m], ``sim_theta`` [rad]) and the
    stricter criterion's band (None with fewer than two real runs)."""

    case: str
    after_iteration: int | None = None
    params: Annotated[dict[str, float], BeforeValidator(lambda v: v or {})] = Field(
        default_factory=dict
    )
    status: str
    message: str | None = None
    transit_time: float | None = Field(None, alias="transit_time_s")
    run_file: str | None = None
    verdict: Annotated[
        Validation | None, PlainValidator(_read_verdict), PlainSerializer(_write_verdict)
    ] = None
    sim_xy: FloatArray | None = Field(None, exclude=True)
    sim_theta: FloatArray | None = Field(None, exclude=True)
    band: BandRecord | None = None

    @property
    def passed(self) -> bool:
        """True when the published criteria hold."""
        return self.verdict is not None and self.verdict.passed

    def details(self, case: str | None = None) -> EvaluationDetails:
        """The verdict as the store's ``details`` of the validation row (message, passed, the
        three criteria and the band test in SI; ``case``: the test case's label in a joint
        study)."""
        out = EvaluationDetails(message=self.message, passed=self.passed)
        v = self.verdict
        if v is not None:
            t = v.transit_time
            out = EvaluationDetails(
                message=self.message,
                passed=self.passed,
                transit=TransitCriterion(
                    simulated=t.simulated, low=t.low, high=t.high, passed=bool(t.passed)
                ),
                xy=_mean_criterion(v.xy),
                theta=_mean_criterion(v.theta),
                # the stricter band test, reported beside the published verdict
                envelope=None
                if v.envelope is None
                else EnvelopeCriterion(
                    inside_y=v.envelope.inside_y,
                    inside_theta=v.envelope.inside_theta,
                    worst_y_m=v.envelope.worst_y,
                    worst_theta_rad=v.envelope.worst_theta,
                    passed=bool(v.envelope.passed),
                ),
            )
        return out if case is None else out.model_copy(update={"case": case})

    @model_validator(mode="before")
    @classmethod
    def _read_simulated(cls, doc: Any) -> Any:
        """The stored ``simulated`` run (``x_m``, ``y_m``, ``theta_rad``) as the curves."""
        if isinstance(doc, Mapping) and "simulated" in doc:
            sim = doc["simulated"]
            doc = {k: v for k, v in doc.items() if k != "simulated"}
            if sim is not None:
                doc["sim_xy"] = np.column_stack([_array(sim["x_m"]), _array(sim["y_m"])])
                doc["sim_theta"] = _array(sim["theta_rad"])
        return doc

    @model_serializer(mode="wrap")
    def _write_stored_form(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """The fields, with the simulated run (None without one) before the band."""
        out: dict[str, Any] = {}
        for key, value in handler(self).items():
            if key == "band":
                out["simulated"] = (
                    None
                    if self.sim_xy is None or self.sim_theta is None
                    else {
                        "x_m": _list(self.sim_xy[:, 0]),
                        "y_m": _list(self.sim_xy[:, 1]),
                        "theta_rad": _list(self.sim_theta),
                    }
                )
            out[key] = value
        return out


def validation_record(
    reference: ReferenceSelection,
    trajectory: Trajectory | None,
    transit_time: float | None,
    *,
    status: str = "ok",
    message: str | None = None,
    params: Mapping[str, float] | None = None,
    after_iteration: int | None = None,
    run_file: str | None = None,
) -> ValidationRecord:
    """Validate a simulated run (``trajectory``, None when the simulation gave none; transit
    time [s]) against the real runs behind ``reference`` and keep the curves the report plots.
    A run that cannot be compared (it misses the regions, say) gets no verdict and a message."""
    base = ValidationRecord(
        case=reference.case.label,
        after_iteration=after_iteration,
        params=dict(params or {}),
        status=status,
        message=message,
        transit_time=transit_time,
        run_file=run_file,
        verdict=None,
    )
    if trajectory is None:
        return base
    try:
        verdict = validate(trajectory, transit_time, reference)
        prepared = reference.comparison.prepare(trajectory)
        band = None
        if len(reference.xy_series) >= 2:
            real = [
                Trajectory(t=np.arange(len(xy), dtype=float), x=xy[:, 0], y=xy[:, 1], theta=th)
                for xy, th in zip(reference.xy_series, reference.theta_series, strict=True)
            ]
            b = envelope_band(prepared, real)
            band = BandRecord(
                grid=b.grid,
                y_low=b.y_low,
                y_high=b.y_high,
                theta_low=b.theta_low,
                theta_high=b.theta_high,
            )
    except ParcelfitError as exc:
        return base.model_copy(update={"message": f"validation not computable: {exc}"})
    return base.model_copy(
        update={
            "verdict": verdict,
            "sim_xy": _array(prepared.xy),
            "sim_theta": _array(prepared.theta),
            "band": band,
        }
    )


class DependenceCurve(ArrayRecord):
    """The GP's partial dependence of the cost on one parameter: ``values`` in catalogue units,
    the predicted ``cost`` averaged over the other parameters and its averaged predictive
    standard deviation ``sd``; ``transformed``: cost after the optimiser's output transform."""

    name: str
    values: FloatArray
    cost: FloatArray
    sd: FloatArray
    log: bool
    transformed: bool = False

    @property
    def amplitude(self) -> float:
        """How much the predicted cost changes across the parameter's range."""
        return float(np.max(self.cost) - np.min(self.cost))


class SurrogateRecord(ArrayRecord):
    """The optimiser's GP surrogate behind the partial dependence plot: the settings it was refitted
    with (the store's record; `OptimizerRecord.note` says when defaults stood in), how many
    finished fitting evaluations it learnt, and its partial dependence curves (None before two
    evaluations succeeded)."""

    optimizer: OptimizerRecord
    evaluations: int
    curves: tuple[DependenceCurve, ...] | None


class KeyFramesRecord(BaseModel):
    """The calibrated run drawn at a few instants: its test case, parameters (SI, fitted ones),
    the figure and animation written (paths relative to the study folder, None if not), and
    why there is no figure (``note``)."""

    model_config = ConfigDict(frozen=True)

    case: str
    params: Annotated[dict[str, float], BeforeValidator(lambda v: v or {})]
    image: str | None = None
    animation: str | None = None
    note: str | None = None

    def to_json(self) -> dict[str, Any]:
        """The stored form."""
        return self.model_dump()

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> KeyFramesRecord:
        """Read the stored form (missing or empty ``params``: none)."""
        return cls.model_validate({"params": None, **doc})


def _read_key_frames(v: Any) -> Any:
    """A stored key-frames record through `KeyFramesRecord.from_json` (missing params: none)."""
    return KeyFramesRecord.from_json(v) if isinstance(v, Mapping) else v


def _write_cases(cases: tuple[CaseRecord, ...]) -> list[dict[str, Any]]:
    """The cases as each was read or made (`CaseRecord.to_json`)."""
    return [c.to_json() for c in cases]


_none_empty = BeforeValidator(lambda v: v or ())  # a missing or null list: none


class ConvergenceRecord(ArrayRecord):
    """The convergence check (`parcelfit.study.finish`): the recommended parameters simulated
    on every validation and transfer case with every mesh spacing and the time step divided by
    ``refinement``, each run judged like a validation (``runs``); or why it did not run
    (``reason``: a simulator that cannot be refined, a check switched off)."""

    refinement: int
    runs: Annotated[tuple[ValidationRecord, ...], _none_empty] = ()
    reason: str | None = None


class StudyResults(ArrayRecord):
    """Everything ``results.json`` holds (see the module docstring): when and by which parcelfit
    version it was written (Unix time [s]), why the study stopped (None: written while it ran),
    the reference runs by role (``fit``, ``validation``), the validations in order, the
    surrogate, the key frames and the figures (paths relative to the study folder). Its stored
    form begins with the file's ``format`` and ``version``."""

    parcelfit: str
    written_at: float
    stop_reason: str | None = None
    references: dict[str, ReferenceRecord]
    validations: tuple[ValidationRecord, ...]
    surrogate: SurrogateRecord | None = None
    key_frames: Annotated[KeyFramesRecord | None, BeforeValidator(_read_key_frames)] = None
    figures: Annotated[tuple[str, ...], _none_empty] = ()
    identifiability: Identifiability | None = None
    transfer: Annotated[tuple[ValidationRecord, ...], _none_empty] = ()
    advice: Advice | None = None
    convergence: ConvergenceRecord | None = None
    # the study's test cases
    cases: Annotated[tuple[CaseRecord, ...], _none_empty, PlainSerializer(_write_cases)] = ()

    @model_serializer(mode="wrap")
    def _write_stored_form(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """The file's format and version, then the fields (``convergence`` only once the
        study stopped: files written before the check existed read back to the same bytes)."""
        fields = handler(self)
        if fields.get("convergence") is None:
            fields.pop("convergence", None)
        return {"format": FORMAT, "version": VERSION, **fields}

    def shown_validation(self) -> ValidationRecord | None:
        """The validation a report shows: the last that passed, else the last one (of a study
        with several validation cases: the first case's record of that iteration)."""
        shown = self.shown_validations()
        return shown[0] if shown else None

    def shown_validations(self) -> list[ValidationRecord]:
        """Every case's record of the validation a report shows: the last iteration whose
        validation passed on every case, else the last one."""
        by_iter: dict[int | None, list[ValidationRecord]] = {}
        for v in self.validations:
            by_iter.setdefault(v.after_iteration, []).append(v)
        groups = list(by_iter.values())
        passed = [g for g in groups if all(v.passed for v in g)]
        return passed[-1] if passed else (groups[-1] if groups else [])

    def reference(self, case: str) -> ReferenceRecord | None:
        """The stored reference record of a test case (by label), None if not stored."""
        return next((r for r in self.references.values() if r.case == case), None)


def new_results(
    references: Mapping[str, ReferenceRecord],
    validations: Sequence[ValidationRecord],
    *,
    stop_reason: str | None = None,
    surrogate: SurrogateRecord | None = None,
    key_frames: KeyFramesRecord | None = None,
    figures: Sequence[str] = (),
    identifiability: Identifiability | None = None,
    transfer: Sequence[ValidationRecord] = (),
    advice: Advice | None = None,
    convergence: ConvergenceRecord | None = None,
    cases: Sequence[CaseRecord | Mapping[str, Any]] = (),
) -> StudyResults:
    """Results stamped with this moment and this parcelfit version."""
    return StudyResults(
        written_at=time.time(),
        parcelfit=__version__,
        stop_reason=stop_reason,
        references=dict(references),
        validations=tuple(validations),
        surrogate=surrogate,
        key_frames=key_frames,
        figures=tuple(figures),
        identifiability=identifiability,
        transfer=tuple(transfer),
        advice=advice,
        convergence=convergence,
        cases=tuple(c if isinstance(c, CaseRecord) else CaseRecord.from_json(c) for c in cases),
    )


def write_json(path: Path, doc: Mapping[str, Any]) -> None:
    """Write a JSON document atomically (a temporary file renamed into place)."""
    write_text_atomic(path, json.dumps(doc))


def write_results(folder: str | Path, results: StudyResults) -> Path:
    """Write ``results.json`` into the study folder; returns its path."""
    path = Path(folder) / RESULTS_FILE
    write_json(path, results.to_json())
    return path


def read_results(folder: str | Path) -> StudyResults | None:
    """The study folder's results (None when it has none: a study stopped before writing them,
    or one made by a parcelfit before results were written)."""
    path = Path(folder) / RESULTS_FILE
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if doc.get("format") != FORMAT:
            raise ValueError("not a parcelfit results file")
        if int(doc.get("version", 0)) > VERSION:
            raise ParcelfitError(
                f"written by a newer parcelfit ({doc.get('parcelfit')}, results version "
                f"{doc.get('version')})",
                file=path,
                fix="read it with that version, or rerun `parcelfit calibrate` to rewrite it",
            )
        return StudyResults.from_json(doc)
    except ParcelfitError:
        raise
    except (OSError, ValueError, TypeError, KeyError, AttributeError) as exc:
        raise ParcelfitError(
            f"the study's results file is unreadable ({exc})",
            file=path,
            fix="rerun `parcelfit calibrate` on the study file: it rewrites the results "
            "without simulating again",
        ) from None


__all__ = [
    "FORMAT",
    "RESULTS_FILE",
    "VERSION",
    "BandRecord",
    "ConvergenceRecord",
    "DependenceCurve",
    "KeyFramesRecord",
    "ReferenceRecord",
    "StudyResults",
    "SurrogateRecord",
    "ValidationRecord",
    "new_results",
    "read_results",
    "validation_record",
    "write_json",
    "write_results",
]
