import base64
import os
import re

import pytest
import yaml
from typer.testing import CliRunner

from parcelfit import ParcelfitError
from parcelfit.cli import app
from parcelfit.optimize.calibration import Calibration
from parcelfit.optimize.screening import load_screen, run_screen
from parcelfit.optimize.study import load_study
from parcelfit.report import build_report
from parcelfit.report.browser import chromium, inspect_page, screenshot

from .fake_sim import TRUTH
from .helpers import write_study

runner = CliRunner()
NEED_BROWSER = os.environ.get("CI") == "true"  # in CI the browser must be there


@pytest.fixture(scope="module")
def demo_folder(tmp_path_factory):
    """A folder like the demo's: calibration/ and screen/ over the analytic simulator."""
    root = tmp_path_factory.mktemp("demo")
    study_file = write_study(root)
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
        "executor": {"kind": "local", "workers": 2},
    }
    (root / "screen.yaml").write_text(yaml.safe_dump(screen))
    run_screen(load_screen(root / "screen.yaml"), root / "screen")
    return root


def _images(text):
    return re.findall(r'src="data:image/(png|gif);base64,([^"]+)"', text)


@pytest.mark.slow
def test_report_is_one_self_contained_file_with_every_section(demo_folder):
    seen = []
    path = build_report(demo_folder, progress=seen.append)
    assert path == demo_folder / "report.html"
    text = path.read_text()
    for anchor in ("stats", "reference", "screening", "calibration", "validation", "frames"):
        assert f'id="{anchor}"' in text
    assert "SYNTHETIC DATA" in text and "Validation PASSED" in text
    # figures embedded, every one a real PNG; nothing fetched from elsewhere
    images = _images(text)
    assert len(images) >= 9
    for _kind, data in images:
        assert base64.b64decode(data)[:4] == b"\x89PNG"
    assert not re.search(r'(src|href)="(?!data:)', text)
    # the truth beside the calibrated values, and the recovery verdict (analytic truth: both)
    assert "truth (hidden)" in text and "recovered within 10 % of their range: 2 of 2" in text
    # the published criteria and the stricter one, each with a verdict
    assert text.count("<td>1. transit time") == 1 and "stricter (parcelfit)" in text
    assert "MuJoCo backend only" in text  # key frames need a MuJoCo study
    # one iteration numbering: 0 is the initial design (8 runs), then batches of 4
    n, last = map(
        int,
        re.search(
            r"(\d+) simulations: the initial design \(iteration 0\) and iterations 1-(\d+) "
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
def test_the_report_of_a_study_folder_goes_inside_it(demo_folder):
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
def test_report_command_prints_the_path_and_verdict(demo_folder, tmp_path):
    out = tmp_path / "r.html"
    result = runner.invoke(app, ["report", str(demo_folder / "calibration"), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert out.is_file() and "validation passed" in result.output
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


def test_identifiability_from_the_surrogate_span():
    import numpy as np

    from parcelfit.optimize.plots import DependenceCurve
    from parcelfit.report.html import ParameterRow

    xs = np.linspace(0.3, 0.6, 31)
    sharp = DependenceCurve("mu_d_BePa", xs, (xs - 0.4) ** 2 * 100, np.full(31, 0.05), False)
    lo, hi = sharp.indistinct()
    assert lo == pytest.approx(0.38) and hi == pytest.approx(0.42)  # (x-0.4)^2*100 <= 0.05
    flat = DependenceCurve("E_Pa", xs, np.full(31, 0.5), np.full(31, 0.05), False)
    assert flat.indistinct() == (pytest.approx(0.3), pytest.approx(0.6))
    row = ParameterRow("mu_d_BePa", "-", 0.3, 0.6, 0.41, 0.4, sharp.amplitude, (lo, hi))
    assert row.identifiable and row.error_share == pytest.approx(1 / 30)
    row = ParameterRow("E_Pa", "-", 0.3, 0.6, 0.41, 0.4, flat.amplitude, flat.indistinct())
    assert row.identifiable is False
