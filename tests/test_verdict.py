"""One honest verdict (`parcelfit.study.verdict`): every check on its own line, and an overall
verdict that is trustworthy only when every check passed, and otherwise no better than the
worst of them; the same in the terminal, ``status --json`` and the report."""

import itertools
import json

import pytest
from typer.testing import CliRunner

from parcelfit.cli import app
from parcelfit.metrics.envelope import EnvelopeCheck
from parcelfit.metrics.validation import MeanDistanceCheck, TransitTimeCheck, Validation
from parcelfit.study.results import ValidationRecord
from parcelfit.study.verdict import (
    CONVERGENCE_ADVICE,
    LEVELS,
    UNDETERMINED_MEANING,
    Check,
    Determined,
    band_check,
    combine,
    criteria_check,
    transfer_check,
)

from .fake_sim import write_reference_dataset
from .helpers import write_study_results, write_study_store

runner = CliRunner()

OUTCOMES = ("passed", "failed", "not run")
NAMES = ("mu_d_BePa", "mu_d_MePa", "E_Pa", "k_MePa")
PARAMETERS = {  # not analysed, and 0, 2 and 4 of 4 determined
    "not analysed": Determined(False, detail="the analysis runs when the study stops"),
    "0 of 4": Determined(True, (), tuple((n, "undetermined") for n in NAMES)),
    "2 of 4": Determined(True, NAMES[:2], ((NAMES[2], "lower bound"), (NAMES[3], "narrowed"))),
    "4 of 4": Determined(True, NAMES),
}


@pytest.mark.parametrize(
    ("criteria", "band", "transfer", "convergence", "parameters"),
    list(itertools.product(OUTCOMES, OUTCOMES, OUTCOMES, OUTCOMES, PARAMETERS)),
)
def test_the_overall_verdict_is_no_better_than_its_worst_check(
    criteria, band, transfer, convergence, parameters
):
    checks = (
        Check("published criteria", criteria, "E3/KPBW/2"),
        Check("band test", band),
        Check("transfer check", transfer, "E1/KPBW/1"),
        Check("convergence check", convergence, "E3/KPBW/2, E1/KPBW/1"),
    )
    p = PARAMETERS[parameters]
    verdict = combine(*checks, p)
    outcomes = (criteria, band, transfer, convergence)
    if "failed" in outcomes:
        expected = "not trustworthy"
    elif "not run" in outcomes or not p.analysed:
        expected = "incomplete"
    else:
        expected = "trustworthy"
    assert verdict.level == expected and verdict.text.startswith(f"{expected}: ")
    assert verdict.trustworthy == (expected == "trustworthy")
    # the level is never better than a check's own: a failed check caps it at "not trustworthy",
    # a check not run at "incomplete"
    for outcome in outcomes:
        cap = {"passed": "trustworthy", "failed": "not trustworthy", "not run": "incomplete"}
        assert LEVELS.index(verdict.level) <= LEVELS.index(cap[outcome])
    # the sentence names every check that failed or was not run, and only those
    for c in checks:
        said = {"failed": f"{c.name} failed", "not run": f"{c.name} not run"}
        for outcome, words in said.items():
            assert (words in verdict.text) == (c.outcome == outcome)
    assert ("parameter analysis not run" in verdict.text) == (not p.analysed)
    # and the determined count, whatever the level (it does not change the level)
    count = f"{len(p.determined)} of 4 parameters determined"
    assert (count in verdict.text) == p.analysed
    # every check on a line of its own, the parameters named, the verdict last
    lines = verdict.lines()
    assert lines[:4] == [c.line() for c in checks]
    assert (
        lines[4].startswith("parameters determined: ") and lines[-1] == f"verdict: {verdict.text}"
    )
    if p.analysed:
        assert lines[4].startswith(f"parameters determined: {len(p.determined)} of 4 (")
        assert all(n in lines[4] for n in NAMES)
    else:
        assert lines[4] == "parameters determined: not run (the analysis runs when the study stops)"
    assert (UNDETERMINED_MEANING in lines) == bool(p.open)
    # what to do about a failed convergence check, only when it failed, before the verdict
    failed_convergence = outcomes[3] == "failed"
    assert (CONVERGENCE_ADVICE in lines) == failed_convergence
    if failed_convergence:
        assert lines[-2] == CONVERGENCE_ADVICE
    doc = verdict.to_json()
    assert (doc["convergence_advice"] == CONVERGENCE_ADVICE) == failed_convergence
    assert (doc["convergence_advice"] is None) == (not failed_convergence)
    assert [c["outcome"] for c in doc["checks"]] == list(outcomes)
    assert doc["level"] == expected and doc["parameters"]["outcome"] == p.outcome
    assert json.loads(json.dumps(doc)) == doc


def test_the_demo_s_case_reads_not_trustworthy():
    """A quick demo of 2026-11: published criteria passed, band test and transfer check
    failed, no parameter determined; it used to end with `verdict: validation passed`."""
    verdict = combine(
        Check("published criteria", "passed"),
        Check("band test", "failed"),
        Check("transfer check", "failed", "E1/KPBW/1: DTW_theta"),
        Check("convergence check", "passed"),
        PARAMETERS["0 of 4"],
    )
    assert verdict.text == (
        "not trustworthy: band test failed, transfer check failed; 0 of 4 parameters determined"
    )
    assert "transfer check: failed (E1/KPBW/1: DTW_theta)" in verdict.lines()


def _record(case, *, theta=True, inside=1.0, envelope=True, after=3, ran=True):
    """A validation record of ``case`` whose heading criterion and band test pass or not."""
    if not ran:
        return ValidationRecord(
            case=case,
            after_iteration=after,
            status="failed",
            message="the parcel fell off",
        )
    env = EnvelopeCheck(inside, 1.0, 0.01, 0.02, 0.95, inside >= 0.95) if envelope else None
    verdict = Validation(
        TransitTimeCheck(2.0, 1.9, 2.1, True),
        MeanDistanceCheck("xy", 1e-4, (2e-4,), 2e-4, True),
        MeanDistanceCheck("theta", 3e-2 if not theta else 1e-2, (2e-2,), 2e-2, theta),
        env,
    )
    return ValidationRecord(
        case=case, after_iteration=after, status="ok", transit_time=2.0, verdict=verdict
    )


def test_the_checks_of_stored_validations_say_which_case_failed_and_why():
    passed = criteria_check([_record("E3/KPBW/2")])
    assert passed.line() == "published criteria: passed (E3/KPBW/2 after iteration 3)"
    failed = criteria_check([_record("E3/KPBW/2"), _record("E3/PB/2", theta=False)])
    assert failed.line() == "published criteria: failed (E3/PB/2: DTW_theta)"
    broken = criteria_check([_record("E3/KPBW/2", ran=False)])
    assert broken.line() == "published criteria: failed (E3/KPBW/2: the parcel fell off)"
    assert criteria_check([]).outcome == "not run"
    band = band_check([_record("E3/KPBW/2", inside=0.94)])
    assert band.line() == (
        "band test: failed (E3/KPBW/2: lateral 94 %, heading 100 % of the path inside; needs 95 %)"
    )
    assert band_check([_record("E3/KPBW/2")]).outcome == "passed"
    # a case without a band (fewer than two real runs, or no verdict): not run, never passed
    assert band_check([_record("E3/KPBW/2"), _record("D1/x/1", envelope=False)]).outcome == (
        "not run"
    )
    assert band_check([_record("E3/KPBW/2", ran=False)]).outcome == "not run"
    assert band_check([]).outcome == "not run"
    # the transfer check: its cases' published criteria, or why it did not run
    records = [_record("E1/KPBW/1", theta=False, after=None)]
    assert transfer_check(records, True, True).line() == (
        "transfer check: failed (E1/KPBW/1: DTW_theta)"
    )
    assert transfer_check([], False, True).detail == "the study names no transfer cases"
    assert transfer_check([], True, False).detail == "it runs when the study stops"
    assert transfer_check([], True, True).outcome == "not run"


def _finished_study(tmp_path):
    """A finished study (no simulation): the fake dataset's R/P, a validation and a transfer
    check that pass, mu_d_BePa determined and E_Pa not."""
    write_reference_dataset(tmp_path / "data")
    study = write_study_store(tmp_path / "study", tmp_path / "data")
    write_study_results(study, tmp_path / "data")
    return study


def _fail_the_transfer_check(study):
    path = study / "results.json"
    doc = json.loads(path.read_text())
    verdict = doc["transfer"][0]["verdict"]
    verdict["theta"]["passed"] = verdict["passed"] = False
    path.write_text(json.dumps(doc))


def _fail_the_refined_run(study):
    path = study / "results.json"
    doc = json.loads(path.read_text())
    verdict = doc["convergence"]["runs"][0]["verdict"]
    verdict["theta"]["passed"] = verdict["passed"] = False
    path.write_text(json.dumps(doc))


def test_status_json_carries_every_check_and_the_overall_verdict(tmp_path):
    study = _finished_study(tmp_path)
    info = json.loads(runner.invoke(app, ["status", str(study), "--json"]).stdout)
    verdict = info["verdict"]
    assert [(c["name"], c["outcome"]) for c in verdict["checks"]] == [
        ("published criteria", "passed"),
        ("band test", "passed"),
        ("transfer check", "passed"),
        ("convergence check", "passed"),
    ]
    assert verdict["parameters"]["determined"] == ["mu_d_BePa"]
    assert verdict["parameters"]["not_determined"] == [{"name": "E_Pa", "kind": "undetermined"}]
    assert verdict["level"] == "trustworthy" and verdict["undetermined_means"]
    assert verdict["text"] == (
        "trustworthy: published criteria, band test, transfer check and convergence check "
        "passed; 1 of 2 parameters determined"
    )
    # the terminal says the same, a line per check
    text = " ".join(runner.invoke(app, ["status", str(study)]).stdout.split())
    for line in (
        "published criteria: passed (R/P/2 after iteration 1)",
        "transfer check: passed (R/P/2)",
        "convergence check: passed (R/P/2: the same outcomes with every mesh spacing and the "
        "time step halved)",
        "parameters determined: 1 of 2 (mu_d_BePa; not determined: E_Pa (undetermined))",
        UNDETERMINED_MEANING,
        f"verdict: {verdict['text']}",
    ):
        assert line in text
    assert text.rstrip().endswith(f"verdict: {verdict['text']}")
    assert verdict["convergence_advice"] is None and CONVERGENCE_ADVICE not in text
    _fail_the_transfer_check(study)
    info = json.loads(runner.invoke(app, ["status", str(study), "--json"]).stdout)
    assert info["verdict"]["level"] == "not trustworthy"
    assert info["verdict"]["checks"][2]["detail"] == "R/P/2: DTW_theta"
    # R/P/2 is validated and transferred: its refined run is paired with its validation (which
    # passes, as the refined run does), not with the transfer record
    assert info["verdict"]["checks"][3]["outcome"] == "passed"
    _fail_the_refined_run(study)
    info = json.loads(runner.invoke(app, ["status", str(study), "--json"]).stdout)
    assert info["verdict"]["checks"][3] == {
        "name": "convergence check",
        "outcome": "failed",
        "detail": "R/P/2 passes on the model, fails (DTW_theta) refined, every mesh spacing and "
        "the time step halved",
    }
    assert info["verdict"]["convergence_advice"] == CONVERGENCE_ADVICE
    text = " ".join(runner.invoke(app, ["status", str(study)]).stdout.split())
    assert CONVERGENCE_ADVICE in text
    # a study without stored results: nothing was judged, nothing is trustworthy
    (study / "results.json").unlink()
    verdict = json.loads(runner.invoke(app, ["status", str(study), "--json"]).stdout)["verdict"]
    assert [c["outcome"] for c in verdict["checks"]] == ["not run"] * 4
    assert verdict["text"] == (
        "incomplete: published criteria not run, band test not run, transfer check not run, "
        "convergence check not run, parameter analysis not run"
    )


def _verdict_box(html: str) -> str:
    """The report's verdict box (its opening tag to its closing one)."""
    start = html.index('<div class="verdict')
    return html[start : html.index("</div>", start)]


@pytest.mark.slow
def test_the_report_s_verdict_box_is_green_only_when_every_check_passes(tmp_path):
    from parcelfit.report import build_report

    study = _finished_study(tmp_path)
    text = build_report(study, out=tmp_path / "r.html", key_frames=False).read_text()
    assert '<div class="verdict pass"><b>Verdict: trustworthy: ' in text
    _fail_the_transfer_check(study)
    text = build_report(study, out=tmp_path / "r.html", key_frames=False).read_text()
    assert '<div class="verdict pass">' not in text
    assert '<div class="verdict fail"><b>Verdict: not trustworthy: transfer check failed; ' in text
    assert '<li><b>transfer check</b>: <span class="bad">failed</span> (R/P/2: DTW_theta)' in text
    assert '<li><b>published criteria</b>: <span class="ok">passed</span>' in text
    # the convergence section: the model's run and the refined one, each with its criteria
    section = text[text.index('id="convergence"') :]
    assert "divided by 2" in section and "as calibrated" in section and "refined" in section
    # what to do when it fails, the verdict's own words (autoescaped: compare around apostrophes)
    assert all(part in section for part in CONVERGENCE_ADVICE.split("'"))
    assert section.count('<span class="ok">pass</span>') >= 2
    box = _verdict_box(text)
    assert CONVERGENCE_ADVICE.split("'")[0] not in box  # (autoescaped: its words before one)
    # a check not run: amber, not green
    path = study / "results.json"
    doc = json.loads(path.read_text())
    doc["transfer"] = []
    path.write_text(json.dumps(doc))
    text = build_report(study, out=tmp_path / "r.html", key_frames=False).read_text()
    assert '<div class="verdict incomplete"><b>Verdict: incomplete: transfer check not run' in text
    assert "the study names no transfer cases" in text
    # a failed convergence check: the box says what to do about it
    _fail_the_refined_run(study)
    text = build_report(study, out=tmp_path / "r.html", key_frames=False).read_text()
    box = _verdict_box(text)
    assert '<li><b>convergence check</b>: <span class="bad">failed</span>' in box
    # (autoescaped: compare the words around the apostrophes)
    assert all(part in box for part in CONVERGENCE_ADVICE.split("'"))


def test_the_last_validation_is_judged_the_recommended_parameters_one():
    """An earlier validation that passed does not stand in for the last one (of the parameters
    recommended, which the transfer check simulates too)."""
    from parcelfit.study.results import new_results
    from parcelfit.study.verdict import study_verdict

    earlier = [_record("E3/KPBW/2", after=2), _record("E3/PB/2", after=2)]
    last = [_record("E3/KPBW/2", after=4), _record("E3/PB/2", theta=False, after=4)]
    verdict = study_verdict(new_results({}, [*earlier, *last]), stopped=True)
    assert verdict.criteria.line() == "published criteria: failed (E3/PB/2: DTW_theta)"
    verdict = study_verdict(new_results({}, [*last, *earlier]), stopped=True)
    assert verdict.criteria.line() == (
        "published criteria: passed (E3/KPBW/2, E3/PB/2 after iteration 2)"
    )
    assert verdict.transfer.detail == "the study names no transfer cases"
    assert verdict.parameters.detail == "too few finished evaluations to analyse"
