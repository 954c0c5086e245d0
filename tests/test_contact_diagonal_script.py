"""scripts/contact_diagonal.py: the penalty mapping's inverse mass against MuJoCo's diagonal."""

import importlib.util
from pathlib import Path

import pytest

from parcelfit.sim.params import parameter

_SPEC = importlib.util.spec_from_file_location(
    "contact_diagonal", Path(__file__).parents[1] / "scripts" / "contact_diagonal.py"
)
contact_diagonal = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(contact_diagonal)


def test_the_row_asks_k_over_n_face_and_reports_both_inverse_masses(capsys):
    assert (
        contact_diagonal.main(
            ["--consignment", "KPBW", "--material", "belt", "--k", "100", "--settle", "0.1"]
        )
        == 0
    )
    row = capsys.readouterr().out.strip().splitlines()[-1].split()
    k, n_face, asked, realised, ratio, contacts, assumed, diagonal, diag_ratio = map(float, row)
    assert k == 100 and n_face > 0
    assert asked == pytest.approx(parameter("k_BePa").to_si(100) / n_face, rel=1e-3)
    assert realised > 0 and ratio == pytest.approx(realised / asked, rel=0.01)
    assert 0 < contacts <= n_face
    assert diag_ratio == pytest.approx(assumed / diagonal, rel=0.01)


def test_inverse_masses_are_a_vertex_s_and_the_weighted_nodes_(capsys):
    assumed, diagonal = contact_diagonal.inverse_masses("KPBW", "belt", 1e5)
    # the shell's mass is spread over more vertices than nodes: a lone vertex is lighter than
    # the nodes that carry it
    assert assumed > diagonal > 0


def test_a_soft_content_is_refused(capsys):
    with pytest.raises(SystemExit):
        contact_diagonal.main(["--consignment", "PB", "--k", "100"])
    assert "soft content" in capsys.readouterr().err
