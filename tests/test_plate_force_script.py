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
        assert plate_force.wall_line_load(world, motion) == pytest.approx(expected, rel=1e-9)
        depth = plate_force.wall_depth(world, motion)
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
