"""Where simulations run: one `Executor` over any ``concurrent.futures.Executor``.

The same loop drives three pools, chosen by name with `make_executor` (``executor: {kind: ...}``
in study and screen files, ``--executor`` on the command line):

* ``serial``: in this process, one task after the other (`SerialPool`); nothing is pickled,
  so a simulator or a twin run can be stepped through in a debugger;
* ``local`` (default): a ``ProcessPoolExecutor`` with the ``spawn`` start method (MuJoCo and
  numba are not fork-safe), one simulation per core; workers die with the process that started
  them (`parcelfit.sim.lifetime.die_with_parent`), leave Ctrl-C to it, and are ended when the
  executor is closed;
* ``dask``: ``client.get_executor()`` of a ``distributed.Client`` on a scheduler address;
  distributed's own loggers are silent while the executor is open (parcelfit reports a lost
  scheduler, or a cluster without workers, in one line).

`Executor.map` submits a batch and yields ``(index, Outcome)`` in the order results arrive, so
a caller can store each result the moment it exists; `Executor.simulate` does the same for
simulation `Task` objects and turns anything that went wrong into a ``failed`` `SimResult`
(the loop never stops on one simulation).

Ctrl-C never waits on a simulation or on the pool: the wait for results wakes every
`_TICK_S` seconds, so an interrupt the kernel hands to another thread of this process is acted
on too; a local worker holds Ctrl-C off while it starts and ignores it afterwards; closing an
executor ends the workers first (SIGTERM, then SIGKILL after `_STOP_GRACE_S` for one that does
not end) and never waits more than `_STOP_WAIT_S` for the pool's lock or its manager thread.

A worker that dies (a segfault, an out-of-memory kill) breaks a process pool: the pool is
recreated and the tasks it was running are started again, up to ``max_restarts`` times each
(``worker_restarts`` in their diagnostics); only then is a task failed. Dask retries a task
itself (twice) when its worker dies. A Dask scheduler lost during a batch stops the run with a
`ParcelfitError`: the evaluations in flight are not recorded (they stay ``pending`` in the store
and run on resume). A batch waits for its slowest member, as in the published method.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import inspect
import logging
import multiprocessing
import multiprocessing.connection
import os
import signal
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any, Generic, TypeVar

from parcelfit.errors import ParcelfitError, missing_extra
from parcelfit.runs import TestCase
from parcelfit.sim.lifetime import die_with_parent
from parcelfit.sim.protocol import SimResult, SimStatus, Simulator

T = TypeVar("T")
R = TypeVar("R")
EXECUTOR_KINDS = ("serial", "local", "dask")
# the most local worker processes (each holds a simulator; more than cores only queue)
MAX_WORKERS = 256
# The longest [s] the wait for results blocks at a time. A lock wait is interrupted only by a
# signal delivered to the waiting thread; Ctrl-C delivered to another thread of this process
# (the kernel may pick any thread that does not block it) is acted on when the wait returns.
_TICK_S = 0.5
_STOP_GRACE_S = 2.0  # [s] a worker gets after SIGTERM (to end its solvers) before SIGKILL
_STOP_WAIT_S = 5.0  # [s] the most closing a pool waits for its lock or for its manager thread


@dataclass(frozen=True)
class Task:
    """One simulation to run: parameters (SI), test case and run id."""

    params: Mapping[str, float]
    case: TestCase
    run_id: str


@dataclass(frozen=True)
class Outcome(Generic[R]):
    """What became of one task: its ``value``, or ``error`` (why there is none) and the
    ``exception`` the task raised if it did, and how often its worker died before it finished
    (``restarts``)."""

    value: R | None
    error: str | None = None
    restarts: int = 0
    exception: BaseException | None = field(default=None, compare=False, repr=False)


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


class SerialPool(cf.Executor):
    """A ``concurrent.futures.Executor`` that runs each call in this process when it is
    submitted. ``KeyboardInterrupt`` and other non-``Exception`` errors propagate at once."""

    def __init__(self) -> None:
        self._shutdown = False
        self._lock = threading.Lock()

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> cf.Future[Any]:
        """Run ``fn(*args, **kwargs)`` now; return a finished future holding its outcome."""
        with self._lock:
            if self._shutdown:
                raise RuntimeError("cannot schedule new futures after shutdown")
        future: cf.Future[Any] = cf.Future()
        future.set_running_or_notify_cancel()
        try:
            result = fn(*args, **kwargs)
        except Exception as exc:
            future.set_exception(exc)
        else:
            future.set_result(result)
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Refuse further calls (nothing runs in the background)."""
        with self._lock:
            self._shutdown = True


class Executor:
    """Tasks on a ``concurrent.futures.Executor`` (see the module docstring).

    ``pool`` is the executor to use, or a function making one; with a function, a pool broken
    by a dying worker is replaced by a new one and its tasks run again (up to ``max_restarts``
    times each). ``window`` is how many tasks are submitted ahead of the results (None: all of
    a batch at once; 1 for `SerialPool`, so each result is yielded before the next task runs).
    ``lost`` tells, from an error, whether the pool itself is gone (it returns the error to stop
    with, or None); ``explain`` words the error of a task that raised; ``on_close`` releases
    what the pool depends on (a Dask client).
    ``idle`` is asked every ``poll`` seconds [s] while no result arrives whether to stop
    waiting (it returns the error to stop with, or None: a Dask cluster left without workers).
    ``restarts`` counts the pools recreated after a worker died.
    """

    def __init__(
        self,
        pool: cf.Executor | Callable[[], cf.Executor],
        *,
        max_restarts: int = 3,
        window: int | None = None,
        lost: Callable[[BaseException], ParcelfitError | None] | None = None,
        on_close: Callable[[], None] | None = None,
        explain: Callable[[BaseException], str] | None = None,
        idle: Callable[[], ParcelfitError | None] | None = None,
        poll: float = 2.0,
    ) -> None:
        self._make = None if isinstance(pool, cf.Executor) else pool
        self._pool: cf.Executor = pool if isinstance(pool, cf.Executor) else pool()
        self.max_restarts = max_restarts
        self.window = window
        self._lost = lost or (lambda exc: None)
        self._on_close = on_close
        self._explain = explain or (lambda exc: f"worker failed: {exc!r}")
        self._idle = idle
        self.poll = poll
        self.restarts = 0

    def map(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[int, Outcome[R]]]:
        """Run ``fn(item)`` for every item; yield ``(index, Outcome)`` as results arrive. An
        exception in ``fn`` becomes an outcome with ``error``; a lost pool raises."""
        deaths = [0] * len(items)
        todo = list(range(len(items)))
        while todo:
            futures: dict[cf.Future[R], int] = {}
            queue = deque(todo)
            again: list[int] = []
            broken = self._submit(fn, items, queue, futures, self.window or len(todo))
            asked = time.monotonic()  # when a result last arrived, or `idle` was last asked
            while futures:
                finished, _ = cf.wait(
                    futures,
                    timeout=_TICK_S if self._idle is None else min(self.poll, _TICK_S),
                    return_when=cf.FIRST_COMPLETED,
                )
                if not finished:
                    if self._idle is not None and time.monotonic() >= asked + self.poll:
                        asked = time.monotonic()  # nothing for `poll` seconds: anyone working?
                        stop = self._idle()
                        if stop is not None:
                            raise stop
                    continue
                asked = time.monotonic()
                for fut in sorted(finished, key=futures.__getitem__):
                    i = futures.pop(fut)
                    outcome = self._outcome(fut, deaths, i)
                    if outcome is None:  # its worker died: run it again in a new pool
                        again.append(i)
                        continue
                    yield i, outcome
                if not broken and self.window is not None:
                    broken = self._submit(fn, items, queue, futures, self.window - len(futures))
            again.extend(queue)  # not submitted because the pool broke
            if again:
                self._renew()
            todo = sorted(again)

    def _submit(
        self,
        fn: Callable[[T], R],
        items: Sequence[T],
        queue: deque[int],
        futures: dict[cf.Future[R], int],
        n: int,
    ) -> bool:
        """Submit up to ``n`` more tasks from ``queue``; True if the pool broke meanwhile."""
        for _ in range(max(n, 0)):
            if not queue:
                return False
            try:
                futures[self._pool.submit(fn, items[queue[0]])] = queue[0]
            except cf.BrokenExecutor:
                if self._make is None:
                    raise
                return True  # a worker died already: what is left in the queue is retried
            except Exception as exc:
                raise self._lost(exc) or exc from None
            queue.popleft()
        return False

    def _outcome(self, fut: cf.Future[R], deaths: list[int], i: int) -> Outcome[R] | None:
        try:
            value = fut.result()
        except cf.BrokenExecutor:
            deaths[i] += 1
            if self._make is not None and deaths[i] <= self.max_restarts:
                return None
            return Outcome(
                None,
                f"its worker process died {deaths[i]} times (a crash or an out-of-memory kill "
                "during the simulation)",
                deaths[i],
            )
        except Exception as exc:
            lost = self._lost(exc)
            if lost is not None:
                raise lost from None
            return Outcome(None, self._explain(exc), deaths[i], exc)
        return Outcome(value, None, deaths[i])

    def _renew(self) -> None:
        if self._make is None:
            raise ParcelfitError("the worker pool broke and cannot be recreated")
        _shutdown(self._pool)
        self._pool = self._make()
        self.restarts += 1

    def simulate(
        self, simulator: Simulator, tasks: Sequence[Task]
    ) -> Iterator[tuple[int, SimResult]]:
        """Simulate every task; yield ``(index, SimResult)`` as results arrive. A task that
        could not run is a ``failed`` result; ``worker_restarts`` in the diagnostics says how
        often its worker died first."""
        for i, out in self.map(partial(simulate_task, simulator), tasks):
            result = out.value
            if result is None:
                result = SimResult(None, SimStatus.FAILED, 0.0, {"message": out.error})
            if out.restarts:
                result = replace(
                    result, diagnostics={**result.diagnostics, "worker_restarts": out.restarts}
                )
            yield i, result

    def close(self) -> None:
        """Shut the pool down (cancelling what has not started) and release its resources."""
        with contextlib.suppress(Exception):  # a lost Dask scheduler cannot cancel anything
            _shutdown(self._pool)
        if self._on_close is not None:
            self._on_close()

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _shutdown(pool: cf.Executor) -> None:
    """Shut ``pool`` down, cancelling what has not started, in bounded time (14 s at the very
    most, tens of milliseconds as a rule, whatever the pool's lock, threads and workers do): the
    worker processes of a local pool are ended first (SIGTERM: each kills its external solvers,
    see `parcelfit.sim.lifetime`; SIGKILL for one still there after `_STOP_GRACE_S` s, e.g. a
    worker inside a long C call, where its SIGTERM handler cannot run), so that a simulation
    still running (the pool is closed early: an error, Ctrl-C) does not keep this process from
    exiting; ``shutdown()`` is given at most `_STOP_WAIT_S` s (it takes the pool's lock).

    Then the pool's manager thread is let finish (it does within milliseconds of the workers'
    end), for at most `_STOP_WAIT_S` s: if the interpreter exits first, concurrent.futures' exit
    hook writes to the thread's wake-up pipe as the thread closes it ("OSError: Bad file
    descriptor" after Ctrl-C), or joins the thread without a time limit. A thread still
    reading a result that a worker ended in the middle of sending is freed by closing this
    process's end of the result pipe (it then reads the pipe's end instead of waiting)."""
    workers = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)  # shutdown() forgets these
    results = getattr(pool, "_result_queue", None)
    for process in workers:
        with contextlib.suppress(Exception):  # gone already
            process.terminate()
    _within(_STOP_WAIT_S, partial(_shutdown_now, pool))
    _end(workers)
    if manager is None or manager is threading.current_thread() or not workers:
        return
    manager.join(timeout=1.0)
    if manager.is_alive() and results is not None:
        with contextlib.suppress(Exception):
            results._writer.close()
    manager.join(timeout=_STOP_WAIT_S)


def _shutdown_now(pool: cf.Executor) -> None:
    try:
        pool.shutdown(wait=False, cancel_futures=True)
    except TypeError:  # Dask's executor cancels on shutdown(wait=False) and has no such option
        pool.shutdown(wait=False)


def _within(seconds: float, fn: Callable[[], object]) -> bool:
    """Run ``fn()`` in a daemon thread and wait for it at most ``seconds`` [s]; True if it
    returned (an exception it raises is dropped: this is for cleaning up)."""
    done = threading.Event()

    def run() -> None:
        try:
            with contextlib.suppress(Exception):  # a lost Dask scheduler cannot cancel anything
                fn()
        finally:
            done.set()

    threading.Thread(target=run, name="parcelfit-pool-shutdown", daemon=True).start()
    return done.wait(seconds)


def _end(workers: Sequence[Any]) -> None:
    """Wait up to `_STOP_GRACE_S` [s] for SIGTERMed worker processes to end; SIGKILL the rest."""
    sentinels: dict[Any, Any] = {}
    for process in workers:
        with contextlib.suppress(Exception):  # closed already
            sentinels[process.sentinel] = process
    deadline = time.monotonic() + _STOP_GRACE_S
    while sentinels and (left := deadline - time.monotonic()) > 0:
        for ready in multiprocessing.connection.wait(list(sentinels), timeout=left):
            sentinels.pop(ready, None)
    for process in sentinels.values():
        with contextlib.suppress(Exception):
            process.kill()
    if sentinels:
        multiprocessing.connection.wait(list(sentinels), timeout=1.0)


@contextlib.contextmanager
def _ctrl_c_held() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) off while a worker process starts: the worker inherits the blocked
    signal and ignores it from its initializer on (`_local_worker`), so a Ctrl-C during its
    start (seconds of imports) cannot end it with a traceback; in the main thread an interrupt
    arriving meanwhile is delivered after the worker is registered with its pool (never one
    started but unknown to the pool, which nothing would stop)."""
    if not hasattr(signal, "pthread_sigmask"):  # Windows: no signal masks
        yield
        return
    main = threading.current_thread() is threading.main_thread()
    caught: list[bool] = []
    previous = signal.signal(signal.SIGINT, lambda *_: caught.append(True)) if main else None
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        if main:
            signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)
            if caught:
                signal.raise_signal(signal.SIGINT)


class _LocalPool(cf.ProcessPoolExecutor):
    """The local process pool: each worker is started with Ctrl-C held off (`_ctrl_c_held`)."""

    def _spawn_process(self) -> None:
        with _ctrl_c_held():
            super()._spawn_process()


def _local_worker(parent_pid: int) -> None:
    """Initializer of a local worker process: Ctrl-C (SIGINT, sent to the terminal's whole
    process group) is left to the parent, which stops the workers itself (it was held off
    while the worker started: `_ctrl_c_held`); and the worker dies with its parent
    (`parcelfit.sim.lifetime.die_with_parent`)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # discards a Ctrl-C held off until now
        if hasattr(signal, "pthread_sigmask"):
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    die_with_parent(parent_pid)


class SharedExecutor:
    """One executor for every phase of a command, made by ``make`` when first asked for
    (`get`) and shut down once (`close`): a local pool then starts its worker processes (each
    importing the simulator, seconds) once per command, not once per phase."""

    def __init__(self, make: Callable[[], Executor]) -> None:
        self._make = make
        self._live: Executor | None = None

    def get(self) -> Executor:
        """The executor, made on the first call."""
        if self._live is None:
            self._live = self._make()
        return self._live

    def close(self) -> None:
        """Shut the executor down, if one was made; a later `get` makes a new one."""
        live, self._live = self._live, None
        if live is not None:
            live.close()


def serial_executor() -> Executor:
    """Tasks in this process, one after the other (for debugging and small jobs)."""
    return Executor(SerialPool(), window=1)


def local_executor(workers: int | None = None, max_restarts: int = 3) -> Executor:
    """Tasks in a pool of ``workers`` local processes (default: one per core, at most
    `MAX_WORKERS`); a pool broken by a dying worker is recreated."""
    n = workers or min(os.cpu_count() or 1, MAX_WORKERS)
    if not 1 <= n <= MAX_WORKERS:
        raise ParcelfitError(
            f"{n} worker processes asked for, more than {MAX_WORKERS}",
            fix=f"use from 1 to {MAX_WORKERS} workers",
        )

    def pool() -> cf.Executor:
        return _LocalPool(
            max_workers=n,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_local_worker,
            initargs=(os.getpid(),),
        )

    return Executor(pool, max_restarts=max_restarts)


_QUIET_LOGGERS = ("distributed", "tornado", "asyncio")  # what a Dask client logs with


def _silence(prefixes: Sequence[str]) -> Callable[[], None]:
    """Silence the loggers named ``prefixes`` and their children (those made later too, which
    inherit the level); returns the function that restores them as they were."""
    manager = logging.Logger.manager
    names = [
        name
        for name in list(manager.loggerDict)
        if any(name == p or name.startswith(p + ".") for p in prefixes)
    ]
    loggers = [logging.getLogger(name) for name in {*names, *prefixes}]
    saved = [(logger, logger.level) for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.CRITICAL + 1)

    def restore() -> None:
        for logger, level in saved:
            logger.setLevel(level)

    return restore


def dask_executor(
    scheduler: str | Any,
    retries: int = 2,
    *,
    connect_timeout: float = 10.0,
    worker_wait: float = 60.0,
) -> Executor:
    """Tasks on a Dask cluster: ``scheduler`` is an address (tcp://HOST:8786) or a connected
    ``distributed.Client``. Each task is retried up to ``retries`` times if its worker dies.

    A scheduler that cannot be reached within ``connect_timeout`` [s], or has no worker attached
    after ``worker_wait`` [s], is an error before anything runs; a cluster left without workers
    while tasks are waiting is one after ``worker_wait`` [s] (checked every 2 s), the tasks in
    flight unrecorded.
    """
    try:
        from distributed import Client
    except ImportError as exc:
        raise missing_extra("distributed", exc, extra="dask", what="the dask executor") from exc
    own = not hasattr(scheduler, "submit")
    address = str(scheduler) if own else str(scheduler.scheduler.address)
    # distributed logs its reconnection attempts and tracebacks of its own when the scheduler
    # or the workers go away; parcelfit says what happened in one line instead
    loud = _silence(_QUIET_LOGGERS)
    if own:
        try:
            client = Client(scheduler, timeout=connect_timeout)
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            loud()
            raise ParcelfitError(
                f"cannot reach the Dask scheduler at {scheduler!r} ({exc})",
                fix="check the address (tcp://HOST:8786) and that the scheduler runs",
            ) from None
    else:
        client = scheduler

    def close() -> None:
        try:
            if own:
                with contextlib.suppress(Exception):
                    client.close(timeout=5)
        finally:
            loud()

    try:
        client.wait_for_workers(1, timeout=worker_wait)
    except (TimeoutError, OSError):
        close()
        raise ParcelfitError(
            f"no Dask worker is attached to the scheduler at {address} (waited {worker_wait:g} s)",
            fix=f"start workers, e.g. `dask worker {address}`, then rerun",
        ) from None

    def connected() -> bool:
        comm = getattr(client, "scheduler_comm", None)
        return client.status == "running" and not (
            comm is not None and getattr(comm.comm, "closed", lambda: False)()
        )

    def lost(exc: BaseException) -> ParcelfitError | None:
        if connected():
            return None
        return ParcelfitError(
            f"lost the Dask scheduler at {address} ({type(exc).__name__}); the simulations "
            "in flight were not recorded and stay pending",
            fix="restart the scheduler and workers (or use --executor local), then rerun the "
            "same command: the study resumes",
        )

    def explain(exc: BaseException) -> str:
        if type(exc).__name__ == "KilledWorker":  # the task killed every worker it ran on
            return f"its worker died {retries + 1} times: {exc}"
        return f"dask task failed: {exc!r}"

    alone_since: list[float] = []  # when the cluster was last seen without a worker

    def idle() -> ParcelfitError | None:
        """While results are awaited: stop when no worker has been attached for
        ``worker_wait`` seconds (the scheduler keeps the tasks and waits for ever)."""
        if not connected():  # a lost scheduler is reported by the tasks themselves
            return None
        try:
            workers = int(client.scheduler_info(n_workers=0).get("n_workers", 1))
        except Exception:  # the scheduler did not answer: ask again later
            return None
        if workers:
            alone_since.clear()
            return None
        if not alone_since:
            alone_since.append(time.monotonic())
        if time.monotonic() - alone_since[0] < worker_wait:
            return None
        return ParcelfitError(
            f"no Dask worker has been attached to the scheduler at {address} for "
            f"{worker_wait:g} s, so nothing runs; the simulations in flight were not recorded "
            "and stay pending",
            fix=f"start workers, e.g. `dask worker {address}` (or use --executor local), then "
            "rerun the same command: it resumes",
        )

    pool = client.get_executor(pure=False, retries=retries)
    return Executor(pool, lost=lost, on_close=close, explain=explain, idle=idle)


def make_executor(
    kind: str = "local",
    *,
    workers: int | None = None,
    scheduler: str | Any | None = None,
) -> Executor:
    """The executor named ``kind`` (serial, local or dask); ``workers`` processes for local, a
    ``scheduler`` address (or client) for dask."""
    if kind == "serial":
        return serial_executor()
    if kind == "local":
        return local_executor(workers)
    if kind == "dask":
        if not scheduler:
            raise ParcelfitError(
                "the dask executor needs a scheduler address",
                fix="pass --scheduler tcp://HOST:8786",
            )
        return dask_executor(scheduler)
    raise ParcelfitError(
        f"unknown executor {kind!r}", fix=f"choose one of {', '.join(EXECUTOR_KINDS)}"
    )


__all__ = [
    "EXECUTOR_KINDS",
    "Executor",
    "Outcome",
    "SerialPool",
    "SharedExecutor",
    "Task",
    "dask_executor",
    "local_executor",
    "make_executor",
    "serial_executor",
    "simulate_task",
]
