"""`parcelfit design` on the analytic test simulator: the expected widths of the linear design,
and a candidate built to depend strongly on a parameter ranks first for it."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from parcelfit.cli import app
from parcelfit.study.design import expected_width, runs_needed

from .helpers import intervals_of
from .predict_helpers import write_finished_study, write_rig_q

runner = CliRunner()


def test_expected_width_of_one_parameter_is_the_posterior_over_the_prior_sd():
    J = np.array([[0.3], [0.0]])  # quantity 1 moves by 0.3 over the interval, quantity 2 not
    scatter = np.array([0.1, 1.0])
    for n in (1, 4, 25):
        w = expected_width(J, scatter, n)
        assert w[0] == pytest.approx(math.sqrt(12 / (n * 9 + 12)))
    assert expected_width(np.zeros((2, 1)), scatter, 10)[0] == pytest.approx(1.0)
    # a share of 0.2: 12 / (9 n + 12) <= 0.04 from n = 32
    assert runs_needed(J, scatter, np.array([0.2])) == [32]
    assert runs_needed(J * 1e-3, scatter, np.array([0.2])) == [None]


def test_a_candidate_that_moves_two_parameters_alike_tells_neither():
    scatter = np.array([0.01])
    alike = expected_width(np.array([[1.0, 1.0]]), scatter, 10)
    apart = expected_width(np.array([[1.0, 1.0], [1.0, -1.0]]), np.array([0.01, 0.01]), 10)
    assert (alike > 0.7).all()  # only their sum is measured
    assert (apart < 0.01).all()


def test_the_candidate_built_to_depend_on_a_parameter_ranks_first_for_it(tmp_path):
    study = write_finished_study(tmp_path)
    q = write_rig_q(tmp_path)  # the analytic simulator turns the parcel by E_Pa on rig Q only
    out = tmp_path / "d"
    argv = ["design", str(study), "--rig", str(q), "--sets", "8", "--placements", "3"]
    for label in ("E3/KPBW/1", "E1/PB/2", "Q/KPBW/1", "Q/BW/2"):
        argv += ["--candidate", label]
    argv += ["--executor", "serial", "--out", str(out)]
    result = runner.invoke(app, argv)
    assert result.exit_code == 0, result.output
    cands = pd.read_csv(out / "candidates.csv")
    assert set(cands["parameter"]) == {"E_Pa"}  # the only parameter not determined
    assert len(cands) == 4
    first = cands[cands["rank"] == 1].iloc[0]
    assert first["rig"] == "Q" and first["quantity"] == "exit_heading"
    assert first["runs_needed"] == 1
    on_r = cands[cands["rig"] != "Q"]
    # on rig R E_Pa turns the parcel by 1e-4 rad per GPa and second: far below the 1 degree floor
    assert (on_r["expected_share"] > 0.999).all() and on_r["runs_needed"].isna().all()
    ranking = pd.read_csv(out / "ranking.csv")
    assert ranking.iloc[0]["candidate"].startswith("Q/")
    # the fitted case is simulated too; after one Q candidate the other Q adds little
    assert json.loads((out / "design.json").read_text())["fitted"] == ["R/P/1"]
    assert ranking.iloc[0]["with_above"] == ranking.iloc[0]["mean_share"]
    assert ranking.iloc[1]["with_above"] <= ranking.iloc[0]["with_above"]
    assert "E_Pa (undetermined): the experiments that narrow it most" in result.output
    again = runner.invoke(app, argv)  # resumes: nothing left to simulate, the same tables
    assert again.exit_code == 0
    pd.testing.assert_frame_equal(pd.read_csv(out / "candidates.csv"), cands)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--candidate", "E3-KPBW-1"], "--candidate 'E3-KPBW-1' is not RIG/TYPE/SETTING"),
        (["--candidate", "E3/KPBW/7"], "rig E3 has no speed setting 7"),
        (["--rig", "E3"], "--rig 'E3' is not a rig .yaml file"),
        (
            ["--sets", "2"],
            "3 parameters need at least 5 parameter sets (with fewer nothing could narrow "
            "anything) Fix: give --sets 5 or more",
        ),
    ],
)
def test_bad_candidates_exit_2(tmp_path, args, message):
    study = write_finished_study(tmp_path)
    result = runner.invoke(app, ["design", str(study), *args, "--out", str(tmp_path / "d")])
    assert result.exit_code == 2
    assert message in " ".join(result.output.split()) and "Traceback" not in result.output


def test_the_bench_tests_are_candidates_with_every_bundled_type():
    from parcelfit.sim.mujoco import bundled_consignment_names, bundled_rig_names, load_rig
    from parcelfit.study.design import candidate_designs

    from .helpers import ROOT

    bench = [str(ROOT / "examples" / "bench" / f"{name}.yaml") for name in ("B1", "B2")]
    assert [sorted(load_rig(p).speeds) for p in bench] == [[1, 2], [1, 2]]
    types = len(bundled_consignment_names())
    every = candidate_designs((), bench)
    settings = sum(len(load_rig(r).speeds) for r in bundled_rig_names())
    assert len(every) == (settings + 2 * 2) * types  # the bundled rigs' settings and the two
    named = candidate_designs(["E3/KPBW/1", "B1/KP/2"], bench)  # a --rig file by its name
    assert [d.label for d in named] == ["E3/KPBW/1", "B1/KP/2"]
    assert named[1].rig == bench[0]


def test_a_candidate_that_informs_only_jointly_with_a_fitted_case_ranks_above_one_that_adds_nothing():
    from parcelfit.study.design import greedy_sequence, information, shares_of

    # parameters (p0, p1), both open; the fitted case measures p0 sharply (10 runs)
    known = 10 * information(np.array([[1.0, 0.0]]), np.array([0.01]))
    joint = information(np.array([[1.0, 1.0]]), np.array([0.01]))  # moves p0 and p1 alike
    same = information(np.array([[0.0, 0.0]]), np.array([0.01]))  # moves nothing
    alone = shares_of(10 * joint)  # on its own it cannot tell p0 from p1
    assert (alone > 0.7).all()
    given = shares_of(10 * joint, known)  # with the fitted case p1 is read off the sum
    # p1's sd: sqrt(2e-5) (p0 + p1 and p0 each to 1e-5) over the prior's sqrt(1 / 12)
    assert given[1] == pytest.approx(math.sqrt(12 * 2e-5), rel=1e-3)
    assert given[0] > 0.999  # p0 is known already: nothing gained
    assert shares_of(10 * same, known) == pytest.approx([1.0, 1.0])
    order = greedy_sequence([same, joint], known, 10, [0, 1])
    assert [c for c, _ in order] == [1, 0]
    assert order[0][1] == pytest.approx(float(np.mean(given)))
    assert order[1][1] == pytest.approx(order[0][1])  # nothing added by the second


def test_the_greedy_second_choice_is_not_the_first_rig_at_another_setting():
    from parcelfit.study.design import greedy_sequence, information, shares_of

    s = np.array([0.1])
    a1 = information(np.array([[1.0, 0.0, 0.0]]), s)  # rig A, setting 1: p0
    a2 = information(np.array([[1.1, 0.0, 0.0]]), s)  # rig A, setting 2: p0 again, a bit more
    b = information(np.array([[0.0, 0.4, 0.0]]), s)  # rig B: p1, weaker
    one = [float(np.mean(shares_of(10 * i))) for i in (a1, a2, b)]
    assert one[1] < one[0] < one[2]  # one by one: A2, A1, then B
    order = greedy_sequence([a1, a2, b], None, 10, [0, 1, 2])
    assert [c for c, _ in order] == [1, 2, 0]  # A2, then B (a new parameter), then A1
    assert order[0][1] == pytest.approx(one[1])
    pair = shares_of(10 * (a2 + b))
    assert order[1][1] == pytest.approx(float(np.mean(pair)))
    assert pair[1] == pytest.approx(math.sqrt(12 / (12 + 10 * 16))) and pair[2] == 1.0


def test_an_effect_counts_at_the_family_wise_t_quantile():
    from scipy.stats import t

    from parcelfit.study.design import resolved_t

    # 4 quantities x 4 parameters share a 5 % chance of a false effect: t at 1 - 0.05 / 32
    assert resolved_t(20, 4) == pytest.approx(t.ppf(1 - 0.05 / 32, 15))
    assert resolved_t(20, 4) == pytest.approx(3.515, abs=1e-3)
    assert resolved_t(10, 4) == pytest.approx(5.33, abs=0.01)
    assert resolved_t(10, 4) > resolved_t(20, 4) > resolved_t(50, 4) > 3.0


def test_a_run_s_angle_informs_once_and_its_scatter_is_unbiased():
    """The rotation and the exit heading are one angle measured twice: only the exit heading
    enters J; the run-to-run scatter divides by the runs less the sets (here 2 placements per
    set: twice what the divisor N gives)."""
    from parcelfit.study.design import FLOOR, sensitivity

    rng = np.random.default_rng(3)
    p = rng.uniform(0.0, 1.0, 20)
    sets = [{"a": float(v)} for v in p]
    placement = np.array([-0.01, 0.01])  # each set's two runs 0.02 rad apart
    angle = 0.5 * p[:, None] + placement[None, :]
    grids = {
        "transit_time": np.full((20, 2), 1.0),
        "rotation": angle,
        "exit_y": np.full((20, 2), 0.1),
        "exit_heading": angle,
    }
    J, scatter = sensitivity(intervals_of(["a"]), sets, grids)
    assert J[1, 0] == 0.0  # rotation: measured again by the exit heading
    assert J[3, 0] == pytest.approx(0.5, rel=1e-9)
    # within-set deviations +-0.01: sum 40 x 1e-4 over 40 runs - 20 sets
    assert scatter[3] ** 2 == pytest.approx(40 * 1e-4 / 20 + FLOOR["exit_heading"] ** 2)


def test_the_real_runs_own_scatter_widens_a_candidate_s_noise_beyond_the_floor():
    """e_q of `sensitivity`: the real runs' scatter beyond the model's, the transit time's as a
    share of the candidate's mean; below the floor it changes nothing."""
    from parcelfit.study.design import FLOOR, sensitivity

    p = np.linspace(0.0, 1.0, 8)
    sets = [{"a": float(v)} for v in p]
    grids = {
        "transit_time": np.full((8, 2), 2.0) + 0.1 * p[:, None],  # no placement scatter
        "rotation": np.zeros((8, 2)),
        "exit_y": np.zeros((8, 2)),
        "exit_heading": np.zeros((8, 2)),
    }
    _, plain = sensitivity(intervals_of(["a"]), sets, grids)
    assert plain[0] == pytest.approx(FLOOR["transit_time"])
    real = {"transit_time": 0.01, "exit_y": 0.001}  # 1 % of the transit time; 1 mm < floor
    _, wider = sensitivity(intervals_of(["a"]), sets, grids, real)
    assert wider[0] == pytest.approx(0.01 * 2.05, rel=1e-9)  # 1 % of the mean 2.05 s
    assert wider[2] == pytest.approx(FLOOR["exit_y"])
