"""Drives off their mean speeds: the rig's seeded speed factors and the placed simulation that
applies them (`parcelfit.sim.mujoco.rig.Rig.speed_factors`, `parcelfit.study.joint`)."""

from __future__ import annotations

import numpy as np
import pytest

from parcelfit.runs import TestCase
from parcelfit.sim.executors import Task
from parcelfit.sim.mujoco import load_rig
from parcelfit.sim.protocol import SimResult, SimStatus
from parcelfit.study.joint import simulate_placed, varies_drives


def test_speed_factors_are_seeded_uniform_draws_per_drive():
    rig = load_rig("E3")
    a = rig.speed_factors(7, 0.03)
    assert list(a) == rig.drives() and len(a) >= 2
    assert a == rig.speed_factors(7, 0.03)  # the seed decides
    assert a != rig.speed_factors(8, 0.03)
    assert all(0.97 <= f <= 1.03 for f in a.values())
    assert all(f == 1.0 for f in rig.speed_factors(7, 0.0).values())
    many = np.array([list(rig.speed_factors(s, 0.03).values()) for s in range(400)])
    # U(-0.03, 0.03): mean 0, sd 0.03 / sqrt(3)
    assert abs(many.mean() - 1.0) < 0.002
    assert many.std() == pytest.approx(0.03 / np.sqrt(3), rel=0.1)


def test_a_negative_seed_mirrors_the_placement_and_the_drives_of_the_positive_one():
    rig = load_rig("E3")  # a rig with a hand-placement scatter along, across and in heading
    for seed in (1, 2, 17):
        dx, dy, dh = rig.placement(seed)
        assert (dx, dy, dh) != (0.0, 0.0, 0.0)
        assert rig.placement(-seed) == (-dx, -dy, -dh)
        f, g = rig.speed_factors(seed, 0.03), rig.speed_factors(-seed, 0.03)
        assert list(g) == list(f)
        for d in f:  # the deviations cancel: a pair of runs averages to the mean speed
            assert f[d] + g[d] == pytest.approx(2.0, abs=1e-15)


class _Recorder:
    """A simulator that records its placement and drive factors in the run's diagnostics."""

    def __init__(self, seed=None, factors=None):
        self.seed, self.factors = seed, factors

    def with_placement(self, seed):
        return _Recorder(seed, self.factors)

    def with_speed_factors(self, factors):
        return _Recorder(self.seed, dict(factors))

    def rig(self, name):
        return load_rig(name)

    def run(self, params, case, run_id=None):
        return SimResult(None, SimStatus.FAILED, 0.0, {"seed": self.seed, "f": self.factors})


def test_a_placed_simulation_runs_its_drives_off_their_mean_speed():
    task = Task({}, TestCase("E3", "KPBW", 1), "x")
    sim = _Recorder()
    assert varies_drives(sim)
    out = simulate_placed(sim, (task, 5), speed_deviation=0.03)
    assert out.diagnostics["seed"] == 5
    assert out.diagnostics["f"] == load_rig("E3").speed_factors(5, 0.03)
    # without a deviation, or at the nominal placement, the drives run at their mean speed
    assert simulate_placed(sim, (task, 5)).diagnostics["f"] is None
    assert simulate_placed(sim, (task, None), speed_deviation=0.03).diagnostics["f"] is None


def test_the_mujoco_model_and_the_reference_take_the_factors():
    from parcelfit.sim.mujoco.simulator import MujocoSimulator
    from parcelfit.sim.rigidbox.simulator import RigidBoxSimulator

    f = {"main": 1.02}
    assert MujocoSimulator().with_speed_factors(f).options.scene.speed_factors == f
    assert RigidBoxSimulator().with_speed_factors(f).options.speed_factors == f
    assert varies_drives(MujocoSimulator()) and varies_drives(RigidBoxSimulator())


@pytest.mark.parametrize("value", [-0.01, 1.0, float("nan")])
def test_a_speed_deviation_out_of_range_is_refused_before_anything_runs(tmp_path, value):
    from parcelfit.errors import ParcelfitError
    from parcelfit.study.design import rank_experiments
    from parcelfit.study.predict import predict

    from .predict_helpers import write_finished_study, write_rig_q

    folder = write_finished_study(tmp_path)
    rig = str(write_rig_q(tmp_path))
    with pytest.raises(ParcelfitError, match="--speed-deviation"):
        predict(folder, rig, "KPBW", 1, speed_deviation=value, out=tmp_path / "p")
    with pytest.raises(ParcelfitError, match="--speed-deviation"):
        rank_experiments(folder, candidates=["E1/KPBW/1"], speed_deviation=value)
    assert not (tmp_path / "p").exists()
