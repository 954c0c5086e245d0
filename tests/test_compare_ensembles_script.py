"""scripts/compare_ensembles.py: two ensemble checks compared placement by placement."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

_SPEC = importlib.util.spec_from_file_location(
    "compare_ensembles", Path(__file__).parents[1] / "scripts" / "compare_ensembles.py"
)
compare_ensembles = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(compare_ensembles)

_A = """# Ensemble check

## E3, speed setting 1

- BW: 108, 62, 24, 111
- KP: 18, 25, 110, 21

- median rotation BW > KP/BW > KP: **NOT met**

## E3, speed setting 2

- KP: 17, 25, 213, 20
"""
_B = """## E3-right-sides, speed setting 1

- BW: 100, 95, 20, -120
- KP: 18, 130, 24, 22
"""


def test_rotations_are_read_per_setting_and_type():
    got = compare_ensembles.rotations(_A)
    assert sorted(got) == [(1, "BW"), (1, "KP"), (2, "KP")]
    assert np.array_equal(got[(1, "KP")], [18, 25, 110, 21])


def test_outcomes_are_compared_placement_by_placement():
    a = compare_ensembles.rotations(_A)[(1, "BW")]
    b = compare_ensembles.rotations(_B)[(1, "BW")]
    c = compare_ensembles.compare(a, b, 90.0)
    # spins: a at placements 0 and 3; b at 0, 1 and 3 (|-120|): alike but at 1
    assert (c["spins a"], c["spins b"], c["alike"]) == (2, 3, 3)
    assert c["median a"] == pytest.approx(85.0)
    assert c["difference"] == pytest.approx(np.median([8, 33, 4, 231]))
    k = compare_ensembles.compare(
        compare_ensembles.rotations(_A)[(1, "KP")], compare_ensembles.rotations(_B)[(1, "KP")], 90
    )
    assert (k["spins a"], k["spins b"], k["alike"]) == (1, 1, 2)


def test_the_table_names_what_both_files_hold(tmp_path, capsys):
    a, b = tmp_path / "a.md", tmp_path / "b.md"
    a.write_text(_A)
    b.write_text(_B)
    assert compare_ensembles.main([str(a), str(b), "--labels", "model", "reference"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert "median model" in out[0] and len(out) == 3  # (1, BW) and (1, KP) only
    assert out[2].split()[:2] == ["1", "KP"] and "2/4" in out[2]


def test_a_missing_file_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        compare_ensembles.main([str(tmp_path / "none.md"), str(tmp_path / "none.md")])
    assert "no such file" in capsys.readouterr().err
