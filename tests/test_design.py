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
    from parcelfit.study.design import few_sets_notes

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
    # the published cost's nominal run counts as exact: no simulated-mean scatter entered
    assert json.loads((out / "design.json").read_text())["fit_scatter"] is False
    assert ranking.iloc[0]["with_above"] == ranking.iloc[0]["mean_share"]
    assert ranking.iloc[1]["with_above"] <= ranking.iloc[0]["with_above"]
    assert "E_Pa (undetermined): the experiments that narrow it most" in result.output
    # 8 sets for 3 calibrated parameters are enough for no note; 6 are not, and design says so
    assert json.loads((out / "design.json").read_text())["notes"] == []
    few = [*argv[:4], "--sets", "6", *argv[6:-1], str(tmp_path / "d6")]
    result = runner.invoke(app, few)
    assert result.exit_code == 0, result.output
    assert json.loads((tmp_path / "d6" / "design.json").read_text())["notes"] == few_sets_notes(
        6, 3
    )
    assert "note: with 6 parameter sets and 3 calibrated parameters" in " ".join(
        result.output.split()
    )
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
    order = greedy_sequence([10 * same, 10 * joint], known, [0, 1])
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
    order = greedy_sequence([10 * a1, 10 * a2, 10 * b], None, [0, 1, 2])
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


def test_the_simulations_own_scatter_caps_what_more_real_runs_tell():
    """information with m_q: n real runs measure the mean against the simulated mean with
    variance s^2 / n + m; the expected share follows that posterior and stops narrowing at
    J^2 / m however many runs are added."""
    from parcelfit.study.design import information

    J = np.array([[0.3]])
    scatter = np.array([0.1])
    model = np.array([0.01])  # the simulated mean's variance: as much as 1 run's
    for n in (1, 10, 100):
        info = information(J, scatter, n, model)
        assert info[0, 0] == pytest.approx(0.09 / (0.01 / n + 0.01), rel=1e-12)
        w = expected_width(J, scatter, n, model=model)[0]
        assert w == pytest.approx(math.sqrt(12 / (info[0, 0] + 12)), rel=1e-12)
    # without it, 10 runs are 10 times one run's information
    assert information(J, scatter, 10)[0, 0] == pytest.approx(10 * 9.0, rel=1e-12)
    # 9 n / (1 + n): 2 runs a share of sqrt(12 / 18) = 0.816, 3 runs sqrt(12 / 18.75) = 0.8
    assert runs_needed(J, scatter, np.array([0.81]), model=model) == [3]
    # the cap: J^2 / m = 9, a share of sqrt(12 / 21) = 0.756 at best (0.2 without m: 32 runs)
    assert runs_needed(J, scatter, np.array([0.75]), model=model) == [None]


def test_the_simulated_mean_s_variance_from_independent_and_from_mirrored_placements():
    """model_variance: R W / K^2 with independent placements (W / K without a nominal run);
    with mirrored pairs 4 P V / K^2, V the variance of a pair's mean, so a response linear in
    the placement gives 0; V = W / 2 where the grid holds fewer than two complete pairs; the
    published cost's nominal run counts as exact."""
    from parcelfit.study.design import (
        design_placement_seeds,
        model_variance,
        run_variance,
    )
    from parcelfit.study.plausible import placement_seeds
    from parcelfit.study.spread import decompose

    rng = np.random.default_rng(5)
    offsets = rng.normal(0.0, 0.01, (20, 2))  # two pairs per set
    linear = np.stack([offsets[:, 0], -offsets[:, 0], offsets[:, 1], -offsets[:, 1]], axis=1)
    bent = linear**2  # even in the placement: the pairs do not cancel it
    grids = {q: linear + 1.0 for q in ("transit_time", "rotation", "exit_y", "exit_heading")}
    grids["exit_y"] = bent
    w_all = decompose(linear).run_variance
    assert w_all == pytest.approx(float(np.sum(linear**2)) / (80 - 20), rel=1e-9)
    assert model_variance(grids, [1, 2], mirrored=False)[0] == pytest.approx(w_all / 2, rel=1e-12)
    assert model_variance(grids, [None], mirrored=False).tolist() == [0.0] * 4  # published
    # mirrored pairs: one run's variance is exact from them (the pooled W runs high by 4 / 3)
    assert run_variance(linear, mirrored=True) == pytest.approx(np.mean(linear**2), rel=1e-9)
    assert model_variance(grids, [1, -1], mirrored=True)[0] == pytest.approx(0.0, abs=1e-20)
    pairs = np.stack([bent[:, 0], bent[:, 2]], axis=1)  # a pair's mean of squares: its square
    V = float(np.sum((pairs - pairs.mean(axis=1, keepdims=True)) ** 2) / (40 - 20))
    assert model_variance(grids, [1, -1], mirrored=True)[2] == pytest.approx(V, rel=1e-9)
    # an odd K: the nominal run first, counted exact; one pair of three runs
    assert model_variance(grids, [None, 1, -1], True)[2] == pytest.approx(4 * V / 9, rel=1e-9)
    # one pair per set: V from W / 2, the independent draws' value
    one_pair = {q: g[:, :2] for q, g in grids.items()}
    Wb = decompose(one_pair["exit_y"]).run_variance
    assert model_variance(one_pair, [1, -1], True)[2] == pytest.approx(Wb / 2, rel=1e-12)
    # a pair's member lost everywhere: no complete pair of two, the same fallback, not 0
    lost = {q: g.copy() for q, g in grids.items()}
    for g in lost.values():
        g[:, 3] = np.nan
    Wl = decompose(lost["exit_y"]).run_variance
    assert model_variance(lost, [1, -1], True)[2] == pytest.approx(Wl / 2, rel=1e-12)
    assert (
        model_variance({q: g[:, :1] for q, g in grids.items()}, [1, 2], False).tolist() == [0.0] * 4
    )
    # design's own placements: in mirrored pairs, else those a prediction draws
    seeds = design_placement_seeds(5, 7, mirrored=True)
    assert seeds[1] == -seeds[0] and seeds[3] == -seeds[2] and len(seeds) == 5 and seeds[4] > 0
    assert design_placement_seeds(4, 7, mirrored=False) == placement_seeds(4, 7)


def test_design_of_an_ensemble_study_counts_the_fit_s_own_placements(tmp_path):
    """rank_experiments: with the ensemble cost the candidates' shares take the simulated
    means' variance m_q (2 placements per case) and are wider than with m_q = 0; with
    antithetic placements design runs its own placements in mirrored pairs."""
    from parcelfit.study.design import rank_experiments
    from parcelfit.study.store import Store

    def shares(folder, out):
        result = rank_experiments(
            folder,
            candidates=["Q/KPBW/1"],
            rig_files=[str(q)],
            sets=8,
            placements=4,
            executor="serial",
            out=out,
        )
        return result, {s.parameter: s.share for s in result.scores}

    study = write_finished_study(tmp_path, cost={"kind": "ensemble", "placements": 2})
    q = write_rig_q(tmp_path)
    result, with_m = shares(study, tmp_path / "d")
    assert result.fit_scatter
    doc = json.loads((tmp_path / "d" / "design.json").read_text())
    assert doc["fit_scatter"] is True
    import parcelfit.study.design as design

    real = design.model_variance
    try:  # the same simulations scored with the simulated means taken as exact
        design.model_variance = lambda grids, seeds, mirrored: np.zeros(4)
        _, without = shares(study, tmp_path / "d")
    finally:
        design.model_variance = real
    assert with_m["E_Pa"] > without["E_Pa"] + 1e-3

    mirrored = tmp_path / "m"
    mirrored.mkdir()
    folder = write_finished_study(
        mirrored, cost={"kind": "ensemble", "placements": 2, "mirrored": True}
    )
    shares(folder, mirrored / "d")
    store = Store(mirrored / "d" / "design.sqlite")
    try:
        seeds = store.get_meta("design")["placements"]
    finally:
        store.close()
    assert seeds[1] == -seeds[0] and seeds[3] == -seeds[2] and seeds[0] > 0


def test_too_few_sets_for_small_effects_are_said_to_be_so():
    from parcelfit.study.design import few_sets_notes
    from parcelfit.study.information import resolved_t

    assert few_sets_notes(7, 2) == [] and few_sets_notes(20, 4) == []
    (note,) = few_sets_notes(5, 2)
    assert f"counts only from {resolved_t(5, 2):.1f} standard errors" in note
    assert "give --sets 7 or more" in note
