"""scripts/parameter_effects.py: the rigid-box reference as a backend, signed ensemble effects."""

import math
from dataclasses import replace

import numpy as np
import pytest

from parcelfit.runs import TestCase
from parcelfit.sim.ensemble import Member
from parcelfit.sim.mujoco import SceneOptions, load_consignment
from parcelfit.sim.protocol import SimStatus

from .helpers import load_file_module

parameter_effects = load_file_module("scripts/parameter_effects.py")


class _BuiltError(Exception):
    pass


class _Done:
    """A finished future."""

    def __init__(self, value):
        self.value = value

    def result(self):
        return self.value


class _Serial:
    """A process pool that runs each job at once, in this process."""

    def __init__(self, *_):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *_):
        return False

    def submit(self, fn, job):
        return _Done(fn(job))


def test_shell_parameters_are_refused_by_the_reference(tmp_path, capsys):
    with pytest.raises(SystemExit):
        parameter_effects.main(
            ["--backend", "rigidbox", "--params", "k_MePa", "k_CoPa", "--out", str(tmp_path)]
        )
    err = capsys.readouterr().err
    assert "k_CoPa" in err and "k_MePa do not" not in err
    assert not (tmp_path / "parameter-effects.md").exists()


@pytest.mark.parametrize(
    "extra, patch",
    [
        (["--bottom-patch", "outline"], "outline"),
        (["--consignment", "BW"], "bulge"),  # the bundled BW rests on its bulge
    ],
)
def test_the_sheets_stiffness_is_refused_where_the_reference_does_not_bend_its_rim(
    tmp_path, capsys, extra, patch
):
    # E_Pa, t_Pa and nu_Pa reach the reference only through its rim's bending
    with pytest.raises(SystemExit):
        args = ["--backend", "rigidbox", "--params", "E_Pa", *extra, "--out", str(tmp_path)]
        parameter_effects.main(args)
    err = capsys.readouterr().err
    assert "rim-bending" in err and f"{patch} patch" in err
    assert not (tmp_path / "parameter-effects.md").exists()


@pytest.mark.parametrize(
    "extra, named",
    [
        (["--bottom-patch", "content"], "--bottom-patch"),
        (["--backend", "rigidbox", "--scene", "impratio=10"], "impratio"),
    ],
)
def test_reference_options_are_refused_where_they_do_not_apply(tmp_path, capsys, extra, named):
    with pytest.raises(SystemExit):
        parameter_effects.main(["--params", "k_MePa", "--out", str(tmp_path), *extra])
    assert named in capsys.readouterr().err


@pytest.mark.parametrize("backend", ["rigidbox", "mujoco"])
def test_a_job_reaches_the_backend_it_names_with_its_consignment(monkeypatch, backend):
    built = []

    def fake(options, *args, **kwargs):
        built.append((options, kwargs["consignments"]))
        raise _BuiltError

    name = "RigidBoxSimulator" if backend == "rigidbox" else "MujocoSimulator"
    monkeypatch.setattr(parameter_effects, name, fake)
    case = TestCase("E3", "KPBW", 1)
    bulged = replace(load_consignment("KPBW"), bulge=(0.004, 0.55))
    with pytest.raises(_BuiltError):
        parameter_effects._simulate(
            ({}, case, 3, SceneOptions(), backend, "content", bulged, 900.0)
        )
    options, consignments = built[0]
    assert consignments == {"KPBW": bulged}  # the bulge given on the command line reaches it
    if backend == "rigidbox":
        assert options.bottom_patch == "content"
    else:
        assert options.wall_limit == 900.0  # --wall-limit reaches MuJoCo's run


@pytest.mark.parametrize(
    "consignment, bulge, says",
    [
        ("PB", "0.5", "needs a rigid content"),
        ("KP", "0.95", "smaller than the content"),
        ("KPBW", "-0.5", "0 (a flat bottom) or positive"),
    ],
)
def test_a_bulge_the_packaging_cannot_have_is_refused_before_any_run(
    tmp_path, capsys, consignment, bulge, says
):
    with pytest.raises(SystemExit):
        args = ["--consignment", consignment, "--bulge", bulge, "--params", "E_Pa"]
        parameter_effects.main([*args, "--out", str(tmp_path)])
    assert says in capsys.readouterr().err
    assert not (tmp_path / "parameter-effects.md").exists()


def _member(seed: int, rotation_deg: float, transit: float) -> Member:
    return Member(seed, SimStatus.OK, transit, math.radians(rotation_deg), None, 1.0)


def test_ensemble_effects_keep_their_sign_and_count_the_placements():
    runs = {}
    for s in range(6):
        runs["k", "low", s] = _member(s, 20.0 + s, 1.0)
        runs["k", "high", s] = _member(s, 18.0 + s, 1.0 + 0.01 * (s + 1))
        runs["k", "minus", s] = _member(s, 20.0 + s, 1.0)
        runs["k", "plus", s] = _member(s, 20.1 + s, 1.0)
    text = "\n".join(parameter_effects._ensemble_lines(runs, ["k"], 6))
    row = next(line for line in text.splitlines() if line.startswith("| k |"))
    assert row.split(" | ")[1].startswith("-2 (")  # the median rotation fell by 2 degrees
    assert row.split(" | ")[2].startswith("+0.035 (")  # the median transit rose by 35 ms
    assert "further at 0 of 6 placements, less at 6, alike at 0" in text
    assert "median paired difference -2.00 degrees" in text


def test_outcome_line_gives_the_signed_turn_or_why_a_run_failed():
    from parcelfit.runs import Run, Trajectory
    from parcelfit.sim.ensemble import outcome_line
    from parcelfit.sim.protocol import SimResult

    # an unwrapped heading (a trajectory's) across 180 degrees and back: a net turn of -20
    theta = np.radians([170.0, 185.0, 150.0])
    track = Trajectory(np.array([0.0, 0.1, 0.2]), np.zeros(3), np.zeros(3), theta)
    run = Run("r", TestCase("E3", "KP", 1), track, transit_time=1.23456)
    assert outcome_line(SimResult(run, SimStatus.OK, 1.0)) == (
        "rotation -20.00 deg, transit 1.2346 s"
    )
    failed = SimResult(None, SimStatus.UNSTABLE, 1.0, {"message": "nan in qacc"})
    assert outcome_line(failed) == "run failed: unstable (nan in qacc)"
    assert outcome_line(SimResult(None, SimStatus.TIMEOUT, 1.0)) == "run failed: timeout"


def test_the_bulge_reaches_the_runs_whatever_the_consignment_is_called(monkeypatch, tmp_path):
    # KP/BW, a lowercase name or a file path name the same type: the runs must get the bulge
    seen = []

    def fake(job):
        seen.append(job)
        raise _BuiltError

    monkeypatch.setattr(parameter_effects, "_simulate", fake)
    monkeypatch.setattr(parameter_effects, "ProcessPoolExecutor", _Serial)
    args = ["--consignment", "KP/BW", "--bulge", "0.55", "--params", "E_Pa", "--placements", "1"]
    with pytest.raises(_BuiltError):
        parameter_effects.main([*args, "--out", str(tmp_path)])
    _, case, *_, cons, _ = seen[0]
    assert case.consignment == cons.name == "KPBW"
    assert cons.bulge == (0.004, 0.55)


@pytest.mark.parametrize(
    "extra",
    [[], ["--consignment", "BW", "--bulge", "0"], ["--bottom-patch", "rim-bending"]],
)
def test_the_sheets_stiffness_reaches_the_reference_where_its_rim_bends(
    tmp_path, monkeypatch, extra
):
    # KP/BW by default, a flat BW and the patch named: the runs are submitted
    def submitted(*args, **kwargs):
        raise _BuiltError

    monkeypatch.setattr(parameter_effects, "ProcessPoolExecutor", submitted)
    with pytest.raises(_BuiltError):
        args = ["--backend", "rigidbox", "--params", "E_Pa", "t_Pa", *extra]
        parameter_effects.main([*args, "--out", str(tmp_path)])


def test_without_the_floor_only_the_ends_run_and_effects_are_judged_by_standard_errors(
    monkeypatch, tmp_path
):
    from parcelfit.sim.ensemble import ensemble_shift

    noise = [0.1, -0.1, 0.6, 0.1, -0.5, 0.4, 1.3, 0.9]  # per placement
    scatter = {"k_CoPa": 0.0005, "E_Pa": 0.0017}  # [s]: z about 9.9 and 2.5 below

    def transit(name: str, seed: int, high: bool) -> float:
        """A 2 ms later transit at the high end, scattered from placement to placement."""
        return 1.0 + 0.003 * seed + ((0.002 + scatter[name] * noise[seed]) if high else 0.0)

    def members(name: str, high: bool) -> list[Member]:
        return [Member(s, SimStatus.OK, transit(name, s, high), 0.3, None, 1.0) for s in range(8)]

    for name, (low, high) in {"k_CoPa": (9, 11), "E_Pa": (2, 3)}.items():
        sh = ensemble_shift(members(name, False), members(name, True))
        assert low < sh.transit_median / sh.transit_median_se < high  # the data are as meant

    labels = []
    defaults = load_consignment("KPBW").parameter_values()

    def fake(job):
        params, _, seed, *_ = job
        name = next(n for n in scatter if params[n] != defaults[n])
        high = params[name] > defaults[name]
        labels.append((name, high))
        return Member(seed, SimStatus.OK, transit(name, seed, high), 0.3, None, 1.0)

    monkeypatch.setattr(parameter_effects, "_simulate", fake)
    monkeypatch.setattr(parameter_effects, "ProcessPoolExecutor", _Serial)
    monkeypatch.setattr(parameter_effects, "as_completed", lambda futures: list(futures))
    args = ["--params", "k_CoPa", "E_Pa", "--placements", "8", "--no-floor", "--out", str(tmp_path)]
    assert parameter_effects.main(args) == 0
    assert len(labels) == 32  # the two ends only, no runs at the default -+step
    assert sorted(set(labels)) == [
        ("E_Pa", False),
        ("E_Pa", True),
        ("k_CoPa", False),
        ("k_CoPa", True),
    ]
    text = (tmp_path / "parameter-effects.md").read_text()
    assert "--no-floor" in text and "Noise floor not measured" in text
    assert "32 simulations (0 not ok)" in text
    # no column, figure or title of a floor that was not measured
    assert "floor DTW" not in text and "floor median" not in text and "ratio" not in text
    assert "noise floor**" not in text.lower()
    assert text.startswith("# Parameter effects\n")
    ensemble_head = next(
        line for line in text.splitlines() if line.startswith("| parameter | effect median")
    )
    row = next(line for line in text.splitlines() if line.startswith("| k_CoPa |") and "(" in line)
    assert ensemble_head.count("|") == row.count("|") == 8  # parameter, 3 effects, 3 z
    # 3 standard errors, not 2: E_Pa at 2.5 SE is not listed as moving the ensemble
    assert "by >= 3 standard errors: k_CoPa; not: E_Pa." in text


def test_without_the_floor_one_placement_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        parameter_effects.main(["--params", "k_CoPa", "--no-floor", "--out", str(tmp_path)])
    assert "--placements 2 or more" in capsys.readouterr().err
    assert not (tmp_path / "parameter-effects.md").exists()


def test_runs_that_time_out_are_named_as_they_end_and_counted_by_status(
    monkeypatch, tmp_path, capsys
):
    def fake(job):
        _, _, seed, *_, wall_limit = job
        assert wall_limit == 30.0
        if seed == 1:  # one placement times out at each level
            return Member(seed, SimStatus.TIMEOUT, None, None, None, 31.0)
        return Member(seed, SimStatus.OK, 1.0 + 0.001 * seed, 0.3, None, 1.0)

    monkeypatch.setattr(parameter_effects, "_simulate", fake)
    monkeypatch.setattr(parameter_effects, "ProcessPoolExecutor", _Serial)
    monkeypatch.setattr(parameter_effects, "as_completed", lambda futures: list(futures))
    args = ["--params", "k_CoPa", "--placements", "3", "--no-floor", "--wall-limit", "30"]
    assert parameter_effects.main([*args, "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "k_CoPa low placement 1: not ok (timeout, 31 s)" in out
    assert "k_CoPa high placement 1: not ok (timeout, 31 s)" in out
    text = (tmp_path / "parameter-effects.md").read_text()
    assert "--wall-limit 30 " in text and "6 simulations (2 not ok: 2 timeout)" in text
