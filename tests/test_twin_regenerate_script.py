"""scripts/twin_regenerate.py: a twin dataset made again with some types' runs taken from
an existing one (no physics here: only the taken runs, and the refusal of a missing one)."""

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


@pytest.fixture(autouse=True)
def _restore_synth(monkeypatch):
    # the script replaces synth's run function and sets its environment entry: undo both
    monkeypatch.setattr(synth, "_twin_run", synth._twin_run)
    monkeypatch.delenv(twin_regenerate._REUSE, raising=False)


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


def test_only_the_named_cases_are_simulated(tmp_path, monkeypatch):
    """With --only, every other case's runs are taken; the named case's are simulated (here by a
    stand-in that marks them)."""
    e3, e1 = TestCase("E3", "PB", 1), TestCase("E1", "PB", 1)
    t = np.linspace(0.0, 1.0, 11)
    old_runs = [
        CaseData(c, (Run(f"{c.rig}-PB-1-01", c, Trajectory(t=t, x=t, y=0 * t, theta=0 * t), 1.5),))
        for c in (e3, e1)
    ]
    save_dataset(tmp_path / "old", "old", old_runs, synthetic=True)
    simulated = []

    def marked(job):
        simulated.append(job.run_id)
        return Run(job.run_id, job.case, Trajectory(t=t, x=2 * t, y=0 * t, theta=0 * t), 9.0), 0.0

    monkeypatch.setattr(twin_regenerate, "_simulate", marked)
    spec = tmp_path / "spec.yaml"
    spec.write_text("name: again\nseed: 3\ncases: [E3/PB/1, E1/PB/1]\nsettings: {runs: 1}\n")
    args = [str(spec), "--out", str(tmp_path / "new"), "--reuse", str(tmp_path / "old")]
    twin_regenerate.main([*args, "--only", "E1/PB/1"])
    assert simulated == ["E1-PB-1-01"]
    new = load_dataset(tmp_path / "new")
    assert new[e3].runs[0].transit_time == 1.5 and new[e1].runs[0].transit_time == 9.0
    with pytest.raises(SystemExit):  # one of the two, not both
        twin_regenerate.main([*args, "--only", "E1/PB/1", "--types", "PB"])
