"""The one executor over any concurrent.futures.Executor: serial, threads, processes."""

from concurrent.futures import ThreadPoolExecutor

import pytest

from parcelfit import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim import SimStatus
from parcelfit.sim.executors import Executor, Task, make_executor, serial_executor

from .fake_sim import AnalyticSimulator, trajectory


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
    result = Calibration(study, tmp_path / "out").run()
    assert result.evaluations == 12 and result.stop_reason == "budget spent"
    by_status = study_status(tmp_path / "out").by_status
    assert sum(by_status.values()) == 12 and "failed" not in by_status
