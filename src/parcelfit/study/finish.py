"""What a calibration concludes (method.md section 8): the validations, and when the study stops
the transfer check, the convergence check (the recommended parameters on a refined model), what
the evaluations determine, the advice on which test case to add, the
study figures and the key frames, written into ``results.json`` for the report
(`parcelfit.study.results`), which computes nothing of its own.

`Finish` works on an open study (its store, references and simulator, from
`parcelfit.study.calibration.Calibration.prepare`): `Finish.validate` simulates the recommended
parameters on every validation case after an iteration, and the validation passes when every
case passes; `Finish.conclude` does the rest once the loop stopped. What it simulated is kept
(validations in the store, the transfer check, the convergence check and the advice in the
store's meta, the key frames in ``results.json``) and reused while the parameters are the same, so a rerun of a finished
study simulates nothing again.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path

from parcelfit.errors import ParcelfitError
from parcelfit.metrics import ReferenceSelection
from parcelfit.runs import read_trajectory, write_trajectory
from parcelfit.sim.executors import Executor, Task
from parcelfit.sim.protocol import SimResult, Simulator
from parcelfit.study.identify import Advice, Identifiability, identify
from parcelfit.study.joint import THRESHOLD_LEVEL, advise, case_threshold, threshold
from parcelfit.study.objective import case_summary, study_cases
from parcelfit.study.results import (
    ConvergenceRecord,
    KeyFramesRecord,
    ReferenceRecord,
    StudyResults,
    SurrogateRecord,
    ValidationRecord,
    new_results,
    read_results,
    validation_record,
    write_results,
)
from parcelfit.study.store import Evaluation, Store
from parcelfit.study.studyfile import CaseSpec, Study

Report = Callable[[int, int, str], None]  # (iteration, running, message): a progress line


def _cost_se(row: Evaluation) -> float | None:
    """The standard error of a joint ensemble evaluation's cost (its cases' trajectory-term
    standard errors, weighted, in quadrature); None when a case states none."""
    parts = row.details.cases or []
    if not parts or any(p.se is None for p in parts):
        return None
    return math.sqrt(sum((p.weight * p.se) ** 2 for p in parts))  # type: ignore[operator]


class Finish:
    """The validations and conclusions of one open study (see the module doc).

    ``references``: every case's reference selection by label; ``report`` receives a progress
    line; ``executor`` returns the executor for the simulations after the loop (the transfer
    and convergence checks and the advice): the calibration's, which the calibration closes.
    With ``figures`` the study figures (`parcelfit.study.plots`) are drawn, with ``key_frames`` too
    the recommended run's key frames (MuJoCo: one more simulation; ``animation`` adds
    ``figures/run.gif``); ``advice`` enables the advice on which test case to add.
    ``last_validation`` is the verdict of the latest finished validation (None before any)."""

    def __init__(
        self,
        study: Study,
        folder: Path,
        store: Store,
        simulator: Simulator,
        references: Mapping[str, ReferenceSelection],
        report: Report,
        executor: Callable[[], Executor],
        *,
        figures: bool = True,
        key_frames: bool = True,
        animation: bool = False,
        advice: bool = True,
    ) -> None:
        self.study = study
        self.folder = folder
        self.store = store
        self.simulator = simulator
        self.references = references
        self.fit_case, self.val_case = study_cases(study)
        self._report = report
        self._executor = executor
        self.figures = figures
        self.key_frames = key_frames
        self.animation = animation
        self.advice = advice
        self.last_validation: bool | None = None
        self._validations: dict[int, ValidationRecord] = {}  # by store row id

    def _full_params(self, fitted: Mapping[str, float]) -> dict[str, float]:
        return {**self.study.fixed, **fitted}

    # -- validation --------------------------------------------------------------------------
    def validate(
        self, iteration: int, params: Mapping[str, float] | None, executor: Executor
    ) -> bool | None:
        """Validate the recommended ``params`` (SI; None before any) after ``iteration``: one
        stored validation row per validation case, simulated one after the other; True when
        every case passed (None without validation cases or parameters)."""
        cases = self.validation_cases()
        if params is None or not cases:
            return None
        ids = self.store.add_pending(
            "validation",
            iteration,
            [params] * len(cases),
            cases[0].case.speed_setting,
            [0] * len(cases),
        )
        passed = True
        for slot, row_id in enumerate(ids):
            passed = self.run_validation(row_id, iteration, params, executor, slot) and passed
        return passed

    def validation_cases(self) -> tuple[CaseSpec, ...]:
        """The validation cases (slot order of the validation rows of one iteration)."""
        return self.study.validation_specs()

    def run_validation(
        self,
        row_id: int,
        iteration: int,
        params: Mapping[str, float],
        executor: Executor,
        slot: int = 0,
    ) -> bool:
        """Simulate a stored (pending) validation row (the validation case of its slot) and
        record its verdict; True when it passed."""
        cases = self.validation_cases()
        spec = cases[slot]
        reference = self.references[spec.label]
        stem = f"validation-{iteration:03d}" + (f"-{slot}" if len(cases) > 1 else "")
        task = Task(self._full_params(params), spec.case, stem)
        ((_, result),) = list(executor.simulate(self.simulator, [task]))
        run_file = None
        if result.ok and result.run is not None:
            run_file = f"runs/{stem}.csv"
            write_trajectory(result.run.trajectory, self.folder / run_file)
        record = validation_record(
            reference,
            result.run.trajectory if run_file is not None and result.run is not None else None,
            None if result.run is None else result.run.transit_time,
            status=result.status.value,
            message=result.diagnostics.get("message"),
            params=params,
            after_iteration=iteration,
            run_file=run_file,
        )
        details = record.details(spec.label if len(cases) > 1 else None)
        self.store.finish(
            row_id,
            status=result.status.value,
            transit_time=record.transit_time,
            wall_time=result.wall_time,
            run_file=run_file,
            details=details,
        )
        self._validations[row_id] = record
        passed = record.passed
        last = slot == len(cases) - 1
        if last:
            self.write_results()
            group = [self._validations.get(r.id) for r in self.validation_rows(iteration)]
            passed = all(v is not None and v.passed for v in group)
            self.last_validation = passed
        where = f" on {spec.label}" if len(cases) > 1 else ""
        self._report(
            iteration,
            0,
            f"validation after iteration {iteration}{where}: "
            f"{'passed' if record.passed else 'failed'}",
        )
        return passed

    def validation_rows(self, iteration: int) -> list[Evaluation]:
        """The validation rows of one iteration, in slot order."""
        rows = [r for r in self.store.evaluations("validation") if r.iteration == iteration]
        return sorted(rows, key=lambda r: r.slot)

    # -- what the study concluded, for the report --------------------------------------------
    def _validation_records(self) -> list[ValidationRecord]:
        """Every finished validation's record: those run now as they were made, earlier ones
        (a resumed study) as the results file has them, else judged again from their stored run
        files (no simulation; a run file keeps every digit, so the record is the one the study
        made; run files written before that kept 9 significant digits)."""
        out = []
        rows = [r for r in self.store.evaluations("validation") if r.status != "pending"]
        earlier = None
        if any(r.id not in self._validations for r in rows):
            kept = self._earlier_results()
            earlier = (
                {} if kept is None else {(v.after_iteration, v.case): v for v in kept.validations}
            )
        cases = self.validation_cases()
        for row in rows:
            if row.slot >= len(cases):
                continue
            reference = self.references[cases[row.slot].label]
            known = None if earlier is None else earlier.get((row.iteration, reference.case.label))
            if (
                row.id not in self._validations
                and known is not None
                and (known.run_file, known.params) == (row.run_file, row.params)
            ):
                self._validations[row.id] = known
            if row.id not in self._validations:
                traj = None
                if row.run_file is not None and (self.folder / row.run_file).is_file():
                    traj = read_trajectory(self.folder / row.run_file)
                self._validations[row.id] = validation_record(
                    reference,
                    traj,
                    row.transit_time,
                    status=row.status,
                    message=row.details.message,
                    params=row.params,
                    after_iteration=row.iteration,
                    run_file=row.run_file,
                )
            out.append(self._validations[row.id])
        return out

    def surrogate(self) -> SurrogateRecord | None:
        """The GP surrogate of the finished fitting evaluations, refitted with the optimiser
        settings the store records, and its partial dependence curves (None without a study
        record)."""
        from parcelfit.study.plots import dependence_curves, surrogate_optimizer

        record = self.store.read_study()
        if record is None or not record.parameters:
            return None
        bo = surrogate_optimizer(record, self.store.evaluations("fit"))
        curves = dependence_curves(bo)
        return SurrogateRecord(
            optimizer=record.optimizer,
            evaluations=bo.n_told,
            curves=None if curves is None else tuple(curves),
        )

    def identifiability(self, epsilon: float | None = None) -> Identifiability | None:
        """What the finished fitting evaluations determine (`parcelfit.study.identify`), with
        the acceptance threshold from the fitted cases' real runs (`joint.threshold`), or
        ``epsilon`` [-] where given (a research check: scripts/threshold_check.py); None
        with fewer than three successful evaluations or real runs that do not differ."""
        study = self.study
        fits = [r for r in self.store.evaluations("fit") if r.status != "pending"]
        references = self.references
        try:
            if epsilon is not None:
                eps, source = epsilon, f"given: {epsilon:.4g}"
            elif study.cases:
                eps, source = threshold(references, study)
            else:  # a Study made in code without its cases
                eps = case_threshold(references[self.fit_case.label], study)
                source = f"{100 * THRESHOLD_LEVEL:g} % quantile of the real runs' costs: {eps:.3g}"
            initial = [r.cost for r in fits if r.iteration == 0 and r.status == "ok" and r.cost]
            typical = math.exp(sum(map(math.log, initial)) / len(initial)) if initial else None
            return identify(
                study.space,
                [r.params for r in fits],
                [r.cost if r.status == "ok" else None for r in fits],
                eps,
                threshold_source=source,
                typical_cost=typical,
                cost_sd=[_cost_se(r) for r in fits],
                seed=study.seed,
            )
        except ParcelfitError:
            return None

    def write_results(
        self,
        stop_reason: str | None = None,
        *,
        surrogate: SurrogateRecord | None = None,
        key_frames: KeyFramesRecord | None = None,
        figures: tuple[Path, ...] = (),
        identifiability: Identifiability | None = None,
        transfer: tuple[ValidationRecord, ...] = (),
        advice: Advice | None = None,
        convergence: ConvergenceRecord | None = None,
    ) -> Path:
        """Write ``results.json``: the references, every validation, the surrogate (refitted
        here unless given), the key frames and figures, and what the study concluded when it
        stopped (identifiability, transfer check, advice, convergence check); returns its
        path."""
        references = {"fit": ReferenceRecord.from_selection(self.references[self.fit_case.label])}
        if self.val_case is not None:
            references["validation"] = ReferenceRecord.from_selection(
                self.references[self.val_case.label]
            )
        known = {r.case for r in references.values()}
        for label, sel in self.references.items():  # the other cases of a joint study
            if label not in known:
                references[f"case {label}"] = ReferenceRecord.from_selection(sel)
        return write_results(
            self.folder,
            new_results(
                references,
                self._validation_records(),
                stop_reason=stop_reason,
                surrogate=surrogate or self.surrogate(),
                key_frames=key_frames,
                figures=[p.relative_to(self.folder).as_posix() for p in figures],
                identifiability=identifiability,
                transfer=transfer,
                advice=advice,
                convergence=convergence,
                cases=case_summary(self.study, self.references) if self.study.cases else (),
            ),
        )

    def conclude(
        self,
        best_params: Mapping[str, float] | None,
        last_iteration: int | None,
        stop_reason: str,
    ) -> tuple[Path, ...]:
        """The results, study figures and key frames of a study stopped after
        ``last_iteration`` for ``stop_reason`` with the recommended ``best_params`` (SI), what
        its evaluations determine, the transfer and convergence checks and the advice; returns the figures
        written."""
        last = -1 if last_iteration is None else last_iteration
        surrogate = self.surrogate()
        self._report(last, 0, "what the data determine (the values the surrogate cannot exclude)")
        ident = self.identifiability()
        transfer: tuple[ValidationRecord, ...] = ()
        advice = None
        convergence = None
        if best_params is not None:
            transfer = self._transfer(best_params, last)
            convergence = self._convergence(best_params, last)
            advice = self._advice(best_params, ident, last)
        figures: list[Path] = []
        key_frames = None
        if self.figures:
            from parcelfit.study.plots import pairwise_figure, study_figures

            self._report(last, 0, "writing the study figures")
            curves = None if surrogate is None or surrogate.curves is None else surrogate.curves
            figures += study_figures(self.folder, None if curves is None else list(curves))
            if ident is not None:
                from parcelfit.figures import save_figure

                figures += save_figure(pairwise_figure(ident), self.folder / "figures" / "pairwise")
            if self.key_frames and best_params is not None:
                key_frames, drawn = self._key_frames(best_params, last)
                figures += drawn
        self.write_results(
            stop_reason,
            surrogate=surrogate,
            key_frames=key_frames,
            figures=tuple(figures),
            identifiability=ident,
            transfer=transfer,
            advice=advice,
            convergence=convergence,
        )
        return tuple(figures)

    def _simulate_tasks(
        self, tasks: list[Task], simulator: Simulator | None = None
    ) -> list[SimResult]:
        """Simulate tasks with the study's executor (on ``simulator``, default the study's);
        results in task order. The executor is the calibration's, which closes it."""
        out: dict[int, SimResult] = {}
        for i, r in self._executor().simulate(simulator or self.simulator, tasks):
            out[i] = r
        return [out[i] for i in range(len(tasks))]

    def _judged_runs(
        self,
        specs: list[CaseSpec],
        run_ids: list[str],
        params: Mapping[str, float],
        simulator: Simulator | None = None,
    ) -> list[ValidationRecord]:
        """``params`` (SI) simulated on each case of ``specs`` (by ``simulator``, default the
        study's; run files ``runs/RUN_ID.csv``) and judged like a validation, in case order."""
        tasks = [
            Task(self._full_params(params), s.case, rid)
            for s, rid in zip(specs, run_ids, strict=True)
        ]
        out = []
        for spec, task, result in zip(
            specs, tasks, self._simulate_tasks(tasks, simulator), strict=True
        ):
            run_file = None
            if result.ok and result.run is not None:
                run_file = f"runs/{task.run_id}.csv"
                write_trajectory(result.run.trajectory, self.folder / run_file)
            out.append(
                validation_record(
                    self.references[spec.label],
                    None if run_file is None or result.run is None else result.run.trajectory,
                    None if result.run is None else result.run.transit_time,
                    status=result.status.value,
                    message=result.diagnostics.get("message"),
                    params=params,
                    run_file=run_file,
                )
            )
        return out

    def _transfer(
        self, params: Mapping[str, float], iteration: int
    ) -> tuple[ValidationRecord, ...]:
        """The transfer check: the recommended parameters simulated on every transfer case and
        judged like a validation; an earlier result for the same parameters is kept (the run
        files stay in ``runs/``)."""
        specs = self.study.transfer
        if not specs:
            return ()
        stored = self.store.get_meta("transfer") or []  # kept in the store: a rerun without
        kept = {
            v.case: v for v in map(ValidationRecord.from_json, stored)
        }  # results simulates none
        todo = [s for s in specs if not (s.label in kept and kept[s.label].params == dict(params))]
        fresh: dict[str, ValidationRecord] = {}
        if todo:
            self._report(
                iteration,
                len(todo),
                f"transfer check on {len(todo)} test case{'s' if len(todo) != 1 else ''}",
            )
            ids = [f"transfer-{s.case.rig}-{s.case.speed_setting}" for s in todo]
            for spec, record in zip(todo, self._judged_runs(todo, ids, params), strict=True):
                fresh[spec.label] = record
        out = tuple(fresh.get(s.label) or kept[s.label] for s in specs)
        if fresh:
            self.store.set_meta("transfer", [v.to_json() for v in out])
        return out

    def _convergence(self, params: Mapping[str, float], iteration: int) -> ConvergenceRecord:
        """The convergence check: the recommended parameters simulated on every validation and
        transfer case by the study's simulator refined ``study.refinement`` times over (every
        mesh spacing and the time step divided by it, ``with_refinement``), each judged like a
        validation; the verdict compares their outcomes with the model's own
        (`parcelfit.study.verdict.convergence_check`). Not run with refinement 1 or a simulator
        that cannot be refined (the record says why). An earlier result for the same parameters
        and refinement is kept (the run files stay in ``runs/``) when every run of it finished;
        a rerun simulates a check with a failed or timed-out run again."""
        factor = self.study.refinement
        if factor <= 1:
            return ConvergenceRecord(
                refinement=factor, reason="switched off (validation.refinement: 1)"
            )
        refine = getattr(self.simulator, "with_refinement", None)
        if not callable(refine):
            return ConvergenceRecord(
                refinement=factor,
                reason=f"the {type(self.simulator).__name__} simulator cannot be refined "
                "(it has no with_refinement): check its convergence by hand",
            )
        specs = list(self.study.judged_specs())
        if not specs:
            return ConvergenceRecord(refinement=factor, reason="no validation or transfer cases")
        stored = self.store.get_meta("convergence")  # kept: a rerun simulates none again
        if stored is not None:
            kept = ConvergenceRecord.from_json(stored)
            labels = [v.case for v in kept.runs]
            if (
                kept.refinement == factor
                and labels == [s.label for s in specs]
                and all(v.params == dict(params) for v in kept.runs)
                and all(v.status == "ok" for v in kept.runs)  # a rerun retries the others
            ):
                return kept
        self._report(
            iteration,
            len(specs),
            f"convergence check: {len(specs)} test cases, every mesh spacing and the time step "
            f"divided by {factor}",
        )
        try:
            refined = refine(factor)
        except ParcelfitError as exc:  # a refined setting out of its range
            return ConvergenceRecord(
                refinement=factor, reason=f"the model cannot be refined {factor} times: {exc}"
            )
        ids = [f"refined-{s.case.rig}-{s.case.consignment}-{s.case.speed_setting}" for s in specs]
        runs = self._judged_runs(specs, ids, params, refined)
        record = ConvergenceRecord(refinement=factor, runs=tuple(runs))
        self.store.set_meta("convergence", record.to_json())
        return record

    def _advice(
        self, params: Mapping[str, float], ident: Identifiability | None, iteration: int
    ) -> Advice | None:
        """Which candidate case (validation and transfer cases) would help most to determine
        the parameters the data leave open (`joint.advise`); None when every parameter is
        determined, there are fewer than two candidates to choose from, or it is disabled. An
        earlier advice for the same parameters and intervals (kept in the store) is reused."""
        if ident is None or not self.advice:
            return None
        open_ = {p.name: p.interval for p in ident.parameters if not p.determined}
        candidates = [*self.validation_cases(), *self.study.transfer]
        if not open_ or len(candidates) < 2:  # a choice needs two candidates
            return None
        stored = self.store.get_meta("advice")  # kept in the store, with the intervals it used
        if stored is not None:
            kept = Advice.from_json(stored["advice"])
            same = {k: tuple(v) for k, v in stored["intervals"].items()} == {
                k: tuple(v) for k, v in open_.items()
            }
            if same and kept.params == {k: float(v) for k, v in params.items()}:
                return kept
        n = 2 * len(open_) * len(candidates)
        self._report(iteration, n, f"which test case would help most: {n} simulations")
        advice = advise(
            self._full_params(params),
            open_,
            candidates,
            self.references,
            self._simulate_tasks,
            self.study.w_xy,
            self.study.w_theta,
        )
        advice = advice.model_copy(update={"params": {k: float(v) for k, v in params.items()}})
        self.store.set_meta(
            "advice",
            {"advice": advice.to_json(), "intervals": {k: list(v) for k, v in open_.items()}},
        )
        return advice

    def _key_frames(
        self, params: Mapping[str, float], iteration: int
    ) -> tuple[KeyFramesRecord, list[Path]]:
        """Draw the recommended run's key frames (MuJoCo only: one more simulation, at the
        validation case if there is one) into ``figures/``; reused while the same."""
        from parcelfit.figures import save_figure
        from parcelfit.sim.mujoco import MujocoSimulator

        case = self.val_case or self.fit_case
        record = KeyFramesRecord(case=case.label, params=dict(params))
        if not isinstance(self.simulator, MujocoSimulator):
            return record.model_copy(
                update={"note": "Key frames are drawn for the MuJoCo backend only."}
            ), []
        stem = self.folder / "figures" / "key-frames"
        gif = self.folder / "figures" / "run.gif"
        earlier = self._earlier_results()
        kept = None if earlier is None else earlier.key_frames
        if (
            kept is not None
            and kept.image is not None
            and (kept.case, kept.params) == (record.case, record.params)
            and stem.with_suffix(".png").is_file()
            and (not self.animation or (kept.animation is not None and gif.is_file()))
        ):
            return kept, [stem.with_suffix(".png"), stem.with_suffix(".svg")]
        self._report(iteration, 1, "drawing the key frames of the calibrated run")
        from parcelfit.sim.mujoco.render import render_key_frames

        try:
            drawn = render_key_frames(
                self.simulator,
                self._full_params(params),
                case,
                animation=gif if self.animation else None,
            )
        except Exception as exc:  # a figure must not cost the study its results
            return record.model_copy(update={"note": f"The key-frame run failed: {exc}"}), []
        if drawn.figure is None:
            return record.model_copy(
                update={"note": f"The key-frame run ended {drawn.status}."}
            ), []
        paths = save_figure(drawn.figure, stem)
        image = paths[0].relative_to(self.folder).as_posix()
        animation = (
            None if drawn.animation is None else drawn.animation.relative_to(self.folder).as_posix()
        )
        return record.model_copy(update={"image": image, "animation": animation}), paths

    def _earlier_results(self) -> StudyResults | None:
        """The results an earlier run of this folder wrote (None if none or unreadable)."""
        try:
            return read_results(self.folder)
        except ParcelfitError:
            return None
