"""A calibration from its study file to what it concluded: `calibrate_study` reads the file,
runs (or resumes) the study and returns a typed `CalibrationOutcome`; `study_summary` reads
what a study folder concludes (`StudySummary`: its status, the parameters to show and what the
data determine, in catalogue units, and the overall verdict). ``parcelfit calibrate``,
``status``, ``report`` and ``demo`` print these records and compute nothing of their own.

Iterations are numbered one way everywhere: 0 is the initial design, k >= 1 the k-th batch the
optimiser chose.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from pydantic import BaseModel, ConfigDict

from parcelfit.errors import ParcelfitError
from parcelfit.progress import ProgressCallback, ignore_progress
from parcelfit.sim.params import catalogue_unit, to_catalogue_units
from parcelfit.study.calibration import Calibration, CalibrationResult
from parcelfit.study.folderlock import check_writable
from parcelfit.study.results import read_results
from parcelfit.study.status import StudyStatus, folder_verdict, study_status
from parcelfit.study.store import STORE_FILE
from parcelfit.study.studyfile import Study, load_study, require_dataset
from parcelfit.study.verdict import Verdict


class _Record(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", arbitrary_types_allowed=True)


class ShownValue(_Record):
    """One parameter's value in its catalogue unit (`parcelfit.sim.params`)."""

    name: str
    value: float
    unit: str


class Determination(_Record):
    """What the data determine of one parameter (`parcelfit.study.identify`): its verdict
    (determined, undetermined, bounded, ...) and the interval of values that fit the data as
    well, ``low`` to ``high`` in its catalogue ``unit`` ("" for a dimensionless or SI one)."""

    name: str
    verdict: str
    determined: bool
    low: float
    high: float
    unit: str


class StudySummary(_Record):
    """What a study folder concludes, for a terminal: its `StudyStatus`, the recommended and
    the lowest-cost parameters in catalogue units (None when there are none), what the data
    determine (None while the study runs) and the overall verdict with its checks."""

    status: StudyStatus
    recommended: list[ShownValue] | None
    lowest_cost: list[ShownValue] | None
    determined: list[Determination] | None
    verdict: Verdict


class CalibrationOutcome(_Record):
    """How a calibration stopped: why (``stop_reason``), after how many fitting
    ``evaluations`` and iterations (``last_iteration``, None before any), its study
    ``folder``, the study ``figures`` written (each as PNG and SVG), where a restart moved the
    earlier outputs (``set_aside``, None without one) and what the folder concludes."""

    stop_reason: str
    evaluations: int
    last_iteration: int | None
    folder: Path
    figures: int
    set_aside: Path | None
    summary: StudySummary


@dataclass(frozen=True)
class CalibrationStart:
    """What a calibration says once its study file is read and its folder found writable, and
    before it opens the folder: its ``name``, study ``folder`` and the expected-cost line
    (None where the cost was said before, as the demo does)."""

    name: str
    folder: Path
    cost: str | None


def calibrate_study(
    study_file: Path,
    folder: Path,
    *,
    executor: str | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    animation: bool = False,
    restart: bool = False,
    started: Callable[[CalibrationStart], None] = lambda start: None,
    progress: ProgressCallback = ignore_progress,
) -> CalibrationOutcome:
    """Read ``study_file``, check that ``folder`` is writable, say ``started`` and run (or
    resume) its calibration in ``folder`` (`Calibration`), reporting to ``progress``; the
    outcome is read back from the folder (`calibration_outcome`)."""
    study = load_study(study_file)
    check_datasets(study)
    check_writable(folder, (STORE_FILE,))
    calibration = Calibration(
        study,
        folder,
        executor=executor,
        scheduler=scheduler,
        workers=workers,
        progress=progress,
        animation=animation,
        restart=restart,
    )
    started(CalibrationStart(study.name, folder, calibration.cost_line()))
    result = calibration.run()
    return calibration_outcome(result, calibration.set_aside)


def check_datasets(study: Study) -> None:
    """Refuse a study whose fitted, validation or transfer case names a dataset folder without
    a dataset.yaml, naming the study file and the case's key (a dataset not made yet, or a
    path written wrong), before anything starts."""
    for spec in (*study.cases, *study.validation_cases, *study.transfer):
        require_dataset(
            spec.dataset,
            spec.label,
            file=study.path,
            where=f"{spec.where}.dataset" if spec.where else "dataset",
            kind="study",
        )


def calibration_outcome(
    result: CalibrationResult, set_aside: Path | None = None
) -> CalibrationOutcome:
    """The outcome of a calibration that returned ``result`` (its folder read back)."""
    return CalibrationOutcome(
        stop_reason=result.stop_reason,
        evaluations=result.evaluations,
        last_iteration=result.last_iteration,
        folder=result.folder,
        figures=len(result.figures) // 2,
        set_aside=set_aside,
        summary=study_summary(result.folder),
    )


def study_summary(folder: Path) -> StudySummary:
    """What the study in ``folder`` concludes (running or finished; see `StudySummary`)."""
    status = study_status(folder)
    rec, low = status.recommended, status.lowest_cost
    return StudySummary(
        status=status,
        recommended=None if rec is None else _shown(rec.params),
        lowest_cost=None if low is None else _shown(low.params),
        determined=_determined(folder),
        verdict=folder_verdict(folder),
    )


def _shown(params: dict[str, float]) -> list[ShownValue]:
    return [
        ShownValue(name=n, value=float(to_catalogue_units(n, v)), unit=catalogue_unit(n))
        for n, v in params.items()
    ]


def _determined(folder: Path) -> list[Determination] | None:
    """Which parameters the data determine, from a finished study's results (None while it
    runs, or when its results cannot be read)."""
    try:
        results = read_results(folder)
    except ParcelfitError:
        return None
    ident = None if results is None else results.identifiability
    if ident is None:
        return None
    out = []
    for p in ident.parameters:
        lo, hi = (float(to_catalogue_units(p.name, v)) for v in p.interval)
        unit = catalogue_unit(p.name)
        out.append(
            Determination(
                name=p.name,
                verdict=p.verdict,
                determined=p.determined,
                low=lo,
                high=hi,
                unit="" if unit in ("-", "SI") else unit,
            )
        )
    return out


__all__ = [
    "CalibrationOutcome",
    "CalibrationStart",
    "Determination",
    "ShownValue",
    "StudySummary",
    "calibrate_study",
    "calibration_outcome",
    "study_summary",
]
