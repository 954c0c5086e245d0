"""``start.align``: where a hand lays consignment types of different sizes on a rig."""

import copy
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from parcelfit import ParcelfitError
from parcelfit.config import load_yaml
from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator, SimOptions, load_consignment, load_rig
from parcelfit.sim.mujoco.rig import parse_rig
from parcelfit.sim.rigidbox import RigidBoxOptions, RigidBoxSimulator


def _e3(**start):
    doc = copy.deepcopy(load_yaml(load_rig("E3").source))
    doc["start"].update(start)
    return parse_rig(doc, "my_rig.yaml")  # the name the simulators know it by: E3


# a point on E3's strips (the start surface): the tests place starts there
ON_STRIPS = [-0.45, -0.65]


def _left(rig):
    """The unit normal to the left of the start surface's direction."""
    h = math.radians(rig.surface(rig.start.surface).heading)
    return np.array([-math.sin(h), math.cos(h)])


def test_centre_puts_every_type_s_centre_at_the_position():
    rig = _e3(align="centre", position=ON_STRIPS)
    for length, width in ((0.32, 0.25), (0.2, 0.15)):
        assert rig.start_centre(length, width) == pytest.approx(tuple(ON_STRIPS))


@pytest.mark.parametrize(("align", "sign"), [("right", 1.0), ("left", -1.0)])
def test_a_side_in_line_puts_that_side_s_middle_at_the_position(align, sign):
    rig = _e3(align=align, position=ON_STRIPS, heading=30)
    n = _left(rig)
    for width in (0.15, 0.20, 0.25):
        centre = np.array(rig.start_centre(0.3, width))
        # the centre lies half the width to the left (right) of the line ...
        assert centre == pytest.approx(np.array(ON_STRIPS) + sign * 0.5 * width * n)
        # ... so that side's middle is the position, whatever the width
        assert centre - sign * 0.5 * width * n == pytest.approx(ON_STRIPS)


def test_a_parcel_laid_across_the_surface_extends_by_its_length():
    """Heading 90 degrees from the surface's: the extent across is the parcel's length."""
    rig = _e3(align="right", position=ON_STRIPS, heading=120)  # strips run at 30 degrees
    n = _left(rig)
    assert np.array(rig.start_centre(0.3, 0.2)) == pytest.approx(np.array(ON_STRIPS) + 0.15 * n)


def test_an_unknown_alignment_is_refused_with_the_key():
    with pytest.raises(ParcelfitError, match=r"my_rig\.yaml.*start\.align.*'middle'") as info:
        _e3(align="middle")
    assert "centre" in str(info.value) and "right" in str(info.value)


def test_the_bundled_e3_lays_every_type_with_its_right_side_on_one_line():
    """Right sides in line, BW's centre where every centre lay with centres on one spot; the
    variant files keep both conventions and the bundled start is the right-sides variant's."""
    rig = load_rig("E3")
    assert rig.start.align == "right"
    assert rig.start_centre(*load_consignment("BW").outer[:2]) == pytest.approx(
        (-0.3031, -0.575), abs=1e-6
    )
    n = _left(rig)
    bw = np.array(rig.start_centre(*load_consignment("BW").outer[:2]))
    for name, further_left in (("KPBW", 0.025), ("PB", 0.0375), ("KP", 0.05)):
        centre = np.array(rig.start_centre(*load_consignment(name).outer[:2]))
        assert centre - bw == pytest.approx(further_left * n, abs=1e-6)
    examples = Path(__file__).resolve().parents[1] / "examples" / "e3-variants"
    right = load_rig(examples / "E3-right-sides.yaml")
    assert right.start == rig.start
    centres = load_rig(examples / "E3-centres.yaml")
    assert centres.start.align == "centre"
    for name in ("BW", "KPBW", "KP", "PB"):
        assert centres.start_centre(*load_consignment(name).outer[:2]) == pytest.approx(
            (-0.3031, -0.575)
        )
    # but for the start, the former bundled rig is today's
    assert replace(centres, name="E3", description="", source="", start=rig.start) == replace(
        rig, description="", source=""
    )


@pytest.mark.parametrize("name", ["KP", "BW"])
def test_both_engines_start_a_parcel_where_its_right_side_meets_the_line(name):
    """E3 with right sides in line at BW's former right side: each engine's first sample is
    the centre `start_centre` gives for the type's outline."""
    rig = _e3(align="right", position=[-0.2656, -0.639952])
    expected = rig.start_centre(*load_consignment(name).outer[:2])
    if name == "BW":  # BW's centre is where every centre lies with align: centre
        assert expected == pytest.approx((-0.3031, -0.575), abs=1e-6)
    rigs = {"E3": rig}
    mj = MujocoSimulator(SimOptions(duration=0.1), rigs=rigs).run({}, TestCase("E3", name, 1))
    rb = RigidBoxSimulator(RigidBoxOptions(duration=0.1), rigs=rigs).run(
        {}, TestCase("E3", name, 1)
    )
    for result in (mj, rb):
        traj = result.run.trajectory
        assert (traj.x[0], traj.y[0]) == pytest.approx(expected, abs=2e-3)
