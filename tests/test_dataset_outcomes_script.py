"""scripts/dataset_outcomes.py: what a dataset's runs did, case by case, and beside another."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from parcelfit.runs import Run, TestCase, Trajectory
from parcelfit.runs.dataset import CaseData, save_dataset

_SPEC = importlib.util.spec_from_file_location(
    "dataset_outcomes", Path(__file__).parents[1] / "scripts" / "dataset_outcomes.py"
)
dataset_outcomes = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(dataset_outcomes)


def _turning(total_deg: float) -> Trajectory:
    t = np.linspace(0.0, 1.0, 21)
    theta = np.radians(total_deg) * t * t  # a turn that starts slowly, as a catch does
    return Trajectory(t=t, x=t, y=0 * t, theta=theta)


def _dataset(folder: Path, turns: list[float], transits: list[float]) -> Path:
    case = TestCase("E3", "KPBW", 1)
    runs = tuple(
        Run(f"E3-KPBW-1-{i:02d}", case, _turning(d), tt)
        for i, (d, tt) in enumerate(zip(turns, transits, strict=True))
    )
    save_dataset(folder, "d", [CaseData(case, runs)], synthetic=True)
    return folder


def test_a_case_s_medians_and_shares(tmp_path):
    folder = _dataset(tmp_path, [20.0, 100.0, 200.0, 30.0], [1.4, 1.6, 1.7, 1.5])
    (case,) = dataset_outcomes.load_dataset(folder).cases.values()
    got = dataset_outcomes.case_summary(case)
    assert got["runs"] == 4
    assert got["median_transit"] == pytest.approx(1.55)
    assert got["median_rotation"] == pytest.approx(65.0, abs=1e-6)
    assert got["above_90"] == 0.5 and got["above_180"] == 0.25
    assert got["rotations"]["E3-KPBW-1-02"] == pytest.approx(200.0, abs=1e-6)


def test_beside_another_dataset_run_by_run(tmp_path):
    new = _dataset(tmp_path / "new", [20.0, 25.0], [1.4, 1.5])
    old = _dataset(tmp_path / "old", [110.0, 25.0], [1.6, 1.5])
    lines = dataset_outcomes.report(new, old)
    assert lines[0] == "E3/KPBW/1"
    assert "above 90 / 180 deg 0 % / 0 %" in lines[1]
    assert lines[2].startswith("  other:") and "above 90 / 180 deg 50 % / 0 %" in lines[2]
    assert lines[3] == "    E3-KPBW-1-00: 20.0 deg (other 110.0)"
    assert math.isclose(float(lines[4].split(":")[1].split()[0]), 25.0)


def test_an_unknown_case_is_refused_by_name(tmp_path):
    folder = _dataset(tmp_path, [20.0], [1.4])
    with pytest.raises(Exception, match="E1/KP/1"):
        dataset_outcomes.report(folder, cases=["E1/KP/1"])
