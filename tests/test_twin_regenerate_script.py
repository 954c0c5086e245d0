"""scripts/twin_regenerate.py: a twin dataset made again with some runs taken from an existing
one. No physics: the runs it would simulate are made by a stand-in that marks them."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import parcelfit.synth as synth
from parcelfit.runs import Run, TestCase, Trajectory, load_dataset
from parcelfit.runs.dataset import CaseData, save_dataset

_SPEC = importlib.util.spec_from_file_location(
    "twin_regenerate", Path(__file__).parents[1] / "scripts" / "twin_regenerate.py"
)
twin_regenerate = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(twin_regenerate)


def _old(folder: Path, runs: int) -> Path:
    case = TestCase("E3", "PB", 1)
    t = np.linspace(0.0, 1.0, 11)
    kept = tuple(
        Run(
            f"E3-PB-1-{k + 1:02d}",
            case,
            Trajectory(t=t, x=t * (k + 1), y=0 * t, theta=0 * t),
            1.2 + k,
        )
        for k in range(runs)
    )
    save_dataset(folder, "old", [CaseData(case, kept)], synthetic=True)
    return folder


def _spec(tmp_path: Path, runs: int) -> Path:
    path = tmp_path / "spec.yaml"
    path.write_text(f"name: again\nseed: 3\ncases: [E3/PB/1]\nsettings: {{runs: {runs}}}\n")
    return path


def _regenerate(tmp_path: Path, old: Path, runs: int) -> None:
    """The script on a spec of E3/PB/1 with ``runs`` runs, PB's taken from ``old``."""
    spec = str(_spec(tmp_path, runs))
    twin_regenerate.main(
        [spec, "--out", str(tmp_path / "new"), "--reuse", str(old), "--types", "PB"]
    )


def test_the_taken_runs_are_the_old_dataset_s(tmp_path):
    old = _old(tmp_path / "old", runs=3)
    _regenerate(tmp_path, old, runs=3)
    (new,) = load_dataset(tmp_path / "new").cases.values()
    (was,) = load_dataset(old).cases.values()
    assert [r.id for r in new.runs] == [r.id for r in was.runs]
    for a, b in zip(new.runs, was.runs, strict=True):
        assert a.transit_time == b.transit_time
        np.testing.assert_array_equal(a.trajectory.x, b.trajectory.x)
        np.testing.assert_array_equal(a.trajectory.t, b.trajectory.t)


def test_a_run_the_old_dataset_lacks_stops_it(tmp_path):
    old = _old(tmp_path / "old", runs=2)
    with pytest.raises(SystemExit, match="has no run E3-PB-1-03"):
        _regenerate(tmp_path, old, runs=3)


T = np.linspace(0.0, 1.0, 11)


@pytest.fixture
def two_cases(tmp_path, monkeypatch):
    """An old dataset with one run of E3/PB/1 and of E1/PB/1, a spec of both plus E1/BW/1, and
    a stand-in simulation that records and marks (transit 9 s) what it simulates: (argv head
    without --out, the simulated run ids)."""
    old_runs = [
        CaseData(c, (Run(f"{c.rig}-PB-1-01", c, Trajectory(t=T, x=T, y=0 * T, theta=0 * T), 1.5),))
        for c in (TestCase("E3", "PB", 1), TestCase("E1", "PB", 1))
    ]
    save_dataset(tmp_path / "old", "old", old_runs, synthetic=True)
    simulated: list[str] = []

    def marked(job):
        simulated.append(job.run_id)
        return Run(job.run_id, job.case, Trajectory(t=T, x=2 * T, y=0 * T, theta=0 * T), 9.0), 0.0

    monkeypatch.setattr(synth, "_twin_run", marked)
    spec = tmp_path / "spec.yaml"
    spec.write_text(
        "name: again\nseed: 3\ncases: [E3/PB/1, E1/PB/1, E1/BW/1]\nsettings: {runs: 1}\n"
    )
    return [str(spec), "--reuse", str(tmp_path / "old")], simulated


def _transits(folder: Path) -> dict[str, float]:
    return {c.label: cd.runs[0].transit_time for c, cd in load_dataset(folder).cases.items()}


def test_types_takes_those_types_and_simulates_the_others(tmp_path, two_cases):
    args, simulated = two_cases
    twin_regenerate.main([*args, "--out", str(tmp_path / "new"), "--types", "PB"])
    assert simulated == ["E1-BW-1-01"]
    assert _transits(tmp_path / "new") == {"E3/PB/1": 1.5, "E1/PB/1": 1.5, "E1/BW/1": 9.0}


def test_only_simulates_the_named_cases_and_takes_the_others(tmp_path, two_cases):
    args, simulated = two_cases
    with pytest.raises(SystemExit, match="has no run E1-BW-1-01"):  # taken, but not in OLD
        twin_regenerate.main([*args, "--out", str(tmp_path / "a"), "--only", "E1/PB/1"])
    simulated.clear()
    # a case written another way (a zero-padded setting) is the same case
    twin_regenerate.main([*args, "--out", str(tmp_path / "b"), "--only", "E1/PB/01", "E1/BW/1"])
    assert sorted(simulated) == ["E1-BW-1-01", "E1-PB-1-01"]
    assert _transits(tmp_path / "b") == {"E3/PB/1": 1.5, "E1/PB/1": 9.0, "E1/BW/1": 9.0}


@pytest.mark.parametrize(
    ("which", "message"),
    [
        (["--types", "KP"], "--types 'KP': no case of the spec has it"),
        (["--only", "e1/pb/1"], "--only 'e1/pb/1': not a case of the spec"),
        (["--only", "E1/PB/x"], "--only 'E1/PB/x': "),
        (["--only", "E1/PB/1", "--types", "PB"], None),  # one of the two, not both
    ],
)
def test_names_not_in_the_spec_stop_it_before_anything_runs(tmp_path, two_cases, which, message):
    args, simulated = two_cases
    with pytest.raises(SystemExit) as stop:
        twin_regenerate.main([*args, "--out", str(tmp_path / "new"), *which])
    if message is not None:
        assert str(stop.value).startswith(message)
    assert simulated == [] and not (tmp_path / "new").exists()


def test_an_existing_out_folder_is_refused(tmp_path, two_cases):
    args, simulated = two_cases
    (tmp_path / "new").mkdir()
    with pytest.raises(SystemExit, match="exists: give a new folder"):
        twin_regenerate.main([*args, "--out", str(tmp_path / "new"), "--types", "PB"])
    assert simulated == []
