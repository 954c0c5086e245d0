"""Sampling time, hand-placement scatter, ensembles, rounded lead-ins and the contact-based
static friction of guide plates."""

import math
from pathlib import Path
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from parcelfit.cli import app
from parcelfit.errors import ParcelfitError
from parcelfit.runs import TestCase, Trajectory, read_trajectory
from parcelfit.sim import SimStatus
from parcelfit.sim.ensemble import Member, ensemble_shift, paired_order, rotation, summarise
from parcelfit.sim.mujoco import MujocoSimulator, SceneOptions, SimOptions, load_rig
from parcelfit.sim.mujoco.rig import SCATTER_CUT, parse_rig
from parcelfit.sim.mujoco.simulator import _FrictionSwitch

from .simhelpers import flat_belt

pytestmark = [pytest.mark.slow, pytest.mark.mujoco]

KPBW = TestCase("flat", "KPBW", 1)


def test_positions_are_labelled_with_their_own_time():
    """A parcel started at belt speed rides with the belt: x(t) = x0 + v t from the first sample
    on (before, every sample after the first belonged to one time step earlier)."""
    v = 0.62
    sim = MujocoSimulator(
        SimOptions(scene=SceneOptions(start_speed_factor=1.0), duration=0.25),
        rigs={"flat": flat_belt(v, barriers=(1.5, 2.0))},
    )
    traj = sim.run({}, KPBW).run.trajectory
    assert traj.t[1] == pytest.approx(1 / 60, abs=1e-9)
    np.testing.assert_allclose(traj.x - traj.x[0], v * traj.t, atol=2e-4)
    speed = np.diff(traj.x) / np.diff(traj.t)
    np.testing.assert_allclose(speed, v, rtol=5e-3)


def _rig(scatter, heading=0.0):
    doc = {
        "name": "s",
        "speeds": {1: {"belt": 1.0}},
        "surfaces": [
            {
                "name": "belt",
                "type": "belt",
                "material": "belt",
                "centre": [0, 0],
                "length": 4,
                "width": 1,
                "heading": heading,
                "top": 0.0,
                "drive": "belt",
            }
        ],
        "start": {"position": [0, 0], "heading": 0, "surface": "belt", "scatter": scatter},
        "light_barriers": [
            {"name": "a", "from": [0.5, -1], "to": [0.5, 1]},
            {"name": "b", "from": [1, -1], "to": [1, 1]},
        ],
        "end": {"x": [-2, 2], "y": [-2, 2], "duration": 1.0, "after_last_barrier": 0.0},
    }
    return parse_rig(doc, "<test rig>")


def test_placement_draws_are_seeded_bounded_and_follow_the_surface():
    rig = _rig({"along": 0.02, "across": 0.01, "heading": 3.0})
    draws = np.array([rig.placement(s) for s in range(400)])
    assert rig.placement(7) == rig.placement(7)
    assert len({tuple(d) for d in draws}) == 400
    sd = draws.std(axis=0)
    assert sd == pytest.approx([0.02, 0.01, 3.0], rel=0.12)
    assert np.all(np.abs(draws) <= SCATTER_CUT * np.array([0.02, 0.01, 3.0]) + 1e-12)
    # along/across follow the start surface's heading: a belt at 90 degrees swaps x and y
    turned = _rig({"along": 0.02, "across": 0.0, "heading": 0.0}, heading=90.0)
    dx, dy, dh = turned.placement(3)
    assert abs(dx) < 1e-12 and dy != 0 and dh == 0
    assert _rig(None).placement(5) == (0.0, 0.0, 0.0)


def test_bad_scatter_is_one_clear_message():
    with pytest.raises(ParcelfitError, match=r"start\.scatter"):
        _rig({"along": -1})
    with pytest.raises(ParcelfitError, match=r"start\.scatter"):
        _rig({"sideways": 0.01})


def test_placement_seed_moves_the_start_and_reproduces_it():
    e3 = load_rig("E3")
    sim = MujocoSimulator()
    case = TestCase("E3", "KPBW", 1)
    nominal = sim.scene({}, case).xml
    a, b = sim.with_placement(1).scene({}, case).xml, sim.with_placement(2).scene({}, case).xml
    assert a != nominal and a != b
    assert a == sim.with_placement(1).scene({}, case).xml
    assert e3.start.scatter != (0.0, 0.0, 0.0)


def test_lead_in_is_a_rounded_end_of_the_plate():
    doc = yaml.safe_load(
        (Path(__file__).parents[1] / "src/parcelfit/sim/mujoco/rigs/E3.yaml").read_text()
    )
    doc["walls"][0]["lead_in"] = 0.01
    rig = parse_rig(doc, "<test rig>")
    assert rig.walls[0].lead_in == 0.01
    sim = MujocoSimulator(rigs={"E3": rig})
    xml = sim.scene({}, TestCase("E3", "KPBW", 1)).xml
    assert 'name="guide_lead_in" type="cylinder" size="0.01 0.048"' in xml
    model = mujoco.MjModel.from_xml_string(xml)
    assert model.geom("guide_lead_in").id >= 0
    doc["walls"][0]["lead_in"] = -0.01
    with pytest.raises(ParcelfitError, match="lead_in"):
        parse_rig(doc, "<test rig>")


def _member(seed, rot_deg, transit):
    return Member(
        seed=seed,
        status=SimStatus.OK if rot_deg is not None else SimStatus.UNSTABLE,
        transit_time=transit,
        rotation=None if rot_deg is None else math.radians(rot_deg),
        run=None,
        wall_time=1.0,
    )


def test_paired_order_counts_matched_placements_and_gives_the_sign_test():
    """Seed by seed: b further at 3 seeds, a at 1, one tie (0.2 degrees), a failed run and a
    seed only b has left out; the two-sided sign test of 3 of 4 is 0.625."""
    a = [_member(0, 20, 1.2), _member(1, 25, 1.2), _member(2, 30, 1.2), _member(3, 110, 1.5)]
    a += [_member(4, 22, 1.2), _member(5, None, None)]
    b = [_member(0, 22, 1.2), _member(1, 25.2, 1.2), _member(2, 29, 1.2), _member(3, 200, 1.6)]
    b += [_member(4, 23, 1.2), _member(5, 40, 1.2), _member(9, 100, 1.4)]
    order = paired_order(a, b)
    assert (order.n_pairs, order.b_further, order.a_further, order.ties) == (5, 3, 1, 1)
    assert order.p_value == pytest.approx(0.625)
    assert math.degrees(order.median_difference) == pytest.approx(1.0)
    reverse = paired_order(b, a)
    assert (reverse.b_further, reverse.a_further) == (1, 3)
    tied = paired_order(a[:2], a[:2])
    assert tied.ties == 2 and math.isnan(tied.p_value)
    twenty = paired_order(
        [_member(i, 20, 1.2) for i in range(20)], [_member(i, 22, 1.2) for i in range(20)]
    )
    assert twenty.p_value == pytest.approx(2 * 0.5**20)


def test_ensemble_summary_statistics():
    members = [
        _member(0, 10, 1.20),
        _member(1, 20, 1.22),
        _member(2, 100, 1.30),
        _member(3, 200, 1.40),
        _member(4, None, None),
    ]
    st = summarise(members)
    assert (st.n, st.n_ok, st.spins, st.slides) == (5, 4, 2, 2)
    assert math.degrees(st.rotation_median) == pytest.approx(60.0)
    assert st.share_over_90 == pytest.approx(0.5) and st.share_over_180 == pytest.approx(0.25)
    assert st.transit_median == pytest.approx(1.26)
    assert st.transit_sem == pytest.approx(np.std([1.2, 1.22, 1.3, 1.4], ddof=1) / 2)
    assert st.rank_correlation == pytest.approx(1.0)
    assert members[4].outcome == "failed"


def test_ensemble_shift_pairs_placements_and_bounds_its_error():
    a = [_member(i, r, t) for i, (r, t) in enumerate([(10, 1.2), (20, 1.3), (30, 1.4), (40, 1.5)])]
    # b: every run 5 degrees more and 10 ms slower, placement 1 now spins, placement 3 failed,
    # and a placement a does not have
    b = [
        _member(0, 15, 1.21),
        _member(1, 120, 1.31),
        _member(2, 35, 1.41),
        _member(3, None, None),
        _member(9, 300, 2.0),
    ]
    sh = ensemble_shift(a, b, seed=1)
    assert sh.n_pairs == 3  # seeds 0, 1, 2
    # medians over the matched pairs: a 20 deg / 1.3 s, b 35 deg / 1.31 s
    assert math.degrees(sh.rotation_median) == pytest.approx(15.0)
    assert sh.transit_median == pytest.approx(0.01)
    assert sh.spin_share == pytest.approx(1 / 3)
    assert sh.rotation_median_se > 0 and sh.spin_share_se > 0
    assert ensemble_shift(a, b, seed=1) == sh  # seeded bootstrap
    # a constant shift of every pair has no sampling error
    c = [_member(m.seed, math.degrees(m.rotation) + 2, m.transit_time + 0.005) for m in a]
    same = ensemble_shift(a, c)
    assert same.transit_median == pytest.approx(0.005)
    assert same.spin_share == 0 and same.spin_share_se == 0
    assert same.transit_median_se == pytest.approx(0.0, abs=1e-12)
    # no common placement: nothing measured
    assert math.isnan(ensemble_shift(a, [_member(7, 1, 1.0)]).rotation_median)


def test_rotation_is_the_net_unwrapped_turn():
    t = np.arange(50) / 60
    theta = np.linspace(0, 3 * math.pi / 2, 50)  # 270 degrees, wrapped in the file
    wrapped = (theta + math.pi) % (2 * math.pi) - math.pi
    traj = Trajectory.from_arrays(t, t, 0 * t, wrapped)
    assert math.degrees(rotation(traj)) == pytest.approx(270.0, abs=1e-6)


def _box_on_metal(v0, stick_speed=SceneOptions.stick_speed, slip_speed=None):
    xml = """<mujoco><option timestep="0.002" cone="elliptic"/><worldbody>
    <geom name="plate" type="plane" size="2 2 .1" friction="0.2 0.005 0.0001" priority="2"/>
    <body pos="0 0 0.0495"><freejoint/><geom type="box" size=".05 .05 .05" mass="0.2"/></body>
    </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qvel[0] = v0
    for _ in range(20):
        mujoco.mj_step(model, data)
    scene = SimpleNamespace(metal_geoms=("plate",), driven=())
    params = {"mu_d_MePa": 0.2, "mu_s_MePa": 0.3, "mu_d_BePa": 0.4, "mu_s_BePa": 0}
    switch = _FrictionSwitch(model, scene, None, params, stick_speed, slip_speed)
    switch.update(model, data, np.zeros(2), np.zeros(2))
    return float(model.geom_friction[model.geom("plate").id, 0])


def test_static_friction_follows_the_slip_of_the_contacts_on_the_plate():
    """A packaging at rest on a metal surface sticks (friction mu_d + offset); one sliding over
    it at 1 m/s, far above the stick speed, has mu_d."""
    assert SceneOptions().stick_speed < 0.01 and SceneOptions().slip_speed is None
    assert _box_on_metal(0.0) == pytest.approx(0.5, abs=1e-3)
    assert _box_on_metal(1.0) == pytest.approx(0.2, abs=1e-6)
    assert _box_on_metal(0.3) == pytest.approx(0.2, abs=1e-6)  # sliding at about 0.22 m/s


def test_a_slip_speed_lets_the_static_offset_act_on_slow_sliding_and_fade_by_it():
    """With stick_speed 0.1 and slip_speed 1 m/s (a multibody solver's velocity-dependent
    friction): the whole offset at rest, nearly all of it sliding at about 0.22 m/s (cubic step:
    0.95), a few hundredths of it at about 0.92 m/s, none above 1 m/s."""
    law = {"stick_speed": 0.1, "slip_speed": 1.0}
    assert _box_on_metal(0.0, **law) == pytest.approx(0.5, abs=1e-3)
    assert 0.2 + 0.3 * 0.93 < _box_on_metal(0.3, **law) < 0.2 + 0.3 * 0.97
    assert 0.2 < _box_on_metal(1.0, **law) < 0.2 + 0.3 * 0.05
    assert _box_on_metal(1.5, **law) == pytest.approx(0.2, abs=1e-6)
    with pytest.raises(ParcelfitError, match="slip_speed must exceed stick_speed"):
        SceneOptions(stick_speed=0.1, slip_speed=0.05)
    with pytest.raises(ParcelfitError, match="stick_speed must be positive"):
        SceneOptions(stick_speed=0)


@pytest.mark.longest
def test_simulate_repeat_writes_an_ensemble_reproducible_per_seed(tmp_path):
    runner = CliRunner()
    out = tmp_path / "run.csv"
    # a coarser step than the default: the test is about seeds and files, not convergence
    args = ["simulate", "--rig", "E1", "--consignment", "BW", "--timestep", "0.000833333333"]
    args += ["--out", str(out)]
    result = runner.invoke(app, [*args, "--seed", "4", "--repeat", "2", "--workers", "1"])
    assert result.exit_code == 0, result.output
    assert "2 slides" in result.output or "spins" in result.output
    table = (tmp_path / "run-ensemble.csv").read_text().splitlines()
    assert table[0].startswith("seed,status,transit_time_s,rotation_deg,outcome")
    assert [line.split(",")[0] for line in table[1:]] == ["4", "5"]
    a, b = read_trajectory(tmp_path / "run-s4.csv"), read_trajectory(tmp_path / "run-s5.csv")
    assert not np.allclose(a.y[:5], b.y[:5])
    single = tmp_path / "single.csv"
    result = runner.invoke(app, [*args[:-1], str(single), "--seed", "5"])
    assert result.exit_code == 0, result.output
    again = read_trajectory(single)
    np.testing.assert_array_equal(again.x, b.x)
    np.testing.assert_array_equal(again.theta, b.theta)


def test_every_under_converged_step_is_counted_and_the_default_leaves_none():
    """MuJoCo prints its singular/under-converged effective-inertia warning once per run but
    flags every step; the diagnostics count the steps. At the default iteration cap the
    polybag's 3-D content is solved to tolerance on every step; at the former cap of 50 it was
    under-converged on every step."""
    sim = MujocoSimulator(SimOptions(duration=0.1))  # 120 steps around the soft content
    rigid = sim.run({}, TestCase("E3", "KPBW", 1)).diagnostics
    assert rigid["under_converged_steps"] == 0
    soft = sim.run({}, TestCase("E3", "PB", 1)).diagnostics
    assert soft["steps"] >= 100 and soft["under_converged_steps"] == 0
    capped = MujocoSimulator(SimOptions(scene=SceneOptions(iterations=50), duration=0.1))
    low = capped.run({}, TestCase("E3", "PB", 1)).diagnostics
    assert low["steps"] - 2 <= low["under_converged_steps"] <= low["steps"] + 2
    assert low["mujoco_warnings"] >= 1
