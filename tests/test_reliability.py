"""Reliability and security: hostile names in reports, brackets in messages, damaged or
read-only study stores."""

import html
import os
import sqlite3

import pytest
import yaml
from typer.testing import CliRunner

from parcelfit import ParcelfitError
from parcelfit.cli import app
from parcelfit.optimize.calibration import Calibration, study_status
from parcelfit.optimize.store import Store
from parcelfit.optimize.study import load_study
from parcelfit.report import build_report
from parcelfit.report.browser import chromium, inspect_page
from parcelfit.report.html import CONTENT_SECURITY_POLICY

from .test_calibration import write_study

runner = CliRunner()
NEED_BROWSER = os.environ.get("CI") == "true"

SCRIPT = "<script>document.title='X'</script>"
HOSTILE = {
    "rig": f"R{SCRIPT}",
    "consignment": "P<img src=x onerror=\"document.title='Y'\">",
    "run": f"run{SCRIPT}",
    "name": f"study{SCRIPT}&amp;",
}


def _hostile_study(tmp_path):
    """A small finished study whose rig, consignment, run ids and name are hostile HTML."""
    study_file = write_study(
        tmp_path,
        name=HOSTILE["name"],
        reference={
            "dataset": "data",
            "rig": HOSTILE["rig"],
            "consignment": HOSTILE["consignment"],
            "speed_setting": 1,
        },
        validation={"speed_setting": 2, "every": 1},
        initial=4,
        batch_size=2,
        budget=6,
    )
    ds_file = tmp_path / "data" / "dataset.yaml"
    doc = yaml.safe_load(ds_file.read_text())
    for case in doc["test_cases"]:
        case["rig"], case["consignment"] = HOSTILE["rig"], HOSTILE["consignment"]
        for run in case["runs"]:
            run["id"] = HOSTILE["run"] + run["id"]
    ds_file.write_text(yaml.safe_dump(doc))
    Calibration(load_study(study_file), tmp_path / "out").run()
    return tmp_path / "out"


def test_hostile_names_are_text_in_the_report(tmp_path):
    page = build_report(_hostile_study(tmp_path), out=tmp_path / "r.html", key_frames=False)
    text = page.read_text()
    assert "<script" not in text.lower() and "<img src=x" not in text
    assert "&lt;script&gt;document.title=" in text  # shown as text, escaped
    policy = f'<meta http-equiv="Content-Security-Policy" content="{CONTENT_SECURITY_POLICY}">'
    assert policy in html.unescape(text) and "default-src 'none'" in CONTENT_SECURITY_POLICY
    if chromium() is None and not NEED_BROWSER:
        pytest.skip("Chromium is not installed (CI installs it)")
    found = inspect_page(page)
    # no script ran: the title is the study's name as plain text, not 'X' or 'Y'
    assert found["title"] == f"parcelfit report: {HOSTILE['name']}"


def test_the_page_policy_blocks_a_script_that_slipped_through(tmp_path):
    """Defence in depth: even unescaped markup cannot run a script under the report's policy."""
    if chromium() is None and not NEED_BROWSER:
        pytest.skip("Chromium is not installed (CI installs it)")
    page = tmp_path / "p.html"
    body = f"<title>safe</title>{SCRIPT}<img src=x onerror=\"document.title='Y'\">"
    page.write_text(
        f'<html><head><meta http-equiv="Content-Security-Policy" '
        f'content="{CONTENT_SECURITY_POLICY}">{body}</head></html>'
    )
    assert inspect_page(page)["title"] == "safe"
    page.write_text(f"<html><head>{body}</head></html>")  # the same page without the policy
    assert inspect_page(page)["title"] in ("X", "Y")


@pytest.mark.parametrize("name", ["a[/i]", "[/b]", "run[/bold]", "[red]x[/red]"])
def test_square_brackets_in_user_text_are_printed_as_they_are(tmp_path, name):
    folder = tmp_path / name
    result = runner.invoke(app, ["reference", str(folder)])
    assert result.exit_code == 2
    assert "MarkupError" not in result.output
    assert f"{folder}: no dataset.yaml here" in result.output


def test_a_bracketed_word_in_a_message_does_not_vanish(tmp_path):
    study = write_study(tmp_path, parameters={"mu_d_BePa": "wide"})
    result = runner.invoke(app, ["calibrate", str(study)])
    assert result.exit_code == 2
    assert "expected [low, high] or {low, high, log}" in result.output


def test_an_empty_store_is_damaged_not_a_new_study(tmp_path):
    study = load_study(write_study(tmp_path, budget=8, validation={}))
    Calibration(study, tmp_path / "out").run()
    runs = sorted((tmp_path / "out" / "runs").iterdir())
    stamps = [p.stat().st_mtime_ns for p in runs]
    (tmp_path / "out" / "study.sqlite").write_bytes(b"")  # truncated to 0 bytes
    with pytest.raises(ParcelfitError, match=r"empty \(0 bytes\)"):
        Calibration(study, tmp_path / "out")
    result = runner.invoke(app, ["status", str(tmp_path / "out")])
    assert result.exit_code == 2 and "empty (0 bytes)" in result.output
    assert (tmp_path / "out" / "study.sqlite").stat().st_size == 0  # nothing written into it
    assert [p.stat().st_mtime_ns for p in runs] == stamps  # runs/ untouched


def test_status_and_report_open_the_store_read_only(tmp_path):
    study = load_study(write_study(tmp_path, budget=8, validation={}))
    Calibration(study, tmp_path / "out").run()
    db = tmp_path / "out" / "study.sqlite"
    before = db.read_bytes()
    info = study_status(tmp_path / "out")
    build_report(tmp_path / "out", out=tmp_path / "r.html", key_frames=False)
    assert info["evaluations"] == 8 and db.read_bytes() == before
    ro = Store(db, readonly=True)
    with pytest.raises(ParcelfitError, match="read-only"):
        ro.set_meta("x", 1)
    ro.close()
    # a database SQLite itself refuses to write (a read-only folder or file) gives advice that
    # keeps the results: never "move the damaged file away"
    store = Store(db)
    store._db.close()
    store._db = sqlite3.connect(f"file:{db}?mode=ro", uri=True, isolation_level=None)
    with pytest.raises(ParcelfitError, match=r"read-only.*results are intact") as err:
        store.set_meta("x", 1)
    assert "move" not in str(err.value) and "new output folder" not in str(err.value)
    store.close()


def test_a_foreign_sqlite_file_is_not_read_as_a_study(tmp_path):
    db = tmp_path / "study.sqlite"
    sqlite3.connect(db).execute("CREATE TABLE t (x)").connection.close()
    result = runner.invoke(app, ["status", str(tmp_path)])
    assert result.exit_code == 2 and "not a parcelfit study database" in result.output
    assert (
        not sqlite3.connect(db)
        .execute("SELECT name FROM sqlite_master WHERE name = 'evaluations'")
        .fetchall()
    )


def test_a_second_calibration_on_the_same_folder_is_refused(tmp_path):
    study = load_study(write_study(tmp_path, budget=8, validation={}))
    first = Calibration(study, tmp_path / "out")
    with pytest.raises(ParcelfitError, match="another parcelfit process is running a calibration"):
        Calibration(study, tmp_path / "out")
    first.run()  # releases the folder when it ends
    again = Calibration(study, tmp_path / "out").run()
    assert again.evaluations == 8
