"""The design benchmark's measures (benchmarks/bench_design.py) and the analytic simulator's
bench tests it ranks."""

import numpy as np
import pytest

from .fake_sim import trajectory
from .helpers import load_file_module


def _bench():
    return load_file_module("benchmarks/bench_design.py")


def test_open_width_sums_the_open_intervals_as_shares_of_their_ranges():
    bench = _bench()
    ranges = {"a": (0.0, 2.0), "b": (100.0, 200.0), "c": (0.0, 1.0)}
    intervals = {"a": [0.5, 1.0], "b": [90.0, 150.0], "c": [0.0, 1.0]}
    # a: 0.25; b clipped to its range: 0.5; c is determined and not counted
    assert bench.open_width(intervals, ranges, ["a", "b"]) == pytest.approx(0.75)
    assert bench.open_width({}, ranges, ["a", "c"]) == pytest.approx(2.0)  # no interval: open
    assert bench.open_width(intervals, ranges, []) == 0.0


def test_helped_most_takes_the_smallest_measure_then_more_parameters_within():
    bench = _bench()
    rows = {
        "Q/KPBW/1": {"open_width": 2.5, "open_error": 0.30, "within": 2},
        "B2/KPBW/1": {"open_width": 2.5004, "open_error": 0.10, "within": 3},
        "B1/KPBW/1": {"open_width": 2.9, "open_error": 0.05, "within": 2},
    }
    assert bench.helped_most(rows) == "B2/KPBW/1"  # a tie to 0.001: more within 10 %
    assert bench.helped_most(rows, "open_error") == "B1/KPBW/1"


def test_the_truths_are_seeded_and_inside_the_ranges():
    bench = _bench()
    a, b = bench.truth_for(0), bench.truth_for(0)
    assert a == b and a != bench.truth_for(1)
    for name, (lo, hi) in bench.PARAMETERS.items():
        assert lo + 0.2 * (hi - lo) - 1e-6 <= a[name] <= lo + 0.8 * (hi - lo) + 1e-6


def test_each_bench_test_of_the_analytic_simulator_answers_to_its_parameter():
    p = {"mu_d_BePa": 0.45, "mu_d_MePa": 0.25, "E_Pa": 9e8, "k_MePa": 5.5e5}
    base = {rig: trajectory(p, 1, rig=rig) for rig in ("R", "B1", "B2")}
    stiff = {rig: trajectory({**p, "k_MePa": 1e6}, 1, rig=rig) for rig in ("R", "B2")}
    # B2: the turn follows k_MePa, 0.5 x 0.45 (1 - exp(-4 t)); R does not see it
    t = stiff["B2"][0].t
    turn = stiff["B2"][0].theta - base["B2"][0].theta
    np.testing.assert_allclose(turn, 0.225 * (1 - np.exp(-4 * t)), atol=1e-12)
    np.testing.assert_array_equal(stiff["R"][0].theta, base["R"][0].theta)
    # B2: the lateral position follows E_Pa, 0.005 (E / 1 GPa - 0.9) t
    soft = trajectory({**p, "E_Pa": 1.9e9}, 1, rig="B2")[0]
    np.testing.assert_allclose(soft.y - base["B2"][0].y, 0.005 * t, atol=1e-12)
    # B1: the transit time follows mu_d_BePa three times as strongly as on R
    fast = {rig: trajectory({**p, "mu_d_BePa": 0.55}, 1, rig=rig)[1] for rig in ("R", "B1")}
    assert fast["B1"] - base["B1"][1] == pytest.approx(3 * (fast["R"] - base["R"][1]))


def test_the_mujoco_design_benchmark_judges_only_the_designed_calibrations():
    bench = load_file_module("benchmarks/bench_design_mujoco.py")

    def row(within, covered, errors):
        names = ["mu_d_BePa", "mu_d_MePa", "E_Pa", "k_MePa"]
        return {
            "within": within,
            "parameters": 4,
            "covered": covered,
            "errors": dict(zip(names, errors, strict=True)),
            "verdicts": {"mu_d_BePa": "determined", "E_Pa": "undetermined"},
            "evaluations": 40,
            "simulations": 170,
            "minutes": 21.5,
            "validated": True,
            "transfer": "1/1",
        }

    results = {
        "truth1": {
            "designed": ["B2/KPBW/1", "B1/KPBW/2"],
            "rows": {
                "published cases": row(4, 4, [0.01, 0.02, 0.03, 0.04]),  # not counted
                "with the designed": row(3, 4, [0.01, 0.02, 0.05, 0.3]),
            },
        },
        "truth2": {
            "designed": ["E1/KPBW/2"],
            "rows": {"with the designed": row(1, 3, [0.2, 0.3, 0.4, 0.5])},
        },
        "truth3": {"designed": [], "rows": {"published cases": row(2, 4, [0, 0, 0.5, 0.5])}},
    }
    assert bench.verdicts(results) == [
        "with the two designed experiments, at least 3 of 4 parameters within 10 %: 1 of 2 "
        "truths (asked: at least 2 of 3)",
        "every interval of the designed calibrations contains its truth: no",
    ]
    lines = bench.table(results).splitlines()
    assert len(lines) == 2 + 4
    assert lines[3] == (
        "| truth1 | + B2/KPBW/1 + B1/KPBW/2 | 3/4 | 0.010 / 0.020 / 0.050 / 0.300 | mu_d_BePa "
        "| 4/4 | 40 | 170 | 21.5 | passed | 1/1 |"
    )


def _start_turns(folder):
    from parcelfit.runs import load_dataset

    data = load_dataset(folder)
    return {
        (c.case.rig, c.case.speed_setting): np.array([r.trajectory.theta[0] for r in c.runs])
        for c in data.cases.values()
    }


def test_the_benchmarks_twin_places_rig_r_as_the_model_does_unless_told(tmp_path):
    from .fake_sim import write_reference_dataset

    # at t = 0 a run's heading is its placement's turn (sd 0.01 rad) plus tracking noise
    # (sd 0.003 rad): rig R's runs scatter like the model's ensemble placements only when R is
    # not among the nominal rigs (the tests' data of rig R keep the nominal start)
    placed = _start_turns(
        write_reference_dataset(tmp_path / "placed", n_runs=30, rigs=("R",), nominal_rigs=())
    )
    nominal = _start_turns(write_reference_dataset(tmp_path / "nominal", n_runs=30, rigs=("R",)))
    for setting in (1, 2):
        assert placed[("R", setting)].std() > 0.006
        assert nominal[("R", setting)].std() < 0.005


def test_a_benchmark_folder_keeps_the_twin_it_was_made_with(tmp_path):
    twin = load_file_module("benchmarks/bench_twin.py")
    assert twin.analytic_nominal_rigs(tmp_path, r_nominal=False) == ()
    assert twin.analytic_nominal_rigs(tmp_path, r_nominal=False) == ()  # a rerun resumes
    with pytest.raises(SystemExit, match="give another --out"):
        twin.analytic_nominal_rigs(tmp_path, r_nominal=True)
    with pytest.raises(SystemExit, match="mirrored placements"):
        twin.analytic_nominal_rigs(tmp_path, r_nominal=False, mirrored=True)
    assert twin.analytic_nominal_rigs(tmp_path / "former", r_nominal=True) == ("R",)
    # a folder of a benchmark from before the choices were recorded: rig R nominal
    old = tmp_path / "old"
    (old / "truth1" / "data").mkdir(parents=True)
    with pytest.raises(SystemExit, match="--r-nominal to resume it"):
        twin.analytic_nominal_rigs(old, r_nominal=False)
    assert twin.analytic_nominal_rigs(old, r_nominal=True) == ("R",)


def test_candidates_design_scores_alike_and_ranks_by_the_mean():
    bench = _bench()
    shares = {"Q/KPBW/1": 0.7091, "Q/KPBW/2": 0.7091 + 1e-9, "B2/KPBW/1": 0.7152}
    assert bench.scored_equal(shares, "Q/KPBW/1") == ["Q/KPBW/1", "Q/KPBW/2"]
    assert bench.scored_equal(shares, "B2/KPBW/1") == ["B2/KPBW/1"]
    stats = {"Q/KPBW/1": (0.47, 0.06), "Q/KPBW/2": (0.44, 0.08), "B2/KPBW/1": (0.37, 0.07)}
    assert [bench.mean_rank(stats, c) for c in stats] == [3, 2, 1]
