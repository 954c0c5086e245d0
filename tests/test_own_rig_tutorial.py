"""The user guide's "Your own rig" tutorial: its files are a rig and a consignment type that
are not bundled, and the page shows the very files."""

from parcelfit.sim.mujoco import (
    bundled_consignment_names,
    bundled_rig_names,
    load_consignment,
    load_rig,
)

from .helpers import ROOT

FILES = ("D1.yaml", "envelope.yaml", "twin-spec.yaml", "study.yaml")


def test_the_tutorial_files_are_a_rig_and_a_type_of_your_own_named_after_their_files():
    folder = ROOT / "examples" / "own-rig"
    rig, cons = load_rig(folder / "D1.yaml"), load_consignment(folder / "envelope.yaml")
    assert rig.name == "D1" not in bundled_rig_names()
    assert cons.name == "envelope" not in bundled_consignment_names()
    guide = (ROOT / "docs" / "guide" / "rig.md").read_text(encoding="utf-8")
    for name in FILES:  # the page shows the very files this test runs
        assert f'--8<-- "examples/own-rig/{name}"' in guide


# The tutorial itself, from scratch to the report, is run by tests/test_user_guide.py (the
# page's own commands) with this test's checks of what it made.
