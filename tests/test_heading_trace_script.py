"""scripts/heading_trace.py: one placement in the model and in the reference, side by side."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from parcelfit.runs import Trajectory

_SPEC = importlib.util.spec_from_file_location(
    "heading_trace", Path(__file__).parents[1] / "scripts" / "heading_trace.py"
)
heading_trace = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(heading_trace)


def test_samples_are_the_nearest_samples_to_each_multiple_of_the_interval():
    t = np.arange(0.0, 0.51, 1 / 60)
    traj = Trajectory(t, t * 2.0, -t, t * 0.1)
    rows = heading_trace.samples(traj, 0.1)
    assert [r[0] for r in rows] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4, 0.5], abs=1 / 120)
    for r in rows:
        assert r[1] == pytest.approx(2 * r[0]) and r[2] == pytest.approx(-r[0])
        assert r[3] == pytest.approx(math.degrees(0.1 * r[0]))


def test_both_engines_are_traced_from_the_same_start(capsys):
    assert heading_trace.main(["--consignment", "BW", "--seed", "1", "--duration", "0.2"]) == 0
    out = capsys.readouterr().out
    blocks = out.split("reference (rigid box, outline patch)")
    assert len(blocks) == 2 and blocks[0].startswith("model (MuJoCo), E3/BW/1, placement 1: ok")
    firsts = [b.splitlines()[1] for b in blocks]
    assert firsts[0] == firsts[1]  # the same start pose, printed alike
    assert out.count("net rotation") == 2
    assert out.count("guide's lead-in reaches") == 2  # E3's one lead-in, in each engine


def test_the_step_check_runs_the_reference_at_three_steps(capsys):
    args = ["--consignment", "BW", "--seed", "1", "--duration", "0.1", "--step-check"]
    assert heading_trace.main(args) == 0
    last = capsys.readouterr().out.splitlines()[-1]
    assert last.startswith("reference's net rotation at its step")
    turns = [float(t) for t in last.split(":")[1].removesuffix(" deg").split(",")]
    assert len(turns) == 3 and all(0 <= t < 360 for t in turns)


def test_lead_in_reach_is_the_deepest_overlap_of_a_cylinder_and_the_outline():
    size = (0.32, 0.25)
    t = np.array([0.0, 0.1, 0.2])
    traj = Trajectory(t, np.zeros(3), np.zeros(3), np.zeros(3))
    # beside the long side, 4 mm out: 6 mm of a 10 mm radius inside; 5 mm inside: 15 mm
    assert heading_trace.lead_in_reach(traj, size, (0.0, -0.129), 0.01) == pytest.approx((0.006, 0))
    assert heading_trace.lead_in_reach(traj, size, (0.0, -0.12), 0.01)[0] == pytest.approx(0.015)
    # off a corner by (3, 4) mm: 5 mm away, so 5 mm of the radius reaches in
    assert heading_trace.lead_in_reach(traj, size, (0.163, -0.129), 0.01)[0] == pytest.approx(0.005)
    # the body turned by 90 degrees at t = 0.2: the same point now lies off its short end
    turned = Trajectory(t, np.zeros(3), np.zeros(3), np.array([0.0, 0.0, math.pi / 2]))
    depth, when = heading_trace.lead_in_reach(turned, size, (0.0, -0.165), 0.01)
    assert depth == pytest.approx(0.005) and when == pytest.approx(0.2)
    # never near: negative
    assert heading_trace.lead_in_reach(traj, size, (1.0, 1.0), 0.01)[0] < 0


def test_set_reaches_both_engines_in_si_units(monkeypatch, capsys):
    seen = []
    for cls in (heading_trace.MujocoSimulator, heading_trace.RigidBoxSimulator):
        original = cls.run

        def run(self, params, case, *rest, _original=original, _cls=cls):
            seen.append((_cls.__name__, dict(params)))
            return _original(self, params, case, *rest)

        monkeypatch.setattr(cls, "run", run)
    args = ["--consignment", "BW", "--seed", "1", "--duration", "0.05", "--set", "k_MePa=300"]
    assert heading_trace.main(args) == 0
    assert seen == [
        ("MujocoSimulator", {"k_MePa": pytest.approx(3e5)}),
        ("RigidBoxSimulator", {"k_MePa": pytest.approx(3e5)}),
    ]
