"""scripts/wall_impact.py: a parcel carried into a metal wall, in the model and in the reference."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from parcelfit.runs import Trajectory
from parcelfit.sim.mujoco import load_rig

_SPEC = importlib.util.spec_from_file_location(
    "wall_impact", Path(__file__).parents[1] / "scripts" / "wall_impact.py"
)
wall_impact = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(wall_impact)

L, W = 0.32, 0.25  # KP's outer size [m]


@pytest.mark.parametrize("wall", [90.0, 16.0])
@pytest.mark.parametrize("angle", [0.0, 8.0, 20.0])
def test_the_parcel_starts_its_gap_from_the_wall_on_a_valid_rig(tmp_path, wall, angle):
    doc = wall_impact.wall_rig(L, W, angle, 1.0, wall)
    path = tmp_path / "wall.yaml"
    path.write_text(yaml.safe_dump(doc))
    rig = load_rig(path)  # a rig file parcelfit accepts
    assert rig.start.heading == pytest.approx(wall - angle)
    # the start's corners: the nearest lies GAP from the wall's face, on the side it comes from
    _, n = wall_impact._axes(wall)
    h = math.radians(wall - angle)
    u, v = np.array([math.cos(h), math.sin(h)]), np.array([-math.sin(h), math.cos(h)])
    centre = np.array(doc["start"]["position"])
    corners = [centre + a * L / 2 * u + b * W / 2 * v for a in (-1, 1) for b in (-1, 1)]
    face = float(np.array(wall_impact.WALL_POINT) @ n) + wall_impact.WALL_THICKNESS / 2
    gaps = [float(c @ n) - face for c in corners]
    assert min(gaps) == pytest.approx(wall_impact.GAP, abs=2e-6)
    # the belt carries it towards the wall: +x has a component against n
    assert n[0] < 0


def test_measures_of_a_bounce_turn_and_settle():
    # square wall (90 degrees): the centre comes at 0.4 m/s, leaves at 0.1 m/s for 20 ms, then
    # the belt brings it back; the heading turns from -20 degrees past flush to +3, then to 0
    dt = 1 / 2400
    t = np.arange(0.0, 0.3, dt)
    vx = np.where(t < 0.1, 0.4, np.where(t < 0.12, -0.1, 0.0))
    x = np.concatenate([[0.0], np.cumsum(vx[:-1] * dt)])
    turn = np.interp(t, [0.0, 0.1, 0.14, 0.2, 0.3], [-20.0, -20.0, 3.0, 0.0, 0.0])
    traj = Trajectory(t, x, np.zeros_like(t), np.radians(90.0 + turn))
    m = wall_impact.measures(traj, (L, W), 20.0, 0.4, 90.0, 0.05)
    assert m["rebound"] == pytest.approx(0.25, abs=1e-6)
    assert m["overshoot"] == pytest.approx(3.0, abs=1e-6)
    assert m["final"] == pytest.approx(0.0, abs=1e-9)
    assert m["end rate"] == pytest.approx(0.0, abs=1e-6)  # settled over the last 20 ms
    assert m["spin"] == pytest.approx(23.0 / 0.04, rel=1e-3)  # the fastest turn [deg/s]
    # started turned the other way (its rear corner towards the wall): past flush is positive
    mirrored = Trajectory(t, x, np.zeros_like(t), np.radians(90.0 - turn))
    assert wall_impact.measures(mirrored, (L, W), -20.0, 0.4, 90.0, 0.05)["overshoot"] == (
        pytest.approx(3.0, abs=1e-6)
    )
    # carried at the belt's speed throughout: no strike, no rebound
    calm = Trajectory(t, 0.4 * t, np.zeros_like(t), np.full_like(t, math.pi / 2))
    assert math.isnan(wall_impact.measures(calm, (L, W), 0.0, 0.4, 90.0, 0.05)["rebound"])


def test_both_engines_strike_the_wall_and_the_reference_is_converged_in_its_step(capsys):
    args = ["--consignment", "BW", "--wall", "90", "--speed", "0.4", "--angles", "0"]
    assert wall_impact.main([*args, "--model", "--reference", "--duration", "0.1"]) == 0
    rows = [r.split() for r in capsys.readouterr().out.splitlines()[2:]]
    assert [r[1] for r in rows] == ["model", "reference", "reference,"]
    rebound = {r[1]: float(r[-6]) for r in rows}
    assert all(0.0 <= v <= 1.0 for v in rebound.values())
    assert rebound["reference"] == pytest.approx(rebound["reference,"], abs=0.01)
