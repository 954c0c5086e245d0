import base64
import os
import re

import pytest
import yaml
from typer.testing import CliRunner

from parcelfit import ParcelfitError
from parcelfit.cli import app
from parcelfit.report import build_report
from parcelfit.report.browser import chromium, inspect_page, screenshot
from parcelfit.study.calibration import Calibration
from parcelfit.study.screening import load_screen, run_screen
from parcelfit.study.studyfile import load_study

from .fake_sim import TRUTH, write_reference_dataset
from .helpers import write_study, write_study_results, write_study_store

runner = CliRunner()
NEED_BROWSER = os.environ.get("CI") == "true"  # in CI the browser must be there


@pytest.fixture(scope="module")
def demo_folder(tmp_path_factory):
    """A folder like the demo's: calibration/ and screen/ over the analytic simulator."""
    root = tmp_path_factory.mktemp("demo")
    study_file = write_study(root, executor={"kind": "serial"})  # no worker processes to start
    (root / "data" / "truth.yaml").write_text(
        yaml.safe_dump({"synthetic": True, "truth": {"P": TRUTH}})
    )
    Calibration(load_study(study_file), root / "calibration").run()
    screen = {
        "name": "fake-screen",
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make"},
        "reference": {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
        "parameters": {"mu_d_BePa": [0.3, 0.58], "mu_d_MePa": [0.15, 0.35], "E_Pa": [200, 1600]},
        "stages": ["full"],
        "executor": {"kind": "serial"},
    }
    (root / "screen.yaml").write_text(yaml.safe_dump(screen))
    run_screen(load_screen(root / "screen.yaml"), root / "screen")
    return root


def _no_analysis(monkeypatch):
    """Make everything the report used to recompute raise: building a simulator, simulating,
    selecting reference runs, validating, refitting the GP surrogate."""

    def refuse(*args, **kwargs):
        raise AssertionError("the report must render stored results, not recompute them")

    # modules that bind these functions by name at import must be imported before the patch,
    # or a later test would find the refusing stand-ins in them
    import parcelfit.analysis
    import parcelfit.cli
    import parcelfit.demo
    import parcelfit.study.calibration
    import parcelfit.study.screening  # noqa: F401
    from parcelfit.sim.mujoco.simulator import MujocoSimulator

    for target in (
        "parcelfit.sim.factory.make_simulator",
        "parcelfit.metrics.select_reference",
        "parcelfit.metrics.reference.select_reference",
        "parcelfit.metrics.validate",
        "parcelfit.metrics.validation.validate",
        "parcelfit.study.results.validate",
        "parcelfit.study.plots.dependence_curves",
        "parcelfit.study.plots.surrogate_optimizer",
        "parcelfit.optimize.bo.BatchBO._fit",
    ):
        monkeypatch.setattr(target, refuse)
    monkeypatch.setattr(MujocoSimulator, "run_with_frames", refuse)


def _images(text):
    return re.findall(r'src="data:image/(png|gif);base64,([^"]+)"', text)


@pytest.mark.slow
def test_report_is_one_self_contained_file_with_every_section(demo_folder, monkeypatch):
    _no_analysis(monkeypatch)  # the calibration's stored results are rendered, nothing more
    seen = []
    path = build_report(demo_folder, progress=seen.append)
    assert path == demo_folder / "report.html"
    text = path.read_text()
    for anchor in ("stats", "reference", "screening", "calibration", "validation", "frames"):
        assert f'id="{anchor}"' in text
    assert "SYNTHETIC DATA" in text
    # the verdict box: every check on a line; without a transfer case the verdict is at best
    # incomplete, never green
    assert '<li><b>published criteria</b>: <span class="ok">passed</span>' in text
    assert "<li><b>band test</b>: " in text and '<div class="verdict pass">' not in text
    assert "(the study names no transfer cases)" in text and "transfer check not run" in text
    assert "The study stopped: validation passed (by the published criteria" in text
    # figures embedded, every one a real PNG; nothing fetched from elsewhere
    images = _images(text)
    assert len(images) >= 9
    for _kind, data in images:
        assert base64.b64decode(data)[:4] == b"\x89PNG"
    assert not re.search(r'(src|href)="(?!data:)', text)
    # the truth beside the calibrated values, and the recovery verdict counted from the
    # recommended parameters (validation passes at 24 evaluations: mu_d_MePa is recovered
    # within 10 %, mu_d_BePa may lie just outside)
    from parcelfit.study import study_status

    rec = study_status(demo_folder / "calibration").recommended.params
    ranges = {"mu_d_BePa": (0.3, 0.6), "mu_d_MePa": (0.15, 0.35)}
    count = sum(abs(rec[k] - TRUTH[k]) <= 0.1 * (hi - lo) for k, (lo, hi) in ranges.items())
    assert count >= 1 and "truth (hidden)" in text
    assert f"Calibrated values within 10 % of their range of the hidden truth: {count} of 2" in text
    # every interval holds the analytic truth
    assert "intervals containing the truth: 2 of 2" in text
    # the published criteria and the stricter one, each with a verdict
    assert text.count("<td>1. transit time") == 1 and "stricter (parcelfit)" in text
    assert "MuJoCo backend only" in text  # key frames need a MuJoCo study
    # one iteration numbering: 0 is the initial design (8 runs), then batches of 4
    n, last = map(
        int,
        re.search(
            r"(\d+) evaluations: the initial design \(iteration 0\) and iterations 1-(\d+) "
            r"\(batches of 4\)",
            text,
        ).groups(),
    )
    assert (
        n == 8 + 4 * last
        and f"The calibrated parameters, validated after iteration {last}," in text
    )
    assert re.search(r"Calibrated parameters: the evaluation made in iteration \d+ with cost", text)
    assert seen[0].job == "report" and seen[0].message.startswith("Transit times")


@pytest.mark.slow
def test_the_report_of_a_study_folder_goes_inside_it(demo_folder, no_report_figures):
    study = demo_folder / "calibration"
    path = build_report(study, key_frames=False)
    assert path == study / "report.html" and path.is_file()
    result = runner.invoke(app, ["report", "--help"], terminal_width=200)
    assert "default: report.html inside FOLDER" in " ".join(result.output.split())


def test_report_names_a_missing_study(tmp_path):
    with pytest.raises(ParcelfitError, match="no calibration study here"):
        build_report(tmp_path)
    result = runner.invoke(app, ["report", str(tmp_path)])
    assert result.exit_code == 2 and "no calibration study here" in result.output


@pytest.mark.slow
def test_report_command_prints_the_path_and_verdict(demo_folder, tmp_path, no_report_figures):
    out = tmp_path / "r.html"
    result = runner.invoke(app, ["report", str(demo_folder / "calibration"), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert out.is_file()
    lines = " ".join(result.output.split())
    # every check on its own line, then the one verdict, no better than the worst check
    for check in ("published criteria:", "band test:", "transfer check:", "parameters determined:"):
        assert check in lines
    assert "verdict: " in lines and "verdict: trustworthy" not in lines
    assert 'id="screening"' in out.read_text()  # screen/ beside the study is found


@pytest.mark.skipif(
    chromium() is None and not NEED_BROWSER, reason="Chromium is not installed (CI installs it)"
)
@pytest.mark.slow
@pytest.mark.browser
def test_report_renders_in_headless_chromium(demo_folder, tmp_path):
    page = build_report(demo_folder, out=tmp_path / "report.html")
    found = inspect_page(page)
    assert found["title"].startswith("parcelfit report")
    assert found["headings"] == [
        "stats",
        "reference",
        "screening",
        "calibration",
        "validation",
        "convergence",
        "frames",
    ]
    assert found["images"] == len(_images(page.read_text())) and found["broken"] == 0
    assert found["height"] > 3000
    png = screenshot(page, tmp_path / "shot.png", height=1200)
    assert png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 20_000


@pytest.mark.skipif(
    chromium() is None and not NEED_BROWSER, reason="Chromium is not installed (CI installs it)"
)
@pytest.mark.browser
def test_the_browser_check_sees_a_broken_image(tmp_path):
    page = tmp_path / "broken.html"
    page.write_text(
        "<html><head><title>t</title></head><body><h2 id='a'>a</h2>"
        "<img src='data:image/png;base64,AAAA'></body></html>"
    )
    found = inspect_page(page)
    assert found["images"] == 1 and found["broken"] == 1 and found["headings"] == ["a"]


def test_parameter_rows_report_values_only_for_determined_parameters():
    from parcelfit.report.calibration import ParameterRow

    row = ParameterRow("mu_d_BePa", "-", 0.3, 0.6, 0.41, 0.4, (0.38, 0.42), "determined", 0.40)
    assert row.determined and row.covers_truth and row.error_share == pytest.approx(1 / 30)
    assert row.bound_text == "0.4 +- 0.02"
    row = ParameterRow("E_Pa", "-", 200, 1600, 900, 1000, (210, 1590), "undetermined")
    assert row.determined is False and row.bound_text == "no value: the data cannot tell"
    row = ParameterRow("k_MePa", "-", 100, 1000, 700, 900, (400, 995), "lower bound")
    assert row.bound_text == "at least 400" and row.covers_truth
    assert ParameterRow("x", "-", 0, 1, 0.5, None).determined is None
    # the verdict box tells a bound from "no value": a bounded parameter is listed with its bound
    from parcelfit.report.html import _summary

    rows = [
        ParameterRow("E_Pa", "-", 200, 1600, 900, 1000, (210, 1590), "undetermined"),
        ParameterRow("k_MePa", "-", 100, 1000, 700, 900, (400, 995), "lower bound"),
    ]
    summary = _summary(None, rows, None, True)
    assert summary["bounded"] == "k_MePa (at least 400)" and summary["open"] == "E_Pa"


@pytest.mark.slow
def test_the_report_renders_the_stored_verdict_without_simulating_or_refitting(
    tmp_path, monkeypatch, no_report_figures
):
    import json

    write_reference_dataset(tmp_path / "data")
    study = write_study_store(tmp_path / "study", tmp_path / "data")
    write_study_results(study, tmp_path / "data")
    # a stored number no analysis would give, so the page can only show it by reading it
    path = study / "results.json"
    doc = json.loads(path.read_text())
    doc["validations"][0]["verdict"]["xy"]["simulated_mean"] = 4.56e-07
    path.write_text(json.dumps(doc))
    _no_analysis(monkeypatch)
    text = build_report(study, out=tmp_path / "r.html").read_text()
    assert '<div class="verdict pass"><b>Verdict: trustworthy: ' in text
    assert "<td>4.56e-07 m&sup2;</td>" in text
    assert "The calibrated parameters, validated after iteration 1," in text
    # the validation and the transfer check (one case) each show the criteria
    assert text.count("<td>1. transit time") == 2 and "stricter (parcelfit)" in text
    assert len(_images(text)) >= 8  # statistics, 2 distance maps, history, curves, traces, 3
    # what the data determine: the stored analysis, said plainly; no value for E_Pa
    assert "<b>Determined by these test cases: mu_d_BePa</b>" in text
    assert "Not determined: E_Pa</span>" in text and "no value: the data cannot tell" in text
    assert (
        "<b>parameters determined</b>: 1 of 2: mu_d_BePa; <b>not determined</b> (no value "
        "reported): E_Pa" in text
    )
    assert re.search(r"<td>mu_d_BePa</td>.*?<span class=\"ok\">determined</span>", text)
    assert "Which further test case would help most to determine E_Pa: <b>R/P/2</b>" in text
    assert "Do the parameters carry over? (transfer check)" in text and 'id="transfer"' in text
    # the surrogate's optimiser settings are the stored ones (the published configuration)
    assert "optimizer published" in text and "batch=kmeans" in text and "noise=fixed" in text
    assert "MuJoCo backend only" in text and 'id="frames"' in text
    # without advice (left out, or too few candidates) the page says there is none
    assert "No advice on which further test case" not in text
    doc["advice"] = None
    path.write_text(json.dumps(doc))
    text = build_report(study, out=tmp_path / "r2.html").read_text()
    assert "No advice on which further test case would help most" in text
    assert "Which further test case would help most to determine" not in text


def test_a_study_without_stored_results_says_so_instead_of_recomputing(tmp_path, monkeypatch):
    write_reference_dataset(tmp_path / "data")
    study = write_study_store(tmp_path / "study", tmp_path / "data")  # as an earlier version
    _no_analysis(monkeypatch)
    text = " ".join(build_report(study, out=tmp_path / "r.html").read_text().split())
    assert "no stored results (results.json)" in text and "nothing is recomputed here" in text
    assert "`parcelfit calibrate` again on the same study file and folder" in text
    assert text.count("Not stored in this study folder") == 4  # references, GP, validation, frames
    assert '<b>published criteria</b>: <span class="warn">not run</span>' in text
    assert '<div class="verdict incomplete">' in text and 'id="calibration"' in text
    assert "<td>mu_d_BePa</td><td>-</td><td>0.3 - 0.6</td><td>0.45</td>" in text
    # a damaged results file is named in the page; the rest still renders
    (study / "results.json").write_text("{")
    text = build_report(study, out=tmp_path / "r.html").read_text()
    assert "results file is unreadable" in text and 'id="calibration"' in text


@pytest.mark.slow
def test_the_report_s_surrogate_has_the_study_s_optimizer_settings(tmp_path, monkeypatch):
    from parcelfit.optimize.bo import BOSettings
    from parcelfit.study import plots

    study_file = write_study(
        tmp_path,
        optimizer={"sampler": "published", "n_samples": 1000, "n_restarts": 1},
        initial=4,
        batch_size=2,
        budget=6,
        validation={"speed_setting": 2, "every": 1},
        executor={"kind": "serial"},
    )
    calibration = Calibration(load_study(study_file), tmp_path / "out", figures=False)
    used = calibration.bo.settings
    assert used != BOSettings() and used.batch == "kmeans" and not used.ard
    refits = []
    real = plots.surrogate_optimizer

    def watched(record, fits):
        refits.append(real(record, fits))
        return refits[-1]

    monkeypatch.setattr(plots, "surrogate_optimizer", watched)
    calibration.run()
    # every GP the calibration refitted for the report had the study's settings, not defaults
    assert refits and all(bo.settings == used for bo in refits)
    _no_analysis(monkeypatch)
    text = build_report(tmp_path / "out", out=tmp_path / "r.html").read_text()
    assert "optimizer published" in text and "batch=kmeans" in text and "ard=False" in text
    assert "partial dependence" in text  # drawn from the stored curves
