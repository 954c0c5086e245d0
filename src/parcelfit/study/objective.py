"""The objective of a calibration: the evaluation of one parameter set (method.md section 7),
simulated, costed and recorded in the store.

`Objective.evaluate` simulates stored (pending) fitting evaluations through an executor and
stores each the moment it is complete: a one-case study's evaluation is one simulation costed
against its reference run (`record_result`); a joint or ensemble study's evaluation simulates
every fitted case (and placement) in one batch and is one store row with the per-case parts in
its details (`parcelfit.study.joint`). It yields each stored evaluation; what to tell the
optimiser, what to show and when to stop is the loop's (`parcelfit.study.loop`).

The reference runs each case's cost compares against are selected here too
(`select_references`), and described for the store and the results (`case_summary`).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from parcelfit.errors import ParcelfitError
from parcelfit.metrics import ReferenceSelection, calibration_cost, select_reference
from parcelfit.metrics.reference import adjusted_reference
from parcelfit.runs import TestCase, load_dataset, write_trajectory
from parcelfit.sim.executors import Executor, Task
from parcelfit.sim.protocol import SimResult, Simulator
from parcelfit.study.details import EvaluationDetails
from parcelfit.study.joint import (
    CaseRun,
    case_threshold,
    evaluation_outcome,
    placement_seeds,
    simulate_items,
    simulations_per_evaluation,
)
from parcelfit.study.store import CaseRecord, Evaluation, Store
from parcelfit.study.studyfile import CaseSpec, Study


def record_result(
    store: Store,
    folder: Path,
    row: Evaluation,
    result: SimResult,
    reference: ReferenceSelection,
    w_xy: float = 1.0,
    w_theta: float = 1.0,
    *,
    run_file: str | None = None,
) -> dict[str, Any]:
    """Write a simulated run next to the store, compute its cost parts, and store the result;
    returns the stored fields (status, cost [-], DTW distances [m], [rad], transit time [s],
    run file) and ``message``, why it failed (None if it did not say). ``run_file``: where the
    run goes, relative to ``folder`` (default ``runs/KIND-ITERATION-SLOT.csv``)."""
    status = result.status.value
    out: dict[str, Any] = {
        "status": status,
        "cost": None,
        "dtw_xy": None,
        "dtw_theta": None,
        "transit_time": None,
        "run_file": None,
    }
    details = EvaluationDetails.from_json(
        {k: v for k, v in result.diagnostics.items() if k != "traceback"}
    )
    if result.run is not None:
        out["run_file"] = run_file or f"runs/{row.kind}-{row.iteration:03d}-{row.slot:02d}.csv"
        write_trajectory(result.run.trajectory, folder / out["run_file"])
        out["transit_time"] = result.run.transit_time
    if result.ok and result.run is not None:
        try:
            c = calibration_cost(result.run.trajectory, reference, w_xy, w_theta)
            out.update(cost=c.value, dtw_xy=c.dtw_xy, dtw_theta=c.dtw_theta)
        except ParcelfitError as exc:
            out["status"] = "failed"
            details = details.with_message(f"cost not computable: {exc}")
    store.finish(row.id, wall_time=result.wall_time, details=details, **out)
    return {**out, "message": details.message}


def study_cases(study: Study) -> tuple[TestCase, TestCase | None]:
    """The study's fitting test case and its validation test case (None without validation)."""
    fit = TestCase(study.rig, study.consignment, study.fit_setting)
    val = (
        None
        if study.validation_setting is None
        else TestCase(study.rig, study.consignment, study.validation_setting)
    )
    return fit, val


def select_references(study: Study) -> dict[str, ReferenceSelection]:
    """The reference selection of every case of the study (fitted, validation, transfer), by
    label; each dataset is read once. A fitted case of a study with adjusted transit times
    compares against its adjusted reference."""
    fit_case, val_case = study_cases(study)
    datasets: dict[Path, Any] = {}
    out = {}
    specs = study.cases or (CaseSpec(fit_case, study.dataset),)
    if not study.validation_cases and val_case is not None:
        specs = (*specs, CaseSpec(val_case, study.dataset))
    for spec in (*specs, *study.validation_cases, *study.transfer):
        if spec.dataset not in datasets:
            datasets[spec.dataset] = load_dataset(spec.dataset)
        if spec.label not in out:
            try:
                data = datasets[spec.dataset][spec.case]
            except (KeyError, ParcelfitError):
                named = study.path is not None and spec.where
                raise ParcelfitError(
                    f"the dataset has no runs of test case {spec.label}"
                    + (f" (dataset {spec.dataset})" if named else ""),
                    file=study.path if named else spec.dataset,
                    where=spec.where if named else None,
                    fix="name a test case the dataset holds (parcelfit stats lists them)",
                ) from None
            out[spec.label] = select_reference(data)
            if study.transit_adjusted and any(spec.case == c.case for c in study.cases):
                # a fitted case: the ensemble cost compares its adjusted transit times
                out[spec.label] = adjusted_reference(out[spec.label], data.runs)
    return out


def case_summary(study: Study, references: Mapping[str, ReferenceSelection]) -> list[CaseRecord]:
    """The study's cases for the store and results: label, role, weight, dataset, reference
    run and the acceptance threshold of the fitted ones."""
    out = []
    for role, specs in (
        ("fit", study.cases),
        ("validation", study.validation_cases),
        ("transfer", study.transfer),
    ):
        for spec in specs:
            ref = references[spec.label]
            out.append(
                CaseRecord(
                    case=spec.label,
                    role=role,
                    weight=spec.weight,
                    dataset=str(spec.dataset),
                    reference_run=ref.reference_id,
                    threshold=case_threshold(ref, study, spec) if role == "fit" else None,
                    transit=None
                    if ref.transit_adjustment is None
                    else ref.transit_adjustment.describe(),
                )
            )
    return out


@dataclass(frozen=True)
class Evaluated:
    """One fitting evaluation as stored: its row, status, cost [-] as stored (the optimiser is
    told it only when the status is ok), why it failed (None if it did not say) and what it
    was, for a progress line."""

    row: Evaluation
    status: str
    cost: float | None
    message: str | None
    label: str


@dataclass(frozen=True)
class Objective:
    """The evaluation of a study's parameter sets against its reference runs (see the module
    doc): ``references`` by case label, runs written under ``folder``, results into
    ``store``."""

    study: Study
    folder: Path
    store: Store
    simulator: Simulator
    references: Mapping[str, ReferenceSelection]

    def full_params(self, fitted: Mapping[str, float]) -> dict[str, float]:
        """The study's fixed parameters with ``fitted`` (SI) over them."""
        return {**self.study.fixed, **fitted}

    def evaluate(self, rows: list[Evaluation], executor: Executor) -> Iterator[Evaluated]:
        """Simulate the stored fitting evaluations ``rows`` and store each; yield each the
        moment it is stored (in arrival order)."""
        if self.study.joint:
            yield from self._evaluate_joint(rows, executor)
            return
        fit_case, _ = study_cases(self.study)
        reference = self.references[fit_case.label]
        tasks = [
            Task(self.full_params(r.params), fit_case, f"fit-{r.iteration:03d}-{r.slot:02d}")
            for r in rows
        ]
        for i, result in executor.simulate(self.simulator, tasks):
            out = record_result(
                self.store,
                self.folder,
                rows[i],
                result,
                reference,
                self.study.w_xy,
                self.study.w_theta,
            )
            yield Evaluated(rows[i], out["status"], out["cost"], out["message"], tasks[i].run_id)

    def _evaluate_joint(self, rows: list[Evaluation], executor: Executor) -> Iterator[Evaluated]:
        """Evaluate rows of a joint or ensemble study: every case (and placement) of every row
        in one batch; each row is stored the moment its last simulation arrives."""
        study = self.study
        items: list[tuple[Task, int | None]] = []
        owner: list[tuple[int, CaseSpec, int | None]] = []
        for i, r in enumerate(rows):
            for k, spec in enumerate(study.cases):
                for seed in placement_seeds(study, spec):
                    stem = f"fit-{r.iteration:03d}-{r.slot:02d}-c{k}"
                    run_id = stem if seed is None else f"{stem}-p{seed}"
                    items.append((Task(self.full_params(r.params), spec.case, run_id), seed))
                    owner.append((i, spec, seed))
        per_row = simulations_per_evaluation(study)
        arrived: dict[int, list[tuple[int, CaseRun]]] = {}
        for j, result in simulate_items(executor, self.simulator, items):
            i, spec, seed = owner[j]
            run_file = None
            if result.run is not None:
                run_file = f"runs/{items[j][0].run_id}.csv"
                write_trajectory(result.run.trajectory, self.folder / run_file)
            arrived.setdefault(i, []).append((j, CaseRun(spec, seed, result, run_file)))
            if len(arrived[i]) < per_row:
                continue
            runs = [run for _, run in sorted(arrived.pop(i), key=lambda t: t[0])]
            out = evaluation_outcome(runs, self.references, study)
            row = rows[i]
            self.store.finish(row.id, **out)
            yield Evaluated(
                row,
                out["status"],
                out["cost"],
                out["details"].message,
                f"fit-{row.iteration:03d}-{row.slot:02d} ({per_row} simulations)",
            )
