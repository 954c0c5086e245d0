"""scripts/friction_budget.py: impulses and ratios summed per material."""

import importlib.util
import math
from pathlib import Path

import pytest

_SPEC = importlib.util.spec_from_file_location(
    "friction_budget", Path(__file__).parents[1] / "scripts" / "friction_budget.py"
)
friction_budget = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(friction_budget)


def test_budget_sums_impulses_and_counts_short_forces_by_hand():
    b = friction_budget.Budget()
    h = 0.001
    # sticking in MuJoCo's cone: 2 N normal, 0.5 N friction, 0.1 m from the centre
    b.add("metal", 2.0, 0.5, 0.0, 0.3, h, 0.05, 0.1)
    # sliding by hand at mu_d N, 0.3 m from the centre
    b.add("metal", 1.0, 0.0, 0.3, 0.3, h, -0.09, 0.3, outside=True)
    # sliding by hand, limited to half of mu_d N
    b.add("metal", 1.0, 0.0, 0.15, 0.3, h, 0.0, 0.1)
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
    assert float(row[9].rstrip(" |")) == pytest.approx((0.2 + 0.3 + 0.1) / 4.0 * 1e3, abs=0.05)
    assert not math.isnan(float(row[8]))
    assert row[10] == "25.0% |"  # a quarter of the normal impulse beyond the content


def test_the_geom_friction_law_is_refused(capsys):
    code = friction_budget.main(
        ["--rig", "E3", "--consignment", "KPBW", "--scene", "friction=geom"]
    )
    assert code == 2
    assert "friction" in capsys.readouterr().err
