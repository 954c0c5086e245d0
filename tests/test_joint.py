"""Joint studies (several test cases), the ensemble cost, the transfer check and the advice,
on the analytic fake simulator (rig R and a second rig Q on which E_Pa turns the parcel)."""

import json
import math

import numpy as np
import pytest
import yaml

from parcelfit import ParcelfitError
from parcelfit.metrics.ensemble import ensemble_real_costs
from parcelfit.study.calibration import Calibration
from parcelfit.study.joint import case_null_costs, case_threshold, threshold
from parcelfit.study.objective import select_references
from parcelfit.study.results import read_results
from parcelfit.study.status import study_status
from parcelfit.study.studyfile import load_study

from .fake_sim import write_reference_dataset
from .helpers import write_study

PARAMS = {"mu_d_BePa": [0.3, 0.55], "mu_d_MePa": [0.15, 0.35], "E_Pa": [200, 1600]}


def _joint_study(tmp_path, **overrides):
    """A joint ensemble study: R/P/1 and Q/P/1 fitted, R/P/2 validated, Q/P/2 transferred."""
    write_reference_dataset(tmp_path / "data", rigs=("R", "Q"), truth={"E_Pa": 1e9})
    doc = {
        "name": "joint",
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make"},
        "parameters": PARAMS,
        "cases": [
            {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
            {"rig": "Q", "consignment": "P", "speed_setting": 1, "weight": 0.5},
        ],
        "validation": {"every": 1, "cases": [{"rig": "R", "consignment": "P", "speed_setting": 2}]},
        "transfer": [{"rig": "Q", "consignment": "P", "speed_setting": 2}],
        "cost": {"kind": "ensemble", "placements": 3},
        "batch_size": 2,
        "initial": 6,
        "budget": 8,
        "seed": 1,
        "optimizer": {"n_samples": 500, "n_restarts": 0},
        "executor": "serial",
    }
    doc.update(overrides)
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_an_old_single_case_study_file_is_read_as_before(tmp_path):
    study = load_study(write_study(tmp_path))
    assert not study.joint and len(study.cases) == 1 and study.cost_kind == "published"
    assert study.cases[0].label == "R/P/1" and study.validation_cases[0].label == "R/P/2"
    assert (study.rig, study.fit_setting, study.validation_setting) == ("R", 1, 2)
    assert study.transfer == () and study.placements == 1


def test_a_joint_study_file_lists_its_cases(tmp_path):
    study = load_study(_joint_study(tmp_path))
    assert study.joint and [c.label for c in study.cases] == ["R/P/1", "Q/P/1"]
    assert [c.weight for c in study.cases] == [1.0, 0.5]
    assert study.cases[1].dataset == (tmp_path / "data").resolve()  # the first case's
    assert [c.label for c in study.validation_cases] == ["R/P/2"]
    assert [c.label for c in study.transfer] == ["Q/P/2"]
    assert (study.cost_kind, study.placements, study.transit_weight) == ("ensemble", 3, 1.0)


@pytest.mark.parametrize(
    ("change", "pattern"),
    [
        (
            {"reference": {"dataset": "data", "speed_setting": 1}},
            r"cases: give either reference .* not both",
        ),
        ({"cases": []}, r"top level: missing required key 'reference'"),
        ({"cost": {"kind": "published", "placements": 3}}, r"cost\.placements: the published"),
        ({"cost": {"kind": "mean"}}, r"cost\.kind: unknown cost 'mean'"),
        (
            {"cost": {"kind": "published", "transit": "adjusted"}},
            r"cost\.transit: the published cost has no transit-time term",
        ),
        ({"cost": {"kind": "ensemble", "transit": "raw"}}, r"cost\.transit: unknown transit"),
        (
            {"cost": {"kind": "published", "mirrored": True}},
            r"cost\.mirrored: the published cost simulates the nominal placement only",
        ),
        ({"cost": {"kind": "ensemble", "mirrored": "yes"}}, r"cost\.mirrored"),
        (
            {"cost": {"kind": "ensemble", "mirrored": True}},
            r"cost\.mirrored: mirrored placements pair .* placements: 2 or more",
        ),
        (
            {"validation": {"speed_setting": 2}},
            r"validation\.speed_setting: a joint study names its validation cases",
        ),
        (
            {"transfer": [{"rig": "R", "consignment": "P", "speed_setting": 1}]},
            r"transfer\[0\]: R/P/1 is also fitted",
        ),
        (
            {
                "cases": [
                    {
                        "dataset": "data",
                        "rig": "R",
                        "consignment": "P",
                        "speed_setting": 1,
                        "weight": 0,
                    }
                ]
            },
            r"cases: every case has weight 0",
        ),
        (
            {"cases": [{"rig": "R", "consignment": "P", "speed_setting": 1}]},
            r"cases\[0\]\.dataset: the first case names no dataset",
        ),
        (
            {"cases": [{"dataset": "data", "rig": "R", "speed_setting": 1, "wieght": 1}]},
            r"cases\[0\]: unknown key 'wieght'.*did you mean 'weight'",
        ),
        (
            {
                "cases": [
                    {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
                    {"rig": "Q", "consignment": "P", "speed_setting": 1, "placements": 0},
                ]
            },
            r"cases\[1\]\.placements: 0 is out of range.*\[1, 1000\]",
        ),
        (
            {
                "cases": [
                    {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
                    {"rig": "Q", "consignment": "P", "speed_setting": 1, "placements": 2},
                ],
                "cost": {"kind": "published"},
            },
            r"cases\[1\]\.placements: a case's placements belong to the ensemble cost",
        ),
        (
            {"transfer": [{"rig": "Q", "consignment": "P", "speed_setting": 2, "placements": 2}]},
            r"transfer\[0\]\.placements: only fitted cases take placements",
        ),
        (
            {"transfer": [{"rig": "Q", "consignment": "P", "speed_setting": 2, "weight": 2.0}]},
            r"transfer\[0\]\.weight: only fitted cases take weight",
        ),
        (
            {
                "validation": {
                    "every": 1,
                    "cases": [
                        {"rig": "R", "consignment": "P", "speed_setting": 2, "placements": 1}
                    ],
                }
            },
            r"validation\.cases\[0\]\.placements: only fitted cases take placements",
        ),
    ],
)
def test_joint_study_file_errors_name_file_key_and_fix(tmp_path, change, pattern):
    path = _joint_study(tmp_path, **change)
    with pytest.raises(ParcelfitError, match=pattern) as info:
        load_study(path)
    assert "study.yaml" in str(info.value)


@pytest.mark.slow
def test_a_case_with_its_own_placements_is_simulated_that_often(tmp_path):
    from parcelfit.study.joint import placement_seeds, simulations_per_evaluation

    cases = [
        {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
        {"rig": "Q", "consignment": "P", "speed_setting": 1, "weight": 0.5, "placements": 1},
    ]
    path = _joint_study(tmp_path, cases=cases, budget=4, initial=4, transfer=[])
    study = load_study(path)
    assert [c.placements for c in study.cases] == [None, 1]
    assert [placement_seeds(study, c) for c in study.cases] == [[1, 2, 3], [1]]
    assert simulations_per_evaluation(study) == 4
    out = tmp_path / "out"
    Calibration(study, out, figures=False).run()
    status = study_status(out)
    parts = status.recommended.parts
    assert [p.seeds for p in parts] == [[1, 2, 3], [1]]
    runs = sorted(f.name for f in (out / "runs").glob("fit-*.csv"))
    assert len(runs) == 4 * 4  # four evaluations of 3 + 1 simulations
    assert sum(name.endswith("-c1-p1.csv") for name in runs) == 4
    assert not any("-c1-p2" in name for name in runs)
    # with one placement the standard error is the real runs' part alone, still stated
    assert parts[0].se > 0 and parts[1].se > 0
    # each case's threshold from sets as large as its own placements: 3 runs, then 1
    refs = select_references(study)
    n = [len(refs[c.label].run_ids) for c in study.cases]
    assert [len(case_null_costs(refs[c.label], study, c)) for c in study.cases] == [
        math.comb(n[0], 3),
        n[1],
    ]
    fitted = [c.threshold for c in status.cases if c.role == "fit"]
    expect = [case_threshold(refs[c.label], study, c) for c in study.cases]
    assert fitted == pytest.approx(expect, rel=1e-12) and expect[1] == pytest.approx(
        max(ensemble_real_costs(refs[study.cases[1].label])), rel=1e-12
    )


@pytest.mark.slow
def test_a_joint_ensemble_study_stores_the_parts_and_checks_transfer(
    tmp_path, monkeypatch, no_report_figures
):
    study = load_study(_joint_study(tmp_path))
    out = tmp_path / "out"
    result = Calibration(study, out, figures=False).run()
    assert result.evaluations == 8
    status = study_status(out)
    assert [c.case for c in status.cases] == ["R/P/1", "Q/P/1", "R/P/2", "Q/P/2"]
    assert [c.role for c in status.cases] == ["fit", "fit", "validation", "transfer"]
    # `status --json` writes the cases in their stored form, every key of the store's record
    import sqlite3

    con = sqlite3.connect(out / "study.sqlite")
    (stored,) = con.execute("SELECT value FROM meta WHERE key = 'cases'").fetchone()
    con.close()
    stored = json.loads(stored)
    assert status.to_json()["cases"] == stored
    assert set(stored[0]) == {
        "case",
        "role",
        "weight",
        "dataset",
        "reference_run",
        "threshold",
        "transit",
    }
    parts = status.recommended.parts
    assert [p.case for p in parts] == ["R/P/1", "Q/P/1"] and len(parts[0].seeds) == 3
    assert status.recommended.cost == pytest.approx(parts[0].cost + 0.5 * parts[1].cost, rel=1e-12)
    for p in parts:  # each part: trajectory term + transit term, with its standard error
        assert p.cost == pytest.approx(p.trajectory_term + p.transit_term, rel=1e-12)
        assert p.se > 0 and all((out / f).is_file() for f in p.run_files)
    results = read_results(out)
    assert [v.case for v in results.transfer] == ["Q/P/2"]
    assert results.transfer[0].verdict is not None
    assert results.identifiability is not None and results.identifiability.evaluations == 8
    # the threshold: per case the 95 % quantile of what sets of 3 real runs score, summed
    refs = select_references(study)
    nulls = [(c.weight, case_null_costs(refs[c.label], study, c)) for c in study.cases]
    assert [len(n) for _, n in nulls] == [
        math.comb(len(refs[c.label].run_ids), 3) for c in study.cases
    ]
    eps = results.identifiability.threshold
    # the 95 % quantile of the sets' costs, at least the largest single run's
    quantiles = [
        max(np.quantile(n, 0.95, method="higher"), max(ensemble_real_costs(refs[c.label])))
        for (_, n), c in zip(nulls, study.cases, strict=True)
    ]
    assert eps == pytest.approx(
        sum(w * q for (w, _), q in zip(nulls, quantiles, strict=True)), rel=1e-12
    )
    assert eps == pytest.approx(threshold(refs, study)[0], rel=1e-12)
    assert "sets of 3 of" in results.identifiability.threshold_source
    # at least 95 % of the sums of one set per case score at most eps (independent cases)
    sums = np.add.outer(nulls[0][0] * nulls[0][1], nulls[1][0] * nulls[1][1])
    assert np.mean(sums <= eps) >= 0.95
    fitted = [c for c in status.cases if c.role == "fit"]
    assert [c.threshold for c in fitted] == pytest.approx(quantiles, rel=1e-12)
    assert status.validations and all(v.after_iteration >= 1 for v in status.validations)
    # the advice, when a parameter stays open, weighs the validation and transfer cases
    assert results.advice is None or set(results.advice.changes) == {"R/P/2", "Q/P/2"}
    # `parcelfit status` shows the parts case by case
    from typer.testing import CliRunner

    from parcelfit.cli import app

    text = CliRunner().invoke(app, ["status", str(out)]).stdout
    assert "Q/P/1" in text and "R/P/1" in text and "trajectories" in text
    assert "what the data determine:" in text  # each parameter's verdict
    # the one verdict: the transfer check ran on Q/P/2 and has its own line
    transfer = status.verdict["checks"][2]
    assert transfer["outcome"] in ("passed", "failed") and "Q/P/2" in transfer["detail"]
    assert " ".join(f"transfer check: {transfer['outcome']} ({transfer['detail']})".split()) in (
        " ".join(text.split())
    )
    assert status.verdict["parameters"]["analysed"]
    # the report: the cases, the transfer section, what the data determine
    from parcelfit.report import build_report

    page = build_report(out).read_text()
    assert 'id="transfer"' in page and "<td>Q/P/1</td><td>fit</td><td>0.5</td>" in page
    assert "What the data determine" in page
    # a rerun of the finished study simulates nothing
    log = tmp_path / "sims.log"
    monkeypatch.setenv("FAKE_SIM_LOG", str(log))
    again = Calibration(study, out, figures=False).run()
    assert again.evaluations == 8 and not log.exists()
    assert read_results(out).transfer[0].params == results.transfer[0].params


@pytest.mark.slow
def test_the_advice_names_the_rig_where_an_undetermined_parameter_matters(tmp_path):
    # fitted on rig R only, where E_Pa has almost no effect: it stays open, and of the two
    # candidates (R at the other speed, rig Q) only Q responds to it
    path = write_study(
        tmp_path,
        parameters=PARAMS,
        transfer=[{"rig": "Q", "consignment": "P", "speed_setting": 1}],
        initial=10,
        batch_size=2,
        budget=12,
        validation={"speed_setting": 2, "every": 5},
        optimizer={"n_samples": 500, "n_restarts": 0},
        executor="serial",
    )  # writes rig R's data; rewritten with rig Q's added:
    write_reference_dataset(tmp_path / "data", rigs=("R", "Q"), truth={"E_Pa": 1e9})
    out = tmp_path / "out"
    Calibration(load_study(path), out, figures=False).run()
    results = read_results(out)
    e_pa = next(p for p in results.identifiability.parameters if p.name == "E_Pa")
    assert not e_pa.determined
    advice = results.advice
    assert advice.best == "Q/P/1" and "E_Pa" in advice.parameters
    assert advice.changes["Q/P/1"]["E_Pa"] > 10 * advice.changes["R/P/2"]["E_Pa"]
    doc = json.loads((out / "results.json").read_text())
    assert doc["advice"]["best"] == "Q/P/1"


@pytest.mark.slow
def test_an_ensemble_on_adjusted_transit_times_adjusts_real_and_simulated_runs_alike(
    tmp_path, no_report_figures
):
    from parcelfit.metrics import select_reference
    from parcelfit.metrics.reference import adjusted_reference
    from parcelfit.metrics.transit_adjustment import ridden_speeds
    from parcelfit.runs import load_dataset, read_trajectory

    cost = {"kind": "ensemble", "placements": 2, "transit": "adjusted"}
    path = _joint_study(tmp_path, cost=cost, budget=4, initial=4, transfer=[])
    study = load_study(path)
    assert study.transit_adjusted
    out = tmp_path / "out"
    Calibration(study, out, figures=False).run()
    data = load_dataset(tmp_path / "data")
    parts = study_status(out).recommended.parts
    for part, spec in zip(parts, study.cases, strict=True):
        runs = data[spec.case].runs
        reference = adjusted_reference(select_reference(data[spec.case]), runs)
        adjustment = reference.transit_adjustment
        assert adjustment is not None and adjustment.runs == len(runs)
        # the real runs' times are adjusted ...
        assert reference.transit_times == tuple(adjustment.adjust_run(r) for r in runs)
        # ... and every simulated run with the same coefficients and mean speeds
        for raw, adjusted, f in zip(
            part.transit_times, part.adjusted_transit_times, part.run_files, strict=True
        ):
            speeds = ridden_speeds(read_trajectory(out / f))
            assert adjusted == pytest.approx(adjustment.adjust(raw, speeds), abs=1e-12)
    # the validation case keeps its measured times (the published criteria judge it)
    assert "adjusted_transit_times" not in json.dumps(study_status(out).to_json()["validations"])
    # `parcelfit status` says the transit term is on adjusted times
    from typer.testing import CliRunner

    from parcelfit.cli import app

    assert "(adjusted times)" in CliRunner().invoke(app, ["status", str(out)]).stdout
    # the report says per fitted case what the adjustment did
    from parcelfit.report import build_report

    page = build_report(out).read_text()
    assert "adjusted for the belt speeds each run rode at" in page
    assert "<li>Q/P/1: transit times adjusted to the real runs" in page


def test_mirrored_placements_pair_each_draw_with_its_mirror_image(tmp_path):
    from parcelfit.study.joint import placement_seeds

    from .fake_sim import placement

    cases = [
        {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
        {"rig": "Q", "consignment": "P", "speed_setting": 1, "placements": 3},
    ]
    cost = {"kind": "ensemble", "placements": 2, "mirrored": True}
    path = _joint_study(tmp_path, cases=cases, cost=cost, budget=2, initial=2, transfer=[])
    study = load_study(path)
    assert study.mirrored
    # an even number: draws beside their mirror images; an odd one: the nominal start first
    assert [placement_seeds(study, c) for c in study.cases] == [[1, -1], [None, 1, -1]]
    four = load_study(_joint_study(tmp_path, cost={**cost, "placements": 4}))
    assert placement_seeds(four, four.cases[0]) == [1, -1, 2, -2]
    plain = load_study(_joint_study(tmp_path, cost={"kind": "ensemble", "placements": 2}))
    assert not plain.mirrored and placement_seeds(plain, plain.cases[0]) == [1, 2]
    # the analytic simulator's placement -s is placement s negated
    assert placement(-3) == tuple(-v for v in placement(3))
    out = tmp_path / "out"
    Calibration(study, out, figures=False).run()
    parts = study_status(out).recommended.parts
    assert [p.seeds for p in parts] == [[1, -1], [None, 1, -1]]
    # the transit term takes the simulations' variance from the pairs' means (antithetic units)
    from parcelfit.metrics.ensemble import transit_statistic

    refs = select_references(study)
    for part, units in zip(parts, ([1, 1], [0, 1, 1]), strict=True):
        real = [t for t in refs[part.case].transit_times if t is not None]
        expect = transit_statistic(part.transit_times, real, units=units)
        assert part.transit_term == pytest.approx(expect, rel=1e-12)
        assert part.transit_term != pytest.approx(transit_statistic(part.transit_times, real))
    # the two runs of an evaluation on R start mirrored: they differ by twice placement 1's
    # offset, dy (1 + t) and dtheta, so they average to the nominal start's run
    from parcelfit.runs.io import read_trajectory

    plus = read_trajectory(out / "runs" / "fit-000-00-c0-p1.csv")
    minus = read_trajectory(out / "runs" / "fit-000-00-c0-p-1.csv")
    dy, dth, _ = placement(1)
    np.testing.assert_allclose(plus.y - minus.y, 2 * dy * (1 + plus.t), atol=1e-12)
    np.testing.assert_allclose(plus.theta - minus.theta, 2 * dth, atol=1e-12)
    assert (out / "runs" / "fit-000-00-c1.csv").is_file()  # Q's nominal start
