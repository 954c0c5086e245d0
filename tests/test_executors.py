"""The one executor over any concurrent.futures.Executor: serial, threads, processes."""

from concurrent.futures import ThreadPoolExecutor

import pytest

from parcelfit import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim import SimStatus
from parcelfit.sim.executors import Executor, Task, make_executor, serial_executor

from .fake_sim import AnalyticSimulator, trajectory
from .helpers import CountedExecutors


def _tasks(n):
    return [
        Task({"mu_d_BePa": 0.4 + 0.05 * i, "mu_d_MePa": 0.2}, TestCase("R", "P", 1), f"t{i}")
        for i in range(n)
    ]


def test_serial_runs_in_this_process_one_task_after_the_other():
    started = []

    class Local:  # a closure-holding simulator: not picklable, fine in this process
        def run(self, params, case, run_id=None):
            started.append(run_id)
            return AnalyticSimulator().run(params, case, run_id)

    tasks = _tasks(3)
    seen = []
    with serial_executor() as ex:
        for i, result in ex.simulate(Local(), tasks):
            seen.append((i, list(started)))  # each result before the next task starts
            assert result.run.transit_time == pytest.approx(trajectory(tasks[i].params, 1)[1])
    assert seen == [(0, ["t0"]), (1, ["t0", "t1"]), (2, ["t0", "t1", "t2"])]


def test_a_task_that_raises_is_an_outcome_not_an_exception_and_ctrl_c_stops():
    def fn(x):
        if x == 1:
            raise ValueError("bad")
        if x == 3:
            raise KeyboardInterrupt
        return 10 * x

    with serial_executor() as ex:
        out = dict(ex.map(fn, [0, 1, 2]))
        assert out[0].value == 0 and out[2].value == 20
        assert out[1].value is None and out[1].error == "worker failed: ValueError('bad')"
        done = []
        with pytest.raises(KeyboardInterrupt):
            for i, o in ex.map(fn, [2, 3, 0]):
                done.append((i, o.value))
        assert done == [(0, 20)]  # what finished before the interrupt was delivered


def test_any_concurrent_futures_executor_works_and_failures_become_failed_results():
    ex = Executor(ThreadPoolExecutor(2))
    tasks = [*_tasks(3), Task({"mu_d_BePa": 0.6, "mu_d_MePa": 0.2}, TestCase("R", "P", 1), "x")]
    with ex:
        results = dict(ex.simulate(AnalyticSimulator(), tasks))
        broken = dict(ex.simulate(None, tasks[:1]))  # no simulator: the task raises in its worker
    assert sorted(results) == [0, 1, 2, 3]
    assert [results[i].ok for i in range(4)] == [True, True, True, False]
    assert results[3].status is SimStatus.UNSTABLE
    assert (
        broken[0].status is SimStatus.FAILED
        and "AttributeError" in broken[0].diagnostics["message"]
    )


def test_executor_kinds_and_the_study_file_shorthand(tmp_path):
    from parcelfit.study.studyfile import load_study

    from .helpers import write_study

    assert make_executor("serial").window == 1
    with pytest.raises(ParcelfitError, match="needs a scheduler address"):
        make_executor("dask")
    with pytest.raises(ParcelfitError, match="unknown executor 'cloud'"):
        make_executor("cloud")
    assert load_study(write_study(tmp_path, executor="serial")).executor == {
        "kind": "serial",
        "workers": None,
        "scheduler": None,
    }
    with pytest.raises(ParcelfitError, match="executor"):
        load_study(write_study(tmp_path, executor={"kind": "threads"}))


@pytest.mark.slow
def test_a_calibration_runs_in_process_with_the_serial_executor(tmp_path):
    from parcelfit.study.calibration import Calibration
    from parcelfit.study.status import study_status
    from parcelfit.study.studyfile import load_study

    from .helpers import write_study

    study = load_study(write_study(tmp_path, budget=12, validation={}, executor="serial"))
    result = Calibration(study, tmp_path / "out", figures=False).run()
    assert result.evaluations == 12 and result.stop_reason == "budget spent"
    by_status = study_status(tmp_path / "out").by_status
    assert sum(by_status.values()) == 12 and "failed" not in by_status


# -- Ctrl-C and closing a pool: nothing waits without a bound ------------------------------------


def test_ctrl_c_delivered_to_another_thread_stops_the_wait_for_results(ctrl_c):
    """The kernel hands a Ctrl-C (SIGINT) to any thread of the process that does not block it;
    the main thread, waiting for results, must act on it without waiting for the running task
    (a pool's manager and feeder threads are such other threads)."""
    import signal
    import threading
    import time

    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signal handlers run in the main thread only")
    release = threading.Event()

    def task(_):  # a simulation of minutes
        release.wait(20)
        return 1

    def bystander():  # another thread of this process receives the Ctrl-C
        time.sleep(0.3)  # the main thread waits for the task's result by now
        signal.pthread_kill(threading.get_ident(), signal.SIGINT)

    ex = Executor(ThreadPoolExecutor(1))
    other = threading.Thread(target=bystander, daemon=True)
    t0 = time.monotonic()
    try:
        other.start()
        with pytest.raises(KeyboardInterrupt):
            for _ in ex.map(task, [0]):
                pass
        waited = time.monotonic() - t0
    finally:
        release.set()
        other.join()
        ex.close()
    assert waited < 10  # not the task's 20 s


def test_ctrl_c_is_held_off_while_a_worker_starts_and_delivered_after(ctrl_c):
    import signal
    import threading

    from parcelfit.sim.executors import _ctrl_c_held

    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signal handlers run in the main thread only")
    handler = signal.getsignal(signal.SIGINT)
    reached = []
    with pytest.raises(KeyboardInterrupt), _ctrl_c_held():
        signal.raise_signal(signal.SIGINT)  # Ctrl-C while the worker is being started
        reached.append(True)  # the start is not cut short
    assert reached == [True]
    assert signal.getsignal(signal.SIGINT) is handler


def _abs(x):
    return abs(x)


def test_ctrl_c_while_a_local_worker_starts_does_not_reach_it(capfd, ctrl_c):
    """Ctrl-C goes to the terminal's whole process group, workers too; one still starting
    (seconds of imports) must not die of it with a traceback (the pool would break)."""
    import contextlib
    import os
    import signal
    import threading
    import time

    import psutil

    from parcelfit.sim.executors import local_executor

    me = psutil.Process()
    before = {c.pid for c in me.children()}
    handler = signal.getsignal(signal.SIGINT)
    hit: list[int] = []
    stop = threading.Event()

    def interrupt_new_workers() -> None:  # SIGINT to each new worker the moment it runs Python
        while not stop.is_set():
            for child in me.children():
                if child.pid in before or child.pid in hit:
                    continue
                with contextlib.suppress(psutil.Error):
                    if "spawn_main" in " ".join(child.cmdline()):
                        os.kill(child.pid, signal.SIGINT)
                        hit.append(child.pid)
            time.sleep(0.005)

    ex = local_executor(1)
    interrupter = threading.Thread(target=interrupt_new_workers, daemon=True)
    try:
        interrupter.start()
        out = [o for _, o in ex.map(_abs, [-3])]
    finally:
        stop.set()
        interrupter.join()
        ex.close()
    assert hit  # the worker was interrupted while it started
    assert [o.value for o in out] == [3] and ex.restarts == 0
    assert "Traceback" not in capfd.readouterr().err
    assert signal.getsignal(signal.SIGINT) is handler


def _deaf_to_sigterm(pid_file):
    """Stands for a worker inside a long C call (a simulation step), where the Python handler
    of SIGTERM cannot run: it ignores SIGTERM, says its pid and runs for a minute."""
    import os
    import signal
    import time
    from pathlib import Path

    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    tmp = Path(f"{pid_file}.tmp")  # written whole, then renamed: the test never reads it empty
    tmp.write_text(str(os.getpid()))
    os.replace(tmp, pid_file)
    time.sleep(60)
    return 0


def test_closing_a_local_pool_ends_a_worker_that_does_not_end_on_sigterm(tmp_path, monkeypatch):
    import contextlib
    import os
    import signal
    import threading
    import time

    import psutil

    import parcelfit.sim.executors as executors

    monkeypatch.setattr(executors, "_STOP_GRACE_S", 0.5)
    ex = executors.local_executor(1, max_restarts=0)
    pid_file = tmp_path / "pid"
    out: list = []
    runner = threading.Thread(
        target=lambda: out.extend(ex.map(_deaf_to_sigterm, [str(pid_file)])), daemon=True
    )
    runner.start()
    deadline = time.monotonic() + 60
    while not pid_file.exists() and time.monotonic() < deadline:
        time.sleep(0.02)
    pid = int(pid_file.read_text())
    try:
        ex.close()
        with contextlib.suppress(psutil.NoSuchProcess, psutil.TimeoutExpired):
            psutil.Process(pid).wait(timeout=10)
        alive = psutil.pid_exists(pid) and psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
        runner.join(30)
    assert not alive
    (outcome,) = [o for _, o in out]  # the task is reported, not retried in a new pool
    assert outcome.value is None and "died" in outcome.error


def test_closing_a_pool_frees_its_manager_thread_from_a_half_sent_result():
    """A worker ended in the middle of sending its result leaves a message's length and part of
    it in the result pipe: the pool's manager thread waits for the rest, for ever, and the
    interpreter would wait for the thread when it exits. Closing the executor frees it."""
    import contextlib
    import os
    import struct

    from parcelfit.sim.executors import local_executor

    ex = local_executor(1)
    manager = None
    try:
        assert [o.value for _, o in ex.map(_abs, [-2])] == [2]
        pool = ex._pool
        manager = pool._executor_manager_thread
        writer = pool._result_queue._writer
        os.write(writer.fileno(), struct.pack("!i", 1 << 20) + b"\x80")  # 1 MiB announced
        ex.close()
        stuck = manager.is_alive()
    finally:
        if manager is not None and manager.is_alive():  # free it, whatever the outcome
            with contextlib.suppress(OSError):
                writer.close()
            manager.join(10)
    assert not stuck


# -- one executor per command ----------------------------------------------------------------


def test_a_shared_executor_is_made_on_first_use_and_closed_once():
    from parcelfit.sim.executors import SharedExecutor

    counted = CountedExecutors(serial_executor)
    shared = SharedExecutor(counted)
    assert counted.made == 0  # nothing made before it is asked for
    first = shared.get()
    assert shared.get() is first and counted.made == 1
    shared.close()
    shared.close()
    assert counted.closed == 1
    assert shared.get() is not first and counted.made == 2  # a new one after closing
    shared.close()
    assert counted.closed == 2


def test_a_calibration_makes_one_executor_for_its_loop_validations_and_checks(
    tmp_path, monkeypatch
):
    """The fitting loop, the validations and the convergence check (its refined run) share one
    executor: a local pool starts its worker processes once per run, and it is closed once."""
    import parcelfit.study.calibration as calibration
    from parcelfit.study.results import read_results
    from parcelfit.study.studyfile import load_study

    from .helpers import write_study

    counted = CountedExecutors(calibration.study_executor)
    monkeypatch.setattr(calibration, "study_executor", counted)
    study = load_study(write_study(tmp_path, budget=8, executor="serial"))
    calibration.Calibration(study, tmp_path / "out", figures=False).run()
    results = read_results(tmp_path / "out")
    assert results is not None and results.validations and results.convergence is not None
    assert results.convergence.runs  # the refined model ran after the loop
    assert (counted.made, counted.closed) == (1, 1)


def test_a_calibration_stopped_by_an_error_closes_its_executor_once(tmp_path, monkeypatch):
    """An error in the loop (here raised by the progress display) closes the executor once and
    releases the folder: the rerun resumes."""
    import parcelfit.study.calibration as calibration
    from parcelfit.study.studyfile import load_study

    from .helpers import write_study

    counted = CountedExecutors(calibration.study_executor)
    monkeypatch.setattr(calibration, "study_executor", counted)
    study = load_study(write_study(tmp_path, budget=8, executor="serial"))

    def stop(event):
        if event.done >= 2:
            raise RuntimeError("display gone")

    with pytest.raises(RuntimeError, match="display gone"):
        calibration.Calibration(study, tmp_path / "out", figures=False, progress=stop).run()
    assert (counted.made, counted.closed) == (1, 1)
    result = calibration.Calibration(study, tmp_path / "out", figures=False).run()
    assert result.evaluations == 8 and (counted.made, counted.closed) == (2, 2)
