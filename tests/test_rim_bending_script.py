"""scripts/rim_bending.py: the reference's rim load over the sheet's and the contact's ranges."""

from .helpers import load_file_module

rim_bending = load_file_module("scripts/rim_bending.py")


def test_it_prints_the_bending_length_and_the_rims_share_per_type(capsys):
    assert rim_bending.main(["--types", "KPBW", "BW", "--spacings", "0.01"]) == 0
    out = capsys.readouterr().out
    defaults = next(line for line in out.splitlines() if line.endswith("| defaults |"))
    cells = [c.strip() for c in defaults.strip("|").split("|")]
    # E_Pa 1000 N/mm^2, t_Pa 0.5 mm, k_BePa 500 N/mm: lambda 8.42 mm, about 27 % on the rim
    assert cells[:4] == ["1000", "0.5", "500", "8.42"]
    assert 0.25 < float(cells[4]) < 0.30
    assert "the rim's own weight: 0.089" in out
    assert "outline patch, spread over cells: 0.626" in out
    assert "BW: skipped" in out  # the bundled BW rests on its bulge
    assert out.count("| corner |") == 8
