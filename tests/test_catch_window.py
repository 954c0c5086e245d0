"""The catch-window script's reading of a sweep (scripts/catch_window.py): windows, the
across scatter's mass on them, and the medians a placement convention would give."""

import numpy as np
import pytest
from scipy.stats import norm

from .helpers import load_file_module


def _script():
    return load_file_module("scripts/catch_window.py")


OFFSETS = np.arange(-30, 31, 3) / 1000.0  # m


def test_windows_are_the_runs_of_caught_offsets():
    cw = _script()
    deg = np.full(OFFSETS.size, 20.0)
    deg[[0, 1, 2, 10, 15, 16]] = 110.0  # -30..-24, 0, +15..+18 mm
    wins = cw._windows(OFFSETS, np.radians(deg))
    assert [(round(a * 1e3), round(b * 1e3)) for a, b in wins] == [(-30, -24), (0, 0), (15, 18)]
    assert cw._windows(OFFSETS, np.radians(np.full(OFFSETS.size, 20.0))) == []


def test_the_scatter_mass_is_the_cut_normal_on_each_offsets_cell():
    cw = _script()
    mass = cw._scatter_mass(OFFSETS, 0.015, 0.0)
    # cut at 2.5 sd = 37.5 mm: the sweep's cells (-31.5..+31.5 mm, 2.1 sd) hold all but the tails
    inside = (norm.cdf(2.1) - norm.cdf(-2.1)) / (norm.cdf(2.5) - norm.cdf(-2.5))
    assert mass.sum() == pytest.approx(inside, rel=1e-9)
    assert mass[10] == max(mass)  # the cell at 0 mm
    assert np.allclose(mass, mass[::-1])  # symmetric about the centre
    # shifted by the sweep's width, nothing lands on it
    assert cw._scatter_mass(OFFSETS, 0.015, 0.2).sum() == pytest.approx(0.0)
    # the share of the scatter on caught offsets: all of the centre cell's mass, none else
    deg = np.full(OFFSETS.size, 20.0)
    deg[10] = 120.0
    assert cw._scatter_share(OFFSETS, np.radians(deg), 0.015) == pytest.approx(mass[10])


def test_the_weighted_median_and_a_convention_that_meets_every_check():
    cw = _script()
    assert cw._weighted_median(np.array([1.0, 2.0, 3.0]), np.array([0.2, 0.2, 0.6])) == 3.0
    assert cw._weighted_median(np.array([5.0, 1.0]), np.array([0.6, 0.4])) == 5.0
    # invented responses in which only "centres on one spot" at shifts near 0 holds: BW spins
    # at every offset, KP/BW turns 40 degrees, KP 20 (the widths do not matter then)
    rot = {
        "BW": np.radians(np.full(OFFSETS.size, 120.0)),
        "KPBW": np.radians(np.full(OFFSETS.size, 40.0)),
        "KP": np.radians(np.full(OFFSETS.size, 20.0)),
    }
    widths = {"BW": 0.15, "KPBW": 0.2, "KP": 0.25}
    lines = cw._conventions(OFFSETS, rot, widths, 0.005, np.array([0.0]))
    assert "| centres on one spot | +0 | 120 / 40 / 20 | 100% | yes | yes | 100% |" in lines
    assert any(
        line.startswith("- centres on one spot: all three checks hold at shifts [mm] +0")
        for line in lines
    )
    # KP above 30 degrees fails the KP check
    rot["KP"] = np.radians(np.full(OFFSETS.size, 35.0))
    lines = cw._conventions(OFFSETS, rot, widths, 0.005, np.array([0.0]))
    assert any(
        line.startswith("- centres on one spot: all three checks hold at shifts [mm] none")
        for line in lines
    )
