"""The loop of a study: stored evaluations through an executor, one after the other, until a
stop rule says so.

`FailureStreak` is the stop rule every loop shares: `FAILURES_IN_A_ROW` evaluations failing
one after the other stop a calibration, a screening stage or a precision check with a
`ParcelfitError` quoting the first failure, instead of spending the budget on a set-up that
cannot work. `LOST_WORKER_MESSAGES` are the failures an earlier version stored when a worker or
the Dask scheduler was lost (not the simulation): a resumed study runs them again.
`study_executor` makes the executor a study file (or the command line, first) asks for.
"""

from __future__ import annotations

from pathlib import Path

from parcelfit.errors import ParcelfitError
from parcelfit.sim.executors import Executor, make_executor
from parcelfit.study.studyfile import Study

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
