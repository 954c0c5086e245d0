"""The ask/tell loop of a study over an executor and the store (method.md section 7).

`AskTellLoop` is the optimiser's side of a calibration: on resume it tells the sampler every
finished evaluation the store holds (in the order they were asked, so that a stored study
replays to the same next batch) and returns the pending ones; each step asks the sampler for a
batch, stores it as pending before anything is simulated, evaluates it through the objective
(`parcelfit.study.objective`) and tells the sampler each result the moment it is stored. What
happens between steps (validations, when to stop before the budget) is the caller's
(`parcelfit.study.calibration`).

`FailureStreak` is the stop rule every loop shares: `FAILURES_IN_A_ROW` evaluations failing
one after the other stop a calibration (or, before their first success, a screening stage
or a precision check) with a
`ParcelfitError` quoting the first failure, instead of spending the budget on a set-up that
cannot work. `LOST_WORKER_MESSAGES` are the failures an earlier version stored when a worker or
the Dask scheduler was lost (not the simulation): a resumed study runs them again.
`study_executor` makes the executor a study file (or the command line, first) asks for.

`DesignLoop` is the same loop over a fixed design (a screening stage, the runs of a precision
check): its sampler is a `FixedDesign`, which asks the design's rows in order and is done when
all of them are told. On a rerun it stores the design as pending only if none of it is stored
yet, runs again what failed while nothing of it has succeeded, and tells the sampler what is
finished;
evaluating, it tells the sampler each result as stored, reports ``done of total`` and stops on
a streak of failures before the stage's first success. Both loops tell results through
`tell_each`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Protocol

from parcelfit.errors import ParcelfitError
from parcelfit.optimize.sampler import Sampler
from parcelfit.sim.executors import Executor, make_executor
from parcelfit.study.objective import Evaluated
from parcelfit.study.store import Evaluation, Store
from parcelfit.study.studyfile import Study

Report = Callable[[int, int, str], None]  # (iteration, running, message): a progress line

FAILURES_IN_A_ROW = 8  # evaluations failing one after the other that stop a study or a screen
LOST_WORKER_MESSAGES = (
    "worker failed: BrokenProcessPool",
    "dask task failed: FutureCancelledError",
    "dask task failed: CancelledError",
)


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
            # a quoted error's own fix reads as the first failure's, not as a second "Fix:"
            text = text.replace(" Fix: ", "; its fix: ")
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


class Teller(Protocol):
    """What a loop tells results to: a `Sampler` or a `FixedDesign`."""

    def tell(self, params: Mapping[str, float], cost: float | None) -> None:
        """Report an evaluated parameter set's cost (None: failed)."""
        ...


def tell_each(
    evaluated: Iterable[Evaluated],
    sampler: Teller,
    streak: FailureStreak,
    report: Callable[[int, Evaluated], None],
) -> None:
    """Tell ``sampler`` each evaluation the moment it is stored (a failure as None), pass it
    to ``report`` with its 1-based arrival number, then count it in ``streak`` (which raises
    when too many failed in a row)."""
    for k, done in enumerate(evaluated, start=1):
        sampler.tell(done.row.params, done.cost if done.status == "ok" else None)
        report(k, done)
        streak.add(done.row.id, done.status, done.message)


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


class AskTellLoop:
    """The ask/tell loop of a study's fitting evaluations (see the module doc).

    ``evaluate`` simulates and stores pending rows, yielding each as stored
    (`parcelfit.study.objective.Objective.evaluate`); ``report`` receives a progress line. The
    initial design (iteration 0) is ``study.initial`` evaluations, every later iteration
    ``study.batch_size``, until ``study.budget`` evaluations are stored. `FAILURES_IN_A_ROW`
    failing one after the other stop it (`FailureStreak`, whose message names ``folder``)."""

    def __init__(
        self,
        study: Study,
        sampler: Sampler,
        store: Store,
        evaluate: Callable[[list[Evaluation], Executor], Iterator[Evaluated]],
        report: Report,
        folder: Path,
        *,
        per_evaluation: int = 1,
    ) -> None:
        self.study = study
        self.sampler = sampler
        self.store = store
        self._evaluate = evaluate
        self._report = report
        self.per_evaluation = per_evaluation  # simulations of one evaluation (joint studies)
        self.iteration = -1  # the last iteration stored (-1 before the initial design)
        self.streak = FailureStreak(
            min(FAILURES_IN_A_ROW, study.budget),
            folder,
            "evaluations" if study.joint else "simulations",
        )

    def replay(self) -> list[Evaluation]:
        """Resume: make pending again what an earlier run lost (a lost worker or scheduler,
        not a failed simulation; every failure while nothing has succeeded yet, as its cause
        may have been fixed), tell the sampler every finished fitting evaluation in the order
        it was asked, and return the pending ones."""
        lost = [
            r.id
            for r in self.store.evaluations()
            if r.status == "failed" and (r.details.message or "").startswith(LOST_WORKER_MESSAGES)
        ]
        fits = self.store.evaluations("fit")
        if not any(r.status == "ok" for r in fits):
            lost += [r.id for r in fits if r.status != "pending" and r.id not in lost]
        if lost:
            self.store.reopen(lost)
        rows = self.store.evaluations("fit")
        for r in rows:
            if r.status != "pending":
                self.sampler.tell(r.params, r.cost if r.status == "ok" else None)
        self.iteration = max((r.iteration for r in rows), default=-1)
        return [r for r in rows if r.status == "pending"]

    def evaluate(self, rows: list[Evaluation], executor: Executor) -> None:
        """Evaluate stored pending rows, telling the sampler each as it is stored (a failure
        as None) and counting failures in a row."""
        tell_each(
            self._evaluate(rows, executor),
            self.sampler,
            self.streak,
            lambda k, done: self._report(
                done.row.iteration, len(rows) - k, f"{done.status}: {done.label}"
            ),
        )

    def step(self, executor: Executor) -> bool:
        """Ask the next iteration's batch (the initial design first), store it as pending,
        evaluate it; False, doing nothing, when the budget is spent."""
        study = self.study
        done = len(self.store.evaluations("fit"))
        if done >= study.budget:
            return False
        self.iteration += 1
        iteration = self.iteration
        n = min(study.initial if iteration == 0 else study.batch_size, study.budget - done)
        batch = self.sampler.ask(n)
        seeds = [study.seed * 100003 + done + k for k in range(n)]
        self.store.add_pending("fit", iteration, batch, study.fit_setting, seeds)
        rows = [r for r in self.store.evaluations("fit") if r.iteration == iteration]
        what = "initial design (iteration 0)" if iteration == 0 else f"iteration {iteration}"
        count = (
            f"{n} evaluations ({n * self.per_evaluation} simulations)"
            if study.joint
            else f"{n} simulations"
        )
        self._report(iteration, n, f"{what}: {count}")
        self.evaluate(rows, executor)
        return True


class FixedDesign:
    """A sampler over a fixed design (a screening stage's rows, in catalogue order): `ask`
    hands out the next rows in order, `tell` counts what is finished; it learns nothing from
    the costs. `done` when every row was told."""

    def __init__(self, points: Sequence[Mapping[str, float]]) -> None:
        self.points = [dict(p) for p in points]
        self.asked = 0
        self.n_told = 0

    def ask(self, n: int | None = None) -> list[dict[str, float]]:
        """The next ``n`` rows of the design (default: all the rest)."""
        end = len(self.points) if n is None else min(len(self.points), self.asked + n)
        batch = self.points[self.asked : end]
        self.asked = end
        return batch

    def tell(self, params: Mapping[str, float], cost: float | None) -> None:
        """Count one finished row (``cost`` None: failed)."""
        self.n_told += 1

    @property
    def done(self) -> bool:
        """Whether every row of the design was told."""
        return self.n_told >= len(self.points)


class DesignLoop:
    """The ask/tell loop of a fixed design over the store (see the module doc). ``rows``
    returns the design's stored rows in the design's order (a screening stage: the store rows
    of its iteration; a precision check: the rows matched to its runs); ``add``, given the
    whole design as `FixedDesign` asks it, stores it as pending when none of it is stored yet
    (None: the caller stores it). ``evaluate`` simulates and stores pending rows, yielding each
    as stored; ``report`` receives each with its arrival number and how many were pending
    (``done``, ``total``, the evaluation). `FAILURES_IN_A_ROW` failing one after the other
    before the design's first success stop it (`FailureStreak`, whose message names
    ``folder``)."""

    def __init__(
        self,
        sampler: FixedDesign,
        rows: Callable[[], list[Evaluation]],
        add: Callable[[list[dict[str, float]]], object] | None,
        evaluate: Callable[[list[Evaluation]], Iterator[Evaluated]],
        report: Callable[[int, int, Evaluated], None],
        folder: Path,
        *,
        reopen: Callable[[list[int]], object],
    ) -> None:
        self.sampler = sampler
        self.rows = rows
        self._add = add
        self._evaluate = evaluate
        self._report = report
        self._reopen = reopen
        self.folder = folder

    def replay(self) -> list[Evaluation]:
        """Store the design as pending if none of it is stored yet; run again what failed
        while nothing of it has succeeded (a set-up problem that stopped an earlier run may
        have been fixed since); tell the sampler every finished row; return the pending ones."""
        rows = self.rows()
        batch = self.sampler.ask()
        if not rows and self._add is not None:
            self._add(batch)
            rows = self.rows()
        if not any(r.status == "ok" for r in rows):
            self._reopen([r.id for r in rows if r.status != "pending"])
            rows = self.rows()
        for r in rows:
            if r.status != "pending":
                self.sampler.tell(r.params, r.cost if r.status == "ok" else None)
        return [r for r in rows if r.status == "pending"]

    def evaluate(self, rows: list[Evaluation]) -> bool:
        """Evaluate the pending ``rows``, telling the sampler each as it is stored and
        reporting it; True when the whole design is told. Only a streak before the design's
        first success stops it: once one has succeeded, its failures are a property of the
        design."""
        streak = FailureStreak(FAILURES_IN_A_ROW, self.folder, until_success=True)
        streak.succeeded = any(r.status == "ok" for r in self.rows())
        tell_each(
            self._evaluate(rows),
            self.sampler,
            streak,
            lambda k, done: self._report(k, len(rows), done),
        )
        return self.sampler.done
