"""scripts/contact_trace.py: which rig geom pushes the parcel, and how hard (docs/research/belt-drums.md)."""

import re
from pathlib import Path

import pytest
import yaml

from parcelfit.sim.mujoco import load_rig

from .helpers import load_file_module

pytestmark = pytest.mark.mujoco


@pytest.fixture(scope="module")
def trace():
    return load_file_module("scripts/contact_trace.py")


def test_bad_arguments_are_refused(trace, capsys):
    with pytest.raises(SystemExit):
        trace.main(["--rig", "E2a", "--consignment", "KPBW", "--from", "1", "--to", "0.5"])
    assert "--to after --from" in capsys.readouterr().err
    for to in ([], ["--to", "0.03"]):
        with pytest.raises(SystemExit):
            trace.main(["--rig", "E3", "--consignment", "KPBW", "--stop", *to])
        assert "--stop needs --to of at least 0.05 s" in capsys.readouterr().err
    assert trace.main(["--rig", "E9", "--consignment", "KPBW"]) == 2
    assert "unknown rig 'E9'" in capsys.readouterr().err
    # a bulge needs a rigid content, and a patch smaller than it
    assert trace.main(["--rig", "E3", "--consignment", "PB", "--bulge", "0.5"]) == 2
    assert "a bulge needs a rigid content" in capsys.readouterr().err
    assert trace.main(["--rig", "E3", "--consignment", "BW", "--bulge", "0.95"]) == 2
    assert "smaller than the content" in capsys.readouterr().err


@pytest.mark.slow
def test_the_bottom_sheet_of_a_bulged_mailer_lies_on_its_patch(trace, capsys):
    # a short run on the strips: the bulge's patch carries BW, its rim stays up by most of the
    # bulge's depth (4 mm) and the content above it; a flat bottom's rim lies as low as its face
    pattern = re.compile(
        r"bottom: face min ([\d.]+) mean ([\d.]+) mm, rim min ([\d.]+) mean ([\d.]+) mm; "
        r"content at ([\d.]+) mm, heading ([-+.\d]+) deg"
    )

    def bottom(*extra: str) -> list[float]:
        args = ["--rig", "E3", "--consignment", "BW", "--bottom", *extra]
        assert (
            trace.main([*args, "--from", "0.2", "--to", "0.21", "--every", "0.01", "--stop"]) == 0
        )
        out = capsys.readouterr().out
        found = pattern.search(out)
        assert found is not None and "transit none" in out  # --stop: ended at 0.21 s
        return [float(found.group(i)) for i in range(1, 6)]

    face_min, face_mean, rim_min, rim_mean, content = bottom("--bulge", "0.5")
    assert face_min == pytest.approx(0.0, abs=0.05) and face_mean < 1.0
    assert 2.0 < rim_min < 5.0 and 2.0 < rim_mean < 5.0
    assert content > rim_mean
    _, _, flat_rim_min, _, flat_content = bottom("--bulge", "0")
    assert flat_rim_min < 0.5 and flat_content < content


@pytest.mark.slow
def test_the_square_end_catch_on_e2a_is_the_outfeed_pushing_the_parcel_back(
    trace, capsys, tmp_path
):
    doc = yaml.safe_load(Path(load_rig("E2a").source).read_text())
    for surface in doc["surfaces"]:
        surface.pop("nose_radius", None)
    square = tmp_path / "E2a-square.yaml"
    square.write_text(yaml.safe_dump(doc))
    # as measured in docs/research/belt-drums.md: with square ends, the shell's former alternating
    # diagonals (with the radiating ones the same push leaves the parcel on the square end) and
    # MuJoCo's equal mass shares (the model before the masses were lumped, docs/research/mass-lumping.md)
    # and the contact and friction laws before 2026-12-01 (contact.py, friction.py), with KP/BW's
    # shell over 4 x 4 x 1 cells (its default until 2026-12-03)
    args = ["--rig", str(square), "--consignment", "KPBW", "--seed", "3", "--top", "1"]
    args += ["--scene", "shell_diagonals=alternating", "mass_lumping=equal", "shell_cells=4,4,1"]
    args += ["contact_law=impedance", "friction=geom"]
    assert trace.main([*args, "--from", "1.79", "--to", "1.801"]) == 0
    out = capsys.readouterr().out
    hardest = re.search(
        r"\n    outfeed ([-+.\d]+) N m \(F ([-+.\d]+) ([-+.\d]+) ([-+.\d]+) N\)", out
    )
    assert hardest is not None, out
    torque, fx, fz = float(hardest.group(1)), float(hardest.group(2)), float(hardest.group(4))
    assert fx < -10.0 and abs(fz) < 1.0 and abs(torque) > 0.3  # a horizontal push, off centre
    assert re.search(r"rotation -1[23]\.\d\d deg, transit 2\.1[34]\d\d s", out)
