"""The guide's example of your own Python model (examples/own-model/toy_model.py) works as a
`backend: python` simulator: it runs a case, places its runs by a seed and fails clearly."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from parcelfit.runs import TestCase
from parcelfit.sim.executors import Task
from parcelfit.sim.factory import SimulatorConfig, make_simulator
from parcelfit.study.joint import places_runs, simulate_placed
from parcelfit.study.plausible import placement_seeds

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "own-model"


@pytest.fixture
def model(monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLE))
    return make_simulator(SimulatorConfig(backend="python", factory="toy_model:make"))


def test_the_example_model_runs_a_case_and_places_its_runs(model):
    case = TestCase("toy", "envelope", 1)
    result = model.run({"mu_d_BePa": 0.5}, case)
    assert result.ok and result.run is not None
    assert result.run.transit_time == pytest.approx(1.0 / 0.62)
    traj = result.run.trajectory
    assert traj.theta[0] == pytest.approx(math.radians(30))
    # a higher belt friction turns it faster
    faster = model.run({"mu_d_BePa": 0.6}, case).run.trajectory
    assert faster.theta[-1] < traj.theta[-1]
    # placements: seeds as predict and design draw them (up to 2^31) give starts a few degrees
    # off, each its own; seed s and its mirror -s start off by opposite angles
    assert places_runs(model)
    task = Task({"mu_d_BePa": 0.5}, case, "p")
    seeds = placement_seeds(6, 0)
    assert max(seeds) > 1_000_000
    offsets = []
    for s in seeds:
        a, b = (simulate_placed(model, (task, x)).run.trajectory.theta[0] for x in (s, -s))
        assert a - math.radians(30) == pytest.approx(math.radians(30) - b, abs=1e-12)
        offsets.append(a - math.radians(30))
    assert max(abs(o) for o in offsets) < math.radians(4) and len(set(offsets)) == 6


def test_an_unknown_speed_setting_is_a_failed_run_with_its_message(model):
    result = model.run({}, TestCase("toy", "envelope", 3))
    assert not result.ok and result.diagnostics["message"] == "unknown speed setting"
