"""What a set of test cases can determine: the precision estimate of parcelfit.study.precision."""

from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from parcelfit.cli import app
from parcelfit.errors import ParcelfitError
from parcelfit.metrics.comparison import Comparison
from parcelfit.runs import Run, TestCase, Trajectory
from parcelfit.runs.regions import Box
from parcelfit.study.precision import (
    CaseSensitivity,
    best_subsets,
    precision,
    run_statistics,
    sensitivity,
)
from parcelfit.study.precision_check import PrecisionCheck, run_precision_check
from parcelfit.study.store import Store
from parcelfit.study.studyfile import load_study

from .fake_sim import write_reference_dataset

Z = 1.959963984540054
NO_INFORMATION = Z / math.sqrt(12.0)  # the uniform prior alone


def _orthogonal_real(mean: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """Four real runs whose statistics have exactly the sample means ``mean``, the sample
    standard deviations ``sd`` and no correlation (orthogonal +-1 columns)."""
    signs = np.array([[1, 1, 1], [-1, 1, -1], [1, -1, -1], [-1, -1, 1]], dtype=float)
    # each column has sample variance 4 / 3 with ddof=1
    return mean + signs * sd / math.sqrt(4.0 / 3.0)


def test_run_statistics_are_transit_rotation_and_drift_inside_the_regions() -> None:
    t = np.linspace(0.0, 2.0, 121)
    x = 0.5 * t - 0.2
    y = np.where(x > 0.3, -0.1 * (x - 0.3), 0.0)
    theta = np.where(x > 0.3, -2.0 * (x - 0.3), 0.0)
    run = Run("r", TestCase("E3", "KPBW", 1), Trajectory(t, x, y, theta), transit_time=1.5)
    whole = run_statistics(run, Comparison(rate=None))
    assert whole is not None
    assert whole[0] == 1.5
    assert whole[1] == pytest.approx(2.0 * 0.5, abs=1e-12)  # theta goes 0 -> -1 rad
    assert whole[2] == pytest.approx(-0.05, abs=1e-12)
    cropped = run_statistics(run, Comparison(regions=(Box(xmin=0.0, xmax=0.29),), rate=None))
    assert cropped is not None
    assert cropped[1] == pytest.approx(0.0, abs=1e-12)  # nothing turns before x = 0.3
    assert cropped[2] == pytest.approx(0.0, abs=1e-12)
    no_time = Run("n", TestCase("E3", "KPBW", 1), Trajectory(t, x, y, theta))
    assert run_statistics(no_time, Comparison(rate=None)) is None


def test_information_is_n_times_the_squared_effect_over_the_variance() -> None:
    # uncorrelated real statistics with known sd: F_jj = n sum_s J_sj^2 / sd_s^2 exactly
    sd = np.array([0.02, 0.1, 0.005])
    real = _orthogonal_real(np.array([1.4, 0.4, 0.1]), sd)
    jac = np.array([[0.05, 0.0], [0.3, 0.0], [0.0, 0.0]])
    case = CaseSensitivity("E3/KPBW/1", ("a", "b"), jac, np.zeros_like(jac), real)
    info = case.information()
    expected = 4 * ((0.05 / 0.02) ** 2 + (0.3 / 0.1) ** 2)
    assert info[0, 0] == pytest.approx(expected, rel=1e-9)
    assert info[1, 1] == pytest.approx(0.0, abs=1e-9)
    p = precision([case])
    assert p.alone[0] == pytest.approx(Z / math.sqrt(expected + 12.0), rel=1e-9)
    assert p.joint[0] == pytest.approx(p.alone[0], rel=1e-9)  # b shares nothing with a
    # a parameter that moves nothing keeps the prior's width: undetermined
    assert p.joint[1] == pytest.approx(NO_INFORMATION, rel=1e-9)
    assert p.determined(0.10) == {"a": p.joint[0] <= 0.10, "b": False}


def test_two_cases_add_their_information_and_confounded_parameters_share_it() -> None:
    sd = np.array([0.02, 0.1, 0.005])
    real = _orthogonal_real(np.array([1.4, 0.4, 0.1]), sd)
    same = np.array([[0.2, 0.2], [0.0, 0.0], [0.0, 0.0]])  # a and b move only the transit, alike
    c1 = CaseSensitivity("E3/KPBW/1", ("a", "b"), same, np.zeros_like(same), real)
    one = precision([c1])
    # alone each is well determined, jointly only their sum is: the joint width is far wider
    assert one.alone[0] < 0.10
    assert one.joint[0] > 4 * one.alone[0]
    # a second case that moves only b breaks the tie
    other = np.array([[0.0, 0.2], [0.0, 0.0], [0.0, 0.0]])
    c2 = CaseSensitivity("E1/KPBW/3", ("a", "b"), other, np.zeros_like(other), real)
    both = precision([c1, c2])
    assert both.joint[0] < 0.5 * one.joint[0]
    assert both.labels == ("E3/KPBW/1", "E1/KPBW/3")
    # the same case twice holds twice the information
    twice = precision([c1, c1])
    f = c1.information()[0, 0]
    assert twice.alone[0] == pytest.approx(Z / math.sqrt(2 * f + 12.0), rel=1e-9)


def test_best_subsets_pick_what_the_cases_determine_and_never_a_confounded_pair() -> None:
    sd = np.array([0.02, 0.1, 0.005])
    real = _orthogonal_real(np.array([1.4, 0.4, 0.1]), sd)
    # a and b move the transit alike (confounded), c the rotation strongly, d the drift weakly,
    # e nothing
    jac = np.array(
        [[0.2, 0.2, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.004, 0.0]]
    )
    case = CaseSensitivity("E3/KPBW/1", tuple("abcde"), jac, np.zeros_like(jac), real)
    info = case.information()
    found = best_subsets([case], 2, top=20)
    assert len(found) == 10  # C(5, 2)
    best = found[0]
    # c is determined within 10 % in any company; a or b alone beside it, never both
    assert "c" in best.names and best.determined == 2
    assert best.names in (("a", "c"), ("b", "c"))
    k = best.names.index("c")
    assert best.half_widths[k] == pytest.approx(Z / math.sqrt(info[2, 2] + 12.0), rel=1e-9)
    pair = next(s for s in found if s.names == ("a", "b"))
    assert pair.determined == 0  # together only their sum is fixed
    assert found[-1].names in (("d", "e"),)  # the weakest pair ranks last
    assert np.allclose(
        next(s for s in found if s.names == ("d", "e")).half_widths[1], NO_INFORMATION
    )
    # ranked: determined count never rises down the list
    counts = [s.determined for s in found]
    assert counts == sorted(counts, reverse=True)
    with pytest.raises(ParcelfitError, match="choose a size"):
        best_subsets([case], 6)
    with pytest.raises(ParcelfitError, match="no test cases"):
        best_subsets([], 2)


def test_with_many_parameters_the_table_lists_one_per_row_and_names_the_best_four() -> None:
    sd = np.array([0.02, 0.1, 0.005])
    real = _orthogonal_real(np.array([1.4, 0.4, 0.1]), sd)
    names = tuple(f"p{i}" for i in range(7))
    jac = np.zeros((3, 7))
    jac[0, 2], jac[1, 5] = 0.3, 2.0  # only p2 (transit) and p5 (rotation) move anything
    case = CaseSensitivity("E3/KPBW/1", names, jac, np.zeros_like(jac), real)
    check = PrecisionCheck(names, ("E3/KPBW/1",), (), {"E3/KPBW/1": case}, 3, 42, 0, 0.0, False)
    text = check.markdown("cmd", 2)
    rows = [line for line in text.splitlines() if re.match(r"\| p\d", line)]
    assert len(rows) == 7 + 5  # one row per parameter, then the five best subsets of four
    assert rows[2].startswith("| p2 | ") and " * / " in rows[2]  # determined, joint and alone
    assert rows[0].startswith("| p0 | 57 % / 57 %")
    ((title, found),) = check.subsets(top=5)
    assert title == "E3/KPBW/1 (fitted)"
    assert all({"p2", "p5"} <= set(s.names) and s.determined == 2 for s in found)
    assert "Which 4 to calibrate" in text


def test_an_effect_the_placements_do_not_resolve_carries_no_information() -> None:
    # the real runs scatter little (0.02 rad) where the placements' mean rotation moves by
    # 0.3 +- 0.2 rad (not resolved: below twice its standard error): counted, it would pin a
    # within 6 % of its range; it must count for nothing, and the table must say so
    sd = np.array([0.02, 0.02, 0.005])
    real = _orthogonal_real(np.array([1.4, 0.4, 0.1]), sd)
    jac = np.array([[0.0, 0.05], [0.3, 0.0], [0.0, 0.0]])
    se = np.array([[0.0, 0.001], [0.2, 0.0], [0.0, 0.0]])
    case = CaseSensitivity("E3/KPBW/1", ("a", "b"), jac, se, real)
    assert not case.resolved[1, 0] and case.resolved[0, 1]
    assert case.information()[0, 0] == pytest.approx(0.0, abs=1e-12)
    counted = 4 * (0.3 / 0.02) ** 2
    assert case.information(resolved_only=False)[0, 0] == pytest.approx(counted, rel=1e-9)
    p = precision([case])
    assert p.alone[0] == pytest.approx(NO_INFORMATION, rel=1e-9)
    assert p.joint[0] == pytest.approx(NO_INFORMATION, rel=1e-9)
    assert p.alone_unresolved[0] == pytest.approx(Z / math.sqrt(counted + 12.0), rel=1e-9)
    assert p.alone[1] == pytest.approx(p.alone_unresolved[1], rel=1e-9)  # b is resolved
    assert p.unresolved() == ("a",)
    check = PrecisionCheck(
        ("a", "b"), ("E3/KPBW/1",), (), {"E3/KPBW/1": case}, 3, 12, 0, 0.0, False
    )
    text = check.markdown("cmd", 2)
    assert "| E3/KPBW/1 (fitted) | 57 % | 57 % |" in text
    assert "- E3/KPBW/1 (fitted): a 6 % *" in text
    # with every effect resolved there is nothing to name
    sure = CaseSensitivity("E3/KPBW/1", ("a", "b"), jac, np.zeros_like(se), real)
    assert precision([sure]).unresolved() == ()
    assert "Not counted" not in PrecisionCheck(
        ("a", "b"), ("E3/KPBW/1",), (), {"E3/KPBW/1": sure}, 3, 12, 0, 0.0, False
    ).markdown("cmd", 2)


def test_where_the_placements_scatter_more_than_the_real_runs_their_scatter_counts() -> None:
    # ten real runs that all slid (rotation sd 0.02 rad) against placements that spin at some
    # seeds (sd 0.5 rad): the real runs' mean is known no better than the population's scatter
    # allows, so the information is that of sd 0.5, not 0.02
    sd = np.array([0.02, 0.02, 0.005])
    real = _orthogonal_real(np.array([1.4, 0.4, 0.1]), sd)
    jac = np.array([[0.0, 0.05], [0.3, 0.0], [0.0, 0.0]])
    narrow = CaseSensitivity("E3/KPBW/1", ("a", "b"), jac, np.zeros_like(jac), real)
    model_sd = np.array([0.01, 0.5, 0.001])  # transit and drift: the real runs scatter more
    wide = CaseSensitivity("E3/KPBW/1", ("a", "b"), jac, np.zeros_like(jac), real, model_sd)
    assert wide.scatter == pytest.approx([0.02, 0.5, 0.005])
    assert narrow.information()[0, 0] == pytest.approx(4 * (0.3 / 0.02) ** 2, rel=1e-9)
    assert wide.information()[0, 0] == pytest.approx(4 * (0.3 / 0.5) ** 2, rel=1e-9)
    # b acts on the transit time, where the real runs' own scatter is the larger: unchanged
    assert wide.information()[1, 1] == pytest.approx(narrow.information()[1, 1], rel=1e-9)
    assert precision([narrow]).alone[0] < 0.10 < precision([wide]).alone[0]
    # a statistic every run shows alike keeps the tracking resolution as its floor
    flat = CaseSensitivity("E3/KPBW/1", ("a", "b"), jac, jac, np.ones((4, 3)), np.zeros(3))
    assert flat.scatter == pytest.approx([1e-3, 1e-3, 1e-3])
    # real runs that all show the same rotation (no scatter of their own) against placements
    # that scatter by 0.5 rad: the rotation counts with the placements' 0.5 rad, in full
    same = real.copy()
    same[:, 1] = 0.4
    alike = CaseSensitivity("E3/KPBW/1", ("a", "b"), jac, np.zeros_like(jac), same, model_sd)
    assert alike.information()[0, 0] == pytest.approx(4 * (0.3 / 0.5) ** 2, rel=1e-9)


def test_sensitivity_pairs_placements_and_drops_failed_ones() -> None:
    low = {"a": [np.array([1.0, 0.1, 0.0]), None, np.array([1.2, 0.3, 0.0])]}
    high = {"a": [np.array([1.1, 0.1, 0.0]), np.array([9.0, 9.0, 9.0]), np.array([1.4, 0.3, 0.0])]}
    real = [np.array([1.0, 0.1, 0.0]), None, np.array([1.1, 0.2, 0.01])]
    s = sensitivity("E3/KPBW/1", ["a"], low, high, real)
    # placement 2 failed at the low end, so its high-end run is dropped too
    assert s.jacobian[:, 0] == pytest.approx([0.15, 0.0, 0.0])
    assert s.jacobian_se[0, 0] == pytest.approx(np.std([0.1, 0.2], ddof=1) / math.sqrt(2))
    assert s.resolved[0, 0] and not s.resolved[1, 0]
    assert s.real.shape == (2, 3)  # the unusable real run is left out
    # the placements' scatter: root mean of the two ends' sample variances over the same pairs
    low_var = np.var([[1.0, 0.1, 0.0], [1.2, 0.3, 0.0]], axis=0, ddof=1)
    high_var = np.var([[1.1, 0.1, 0.0], [1.4, 0.3, 0.0]], axis=0, ddof=1)
    assert s.model_sd == pytest.approx(np.sqrt(0.5 * (low_var + high_var)))
    # with runs at the point itself, their scatter counts (failed ones left out)
    point = [np.array([1.0, 0.0, 0.0]), None, np.array([1.3, 2.0, 0.02])]
    at = sensitivity("E3/KPBW/1", ["a"], low, high, real, point)
    assert at.model_sd == pytest.approx(np.std([[1.0, 0.0, 0.0], [1.3, 2.0, 0.02]], axis=0, ddof=1))
    assert np.array_equal(at.jacobian, s.jacobian)
    # one usable run at the point has no scatter: the ends' pooled scatter stands in
    one = sensitivity("E3/KPBW/1", ["a"], low, high, real, [None, point[0]])
    assert one.model_sd == pytest.approx(s.model_sd)
    with pytest.raises(ParcelfitError, match="both ends"):
        sensitivity("E3/KPBW/1", ["a"], {"a": [None]}, {"a": [np.zeros(3)]}, real)


def test_a_case_with_one_real_run_is_refused() -> None:
    jac = np.ones((3, 1))
    case = CaseSensitivity("E3/KPBW/1", ("a",), jac, np.zeros_like(jac), np.ones((1, 3)))
    with pytest.raises(ParcelfitError, match="two or more"):
        precision([case])
    with pytest.raises(ParcelfitError, match="no test cases"):
        precision([])


def _two_rig_study(tmp_path: Path) -> Path:
    """R/P/1 fitted, Q/P/1 as the transfer case: on the analytic simulator E_Pa turns the parcel
    on rig Q only, the frictions act on both."""
    write_reference_dataset(tmp_path / "data", rigs=("R", "Q"), truth={"E_Pa": 1e9})
    doc = {
        "name": "precision",
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make"},
        "parameters": {"mu_d_BePa": [0.3, 0.55], "mu_d_MePa": [0.15, 0.35], "E_Pa": [200, 1600]},
        "cases": [{"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1}],
        "transfer": [{"rig": "Q", "consignment": "P", "speed_setting": 1}],
        "executor": "serial",
    }
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_the_check_says_which_case_determines_which_parameter_and_resumes(tmp_path: Path) -> None:
    study = _two_rig_study(tmp_path)
    check = run_precision_check(study, tmp_path / "out", placements=3, executor="serial")
    # 2 cases x (3 parameters x 2 ends + the point) x 3 placements
    assert check.simulations == check.simulated_now == 2 * (3 * 2 + 1) * 3
    store = Store(tmp_path / "out" / "precision.sqlite", readonly=True)
    stored = store.evaluations("precision")
    store.close()
    assert len(stored) == check.simulations and all(e.status == "ok" for e in stored)
    assert len({(e.details.case, json.dumps(e.params), e.seed) for e in stored}) == len(stored)
    bounds = {d.name: (d.low, d.high) for d in load_study(study).space.dims}
    at_point = [
        e for e in stored if all(v not in bounds[n] for n, v in e.params.items() if n in bounds)
    ]
    assert len(at_point) == 2 * 3
    assert all(e.details.lateral_drift is not None and e.transit_time for e in stored)
    rows = dict(check.rows())
    e = check.names.index("E_Pa")
    alone = rows["R/P/1 (fitted)"]
    # rig R cannot see E_Pa: the prior's width, undetermined; the frictions it determines
    assert alone.joint[e] == pytest.approx(NO_INFORMATION, rel=1e-3)
    assert alone.determined() == {"E_Pa": False, "mu_d_BePa": True, "mu_d_MePa": True}
    # adding rig Q, where E_Pa turns the parcel, determines it too
    assert rows["fitted + Q/P/1"].joint[e] < 0.10
    # a rerun simulates nothing and gives the same answer
    again = run_precision_check(study, tmp_path / "out", placements=3, executor="serial")
    assert again.simulated_now == 0 and again.simulations == check.simulations
    for (t1, p1), (t2, p2) in zip(check.rows(), again.rows(), strict=True):
        assert t1 == t2 and np.array_equal(p1.joint, p2.joint)
    # the runs kept by an earlier parcelfit in statistics.json (run id: statistics and ridden
    # speeds) are taken over: nothing is simulated again, the same answer
    legacy = {}
    for e in stored:
        tag = next(
            (
                f"{n}-{end}"
                for n, (lo, hi) in bounds.items()
                for end, v in (("low", lo), ("high", hi))
                if e.params[n] == v
            ),
            "point",
        )
        d = e.details
        legacy[f"precision-{d.case}-{tag}-{e.seed}"] = [
            e.transit_time,
            d.region_rotation,
            d.lateral_drift,
            d.start_speed,
            d.end_speed,
        ]
    store = Store(tmp_path / "out" / "precision.sqlite", readonly=True)
    setup = store.get_meta("setup")
    store.close()
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "statistics.json").write_text(json.dumps({"setup": setup, "runs": legacy}))
    old = run_precision_check(study, tmp_path / "old", placements=3, executor="serial")
    assert old.simulated_now == 0 and old.simulations == check.simulations
    for (t1, p1), (t2, p2) in zip(check.rows(), old.rows(), strict=True):
        assert t1 == t2 and np.array_equal(p1.joint, p2.joint)
    # adjusting the transit times for the belt speeds reuses every stored run (the cache keeps
    # the ridden speeds) and says per case what the adjustment did
    adjusted = run_precision_check(
        study, tmp_path / "out", placements=3, adjust_transit=True, executor="serial"
    )
    assert adjusted.simulated_now == 0
    assert set(adjusted.adjustments) == {"R/P/1", "Q/P/1"}
    assert all(a.runs >= 2 for a in adjusted.adjustments.values())
    text = adjusted.markdown("cmd", 1)
    assert "Transit times adjusted for the belt speeds" in text and "- R/P/1: transit" in text
    assert not check.adjustments and "Transit times adjusted" not in check.markdown("cmd", 1)
    # at the same point, other ranges make other runs: the check before is neither reused nor
    # overwritten; the same ranges in another folder simulate afresh
    at = {"mu_d_BePa": 0.4, "mu_d_MePa": 0.25, "E_Pa": 1000}
    run_precision_check(study, tmp_path / "at", placements=2, at=at, executor="serial")
    kept = (tmp_path / "at" / "precision.sqlite").read_bytes()
    doc = yaml.safe_load(study.read_text())
    doc["parameters"]["E_Pa"] = [400, 1600]
    study.write_text(yaml.safe_dump(doc))
    with pytest.raises(ParcelfitError, match="another point, range or simulator") as refused:
        run_precision_check(study, tmp_path / "at", placements=2, at=at, executor="serial")
    assert "another --out folder" in str(refused.value)
    assert (tmp_path / "at" / "precision.sqlite").read_bytes() == kept
    moved = run_precision_check(study, tmp_path / "at2", placements=2, at=at, executor="serial")
    assert moved.simulated_now == moved.simulations
    # the same study and data in another folder (another checkout) reuse the runs: the key
    # holds the study's settings, not the absolute path of its folder
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.copytree(tmp_path / "data", elsewhere / "data")
    shutil.copy(study, elsewhere / "study.yaml")
    reused = run_precision_check(
        elsewhere / "study.yaml", tmp_path / "at2", placements=2, at=at, executor="serial"
    )
    assert reused.simulated_now == 0
    assert np.array_equal(reused.rows()[0][1].joint, moved.rows()[0][1].joint)


def test_the_precision_command_writes_its_table_and_refuses_bad_input(tmp_path: Path) -> None:
    study = _two_rig_study(tmp_path)
    out = tmp_path / "check"
    args = ["precision", str(study), "--placements", "2", "--executor", "serial", "--out", str(out)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    table = (out / "precision-check.md").read_text()
    assert "| R/P/1 (fitted) | 57 % |" in table and "fitted + Q/P/1" in table
    adjusted = CliRunner().invoke(app, [*args, "--adjust-transit"])
    assert adjusted.exit_code == 0, adjusted.output
    table = (out / "precision-check.md").read_text()
    assert "--adjust-transit" in table and "Transit times adjusted" in table
    bad = CliRunner().invoke(app, [*args, "--at", "k_MePa=400"])
    assert bad.exit_code == 2 and "not a parameter of the study" in bad.output
    few = CliRunner().invoke(app, [*args[:2], "--placements", "1"])
    assert few.exit_code == 2


def test_the_cited_command_repeats_the_options_as_each_program_takes_them() -> None:
    from parcelfit.study.precision_check import command_line

    options = {
        "placements": 4,
        "candidates": ["E1/KP/1", "E2a/KP/1"],
        "at": ["E_Pa=600", "k_MePa=400"],
        "adjust_transit": True,
    }
    cli = command_line("parcelfit precision", Path("a/study.yaml"), **options, repeated=True)
    assert cli == (
        "parcelfit precision a/study.yaml --placements 4 --candidate E1/KP/1 --candidate "
        "E2a/KP/1 --at E_Pa=600 --at k_MePa=400 --adjust-transit"
    )
    script = command_line("python s.py", Path("a/study.yaml"), **options, repeated=False)
    assert script == (
        "python s.py a/study.yaml --placements 4 --candidates E1/KP/1 E2a/KP/1 "
        "--at E_Pa=600 k_MePa=400 --adjust-transit"
    )
    bare = command_line(
        "p", Path("s.yaml"), placements=2, candidates=[], at=[], adjust_transit=False, repeated=True
    )
    assert bare == "p s.yaml --placements 2"
