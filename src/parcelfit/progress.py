"""Progress of long jobs, one convention for all of them: a callback taking a `ProgressEvent`.

Calibration, screening, twin-data generation (synth), the report and the demo all accept
``progress: ProgressCallback | None`` and call it with one event per step (a finished
evaluation, run or report section, a stage starting). ``message`` is a complete line for a
person; ``done`` and ``total`` count the job's work items where it has them; a calibration also
fills the fields of its loop (``iteration``, ``running``, ``best_cost``, ``last_validation``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class ProgressEvent:
    """One step of a long job.

    ``job`` names it (calibration, screening, synth, report, demo); ``done`` of ``total`` work
    items are finished (evaluations against the budget for a calibration, simulations of the
    current stage for a screen, runs for synth, stages for the demo), None where not counted.
    Calibration only: ``iteration`` (0 = initial design, k >= 1 the k-th optimiser batch),
    ``running`` simulations, ``best_cost`` so far (dimensionless), ``last_validation`` verdict.
    """

    job: str
    message: str
    done: int | None = None
    total: int | None = None
    iteration: int | None = None
    running: int | None = None
    best_cost: float | None = None
    last_validation: bool | None = None


ProgressCallback = Callable[[ProgressEvent], None]


def ignore_progress(event: ProgressEvent) -> None:
    """A progress callback that does nothing (the default)."""


__all__ = ["ProgressCallback", "ProgressEvent", "ignore_progress"]
