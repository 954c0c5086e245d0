"""The calibration loop (method.md sections 7 and 8): reference runs, initial design, batch BO
iterations, validation every N iterations, stop when the validation passes or the budget is
spent. Every evaluation goes through the `Store` before the loop moves on; restarting the same
study folder replays the store (finished evaluations are never simulated again, pending ones
are run) and continues exactly where it stopped.

`Calibration` is the facade over the study's parts, as Optuna splits a study: the objective
(`parcelfit.study.objective`: one parameter set simulated, costed and stored; a joint or
ensemble study simulates every case and placement of it in one batch), the sampler
(`parcelfit.optimize.sampler`), the storage (`parcelfit.study.store`) and what the study
concludes (`parcelfit.study.finish`: the validations, whose cases are simulated one after the
other and pass when every case passes, and after the loop the transfer check, the convergence
check, the advice, the study figures and the key frames).

Failed, unstable and timed-out simulations, and runs whose trajectory misses the regions of
interest, are stored with their status and told to the optimiser as failures (it penalises them
with the worst cost seen) and count against the budget. One failure never stops the loop, but
`FAILURES_IN_A_ROW` fitting evaluations failing one after the other do
(`parcelfit.study.loop.FailureStreak`): a
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
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

from filelock import FileLock

from parcelfit.errors import ParcelfitError, os_error
from parcelfit.metrics import ReferenceSelection
from parcelfit.optimize.sampler import Sampler
from parcelfit.progress import ProgressCallback, ProgressEvent, ignore_progress
from parcelfit.sim.executors import Executor, SharedExecutor
from parcelfit.sim.factory import make_simulator
from parcelfit.sim.protocol import Simulator
from parcelfit.study.estimate import calibration_cost_line
from parcelfit.study.finish import Finish
from parcelfit.study.folderlock import (
    check_writable,
    lock_folder,
    refuse_orphaned_outputs,
    set_aside_outputs,
)
from parcelfit.study.joint import check_placements, simulations_per_evaluation
from parcelfit.study.loop import AskTellLoop, study_executor
from parcelfit.study.objective import (
    Objective,
    case_summary,
    select_references,
    study_cases,
)
from parcelfit.study.store import (
    STORE_FILE,
    OptimizerRecord,
    RecommendedRecord,
    SourceRecord,
    Store,
    StudyRecord,
)
from parcelfit.study.studyfile import Study


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
            sampler=study.sampler,
            settings=None if settings is None else dataclasses.asdict(settings),
        ),
    )


@dataclass(frozen=True)
class _Opened:
    """What `Calibration.prepare` opened and read: the folder's lock, the store, the reference
    runs (by case label) and the simulator, with the study's objective and finish over them."""

    lock: FileLock
    store: Store
    references: Mapping[str, ReferenceSelection]
    simulator: Simulator
    objective: Objective
    finish: Finish


class Calibration:
    """One study folder: its store, references, optimiser and executor (see the module doc).

    ``executor`` (serial, local or dask), ``scheduler`` and ``workers`` override the study
    file's ``executor``; ``sampler``, an optimiser object (`parcelfit.optimize.sampler.Sampler`),
    replaces the one the study file names (a resumed study needs the same one); ``progress``
    receives a `ProgressEvent` after every result. When the
    study stops it writes its results (``results.json``, `parcelfit.study.results`: the
    references, validations and surrogate the report renders) and, with ``figures``, the study
    figures (`parcelfit.study.plots.study_figures`) and, with ``key_frames`` too, the
    recommended run's key frames (MuJoCo studies: one more simulation; ``animation`` adds
    ``figures/run.gif``). When the study stops it also analyses what its evaluations determine
    (`parcelfit.study.identify`), runs the transfer check of a study with ``transfer`` cases,
    the convergence check (every validation and transfer case once more on the refined model)
    and, with ``advice`` and at least two validation or transfer cases, simulates the
    calibrated set at the ends of the open intervals on each to say which case would help most
    (`parcelfit.study.joint`); all four go into ``results.json``.

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
        sampler: Sampler | None = None,
    ) -> None:
        self.study = study
        self._sampler = sampler
        self.advice = advice
        self.restart = restart
        self.set_aside: Path | None = None  # where a restart moved the earlier outputs
        self.folder = Path(folder)
        self.figures = figures
        self.key_frames = key_frames
        self.animation = animation
        self.fit_case, self.val_case = study_cases(study)
        self._executor_args = (executor, scheduler, workers)
        self.progress = progress or ignore_progress
        self._opened: _Opened | None = None
        self._closed = False
        # the study's executor, made on first use and shared by the fitting loop and the
        # closing phases (validations, checks, advice); `close` shuts it down
        self._shared = SharedExecutor(lambda: study_executor(study, *self._executor_args))

    def cost_line(self) -> str:
        """The line said before the study starts: its expected cost on its executor and workers
        (`parcelfit.study.estimate.calibration_cost_line`), noting a resumed study."""
        executor, _, workers = self._executor_args
        resumed = (self.folder / STORE_FILE).exists()
        return calibration_cost_line(self.study, executor, workers, resumed)

    @cached_property
    def bo(self) -> Sampler:
        """The study's optimiser: the ``sampler`` given, else the one its study file names
        (`Study.new_sampler`); `run` tells it the stored evaluations."""
        return self._sampler or self.study.new_sampler()

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
            if not store.claim_meta("fingerprint", study.fingerprint):
                raise ParcelfitError(
                    "this folder holds a study made from a different study file",
                    file=self.folder,
                    fix="use a new output folder, or restore the study file it was made from",
                )
            # where the study came from, so a report can find its file and data again
            store.write_source(
                SourceRecord(
                    study_file=None if study.path is None else str(study.path),
                    dataset=str(Path(study.dataset).resolve()),
                    rig=study.rig,
                    consignment=study.consignment,
                )
            )
            references = select_references(study)
            store.set_meta("reference_run", references[self.fit_case.label].reference_id)
            if study.joint or len(study.validation_cases) > 1 or study.transfer:
                store.write_cases(case_summary(study, references))
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
        objective = Objective(study, self.folder, store, simulator, references)
        finish = Finish(
            study,
            self.folder,
            store,
            simulator,
            references,
            self._report,
            self._shared.get,
            figures=self.figures,
            key_frames=self.key_frames,
            animation=self.animation,
            advice=self.advice,
        )
        self._opened = _Opened(lock, store, references, simulator, objective, finish)

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
        return self._open().references[self.fit_case.label]

    @property
    def val_reference(self) -> ReferenceSelection | None:
        """The validation test case's reference run selection (None without validation)."""
        return None if self.val_case is None else self._open().references[self.val_case.label]

    @property
    def references(self) -> Mapping[str, ReferenceSelection]:
        """The reference selection of every case of the study, by label (from `prepare` on)."""
        return self._open().references

    @property
    def simulator(self) -> Simulator:
        """The study's simulator (built by `prepare`)."""
        return self._open().simulator

    @property
    def finish(self) -> Finish:
        """The study's validations and conclusions (`parcelfit.study.finish`, from `prepare`)."""
        return self._open().finish

    @property
    def last_validation(self) -> bool | None:
        """The verdict of the latest finished validation (None before any)."""
        return None if self._opened is None else self._opened.finish.last_validation

    def close(self) -> None:
        """Shut the study's executor down, close the store and release the folder's lock
        (`run` does this when it ends); nothing to do before `prepare`."""
        try:
            self._shared.close()
        finally:
            if self._opened is not None and not self._closed:
                self._opened.store.close()
                self._opened.lock.release()
                self._closed = True

    # -- helpers -----------------------------------------------------------------------------
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

    # -- the loop ----------------------------------------------------------------------------
    def run(self) -> CalibrationResult:
        """Run (or resume) the study until validation passes or the budget is spent; then write
        the results (`parcelfit.study.results`), the study figures and the key frames, close
        the store and release the folder. Opens the study first (`prepare`). A full disk stops
        it with a `ParcelfitError` (what is stored stays; a rerun resumes)."""
        try:
            self.prepare()
            result = self._run()
            figures = self.finish.conclude(
                result.best_params, result.last_iteration, result.stop_reason
            )
            result = dataclasses.replace(result, figures=figures)
        except OSError as exc:  # a full disk while writing a run or the results
            raise os_error(exc, resumes=True) or exc from None
        finally:
            self.close()
        return result

    def _run(self) -> CalibrationResult:
        study, finish = self.study, self.finish
        if self.set_aside is not None:
            self._report(-1, 0, f"restarted: the earlier study is in {self.set_aside.name}/")
        loop = AskTellLoop(
            study,
            self.bo,
            self.store,
            self._open().objective.evaluate,
            self._report,
            self.folder,
            per_evaluation=simulations_per_evaluation(study) if study.joint else 1,
        )
        pending = loop.replay()  # the optimiser learns every finished evaluation again
        stored = self.store.evaluations("validation")
        validated = {v.iteration for v in stored}
        already_passed = False
        for it in sorted(validated):  # an iteration's validation passes when all its cases do
            group = [v for v in stored if v.iteration == it]
            if any(v.status == "pending" for v in group):
                continue
            finish.last_validation = all(bool(v.details.passed) for v in group)
            already_passed = already_passed or finish.last_validation
        if already_passed and not pending:
            return self._result("validation passed")
        if (self._executor_args[0] or study.executor.get("kind")) == "dask":
            self._report(
                loop.iteration, 0, "connecting to the Dask scheduler, waiting for a worker"
            )
        executor = self._shared.get()  # `run` closes it as it ends, on an error or Ctrl-C too
        if already_passed:
            # a finished study whose record lost fitting runs (a lost worker): complete the
            # record, no new iterations
            self._report(loop.iteration, len(pending), f"resuming {len(pending)} lost simulations")
            loop.evaluate(pending, executor)
            finish.last_validation = True
            return self._result("validation passed")
        # a validation interrupted by a kill is run again before anything else
        for v in stored:
            if v.status == "pending" and finish.validation_cases():
                self._report(
                    v.iteration, 1, f"resuming the validation after iteration {v.iteration}"
                )
                finish.run_validation(v.id, v.iteration, v.params, executor, v.slot)
                group = finish.validation_rows(v.iteration)
                if all(r.status != "pending" for r in group) and all(
                    bool(r.details.passed) for r in group
                ):
                    return self._result("validation passed")
        while True:
            if pending:
                self._report(
                    loop.iteration, len(pending), f"resuming {len(pending)} pending simulations"
                )
                loop.evaluate(pending, executor)
                pending = []
            elif not loop.step(executor):
                break
            iteration = loop.iteration
            if (
                iteration >= 1
                and iteration % study.validate_every == 0
                and iteration not in validated
            ):
                validated.add(iteration)
                if self._validate(iteration, executor):
                    return self._result("validation passed")
        if (
            finish.validation_cases()
            and loop.iteration not in validated
            and self._validate(loop.iteration, executor)
        ):
            return self._result("validation passed")
        return self._result("budget spent")

    def _validate(self, iteration: int, executor: Executor) -> bool | None:
        """Validate the recommended parameters after ``iteration`` (`Finish.validate`)."""
        best = self.bo.recommend()
        return self.finish.validate(iteration, None if best is None else best[0], executor)

    def _result(self, reason: str) -> CalibrationResult:
        best = self.bo.recommend()
        fits = self.store.evaluations("fit")
        self.store.set_meta("stop_reason", reason)
        if best is not None:
            self.store.write_recommended(RecommendedRecord(params=best[0], cost=best[1]))
        return CalibrationResult(
            best_params=None if best is None else best[0],
            best_cost=None if best is None else best[1],
            evaluations=len(fits),
            last_iteration=max((r.iteration for r in fits), default=None),
            validated=self.last_validation,
            stop_reason=reason,
            folder=self.folder,
        )
