"""scripts/plate_force.py: the plate's force on the reference's parcel against its rim's
buckling load."""

import math

import numpy as np
import pytest

from parcelfit.sim.mujoco import load_consignment
from parcelfit.sim.rigidbox import Motion, Primitives, World, parcel_body
from parcelfit.sim.rigidbox.contact import law_array
from parcelfit.sim.rigidbox.geometry import BELT, BOX, METAL, WALL, primitive, rot_z

from .helpers import load_file_module

plate_force = load_file_module("scripts/plate_force.py")


@pytest.mark.parametrize("outline", ["outline", "content"])
def test_the_line_load_is_kappa_h_delta_at_the_deepest_corner(outline):
    """KP/BW turned 10 degrees, its wall outline's farthest corner 2 mm past a wall's face (a
    wall 4 mm above the belt): the spring's line load there is kappa h delta, the depth delta; a
    belt is not a wall; 5 mm short of the face, none."""
    cons = load_consignment("KPBW")
    body = parcel_body(cons, 0.02, 0.01, "outline", wall_outline=outline)
    hx, hy, hz = body.wall_half
    a = math.radians(10.0)
    reach = hx * math.cos(a) + hy * math.sin(a)
    law = law_array((5e5, 6e5), (1, 1), (0.3, 0.3), (0, 0), cons.mass, body.bottom_area)
    belt = primitive("belt", BOX, (0, 0, -0.02), rot_z(0), (5, 1, 0.02), BELT)
    kappa, h = 6e5 / body.bottom_area, 2 * hz - 0.004
    for delta in (0.002, -0.005):
        wall = primitive("wall", WALL, (reach - delta + 0.0015, 0.0, 0.054), rot_z(90),
                         (0.5, 0.0015, 0.05), METAL)  # fmt: skip
        world = World(body, Primitives.of([belt, wall]), law, 0.001, 0.0015, 0.0)
        q = np.array([math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)])
        motion = Motion(world, (0, 0, hz), q)
        expected = kappa * h * delta if delta > 0 else 0.0
        load, depth = plate_force.wall_press(world, motion)
        assert load == pytest.approx(expected, rel=1e-9)
        assert depth == (pytest.approx(delta, rel=1e-9) if delta > 0 else 0.0)


def test_one_placement_meets_the_plate_and_bad_counts_are_refused(capsys):
    assert plate_force.main(["--types", "KPBW", "--settings", "1", "--placements", "1"]) == 0
    out = capsys.readouterr().out
    defaults = next(line for line in out.splitlines() if line.endswith("| defaults |"))
    cells = [c.strip() for c in defaults.strip("|").split("|")]
    assert cells[:4] == ["1000", "0.5", "40.2", "18.7"]  # N/m: 37.5 and 55 mm wide rims
    peaks = next(line for line in out.splitlines() if line.startswith("peak force"))
    assert float(peaks.rsplit(":", 1)[1]) > 1.0  # N: E3's plate catches every placement
    with pytest.raises(SystemExit):
        plate_force.main(["--placements", "0"])


def _rot_z(deg):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_the_gap_is_the_nearest_footprint_corner_s_distance_from_the_plate_s_face():
    """A plate 3 mm thick along world y (its thin axis local y) at y = 0.1; a 0.2 x 0.1 footprint
    at the origin turned 10 degrees: its corner (0.1, 0.05) reaches y = 0.1 sin 10 + 0.05 cos 10,
    so the gap is 0.1 - 0.0015 less that; a footprint moved 2 mm past the face: -2 mm; a plate
    whose length misses every corner: inf."""
    plate_centre = np.array([0.0, 0.1, 0.0])
    plate_half = np.array([0.5, 0.0015, 0.05])
    rot = _rot_z(10.0)
    reach = 0.1 * math.sin(math.radians(10)) + 0.05 * math.cos(math.radians(10))
    gap = plate_force.plate_gap(np.zeros(3), rot, (0.1, 0.05), plate_centre, np.eye(3), plate_half)
    assert gap == pytest.approx(0.1 - 0.0015 - reach, rel=1e-12)
    past = np.array([0.0, 0.1 - 0.0015 - 0.05 + 0.002, 0.0])
    gap = plate_force.plate_gap(past, np.eye(3), (0.1, 0.05), plate_centre, np.eye(3), plate_half)
    assert gap == pytest.approx(-0.002, abs=1e-12)
    short = np.array([0.01, 0.0015, 0.05])  # 2 cm long, centred away from every corner
    far = plate_force.plate_gap(
        np.zeros(3), np.eye(3), (0.1, 0.05), np.array([0.0, 0.1, 0.0]), np.eye(3), short
    )
    assert far == math.inf
    # the same plate turned 14 degrees about z (E3's): its face's normal is its local y axis
    turn = _rot_z(14.0)
    normal = turn[:, 1]
    centre = normal * 0.1  # the plate 0.1 m from the origin along its normal
    gap = plate_force.plate_gap(np.zeros(3), turn, (0.1, 0.05), centre, turn, plate_half)
    assert gap == pytest.approx(0.1 - 0.0015 - 0.05, rel=1e-12)  # the footprint turned with it


def test_the_facing_rim_is_the_one_beyond_the_edge_turned_to_the_plate():
    """KP/BW (outer 275 x 200, content 165 x 125 mm) against a plate whose normal is world y:
    lying along x its long edge faces it (rim 37.5 mm); turned 80 degrees its short edge (55)."""
    plate_half = np.array([0.5, 0.0015, 0.05])
    outer, content = (0.275, 0.2), (0.165, 0.125)
    along = plate_force.facing_rim(_rot_z(10.0), np.eye(3), plate_half, outer, content)
    across = plate_force.facing_rim(_rot_z(80.0), np.eye(3), plate_half, outer, content)
    assert along == pytest.approx(0.0375) and across == pytest.approx(0.055)


def test_the_model_s_content_stays_within_its_rim_of_the_plate(capsys):
    """One placement of KP/BW in the MuJoCo model: the content's least gap to the plate is
    finite and between nothing and the widest rim (55 mm): it met the plate through its rim."""
    args = ["--engines", "model", "--types", "KPBW", "--settings", "1", "--placements", "1"]
    assert plate_force.main(args) == 0
    out = capsys.readouterr().out
    assert "--engines model" in out
    gaps = next(line for line in out.splitlines() if line.startswith("the content's least gap"))
    gap = float(gaps.rsplit(":", 1)[1])
    assert 0.0 < gap < 55.0
    outline = next(line for line in out.splitlines() if line.startswith("the outline's least"))
    # the outline set at the content's pose lies the facing rim's width nearer the plate
    assert float(outline.rsplit(":", 1)[1]) < gap - 30.0
    assert "peak force" not in out  # the reference not run
