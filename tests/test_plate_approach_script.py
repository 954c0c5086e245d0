"""scripts/plate_approach.py: the model's content's least gap to E3's guide plate."""

import math

import numpy as np
import pytest

from .helpers import load_file_module

plate_approach = load_file_module("scripts/plate_approach.py")


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
    gap = plate_approach.plate_gap(
        np.zeros(3), rot, (0.1, 0.05), plate_centre, np.eye(3), plate_half
    )
    assert gap == pytest.approx(0.1 - 0.0015 - reach, rel=1e-12)
    past = np.array([0.0, 0.1 - 0.0015 - 0.05 + 0.002, 0.0])
    gap = plate_approach.plate_gap(
        past, np.eye(3), (0.1, 0.05), plate_centre, np.eye(3), plate_half
    )
    assert gap == pytest.approx(-0.002, abs=1e-12)
    short = np.array([0.01, 0.0015, 0.05])  # 2 cm long, centred away from every corner
    far = plate_approach.plate_gap(
        np.zeros(3), np.eye(3), (0.1, 0.05), np.array([0.0, 0.1, 0.0]), np.eye(3), short
    )
    assert far == math.inf


def test_bad_counts_are_refused():
    with pytest.raises(SystemExit):
        plate_approach.main(["--placements", "0"])


def test_the_facing_rim_is_the_one_beyond_the_edge_turned_to_the_plate():
    """KP/BW (outer 275 x 200, content 165 x 125 mm) against a plate whose normal is world y:
    lying along x its long edge faces it (rim 37.5 mm); turned 80 degrees its short edge (55)."""
    plate_half = np.array([0.5, 0.0015, 0.05])
    outer, content = (0.275, 0.2), (0.165, 0.125)
    along = plate_approach.facing_rim(_rot_z(10.0), np.eye(3), plate_half, outer, content)
    across = plate_approach.facing_rim(_rot_z(80.0), np.eye(3), plate_half, outer, content)
    assert along == pytest.approx(0.0375) and across == pytest.approx(0.055)
