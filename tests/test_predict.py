"""`parcelfit predict` on the analytic test simulator: the variance decomposition on a
constructed case, the effects regression, resume, determinism with the seed and clear errors."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from parcelfit.cli import app
from parcelfit.study.predict import PREDICT_STORE
from parcelfit.study.spread import decompose, effects_of
from parcelfit.study.store import Store

from .helpers import intervals_of
from .predict_helpers import write_finished_study, write_rig_q

runner = CliRunner()


def test_decomposition_splits_an_additive_case_exactly():
    rng = np.random.default_rng(0)
    a = rng.normal(0, 2.0, 7)  # the parameter sets' part
    b = rng.normal(0, 0.5, 5)  # the placements' part, the same placements for every set
    d = decompose(a[:, None] + b[None, :] + 10.0)
    assert d.between == pytest.approx(np.var(a), rel=1e-12)
    assert d.within == pytest.approx(np.var(b), rel=1e-12)
    assert d.total == pytest.approx(np.var(a) + np.var(b), rel=1e-12)
    assert d.parameter_share + d.placement_share == pytest.approx(1.0)
    assert (d.runs, d.sets) == (35, 7)


def test_decomposition_with_missing_runs_is_the_law_of_total_variance():
    q = np.array([[1.0, 2.0, np.nan], [4.0, 6.0, 8.0], [np.nan, np.nan, np.nan]])
    d = decompose(q)
    values = np.array([1.0, 2.0, 4.0, 6.0, 8.0])
    assert d.total == pytest.approx(np.var(values))
    # set means 1.5 (2 runs) and 6 (3 runs) about the grand mean 4.2
    assert d.between == pytest.approx((2 * (1.5 - 4.2) ** 2 + 3 * (6 - 4.2) ** 2) / 5)
    assert d.within == pytest.approx((0.25 + 0.25 + 4 + 0 + 4) / 5)
    assert (d.runs, d.sets) == (5, 2)
    assert math.isnan(decompose(np.full((2, 2), np.nan)).total)


def test_one_set_has_no_parameter_share_and_a_run_s_variance_is_unbiased():
    one = decompose(np.array([[1.0, 2.0, 3.0]]))
    assert math.isnan(one.parameter_share) and one.placement_share == pytest.approx(1.0)
    q = np.array([[1.0, 3.0], [5.0, 9.0], [2.0, np.nan]])
    d = decompose(q)
    # deviations from the set means: 1, 1, 2, 2 (the single run's 0) over 5 runs - 3 sets
    assert d.run_variance == pytest.approx(10.0 / 2.0)
    assert d.within == pytest.approx(10.0 / 5.0)
    assert math.isnan(decompose(np.array([[1.0], [2.0]])).run_variance)  # one run per set


def test_an_effect_counts_at_the_family_wise_threshold_and_a_flat_one_never():
    from parcelfit.study.spread import Effect, t_threshold

    t = t_threshold(20, 4, 4)
    assert t == pytest.approx(3.515, abs=1e-3)
    assert not Effect("a", "undetermined", "exit_y", 0.0, 1.0, 2.5, 1.0, t).resolved
    assert Effect("a", "undetermined", "exit_y", 0.0, 1.0, 3.6, 1.0, t).resolved
    assert not Effect("a", "undetermined", "exit_y", 0.0, 1.0, 0.0, 0.0, t).resolved
    nan = Effect("a", "undetermined", "exit_y", 0.0, 1.0, math.nan, math.nan, t)
    assert not nan.resolved and not nan.estimated


def test_effects_are_the_change_over_the_plausible_interval():
    rng = np.random.default_rng(1)
    X = np.column_stack([rng.uniform(0.4, 0.5, 30), rng.uniform(2e8, 1.6e9, 30)])
    means = 3.0 + 0.8 * (X[:, 0] - 0.4) / 0.1 + rng.normal(0, 0.01, 30)  # E_Pa moves nothing
    eff, se = effects_of(means, X, [(0.4, 0.5), (2e8, 1.6e9)])
    assert eff[0] == pytest.approx(0.8, abs=4 * se[0]) and se[0] < 0.02
    assert abs(eff[1]) < 4 * se[1]
    few, few_se = effects_of(means[:3], X[:3], [(0.4, 0.5), (2e8, 1.6e9)])
    assert np.isnan(few).all() and np.isnan(few_se).all()


def _predict(folder: Path, out: Path, *extra: str):
    return runner.invoke(
        app,
        [
            "predict",
            str(folder),
            "--rig",
            str(folder.parent / "Q.yaml"),
            "--consignment",
            "KPBW",
            "--setting",
            "1",
            "--sets",
            "8",
            "--placements",
            "4",
            "--executor",
            "serial",
            "--out",
            str(out),
            *extra,
        ],
    )


def _tables(out: Path) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    runs = pd.read_csv(out / "runs.csv").drop(columns="wall_time")
    return runs, pd.read_csv(out / "summary.csv"), pd.read_csv(out / "effects.csv")


@pytest.fixture
def study(tmp_path: Path) -> Path:
    folder = write_finished_study(tmp_path)
    write_rig_q(tmp_path)
    return folder


def test_predict_names_what_the_undetermined_parameter_moves(study, tmp_path):
    result = _predict(study, tmp_path / "p")
    assert result.exit_code == 0, result.output
    runs, summary, effects = _tables(tmp_path / "p")
    assert len(runs) == 32 and (runs["status"] == "ok").all()
    assert runs.groupby("set")["seed"].apply(tuple).nunique() == 1  # the same placements
    row = summary.set_index("quantity").loc["exit_heading"]
    assert row["q05"] < row["median"] < row["q95"]
    assert row["variance"] == pytest.approx(row["between_sets"] + row["within_sets"])
    # a study without fitted runs tells nothing of the real runs' own scatter
    assert (row["run_q05"], row["run_q95"]) == (row["q05"], row["q95"])
    # rig Q turns the parcel by 2 (E_Pa / GPa - 0.9) rad (tests/fake_sim.py): over E_Pa's
    # interval of 1.4 GPa the exit heading moves by 2.8 (1 - exp(-3 t_end)) rad
    e = effects.set_index(["parameter", "quantity"]).loc[("E_Pa", "exit_heading")]
    assert e["effect"] == pytest.approx(2.8 * (1 - math.exp(-3 * 1.4833)), rel=0.02)
    assert bool(e["resolved"])
    assert "E_Pa is undetermined and moves the exit heading by" in " ".join(result.output.split())
    doc = json.loads((tmp_path / "p" / "prediction.json").read_text())
    assert doc["sentences"][0].startswith("E_Pa is undetermined and moves the exit heading by")
    # the calibration's dataset is synthetic: the terminal, the json and the page say so
    assert any("real runs are SYNTHETIC" in n for n in doc["notes"])
    assert "real runs are SYNTHETIC" in " ".join(result.output.split())
    assert "real runs are SYNTHETIC" in (tmp_path / "p" / "prediction.html").read_text()
    assert len(doc["sentences"]) == 1  # only E_Pa is not determined
    page = (tmp_path / "p" / "prediction.html").read_text()
    assert "Q/KPBW/1" in page and "<script" not in page
    # the study was calibrated on the test simulator's type P: another type is noted
    assert any("calibrated on P, not on KPBW" in n for n in doc["notes"]), doc["notes"]


def test_resume_gives_the_same_tables(study, tmp_path):
    assert _predict(study, tmp_path / "p").exit_code == 0
    first = _tables(tmp_path / "p")
    store = Store(tmp_path / "p" / PREDICT_STORE)
    rows = store.evaluations("screen")
    kept = {e.id: e.finished_at for e in rows[:20]}
    store.reopen([e.id for e in rows[20:]])  # as if the run had stopped after 20 simulations
    store.close()
    (tmp_path / "p" / "runs.csv").unlink()
    assert _predict(study, tmp_path / "p").exit_code == 0
    store = Store(tmp_path / "p" / PREDICT_STORE, readonly=True)
    again = store.evaluations("screen")
    store.close()
    assert all(e.status == "ok" for e in again)
    assert {e.id: e.finished_at for e in again[:20]} == kept  # not simulated again
    for a, b in zip(first, _tables(tmp_path / "p"), strict=True):
        pd.testing.assert_frame_equal(a, b)


def test_the_seed_decides(study, tmp_path):
    for name, seed, form in (("a", "3", "csv"), ("b", "3", "parquet"), ("c", "4", "csv")):
        assert _predict(study, tmp_path / name, "--seed", seed, "--format", form).exit_code == 0
    a, c = (_tables(tmp_path / n)[0] for n in "ac")
    b = pd.read_parquet(tmp_path / "b" / "runs.parquet").drop(columns="wall_time")
    pd.testing.assert_frame_equal(b, a, check_dtype=False)  # the same seed, another format
    assert not (tmp_path / "b" / "runs.csv").exists()
    assert not a["E_Pa"].equals(c["E_Pa"]) and not a["seed"].equals(c["seed"])
    # other inputs in the same folder are refused, not mixed
    other = _predict(study, tmp_path / "a", "--seed", "5")
    assert other.exit_code == 2 and "a prediction with other inputs" in other.output
    fewer = _predict(study, tmp_path / "a", "--seed", "3", "--scatter-runs", "3")
    assert fewer.exit_code == 2 and "a prediction with other inputs" in fewer.output
    one = _predict(study, tmp_path / "d", "--scatter-runs", "1")
    assert one.exit_code == 2 and "--scatter-runs" in one.output


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--rig", "E9"], "--rig: unknown rig 'E9'"),
        (["--consignment", "XY"], "--consignment: unknown consignment type 'XY'"),
        (["--setting", "3"], "--setting: rig E3 has no speed setting 3"),
        (["--rig", "missing.yaml"], "missing.yaml: --rig: file not found"),
    ],
)
def test_bad_design_exits_2_with_a_clear_message(study, tmp_path, args, message):
    base = {"--rig": "E3", "--consignment": "KPBW", "--setting": "1"}
    base.update(dict(zip(args[::2], args[1::2], strict=True)))
    argv = ["predict", str(study), *[x for kv in base.items() for x in kv]]
    result = runner.invoke(app, [*argv, "--out", str(tmp_path / "p"), "--executor", "serial"])
    assert result.exit_code == 2
    assert message in " ".join(result.output.split()) and "Traceback" not in result.output
    assert not (tmp_path / "p").exists()


def test_a_folder_without_a_finished_study_exits_2(study, tmp_path):
    argv = ["--rig", "E3", "--consignment", "KPBW", "--out", str(tmp_path / "p")]
    missing = runner.invoke(app, ["predict", str(tmp_path / "nowhere"), *argv])
    assert missing.exit_code == 2 and "no such study folder" in missing.output
    empty = tmp_path / "empty"
    empty.mkdir()
    none = runner.invoke(app, ["predict", str(empty), *argv])
    assert none.exit_code == 2 and "no calibration study here" in none.output
    (study / "results.json").unlink()
    unfinished = runner.invoke(app, ["predict", str(study), *argv])
    assert unfinished.exit_code == 2
    assert "no stored analysis of what its data determine" in " ".join(unfinished.output.split())


def test_a_parameter_whose_effect_could_not_be_estimated_is_not_called_harmless():
    """Fewer parameter sets than parameters + 2: no effect is estimated, and the sentence says
    so instead of "for this design it does not matter"."""
    from parcelfit.study.predict import summarise_prediction

    names = ["a", "b", "c", "d"]
    ident = intervals_of(names)
    rng = np.random.default_rng(4)
    sets = [
        {n: float(v) for n, v in zip(names, rng.uniform(0, 1, 4), strict=True)} for _ in range(5)
    ]
    rows = [
        {
            "set": i,
            "placement": j,
            "transit_time": 1.0 + 0.05 * s["a"] + 0.001 * j,  # a moves it by 50 ms
            "rotation": 0.1,
            "exit_y": 0.0,
            "exit_heading": 0.1,
        }
        for i, s in enumerate(sets)
        for j in range(3)
    ]
    _, effects, sentences = summarise_prediction(ident, sets, [0, 1, 2], pd.DataFrame(rows))
    assert not any(e.estimated for e in effects)
    assert len(sentences) == 4
    assert all("was not estimated" in s and "at least 6 parameter sets" in s for s in sentences)
    assert not any("does not matter" in s for s in sentences)


def _effect_rows(sets, placements, transit):
    """A runs table: the transit time ``transit(set, placement)``, the other quantities fixed."""
    return pd.DataFrame(
        [
            {
                "set": i,
                "placement": j,
                "transit_time": transit(s, j),
                "rotation": 0.1,
                "exit_y": 0.0,
                "exit_heading": 0.1,
            }
            for i, s in enumerate(sets)
            for j in range(placements)
        ]
    )


def test_an_unresolved_effect_is_not_called_harmless_and_a_negligible_one_is():
    """Six sets and four parameters leave the regression one degree of freedom: an effect must
    reach some 200 standard errors. A large effect that falls short is reported as not resolved,
    with its size, not as "does not matter"; one whose upper bound lies below every floor is."""
    from parcelfit.study.predict import summarise_prediction

    names = ["a", "b", "c", "d"]
    ident = intervals_of(names)
    rng = np.random.default_rng(4)
    sets = [
        {n: float(v) for n, v in zip(names, rng.uniform(0, 1, 4), strict=True)} for _ in range(6)
    ]
    noise = rng.normal(0.0, 0.02, (6, 2))
    # a moves the transit by 150 ms over its interval, the set means scattered by about 15 ms
    big = _effect_rows(sets, 2, lambda s, j: 1.0 + 0.15 * s["a"] + noise[sets.index(s), j])
    _, effects, sentences = summarise_prediction(ident, sets, [0, 1], big)
    a = next(e for e in effects if e.parameter == "a" and e.quantity == "transit_time")
    assert a.estimated and not a.resolved and a.threshold > 10
    assert 3 * a.se < abs(a.effect)  # large against its error, below the threshold
    said = next(s for s in sentences if s.startswith("a "))
    assert "not resolved" in said and "does not matter" not in said and "--sets" in said
    assert f"with 6 parameter sets an effect counts from {a.threshold:.1f} standard errors" in said
    # nothing moves anything by more than a few microseconds: harmless, and said so
    tiny = _effect_rows(sets, 2, lambda s, j: 1.0 + 1e-6 * s["a"] + 1e-7 * j)
    _, effects, sentences = summarise_prediction(ident, sets, [0, 1], tiny)
    assert all(e.negligible for e in effects) and len(sentences) == 4
    assert all("for this design it does not matter" in s for s in sentences)
    assert all("below 2 ms, 3 mm and 1 deg)" in s for s in sentences)  # the floors, FLOOR's


def test_one_placement_per_set_gives_no_split_of_the_spread():
    d = decompose(np.array([[1.0], [2.0], [4.0]]))  # three sets, one run each
    assert math.isnan(d.parameter_share) and math.isnan(d.placement_share)
    two = decompose(np.array([[1.0, 1.5], [2.0, 2.5], [4.0, 4.5]]))
    assert two.parameter_share + two.placement_share == pytest.approx(1.0)


def test_a_simulator_that_cannot_place_its_runs_predicts_and_designs_with_one_placement(tmp_path):
    # an external solver, or a Python factory without with_placement: the defaults of 10 and 5
    # placements would only repeat its one run, so without --placements they run 1; a number
    # given is refused as before, naming the option
    unplaced = {"backend": "python", "factory": "tests.test_screening_placements:make_unplaced"}
    study = write_finished_study(tmp_path, simulator=unplaced)
    q = write_rig_q(tmp_path)
    common = ["--sets", "5", "--executor", "serial"]
    result = runner.invoke(
        app,
        [
            "predict",
            str(study),
            "--rig",
            str(q),
            "--consignment",
            "KPBW",
            *common,
            "--out",
            str(tmp_path / "p"),
        ],
    )
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    # the page's path may wrap anywhere in the terminal: the line's end is checked
    assert "(tables, prediction.json) and" in said, said
    assert re.search(r" in \d+ s \(this run's wall time\)$", said), said
    runs = pd.read_csv(tmp_path / "p" / "runs.csv")
    assert len(runs) == 5 and (runs["status"] == "ok").all()  # one run per set
    # one placement per set: no split of the spread, and a note saying why
    doc = json.loads((tmp_path / "p" / "prediction.json").read_text())
    assert any(n.startswith("one placement per parameter set") for n in doc["notes"])
    summary = pd.read_csv(tmp_path / "p" / "summary.csv")
    assert summary["parameter_share"].isna().all() and summary["placement_share"].isna().all()
    result = runner.invoke(
        app, ["design", str(study), "--rig", str(q), *common, "--out", str(tmp_path / "d")]
    )
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    assert re.search(r"design\.json\) in \d+ s \(this run's wall time\)$", said), said
    assert json.loads((tmp_path / "d" / "design.json").read_text())["placements"] == 1
    for command in (
        ["predict", str(study), "--rig", str(q), "--consignment", "KPBW"],
        ["design", str(study), "--rig", str(q)],
    ):
        result = runner.invoke(
            app, [*command, *common, "--placements", "3", "--out", str(tmp_path / "x")]
        )
        assert result.exit_code == 2
        assert "has no seeded placements" in result.output and "--placements" in result.output


def test_the_default_placements_follow_what_the_simulator_can_place():
    from parcelfit.errors import ParcelfitError
    from parcelfit.study.joint import placements_for, require_placements

    from .fake_sim import AnalyticSimulator
    from .test_screening_placements import Unplaced

    placed, unplaced = AnalyticSimulator(), Unplaced()
    assert callable(getattr(placed, "with_placement", None))
    assert placements_for(placed, None, 10) == 10 and placements_for(placed, None, 5) == 5
    assert placements_for(unplaced, None, 10) == 1
    assert placements_for(placed, 3, 10) == placements_for(unplaced, 3, 10) == 3  # given: kept
    with pytest.raises(ParcelfitError) as err:
        require_placements(unplaced, 3, file=None, where="--placements")
    assert err.value.fix.startswith("leave --placements out")


def test_the_wall_time_reads_in_seconds_then_minutes():
    import time

    from parcelfit.cli.output import elapsed_text

    now = time.perf_counter()
    assert re.fullmatch(r"(3[0-2]) s", elapsed_text(now - 30.4))
    assert elapsed_text(now - 119) in ("119 s", "120 s", "2.0 min")
    assert elapsed_text(now - 300) == "5.0 min"


def test_a_mistake_inside_a_rig_file_names_its_key_there(study, tmp_path):
    # the file is named, so the place is the key inside it, not the option --rig
    q = study.parent / "Q.yaml"
    bad = tmp_path / "Qbad.yaml"
    bad.write_text(
        q.read_text(encoding="utf-8")
        .replace("name: Q", "name: Qbad", 1)
        .replace("centre: [1.75, -0.1], length: 4.5", "centre: [1.75, -0.1], lenght: 4.5", 1),
        encoding="utf-8",
    )
    argv = ["predict", str(study), "--rig", str(bad), "--consignment", "KPBW"]
    result = runner.invoke(app, [*argv, "--out", str(tmp_path / "p"), "--executor", "serial"])
    text = " ".join(result.output.split())
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"{bad}: surfaces[0]: unknown key 'lenght'" in text
