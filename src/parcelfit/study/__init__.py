"""Studies: what is calibrated or screened against which data, and what came of it.

The layer above the optimisers (`parcelfit.optimize`: parameters and costs only) and the
simulators (`parcelfit.sim`): the study and screen files (`studyfile`, `screening`), the
evaluation store (`store`) and its folder lock (`folderlock`), the calibration loop
(`calibration`), a study folder's state (`status`: ``study_status``), what a study concluded
(`results`: ``results.json``), its one overall verdict (`verdict`) and the study figures
(`plots`). Constructing a `Calibration` reads and writes nothing; `run` (through
`Calibration.prepare`) opens the folder, the data and the simulator.

The names below are importable from here; each module is loaded when one of its names is first
used, so ``import parcelfit.study`` stays cheap.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_EXPORTS = {
    "Calibration": "calibration",
    "CalibrationResult": "calibration",
    "StudyStatus": "status",
    "study_status": "status",
    "folder_verdict": "status",
    "Verdict": "verdict",
    "study_verdict": "verdict",
    "Study": "studyfile",
    "load_study": "studyfile",
    "Screen": "screening",
    "StageResult": "screening",
    "load_screen": "screening",
    "run_screen": "screening",
    "STORE_FILE": "store",
    "Evaluation": "store",
    "Store": "store",
    "StudyRecord": "store",
    "StudyResults": "results",
    "read_results": "results",
}

__all__ = [
    "STORE_FILE",
    "Calibration",
    "CalibrationResult",
    "Evaluation",
    "Screen",
    "StageResult",
    "Store",
    "Study",
    "StudyRecord",
    "StudyResults",
    "StudyStatus",
    "Verdict",
    "folder_verdict",
    "load_screen",
    "load_study",
    "read_results",
    "run_screen",
    "study_status",
    "study_verdict",
]  # the keys of _EXPORTS

if TYPE_CHECKING:
    from parcelfit.study.calibration import Calibration, CalibrationResult
    from parcelfit.study.results import StudyResults, read_results
    from parcelfit.study.screening import Screen, StageResult, load_screen, run_screen
    from parcelfit.study.status import StudyStatus, folder_verdict, study_status
    from parcelfit.study.store import STORE_FILE, Evaluation, Store, StudyRecord
    from parcelfit.study.studyfile import Study, load_study
    from parcelfit.study.verdict import Verdict, study_verdict


def __getattr__(name: str) -> Any:
    """A name of `__all__`, from the module that defines it (imported on first use)."""
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
