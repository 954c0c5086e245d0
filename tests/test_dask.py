"""Scale-out on Dask: a LocalCluster on loopback stands in for a cluster."""

import os
import signal
import time

import pytest

distributed = pytest.importorskip("distributed")

from parcelfit.runs import TestCase  # noqa: E402
from parcelfit.sim.executors import Task, dask_executor  # noqa: E402
from parcelfit.study.calibration import Calibration  # noqa: E402
from parcelfit.study.studyfile import load_study  # noqa: E402

from .fake_sim import AnalyticSimulator  # noqa: E402
from .helpers import write_study  # noqa: E402

pytestmark = [pytest.mark.slow]


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as c:
        yield c


def test_killed_worker_costs_time_not_results(cluster, tmp_path):
    log = tmp_path / "log"
    with distributed.Client(cluster) as client:
        executor = dask_executor(client)
        sim = AnalyticSimulator(delay=1.0, log=str(log))
        tasks = [
            Task({"mu_d_BePa": 0.4 + 0.01 * i, "mu_d_MePa": 0.2}, TestCase("R", "P", 1), f"t{i}")
            for i in range(6)
        ]
        results = {}
        killed = False
        for i, res in executor.simulate(sim, tasks):
            results[i] = res
            if not killed:  # kill one worker while the others' tasks are still running
                victim = next(iter(cluster.workers.values()))
                os.kill(victim.process.process.pid, signal.SIGKILL)
                killed = True
        assert sorted(results) == list(range(6))
        assert all(r.ok for r in results.values())
        assert [results[i].run.transit_time for i in range(6)] == sorted(
            results[i].run.transit_time for i in range(6)
        )
        simulated = log.read_text().split()
        assert set(simulated) == {f"t{i}" for i in range(6)}
        # the victim was busy (four tasks were still queued): its task started again elsewhere
        assert len(simulated) > 6


def test_calibration_through_a_scheduler_address(cluster, tmp_path):
    study = load_study(write_study(tmp_path, budget=12, validation={}))
    t0 = time.time()
    result = Calibration(
        study,
        tmp_path / "out",
        executor="dask",
        scheduler=cluster.scheduler_address,
        figures=False,
    ).run()
    assert result.evaluations == 12 and result.best_cost is not None
    assert time.time() - t0 < 120
