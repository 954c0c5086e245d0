"""How many simulations a calibration, screening or precision check runs, and for how long:
the estimate ``parcelfit calibrate``, ``screen``, ``precision`` and ``demo`` print before they
start (per-run times: `parcelfit.sim.cost`)."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

from parcelfit.runs import TestCase
from parcelfit.sim.cost import Estimate, estimate, refined_seconds, run_seconds
from parcelfit.study.joint import placement_seeds
from parcelfit.study.screening import Screen
from parcelfit.study.studyfile import Study


def _seconds(study_or_config: object, case: TestCase) -> float | None:
    config = getattr(study_or_config, "simulator", study_or_config)
    return run_seconds(config, case.rig, case.consignment)  # type: ignore[arg-type]


def validation_checks(study: Study) -> int:
    """The most validations a study runs: after every ``validate_every``-th optimiser
    iteration, and once more after the last when that was not one of them."""
    batches = max(0, math.ceil((study.budget - study.initial) / study.batch_size))
    checks = batches // study.validate_every
    return checks + (1 if batches == 0 or batches % study.validate_every else 0)


def _processes(
    executor: str | None,
    workers: int | None,
    section: Mapping[str, Any],
    single: tuple[str, ...] = ("serial",),
) -> tuple[str, int]:
    """The executor a job runs on and its parallel processes: the command line's ``executor``
    and ``workers`` first, then the file's ``executor`` ``section`` (local, one process per
    core, by default); one process for the kinds in ``single``."""
    kind = executor or section.get("kind", "local")
    n = 1 if kind in single else workers or section.get("workers") or os.cpu_count() or 1
    return kind, n


def calibration_estimate(study: Study, workers: int) -> Estimate:
    """At most ``budget`` evaluations (each simulating every fitted case at its placements),
    the validations, the transfer check, the convergence check (each validation and transfer
    case once on the refined model, `parcelfit.sim.cost.refined_seconds`; not with an external
    solver, which cannot be refined) and the key frames."""
    runs: list[tuple[int, float | None]] = []
    for spec in study.cases:
        runs.append((study.budget * len(placement_seeds(study, spec)), _seconds(study, spec.case)))
    checks = validation_checks(study)
    for spec in study.validation_specs():
        runs.append((checks, _seconds(study, spec.case)))
    for spec in study.transfer:
        runs.append((1, _seconds(study, spec.case)))
    refinable = study.simulator.backend != "external"  # a Python factory's may refine
    if study.refinement > 1 and refinable:  # the convergence check: each case judged, once
        for spec in study.judged_specs():
            seconds = refined_seconds(
                study.simulator, study.refinement, spec.case.rig, spec.case.consignment
            )
            runs.append((1, seconds))
    runs.append((1, _seconds(study, study.cases[0].case)))  # the key frames
    return estimate(runs, workers)


def calibration_cost_line(
    study: Study, executor: str | None, workers: int | None, resumed: bool
) -> str:
    """The line ``calibrate`` prints before it starts: the calibration's expected cost (at most
    its budget) on the ``executor`` and ``workers`` the command line (first) or the study file
    asks for (local, one process per core, by default); ``resumed`` says only what is left
    runs. A Dask cluster's workers are unknown here: its line is for one."""
    kind, n = _processes(executor, workers, study.executor, single=("serial", "dask"))
    return calibration_estimate(study, n).text(
        "at most: it stops when a validation passes"
        + ("; divide by the Dask cluster's worker processes" if kind == "dask" else "")
        + ("; a resumed study runs only what is left" if resumed else "")
    )


def screen_estimate(screen: Screen, workers: int) -> Estimate:
    """The first stage of a screening, each design row at the screen's placements (how many
    runs the later stages take depends on what the first finds)."""
    from parcelfit.doe.designs import fractional_factorial, full_factorial

    k = len(screen.parameters)
    kind = screen.stages[0] if screen.stages else "fractional"
    design = fractional_factorial(k, screen.resolution) if kind == "fractional" else None
    runs = len(design.matrix) if design is not None else len(full_factorial(k).matrix)
    rows = runs + screen.centre_points
    return estimate([(rows * screen.placements, _seconds(screen, screen.case))], workers)


def precision_estimate(
    study: Study, placements: int, candidates: Sequence[str], workers: int
) -> Estimate:
    """The precision check: every case (fitted, validation, transfer, candidates) at the point
    and at both ends of every parameter's range, ``placements`` runs each."""
    cases = [s.case for s in (*study.cases, *study.validation_cases, *study.transfer)]
    for label in candidates:
        case = TestCase.parse(label)
        if case not in cases:
            cases.append(case)
    variants = 1 + 2 * len(study.space.names)
    return estimate([(variants * placements, _seconds(study, c)) for c in cases], workers)


def screen_cost_line(screen: Screen, executor: str | None, workers: int | None) -> str:
    """The line ``screen`` prints before it starts: the first stage's expected cost on the
    ``executor`` and ``workers`` the command line (first) or the screen file asks for."""
    _, n = _processes(executor, workers, screen.executor)
    return screen_estimate(screen, n).text("the first stage; later stages follow from it")


def precision_cost_line(
    study: Study,
    placements: int,
    candidates: Sequence[str],
    executor: str | None,
    workers: int | None,
) -> str:
    """The line ``precision`` prints before it starts: the check's expected cost on the
    ``executor`` and ``workers`` the command line (first) or the study file asks for."""
    _, n = _processes(executor, workers, study.executor)
    return precision_estimate(study, placements, candidates, n).text(
        "runs kept from an earlier check are not simulated again"
    )


__all__ = [
    "calibration_cost_line",
    "calibration_estimate",
    "precision_cost_line",
    "precision_estimate",
    "screen_cost_line",
    "screen_estimate",
    "validation_checks",
]
