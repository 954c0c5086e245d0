"""scripts/friction_budget.py: impulses and ratios summed per material."""

import math

import numpy as np
import pytest

from .helpers import load_file_module

friction_budget = load_file_module("scripts/friction_budget.py")


def test_budget_sums_impulses_and_counts_short_forces_by_hand():
    b = friction_budget.Budget()
    h = 0.001
    # sticking in MuJoCo's cone: 2 N normal, 0.5 N friction, 0.1 m from the centre
    b.add("metal", 2.0, 0.5, 0.0, 0.3, h, 0.05, 0.1, t=0.0)
    # sliding by hand at mu_d N, 0.3 m from the centre
    b.add("metal", 1.0, 0.0, 0.3, 0.3, h, -0.09, 0.3, outside=True, t=0.5)
    # sliding by hand, limited to half of mu_d N
    b.add("metal", 1.0, 0.0, 0.15, 0.3, h, 0.0, 0.1, t=1.0)
    assert b.normal["metal"] == pytest.approx(4.0 * h)
    assert b.friction["metal"] == pytest.approx(0.95 * h)
    assert b.torque["metal"] == pytest.approx(-0.04 * h)
    assert (b.steps["metal"], b.by_hand["metal"], b.short["metal"]) == (3, 2, 1)
    rows = {line.split(" | ")[0]: line.split(" | ") for line in b.lines()[2:]}
    assert set(rows) == {"| metal"}  # no belt contacts, no belt row
    row = rows["| metal"]
    assert float(row[4]) == pytest.approx(0.95 / 4.0, abs=1e-4)  # friction / normal
    assert row[5] == "66.7%" and row[6] == "50.0%"
    assert float(row[7]) == pytest.approx(0.45 / 0.6, abs=1e-4)  # by hand / (mu_d N)
    assert float(row[8]) == pytest.approx(-0.04 * h)
    # turn impulse up to the last step (t = 1): 0.05 h (1 - 0) - 0.09 h (1 - 0.5) + 0
    assert b.turn_impulse("metal") == pytest.approx(0.005 * h)
    assert float(row[9]) == pytest.approx(0.005 * h)
    assert float(row[10]) == pytest.approx((0.2 + 0.3 + 0.1) / 4.0 * 1e3, abs=0.05)
    assert row[11] == "25.0% |"  # a quarter of the normal impulse beyond the content
    assert not math.isnan(float(row[4]))


def test_a_soft_content_has_no_footprint_share():
    b = friction_budget.Budget(rigid_content=False)
    b.add("belt", 1.0, 0.2, 0.0, 0.3, 0.001, 0.0, 0.1)
    assert b.lines()[2].endswith("| n/a |")


def test_the_force_on_the_packaging_follows_the_contact_frame():
    # normal along +z (from geom 0, the surface, to geom 1, the packaging), tangents x and y
    frame = np.array([0, 0, 1, 1, 0, 0, 0, 1, 0], dtype=float)
    rows = np.array([2.0, 0.5, -0.25])  # normal 2 N, friction +0.5 N along x, -0.25 along y
    on_packaging = friction_budget.force_on_packaging(frame, rows, surface_first=True)
    np.testing.assert_allclose(on_packaging, [0.5, -0.25, 2.0])
    # the packaging as geom 0: the rows give the force on the surface, the packaging's is opposite
    np.testing.assert_allclose(
        friction_budget.force_on_packaging(frame, rows, surface_first=False), [-0.5, 0.25, -2.0]
    )


def test_beyond_the_footprint_in_the_contents_frame_with_a_margin():
    half = np.array([0.08, 0.06])
    turned = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=float)  # 90 degrees about z
    centre = np.array([1.0, 2.0, 0.0])
    # 0.07 m along the content's x axis (world +y after the turn): inside
    assert not friction_budget.beyond_footprint(
        centre + np.array([0, 0.07, 0]), centre, turned, half
    )
    # 0.07 m along its y axis (world -x): beyond 0.06 + 0.005
    assert friction_budget.beyond_footprint(centre + np.array([-0.07, 0, 0]), centre, turned, half)
    # within the margin of the edge: under the content
    assert not friction_budget.beyond_footprint(
        centre + np.array([-0.064, 0, 0]), centre, turned, half
    )


def test_the_geom_friction_law_is_refused(capsys):
    code = friction_budget.main(
        ["--rig", "E3", "--consignment", "KPBW", "--scene", "friction=geom"]
    )
    assert code == 2
    assert "per-contact friction law" in capsys.readouterr().err
