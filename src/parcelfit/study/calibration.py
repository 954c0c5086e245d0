"""The calibration loop (method.md sections 7 and 8): reference runs, initial design, batch BO
iterations, validation every N iterations, stop when the validation passes or the budget is
spent. Every evaluation goes through the `Store` before the loop moves on; restarting the same
study folder replays the store (finished evaluations are never simulated again, pending ones
are run) and continues exactly where it stopped.

A study with several fitted test cases, or with the ensemble cost, evaluates one parameter set
by simulating every case (and placement) in one batch through the executor; the evaluation is
one store row with the per-case parts in its details (`parcelfit.study.joint`). Its validation
cases are simulated one after the other, and the validation passes when every case passes.

Failed, unstable and timed-out simulations, and runs whose trajectory misses the regions of
interest, are stored with their status and told to the optimiser as failures (it penalises them
with the worst cost seen) and count against the budget. One failure never stops the loop, but
`FAILURES_IN_A_ROW` fitting evaluations failing one after the other do (`FailureStreak`): a
study whose every simulation fails (a broken simulator or solver set-up, parameter ranges
where nothing runs) stops with a `ParcelfitError` quoting the first failure, instead of
spending its budget. A rerun of a study that has no successful evaluation yet runs its failed
ones again (the cause may have been fixed); otherwise it continues, the optimiser knowing the
failures.

Iterations are numbered one way in the store, the progress, `study_status` and the report:
0 is the initial design, k >= 1 the k-th batch the optimiser chose; the validation "after
iteration k" simulates the recommended parameters once iteration k has finished.

What the study concluded is written for the report, which computes nothing of its own:
``results.json`` (`parcelfit.study.results`: the reference runs used, every validation with
its verdict and curves, the GP surrogate's partial dependence refitted with the optimiser
settings the store records, the key frames) after every validation and when the study stops,
with the study figures in ``figures/``.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import Any

from filelock import FileLock

from parcelfit.errors import ParcelfitError, os_error
from parcelfit.metrics import ReferenceSelection, calibration_cost, select_reference
from parcelfit.metrics.reference import adjusted_reference
from parcelfit.optimize.sampler import Sampler, make_sampler
from parcelfit.progress import ProgressCallback, ProgressEvent, ignore_progress
from parcelfit.runs import (
    TestCase,
    load_dataset,
    read_trajectory,
    write_trajectory,
)
from parcelfit.sim.executors import Executor, Task, make_executor
from parcelfit.sim.factory import make_simulator
from parcelfit.sim.protocol import SimResult, Simulator
from parcelfit.study.folderlock import check_writable, lock_folder
from parcelfit.study.identify import Advice, Identifiability, identify
from parcelfit.study.joint import (
    CaseRun,
    advise,
    case_threshold,
    check_placements,
    evaluation_outcome,
    placement_seeds,
    simulate_items,
    simulations_per_evaluation,
    threshold,
)
from parcelfit.study.results import (
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
from parcelfit.study.store import (
    STORE_FILE,
    Evaluation,
    OptimizerRecord,
    RecommendedRecord,
    SourceRecord,
    Store,
    StudyRecord,
)
from parcelfit.study.studyfile import CaseSpec, Study

FAILURES_IN_A_ROW = 8  # evaluations failing one after the other that stop a study or a screen
LOST_WORKER_MESSAGES = (
    "worker failed: BrokenProcessPool",
    "dask task failed: FutureCancelledError",
    "dask task failed: CancelledError",
)


@dataclass(frozen=True)
class CalibrationResult:
    """Outcome of a study: the recommended parameters (SI) and their cost, the number of fitting
    evaluations, the last iteration (0 = the initial design, k >= 1 the k-th optimiser batch;
    None before any), the validation verdict, why it stopped, the study figures written (PNG
    and SVG in ``folder/figures``, with the key frames of MuJoCo studies)."""

    best_params: dict[str, float] | None
    best_cost: float | None
    evaluations: int
    last_iteration: int | None
    validated: bool | None
    stop_reason: str
    folder: Path
    figures: tuple[Path, ...] = ()


STUDY_OUTPUTS = ("runs", "results.json", "figures", "report.html")  # beside the store


def _outputs(folder: Path) -> list[str]:
    """The outputs of a study that ``folder`` holds (a folder counts when not empty)."""
    return [
        name
        for name in STUDY_OUTPUTS
        if (folder / name).is_file()
        or ((folder / name).is_dir() and any((folder / name).iterdir()))
    ]


def refuse_orphaned_outputs(folder: Path) -> None:
    """Refuse to start a new study in a folder that holds an earlier study's outputs (run
    files, results, figures) without its store (``study.sqlite`` deleted or moved): the new
    study would overwrite them."""
    if (folder / STORE_FILE).exists():
        return
    found = _outputs(folder)
    if found:
        names = ", ".join(f"{n}/" if (folder / n).is_dir() else n for n in found)
        raise ParcelfitError(
            f"this folder holds an earlier study's outputs ({names}) but no {STORE_FILE}, so a "
            "new study would overwrite them",
            file=folder,
            fix=f"restore {STORE_FILE} to resume that study, use a new output folder, or "
            "rerun with --restart to move them into earlier-TIME/ in the folder and start afresh",
        )


def set_aside_outputs(folder: Path) -> Path | None:
    """Move a study's store and outputs out of the way, into ``folder/earlier-YYYYmmdd-HHMMSS``
    (the UTC time; a new name if taken), so that a new study starts afresh; returns that
    folder (None when there was nothing to move). Call with the folder locked."""
    names = [
        n for n in (STORE_FILE, f"{STORE_FILE}-wal", f"{STORE_FILE}-shm") if (folder / n).exists()
    ] + _outputs(folder)
    if not names:
        return None
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    target = folder / f"earlier-{stamp}"
    k = 1
    while target.exists():
        k += 1
        target = folder / f"earlier-{stamp}-{k}"
    target.mkdir()
    for name in names:  # the store's WAL files with it: they hold its latest transactions
        os.replace(folder / name, target / name)
    return target


class FailureStreak:
    """Counts simulations (or evaluations) that failed one after the other, in the order they
    arrive, and stops the run when ``limit`` of them did.

    Why 8: a batch is 4 by default, so 8 is two whole batches, or the whole initial design of
    the default study, without a single success; a fixed set-up problem (a simulator that
    raises, a solver that is missing) fails every simulation in about the same time as one, so
    stopping there costs minutes, while a study whose optimiser merely strays into a region
    where the physics breaks down has successes between its failures. ``what`` names the counted
    things in the message, ``where`` is the folder the message names. With ``until_success``
    only a streak before the first success counts (a screening design, whose failures after a
    success are a property of its fixed design, not of the set-up)."""

    def __init__(
        self, limit: int, where: Path, what: str = "simulations", *, until_success: bool = False
    ) -> None:
        self.limit = max(1, limit)
        self.where = where
        self.what = what
        self.until_success = until_success
        self.succeeded = False
        self.ids: list[int] = []  # store rows of the current streak, in arrival order
        self.first: str | None = None  # the first failure's message, one line

    def add(self, row_id: int, status: str, message: str | None) -> None:
        """Count one finished evaluation (store row ``row_id``): ``status`` ok ends a streak;
        any other status extends it, and reaching the limit raises the `ParcelfitError` that
        stops the run, quoting the streak's first failure."""
        if status == "ok":
            self.ids, self.first, self.succeeded = [], None, True
            return
        if self.until_success and self.succeeded:
            return
        if not self.ids:
            text = " ".join(str(message or "").split()) or "no message"
            self.first = f"{status}: {text if len(text) <= 300 else text[:297] + '...'}"
        self.ids.append(row_id)
        if len(self.ids) >= self.limit:
            raise ParcelfitError(
                f"{len(self.ids)} {self.what} in a row failed, so the run stopped early; "
                f"the first: {self.first}",
                file=self.where,
                fix="fix the cause the first failure names, then rerun the same command to "
                "resume (what failed is run again while nothing has succeeded yet)",
            )


def study_record(study: Study, sampler: Sampler) -> StudyRecord:
    """The store's record of ``study`` with the optimiser ``sampler`` as it runs (bounds SI)."""
    settings = getattr(sampler, "settings", None)
    return StudyRecord(
        name=study.name,
        parameters=tuple(study.space.names),
        bounds=tuple((d.low, d.high) for d in study.space.dims),
        log=tuple(d.log for d in study.space.dims),
        batch_size=study.batch_size,
        seed=study.seed,
        fit_setting=study.fit_setting,
        validation_setting=study.validation_setting,
        optimizer=OptimizerRecord(
            study.sampler, None if settings is None else dataclasses.asdict(settings)
        ),
    )


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
    details: dict[str, Any] = {k: v for k, v in result.diagnostics.items() if k != "traceback"}
    if result.run is not None:
        out["run_file"] = run_file or f"runs/{row.kind}-{row.iteration:03d}-{row.slot:02d}.csv"
        write_trajectory(result.run.trajectory, folder / out["run_file"])
        out["transit_time"] = result.run.transit_time
    if result.ok and result.run is not None:
        try:
            c = calibration_cost(result.run.trajectory, reference, w_xy, w_theta)
            out.update(cost=c.value, dtw_xy=c.dtw_xy, dtw_theta=c.dtw_theta)
        except ParcelfitError as exc:
            out["status"], details["message"] = "failed", f"cost not computable: {exc}"
    store.finish(row.id, wall_time=result.wall_time, details=details, **out)
    return {**out, "message": details.get("message")}


def study_executor(
    study: Study,
    executor: str | None,
    scheduler: str | None,
    workers: int | None,
) -> Executor:
    """The executor the command line (first) or the study file asks for; local by default."""
    return make_executor(
        executor or study.executor.get("kind", "local"),
        workers=workers or study.executor.get("workers"),
        scheduler=scheduler or study.executor.get("scheduler"),
    )


@dataclass(frozen=True)
class _Opened:
    """What `Calibration.prepare` opened and read: the folder's lock, the store, the reference
    runs and the simulator."""

    lock: FileLock
    store: Store
    reference: ReferenceSelection
    val_reference: ReferenceSelection | None
    simulator: Simulator
    references: Mapping[str, ReferenceSelection] = dataclasses.field(default_factory=dict)


class Calibration:
    """One study folder: its store, references, optimiser and executor (see the module doc).

    ``executor`` (serial, local or dask), ``scheduler`` and ``workers`` override the study
    file's ``executor``; ``progress`` receives a `ProgressEvent` after every result. When the
    study stops it writes its results (``results.json``, `parcelfit.study.results`: the
    references, validations and surrogate the report renders) and, with ``figures``, the study
    figures (`parcelfit.study.plots.study_figures`) and, with ``key_frames`` too, the
    recommended run's key frames (MuJoCo studies: one more simulation; ``animation`` adds
    ``figures/run.gif``). When the study stops it also analyses what its evaluations determine
    (`parcelfit.study.identify`), runs the transfer check of a study with ``transfer`` cases
    and, with ``advice`` and at least two validation or transfer cases, simulates the
    calibrated set at the ends of the open intervals on each to say which case would help most
    (`parcelfit.study.joint`); all three go into ``results.json``.

    A folder holding an earlier study's outputs (``runs/``, ``results.json``, ``figures/``)
    without its store is refused (`refuse_orphaned_outputs`); with ``restart`` the folder's
    store and outputs are first moved into ``earlier-TIME/`` in it (`set_aside_outputs`,
    ``set_aside`` says where) and the study starts afresh.

    Constructing one keeps its inputs and touches nothing: `run` opens the folder, reads the
    data and builds the simulator (through `prepare`), runs the study and closes the folder.
    ``store``, ``reference``, ``val_reference`` and ``simulator`` exist from `prepare` on; a
    calibration runs once (a new one on the same folder resumes it)."""

    def __init__(
        self,
        study: Study,
        folder: str | Path,
        *,
        executor: str | None = None,
        scheduler: str | None = None,
        workers: int | None = None,
        progress: ProgressCallback | None = None,
        figures: bool = True,
        key_frames: bool = True,
        animation: bool = False,
        advice: bool = True,
        restart: bool = False,
    ) -> None:
        self.study = study
        self.advice = advice
        self.restart = restart
        self.set_aside: Path | None = None  # where a restart moved the earlier outputs
        self.folder = Path(folder)
        self.figures = figures
        self.key_frames = key_frames
        self.animation = animation
        self.fit_case = TestCase(study.rig, study.consignment, study.fit_setting)
        self.val_case = (
            None
            if study.validation_setting is None
            else TestCase(study.rig, study.consignment, study.validation_setting)
        )
        self._executor_args = (executor, scheduler, workers)
        self.progress = progress or ignore_progress
        self.last_validation: bool | None = None
        self._validations: dict[int, ValidationRecord] = {}  # by store row id
        self._opened: _Opened | None = None
        self._closed = False
        self._streak = FailureStreak(
            min(FAILURES_IN_A_ROW, study.budget),
            self.folder,
            "evaluations" if study.joint else "simulations",
        )

    @cached_property
    def bo(self) -> Sampler:
        """The study's optimiser (made on first use; `run` tells it the stored evaluations)."""
        study = self.study
        return make_sampler(
            study.sampler,
            study.space,
            batch_size=study.batch_size,
            seed=study.seed,
            settings=study.bo,
            n_initial=study.initial,
        )

    def prepare(self) -> None:
        """Open the study: create and lock the folder (until `close`), set an earlier study
        aside (``restart``) or refuse its outputs without a store, open its store and
        refuse one made from a different study file, record the study and where it came from,
        load the dataset, select the fitting and validation reference runs and build the
        simulator. `run` calls it; once prepared, calling it again does nothing. Whatever it
        opened is closed again if it fails."""
        if self._closed:
            raise RuntimeError("this calibration has run; make a new one to resume the study")
        if self._opened is not None:
            return
        study = self.study
        check_writable(self.folder, (STORE_FILE,))
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise os_error(exc, self.folder) or ParcelfitError(
                f"cannot create the study folder ({exc.strerror or exc})",
                file=self.folder,
                fix="choose a writable output folder",
            ) from None
        lock = lock_folder(self.folder, "a calibration")  # released by close()
        store = None
        try:
            if self.restart:
                self.set_aside = set_aside_outputs(self.folder)
            else:
                refuse_orphaned_outputs(self.folder)
            store = Store(self.folder / STORE_FILE)
            known = store.get_meta("fingerprint")
            if known is not None and known != study.fingerprint:
                raise ParcelfitError(
                    "this folder holds a study made from a different study file",
                    file=self.folder,
                    fix="use a new output folder, or restore the study file it was made from",
                )
            if known is None:
                store.set_meta("fingerprint", study.fingerprint)
            # where the study came from, so a report can find its file and data again
            store.write_source(
                SourceRecord(
                    study_file=None if study.path is None else str(study.path),
                    dataset=str(Path(study.dataset).resolve()),
                    rig=study.rig,
                    consignment=study.consignment,
                )
            )
            references = self._select_references()
            reference = references[self.fit_case.label]
            val_reference = None if self.val_case is None else references[self.val_case.label]
            store.set_meta("reference_run", reference.reference_id)
            if study.joint or len(study.validation_cases) > 1 or study.transfer:
                store.set_meta("cases", self._case_summary(references))
            try:
                simulator = make_simulator(study.simulator)
            except ParcelfitError as exc:  # e.g. a python factory that cannot be imported
                if exc.file is not None or study.path is None:
                    raise
                raise ParcelfitError(
                    exc.message, file=study.path, where="simulator", fix=exc.fix
                ) from None
            check_placements(study, simulator)
            recorded = store.read_study()
            if recorded is None or not recorded.optimizer.recorded:
                # the study and its optimiser as it runs (so figures refit its surrogate with
                # the same settings); a store of an earlier version gets the settings in use
                # from now on
                store.write_study(study_record(study, self.bo))
        except BaseException:
            if store is not None:
                store.close()
            lock.release()
            raise
        self._opened = _Opened(lock, store, reference, val_reference, simulator, references)

    def _select_references(self) -> dict[str, ReferenceSelection]:
        """The reference selection of every case of the study (fitted, validation, transfer),
        by label; each dataset is read once."""
        study = self.study
        datasets: dict[Path, Any] = {}
        out = {}
        specs = study.cases or (CaseSpec(self.fit_case, study.dataset),)
        if not study.validation_cases and self.val_case is not None:
            specs = (*specs, CaseSpec(self.val_case, study.dataset))
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

    def _case_summary(self, references: Mapping[str, ReferenceSelection]) -> list[dict[str, Any]]:
        """The study's cases for the store and results: label, role, weight, dataset, reference
        run and the acceptance threshold of the fitted ones."""
        study = self.study
        out = []
        for role, specs in (
            ("fit", study.cases),
            ("validation", study.validation_cases),
            ("transfer", study.transfer),
        ):
            for spec in specs:
                ref = references[spec.label]
                out.append(
                    {
                        "case": spec.label,
                        "role": role,
                        "weight": spec.weight,
                        "dataset": str(spec.dataset),
                        "reference_run": ref.reference_id,
                        "threshold": case_threshold(ref, study) if role == "fit" else None,
                        "transit": None
                        if ref.transit_adjustment is None
                        else ref.transit_adjustment.describe(),
                    }
                )
        return out

    def _open(self) -> _Opened:
        if self._opened is None:
            raise RuntimeError("the calibration is not open: call run() (or prepare() first)")
        return self._opened

    @property
    def store(self) -> Store:
        """The study's store (open from `prepare` to `close`)."""
        return self._open().store

    @property
    def reference(self) -> ReferenceSelection:
        """The fitting test case's reference run selection (from `prepare` on)."""
        return self._open().reference

    @property
    def val_reference(self) -> ReferenceSelection | None:
        """The validation test case's reference run selection (None without validation)."""
        return self._open().val_reference

    @property
    def references(self) -> Mapping[str, ReferenceSelection]:
        """The reference selection of every case of the study, by label (from `prepare` on)."""
        return self._open().references

    @property
    def simulator(self) -> Simulator:
        """The study's simulator (built by `prepare`)."""
        return self._open().simulator

    def close(self) -> None:
        """Close the store and release the folder's lock (`run` does this when it ends);
        nothing to do before `prepare`."""
        if self._opened is None or self._closed:
            return
        self._opened.store.close()
        self._opened.lock.release()
        self._closed = True

    # -- helpers -----------------------------------------------------------------------------
    def _full_params(self, fitted: Mapping[str, float]) -> dict[str, float]:
        return {**self.study.fixed, **fitted}

    def _report(self, iteration: int, running: int, message: str) -> None:
        best = self.bo.best()
        done = self.bo.n_told  # every finished evaluation is told exactly once
        self.progress(
            ProgressEvent(
                "calibration",
                message,
                done=done,
                total=self.study.budget,
                iteration=iteration,
                running=running,
                best_cost=None if best is None else best[1],
                last_validation=self.last_validation,
            )
        )

    def _record_fit(self, row: Evaluation, result: SimResult) -> dict[str, Any]:
        outcome = record_result(
            self.store,
            self.folder,
            row,
            result,
            self.reference,
            self.study.w_xy,
            self.study.w_theta,
        )
        self.bo.tell(row.params, outcome["cost"] if outcome["status"] == "ok" else None)
        return outcome

    def _run_rows(self, rows: list[Evaluation], executor: Executor) -> None:
        if self.study.joint:
            self._run_joint_rows(rows, executor)
            return
        tasks = [
            Task(self._full_params(r.params), self.fit_case, f"fit-{r.iteration:03d}-{r.slot:02d}")
            for r in rows
        ]
        remaining = len(rows)
        for i, result in executor.simulate(self.simulator, tasks):
            outcome = self._record_fit(rows[i], result)
            remaining -= 1
            self._report(rows[i].iteration, remaining, f"{outcome['status']}: {tasks[i].run_id}")
            self._streak.add(rows[i].id, outcome["status"], outcome["message"])

    def _run_joint_rows(self, rows: list[Evaluation], executor: Executor) -> None:
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
                    items.append((Task(self._full_params(r.params), spec.case, run_id), seed))
                    owner.append((i, spec, seed))
        per_row = simulations_per_evaluation(study)
        arrived: dict[int, list[tuple[int, CaseRun]]] = {}
        remaining = len(rows)
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
            self.bo.tell(row.params, out["cost"] if out["status"] == "ok" else None)
            remaining -= 1
            self._report(
                row.iteration,
                remaining,
                f"{out['status']}: fit-{row.iteration:03d}-{row.slot:02d} ({per_row} simulations)",
            )
            self._streak.add(row.id, out["status"], out["details"].get("message"))

    def _validate(self, iteration: int, executor: Executor) -> bool | None:
        best = self.bo.recommend()
        cases = self._validation_cases()
        if best is None or not cases:
            return None
        params, _ = best
        ids = self.store.add_pending(
            "validation",
            iteration,
            [params] * len(cases),
            cases[0].case.speed_setting,
            [0] * len(cases),
        )
        passed = True
        for slot, row_id in enumerate(ids):
            passed = self._run_validation(row_id, iteration, params, executor, slot) and passed
        return passed

    def _validation_cases(self) -> tuple[CaseSpec, ...]:
        """The validation cases (slot order of the validation rows of one iteration)."""
        return self.study.validation_cases or (
            () if self.val_case is None else (CaseSpec(self.val_case, self.study.dataset),)
        )

    def _run_validation(
        self,
        row_id: int,
        iteration: int,
        params: Mapping[str, float],
        executor: Executor,
        slot: int = 0,
    ) -> bool:
        """Simulate a stored (pending) validation row (the validation case of its slot) and
        record its verdict; True when it passed."""
        cases = self._validation_cases()
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
        details = record.details()
        if len(cases) > 1:
            details["case"] = spec.label
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
            group = [self._validations.get(r.id) for r in self._validation_rows(iteration)]
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

    def _validation_rows(self, iteration: int) -> list[Evaluation]:
        """The validation rows of one iteration, in slot order."""
        rows = [r for r in self.store.evaluations("validation") if r.iteration == iteration]
        return sorted(rows, key=lambda r: r.slot)

    # -- the loop ----------------------------------------------------------------------------
    def run(self) -> CalibrationResult:
        """Run (or resume) the study until validation passes or the budget is spent; then write
        the results (`parcelfit.study.results`), the study figures and the key frames, close
        the store and release the folder. Opens the study first (`prepare`). A full disk stops
        it with a `ParcelfitError` (what is stored stays; a rerun resumes)."""
        try:
            self.prepare()
            result = self._run()
            result = self._finish(result)
        except OSError as exc:  # a full disk while writing a run or the results
            raise os_error(exc, resumes=True) or exc from None
        finally:
            self.close()
        return result

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
        cases = self._validation_cases()
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
                    message=row.details.get("message"),
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
            record.optimizer, bo.n_told, None if curves is None else tuple(curves)
        )

    def identifiability(self) -> Identifiability | None:
        """What the finished fitting evaluations determine (`parcelfit.study.identify`), with
        the acceptance threshold from the fitted cases' real runs (`joint.threshold`); None
        with fewer than three successful evaluations or real runs that do not differ."""
        study = self.study
        fits = [r for r in self.store.evaluations("fit") if r.status != "pending"]
        references = self.references
        try:
            if study.cases:
                eps, source = threshold(references, study)
            else:  # a Study made in code without its cases
                eps = case_threshold(self.reference, study)
                source = f"largest equation (3) of a real run: {eps:.3g}"
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
    ) -> Path:
        """Write ``results.json``: the references, every validation, the surrogate (refitted
        here unless given), the key frames and figures, and what the study concluded when it
        stopped (identifiability, transfer check, advice); returns its path."""
        references = {"fit": ReferenceRecord.from_selection(self.reference)}
        if self.val_reference is not None:
            references["validation"] = ReferenceRecord.from_selection(self.val_reference)
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
                cases=self._case_summary(self.references) if self.study.cases else (),
            ),
        )

    def _finish(self, result: CalibrationResult) -> CalibrationResult:
        """The results, study figures and key frames of a stopped study, what its evaluations
        determine, the transfer check and the advice."""
        last = -1 if result.last_iteration is None else result.last_iteration
        surrogate = self.surrogate()
        self._report(last, 0, "what the data determine (the values the surrogate cannot exclude)")
        ident = self.identifiability()
        transfer: tuple[ValidationRecord, ...] = ()
        advice = None
        if result.best_params is not None:
            transfer = self._transfer(result.best_params, last)
            advice = self._advice(result.best_params, ident, last)
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
            if self.key_frames and result.best_params is not None:
                key_frames, drawn = self._key_frames(result.best_params, last)
                figures += drawn
        self.write_results(
            result.stop_reason,
            surrogate=surrogate,
            key_frames=key_frames,
            figures=tuple(figures),
            identifiability=ident,
            transfer=transfer,
            advice=advice,
        )
        return dataclasses.replace(result, figures=tuple(figures))

    def _simulate_tasks(self, tasks: list[Task]) -> list[SimResult]:
        """Simulate tasks with the study's executor; results in task order."""
        out: dict[int, SimResult] = {}
        executor = study_executor(self.study, *self._executor_args)
        try:
            for i, r in executor.simulate(self.simulator, tasks):
                out[i] = r
        finally:
            executor.close()
        return [out[i] for i in range(len(tasks))]

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
            self._report(iteration, len(todo), f"transfer check on {len(todo)} test cases")
            tasks = [
                Task(
                    self._full_params(params),
                    s.case,
                    f"transfer-{s.case.rig}-{s.case.speed_setting}",
                )
                for s in todo
            ]
            for spec, task, result in zip(todo, tasks, self._simulate_tasks(tasks), strict=True):
                run_file = None
                if result.ok and result.run is not None:
                    run_file = f"runs/{task.run_id}.csv"
                    write_trajectory(result.run.trajectory, self.folder / run_file)
                fresh[spec.label] = validation_record(
                    self.references[spec.label],
                    None if run_file is None or result.run is None else result.run.trajectory,
                    None if result.run is None else result.run.transit_time,
                    status=result.status.value,
                    message=result.diagnostics.get("message"),
                    params=params,
                    run_file=run_file,
                )
        out = tuple(fresh.get(s.label) or kept[s.label] for s in specs)
        if fresh:
            self.store.set_meta("transfer", [v.to_json() for v in out])
        return out

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
        candidates = [*self._validation_cases(), *self.study.transfer]
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
        advice = dataclasses.replace(advice, params={k: float(v) for k, v in params.items()})
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
        record = KeyFramesRecord(case.label, dict(params))
        if not isinstance(self.simulator, MujocoSimulator):
            return replace(record, note="Key frames are drawn for the MuJoCo backend only."), []
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
            return replace(record, note=f"The key-frame run failed: {exc}"), []
        if drawn.figure is None:
            return replace(record, note=f"The key-frame run ended {drawn.status}."), []
        paths = save_figure(drawn.figure, stem)
        return replace(
            record,
            image=paths[0].relative_to(self.folder).as_posix(),
            animation=None
            if drawn.animation is None
            else drawn.animation.relative_to(self.folder).as_posix(),
        ), paths

    def _earlier_results(self) -> StudyResults | None:
        """The results an earlier run of this folder wrote (None if none or unreadable)."""
        try:
            return read_results(self.folder)
        except ParcelfitError:
            return None

    def _run(self) -> CalibrationResult:
        study = self.study
        if self.set_aside is not None:
            self._report(-1, 0, f"restarted: the earlier study is in {self.set_aside.name}/")
        # evaluations an earlier version stored as failed because their worker or the Dask
        # scheduler was lost (not because the simulation failed) are run again
        lost = [
            r.id
            for r in self.store.evaluations()
            if r.status == "failed"
            and str(r.details.get("message", "")).startswith(LOST_WORKER_MESSAGES)
        ]
        fits = self.store.evaluations("fit")
        if not any(r.status == "ok" for r in fits):
            # nothing has succeeded yet: what failed is run again (a set-up problem that
            # stopped the study, see FailureStreak, may have been fixed since)
            lost += [r.id for r in fits if r.status != "pending" and r.id not in lost]
        if lost:
            self.store.reopen(lost)
        rows = self.store.evaluations("fit")
        for r in rows:  # replay: the optimiser learns every finished evaluation again
            if r.status != "pending":
                self.bo.tell(r.params, r.cost if r.status == "ok" else None)
        stored = self.store.evaluations("validation")
        validated = {v.iteration for v in stored}
        already_passed = False
        for it in sorted(validated):  # an iteration's validation passes when all its cases do
            group = [v for v in stored if v.iteration == it]
            if any(v.status == "pending" for v in group):
                continue
            self.last_validation = all(bool(v.details.get("passed")) for v in group)
            already_passed = already_passed or self.last_validation
        pending = [r for r in rows if r.status == "pending"]
        if already_passed and not pending:
            return self._result("validation passed")
        iteration = max((r.iteration for r in rows), default=-1)
        if (self._executor_args[0] or study.executor.get("kind")) == "dask":
            self._report(iteration, 0, "connecting to the Dask scheduler, waiting for a worker")
        executor = study_executor(study, *self._executor_args)
        try:
            if already_passed:
                # a finished study whose record lost fitting runs (a lost worker): complete the
                # record, no new iterations
                self._report(iteration, len(pending), f"resuming {len(pending)} lost simulations")
                self._run_rows(pending, executor)
                self.last_validation = True
                return self._result("validation passed")
            # a validation interrupted by a kill is run again before anything else
            for v in stored:
                if v.status == "pending" and self._validation_cases():
                    self._report(
                        v.iteration, 1, f"resuming the validation after iteration {v.iteration}"
                    )
                    self._run_validation(v.id, v.iteration, v.params, executor, v.slot)
                    group = self._validation_rows(v.iteration)
                    if all(r.status != "pending" for r in group) and all(
                        bool(r.details.get("passed")) for r in group
                    ):
                        return self._result("validation passed")
            while True:
                if pending:
                    self._report(
                        iteration, len(pending), f"resuming {len(pending)} pending simulations"
                    )
                    self._run_rows(pending, executor)
                    pending = []
                elif (done := len(self.store.evaluations("fit"))) < study.budget:
                    iteration += 1
                    n = min(
                        study.initial if iteration == 0 else study.batch_size, study.budget - done
                    )
                    batch = self.bo.ask(n)
                    seeds = [study.seed * 100003 + done + k for k in range(n)]
                    self.store.add_pending("fit", iteration, batch, study.fit_setting, seeds)
                    new_rows = [
                        r for r in self.store.evaluations("fit") if r.iteration == iteration
                    ]
                    what = (
                        "initial design (iteration 0)"
                        if iteration == 0
                        else f"iteration {iteration}"
                    )
                    per = simulations_per_evaluation(study) if study.joint else 1
                    count = (
                        f"{n} evaluations ({n * per} simulations)"
                        if study.joint
                        else f"{n} simulations"
                    )
                    self._report(iteration, n, f"{what}: {count}")
                    self._run_rows(new_rows, executor)
                else:
                    break
                due = (
                    iteration >= 1
                    and iteration % study.validate_every == 0
                    and iteration not in validated
                )
                if due:
                    validated.add(iteration)
                    if self._validate(iteration, executor):
                        return self._result("validation passed")
            if (
                self._validation_cases()
                and iteration not in validated
                and self._validate(iteration, executor)
            ):
                return self._result("validation passed")
            return self._result("budget spent")
        finally:
            executor.close()

    def _result(self, reason: str) -> CalibrationResult:
        best = self.bo.recommend()
        fits = self.store.evaluations("fit")
        self.store.set_meta("stop_reason", reason)
        if best is not None:
            self.store.write_recommended(RecommendedRecord(best[0], best[1]))
        return CalibrationResult(
            best_params=None if best is None else best[0],
            best_cost=None if best is None else best[1],
            evaluations=len(fits),
            last_iteration=max((r.iteration for r in fits), default=None),
            validated=self.last_validation,
            stop_reason=reason,
            folder=self.folder,
        )


def _cost_se(row: Evaluation) -> float | None:
    """The standard error of a joint ensemble evaluation's cost (its cases' trajectory-term
    standard errors, weighted, in quadrature); None when a case states none."""
    parts = row.details.get("cases") or []
    if not parts or any(p.get("se") is None for p in parts):
        return None
    return math.sqrt(sum((p["weight"] * p["se"]) ** 2 for p in parts))
