"""Where simulations run: a local process pool (default) or a Dask cluster.

Both take a batch of tasks and yield ``(index, SimResult)`` in the order results arrive, so the
loop can store each result the moment it exists. A task that raises becomes a ``failed``
result; the loop never stops on one simulation.

Local: ``concurrent.futures.ProcessPoolExecutor`` with the ``spawn`` start method (MuJoCo and
numba are not fork-safe), one simulation per core. A worker that dies (a segfault, an
out-of-memory kill) breaks the pool: the pool is recreated and the simulations it was running
are started again, up to ``max_restarts`` times each (``worker_restarts`` in their
diagnostics); only then is a simulation ``failed``. Workers die with the process that started
them (`parcelfit.sim.lifetime.die_with_parent`). Dask: ``distributed.Client`` on a scheduler
address; each task is retried up to twice if its worker dies, so a lost worker costs time, not
results. A batch waits for its slowest member, as in the published method; workers beyond the
batch size only help the initial design (16 simulations at once) and validation runs.
"""

from __future__ import annotations

import contextlib
import inspect
import multiprocessing
import os
import time
import traceback
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from typing import Any

from parcelfit.errors import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim.lifetime import die_with_parent
from parcelfit.sim.protocol import SimResult, SimStatus, Simulator


@dataclass(frozen=True)
class Task:
    """One simulation to run: parameters (SI), test case and run id."""

    params: Mapping[str, float]
    case: TestCase
    run_id: str


def simulate_task(simulator: Simulator, task: Task) -> SimResult:
    """Run one task; any exception becomes a ``failed`` result with the traceback's last lines."""
    t0 = time.perf_counter()
    try:
        if "run_id" in inspect.signature(simulator.run).parameters:
            return simulator.run(task.params, task.case, run_id=task.run_id)  # type: ignore[call-arg]
        return simulator.run(task.params, task.case)
    except Exception as exc:
        tail = "".join(traceback.format_exception(exc)[-3:])
        return SimResult(
            None,
            SimStatus.FAILED,
            time.perf_counter() - t0,
            {"message": f"{type(exc).__name__}: {exc}", "traceback": tail},
        )


class LocalExecutor:
    """Simulations in a pool of local processes (default: one per core)."""

    def __init__(
        self, simulator: Simulator, workers: int | None = None, max_restarts: int = 3
    ) -> None:
        self.simulator = simulator
        self.workers = workers or os.cpu_count() or 1
        self.max_restarts = max_restarts
        self.restarts = 0  # pools recreated after a worker died
        self._pool = self._new_pool()

    def _new_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(
            max_workers=self.workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=die_with_parent,
            initargs=(os.getpid(),),
        )

    def run(self, tasks: Sequence[Task]) -> Iterator[tuple[int, SimResult]]:
        """Submit all tasks; yield (index, result) as they finish. Tasks whose worker died are
        run again in a new pool."""
        deaths = [0] * len(tasks)
        todo = list(range(len(tasks)))
        while todo:
            futures = {}
            try:
                for i in todo:
                    futures[self._pool.submit(simulate_task, self.simulator, tasks[i])] = i
            except BrokenProcessPool:
                pass  # a worker died already; what was not submitted is retried below
            again = [i for i in todo if i not in futures.values()]
            for fut in as_completed(futures):
                i = futures[fut]
                try:
                    result = fut.result()
                except BrokenProcessPool:
                    deaths[i] += 1
                    if deaths[i] <= self.max_restarts:
                        again.append(i)
                        continue
                    result = SimResult(
                        None,
                        SimStatus.FAILED,
                        0.0,
                        {
                            "message": f"its worker process died {deaths[i]} times (a crash or "
                            "an out-of-memory kill during the simulation)"
                        },
                    )
                except Exception as exc:
                    result = SimResult(
                        None, SimStatus.FAILED, 0.0, {"message": f"worker failed: {exc!r}"}
                    )
                if deaths[i]:
                    result = replace(
                        result, diagnostics={**result.diagnostics, "worker_restarts": deaths[i]}
                    )
                yield i, result
            if again:
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = self._new_pool()
                self.restarts += 1
            todo = sorted(again)

    def close(self) -> None:
        """Shut the pool down."""
        self._pool.shutdown(wait=False, cancel_futures=True)


class DaskExecutor:
    """Simulations on a Dask cluster; tasks are retried if their worker dies.

    A scheduler that cannot be reached, or has no worker attached after ``worker_wait`` [s],
    is an error before anything runs. A scheduler lost during a batch stops the run with a
    `ParcelfitError`: the evaluations in flight are not recorded (they stay ``pending`` in the
    store and run on resume), never stored as ``failed``.
    """

    def __init__(
        self,
        simulator: Simulator,
        scheduler: str | Any,
        retries: int = 2,
        *,
        connect_timeout: float = 10.0,
        worker_wait: float = 60.0,
    ) -> None:
        try:
            from distributed import Client
        except ImportError as exc:
            raise ParcelfitError(
                "the dask executor needs the 'dask' extra", fix='pip install "parcelfit[dask]"'
            ) from exc
        self.simulator = simulator
        self.retries = retries
        self._own = not hasattr(scheduler, "submit")
        self.address = str(scheduler) if self._own else str(scheduler.scheduler.address)
        if self._own:
            try:
                self.client = Client(scheduler, timeout=connect_timeout)
            except (OSError, TimeoutError, ValueError, TypeError) as exc:
                raise ParcelfitError(
                    f"cannot reach the Dask scheduler at {scheduler!r} ({exc})",
                    fix="check the address (tcp://HOST:8786) and that the scheduler runs",
                ) from None
        else:
            self.client = scheduler
        try:
            self.client.wait_for_workers(1, timeout=worker_wait)
        except (TimeoutError, OSError):
            self.close()
            raise ParcelfitError(
                f"no Dask worker is attached to the scheduler at {self.address} "
                f"(waited {worker_wait:g} s)",
                fix=f"start workers, e.g. `dask worker {self.address}`, then rerun",
            ) from None

    def _lost(self, exc: BaseException) -> ParcelfitError:
        return ParcelfitError(
            f"lost the Dask scheduler at {self.address} ({type(exc).__name__}); the simulations "
            "in flight were not recorded and stay pending",
            fix="restart the scheduler and workers (or use --executor local), then rerun the "
            "same command: the study resumes",
        )

    def _connected(self) -> bool:
        comm = getattr(self.client, "scheduler_comm", None)
        return self.client.status == "running" and not (
            comm is not None and getattr(comm.comm, "closed", lambda: False)()
        )

    def run(self, tasks: Sequence[Task]) -> Iterator[tuple[int, SimResult]]:
        """Submit all tasks; yield (index, result) as they finish."""
        from distributed import KilledWorker
        from distributed import as_completed as dask_completed

        try:
            futures = {
                self.client.submit(
                    simulate_task, self.simulator, t, pure=False, retries=self.retries
                ): i
                for i, t in enumerate(tasks)
            }
        except Exception as exc:
            raise self._lost(exc) from None
        try:
            for fut in dask_completed(list(futures)):
                i = futures[fut]
                try:
                    result = fut.result()
                except KilledWorker as exc:  # the simulation killed every worker it ran on
                    result = SimResult(
                        None,
                        SimStatus.FAILED,
                        0.0,
                        {"message": f"its worker died {self.retries + 1} times: {exc}"},
                    )
                except Exception as exc:
                    if not self._connected():
                        raise self._lost(exc) from None
                    result = SimResult(
                        None, SimStatus.FAILED, 0.0, {"message": f"dask task failed: {exc!r}"}
                    )
                yield i, result
        except ParcelfitError:
            raise
        except Exception as exc:  # the client itself failed (closed, connection lost)
            raise self._lost(exc) from None

    def close(self) -> None:
        """Close the client if this executor opened it."""
        if self._own:
            with contextlib.suppress(Exception):
                self.client.close(timeout=5)
