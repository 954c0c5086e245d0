"""Reliability and security: hostile names in reports, brackets in messages, damaged or
read-only study stores."""

import contextlib
import html
import json
import os
import re
import sqlite3
import time
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from parcelfit import ParcelfitError
from parcelfit.cli import app
from parcelfit.errors import short_path
from parcelfit.report import build_report
from parcelfit.report.browser import chromium, inspect_page
from parcelfit.report.page import CONTENT_SECURITY_POLICY
from parcelfit.study.calibration import Calibration
from parcelfit.study.status import study_status
from parcelfit.study.store import Store
from parcelfit.study.studyfile import load_study

from .helpers import finished_fits, write_study

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
        executor={"kind": "serial"},
    )
    ds_file = tmp_path / "data" / "dataset.yaml"
    doc = yaml.safe_load(ds_file.read_text())
    for case in doc["test_cases"]:
        case["rig"], case["consignment"] = HOSTILE["rig"], HOSTILE["consignment"]
        for run in case["runs"]:
            run["id"] = HOSTILE["run"] + run["id"]
    ds_file.write_text(yaml.safe_dump(doc))
    Calibration(load_study(study_file), tmp_path / "out", figures=False).run()
    return tmp_path / "out"


@pytest.mark.slow
@pytest.mark.browser
def test_hostile_names_are_text_in_the_report(tmp_path, no_report_figures):
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


@pytest.mark.slow
@pytest.mark.browser
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


PNG = b"\x89PNG\r\n\x1a\n"


def _spy_on_reads(monkeypatch):
    """Every file opened from now on (builtins.open, io.open: what pathlib uses), resolved."""
    import builtins
    import io

    opened, real_open = [], io.open

    def spy(file, *args, **kwargs):
        if isinstance(file, str | os.PathLike):
            opened.append(Path(file).resolve())
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", spy)
    monkeypatch.setattr(io, "open", spy)
    return opened


def _study_with_outside_files(tmp_path):
    """A finished study (no simulation) at a/b/study, a PNG image outside it (``secret.png``),
    one inside (``frames.png``) and links inside it leading out and in."""
    from .helpers import write_reference_dataset, write_study_results, write_study_store

    write_reference_dataset(tmp_path / "data")
    study = write_study_store(tmp_path / "a" / "b" / "study", tmp_path / "data")
    write_study_results(study, tmp_path / "data")
    secret = tmp_path / "secret.png"
    secret.write_bytes(PNG + b"secret bytes of an image outside the study folder")
    (study / "frames.png").write_bytes(PNG + b"the key frames")
    (study / "sub").mkdir()
    (study / "link.png").symlink_to(secret)
    (study / "inner-link.png").symlink_to(study / "frames.png")
    return study, secret


def _store_key_frames(study, image, animation):

    doc = json.loads((study / "results.json").read_text())
    doc["key_frames"].update(image=image, animation=animation)
    (study / "results.json").write_text(json.dumps(doc))


@pytest.mark.parametrize(
    ("name", "embedded", "note"),
    [
        ("../../../secret.png", False, "outside the study folder"),
        ("ABSOLUTE", False, "outside the study folder"),
        ("link.png", False, "outside the study folder"),  # a link inside, leading out
        ("sub/../frames.png", True, None),
        ("inner-link.png", True, None),  # a link inside, leading inside
        ("study.sqlite", False, "not a PNG image"),
        ("gone.png", False, "missing"),
        ("", False, "not a file name"),
    ],
)
def test_key_frames_are_embedded_only_from_inside_the_study_folder(
    tmp_path, monkeypatch, name, embedded, note
):
    import base64

    from parcelfit.report.html import _frames_section
    from parcelfit.report.page import Page
    from parcelfit.study.results import read_results

    study, secret = _study_with_outside_files(tmp_path)
    stored = str(secret) if name == "ABSOLUTE" else name
    _store_key_frames(study, stored, stored)
    results = read_results(study)
    opened = _spy_on_reads(monkeypatch)
    page = Page(lambda event: None)
    _frames_section(page, study, results, animation=True)
    data = page.sections[0].data
    assert secret.resolve() not in opened  # never read, not even its first bytes
    assert (data["image"] is not None) is embedded
    if embedded:
        assert base64.b64encode(PNG + b"the key frames").decode() in data["image"]
    elif note == "missing":
        assert data["note"] == f"The key-frame figure {stored} is missing from the study folder."
    else:
        assert data["note"] == f"The key-frame figure {stored} is not embedded: {note}."
        reason = note.replace("PNG", "GIF")
        assert data["no_animation"] == f"The animation {stored} is not embedded: {reason}."
    assert data["animation"] is None  # a PNG is no GIF, and the others are refused


@pytest.mark.slow  # draws the whole report (~10 s)
def test_the_report_reads_no_file_outside_the_study_and_screening_folders(
    tmp_path, monkeypatch, no_report_figures
):
    import base64

    study, secret = _study_with_outside_files(tmp_path)
    _store_key_frames(study, "../../../secret.png", str(secret))
    # the demo's extra files beside the study and a screening folder: links leading out
    outside = tmp_path / "outside.json"
    outside.write_text('{"description": "SECRET", "selected": ["SECRET"]}')
    for extra in ("reference_runs.json", "stricter-criterion.json"):
        (study.parent / extra).symlink_to(outside)
    screen = tmp_path / "screen"
    screen.mkdir()
    (screen / "stage1-effects.csv").write_text("parameter,effect\n")
    (screen / "selection.yaml").symlink_to(outside)
    (screen / "stage1-pareto-xy.png").symlink_to(secret)
    opened = _spy_on_reads(monkeypatch)
    page = build_report(study, out=tmp_path / "r.html", screen=screen, animation=True)
    text = html.unescape(" ".join(page.read_text().split()))
    assert secret.resolve() not in opened and outside.resolve() not in opened
    assert base64.b64encode(secret.read_bytes()).decode() not in text and "SECRET" not in text
    assert (
        "The key-frame figure ../../../secret.png is not embedded: outside the study folder."
        in text
    )
    assert f"The animation {secret} is not embedded: outside the study folder." in text
    for refused in ("reference_runs.json", "stricter-criterion.json"):
        assert f"{refused} is not embedded: outside its folder." in text
    for refused in ("selection.yaml", "stage1-pareto-xy.png"):
        assert f"{refused} is not embedded: outside the screening folder." in text


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


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A small finished study (4 initial fitting runs, then batches of 2 up to 8, a validation
    after every iteration; how many it ran depends on when validation passed)."""
    root = tmp_path_factory.mktemp("finished")
    study = write_study(
        root,
        initial=4,
        batch_size=2,
        budget=8,
        validation={"speed_setting": 2, "every": 1},
        executor={"kind": "serial"},
    )
    Calibration(load_study(study), root / "out", figures=False).run()
    info = study_status(root / "out")
    assert info.evaluations >= 6 and info.validations, info  # what the tests below need
    return root


def _fits(out) -> int:
    """The number of fitting evaluations in a study folder, read straight from its store."""
    con = sqlite3.connect(out / "study.sqlite")
    try:
        return con.execute("SELECT count(*) FROM evaluations WHERE kind = 'fit'").fetchone()[0]
    finally:
        con.close()


def _copy(finished, tmp_path):
    """A private copy of the finished study: (study, its folder)."""
    import shutil

    shutil.copytree(finished, tmp_path / "s")
    return load_study(tmp_path / "s" / "study.yaml"), tmp_path / "s" / "out"


@pytest.mark.slow
def test_an_empty_store_is_damaged_not_a_new_study(finished, tmp_path):
    study, out = _copy(finished, tmp_path)
    runs = sorted((out / "runs").iterdir())
    stamps = [p.stat().st_mtime_ns for p in runs]
    (out / "study.sqlite").write_bytes(b"")  # truncated to 0 bytes
    with pytest.raises(ParcelfitError, match=r"empty \(0 bytes\)"):
        Calibration(study, out, figures=False).run()
    result = runner.invoke(app, ["status", str(out)])
    assert result.exit_code == 2 and "empty (0 bytes)" in result.output
    assert (out / "study.sqlite").stat().st_size == 0  # nothing written into it
    assert [p.stat().st_mtime_ns for p in runs] == stamps  # runs/ untouched


@pytest.mark.slow
def test_status_and_report_open_the_store_read_only(finished, tmp_path, no_report_figures):
    _, out = _copy(finished, tmp_path)
    db = out / "study.sqlite"
    before = db.read_bytes()
    n = _fits(out)
    info = study_status(out)
    build_report(out, out=tmp_path / "r.html", key_frames=False)
    assert info.evaluations == n and db.read_bytes() == before
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


@pytest.mark.slow
def test_a_second_calibration_on_the_same_folder_is_refused(finished, tmp_path):
    study, out = _copy(finished, tmp_path)
    n = _fits(out)
    first = Calibration(study, out, figures=False)
    first.prepare()  # opens and locks the folder
    with pytest.raises(ParcelfitError, match="another parcelfit process is running a calibration"):
        Calibration(study, out, figures=False).run()
    first.run()  # releases the folder when it ends
    again = Calibration(study, out, figures=False).run()
    assert again.evaluations == n  # the finished study is not run a second time


def _dataset_with_outside_file(make_dataset, tmp_path):
    from .conftest import line_trajectory

    root = make_dataset(
        {("R", "P", 1): [("a", line_trajectory(), 1.0), ("b", line_trajectory(), 1.0)]}
    )
    line_trajectory().to_frame().to_csv(tmp_path / "outside.csv", index=False)
    return root


def _set_file(root, index, name):
    path = root / "dataset.yaml"
    doc = yaml.safe_load(path.read_text())
    doc["test_cases"][0]["runs"][index]["file"] = name
    path.write_text(yaml.safe_dump(doc))


@pytest.mark.parametrize("kind", ["dotdot", "absolute", "symlink"])
def test_run_files_outside_the_dataset_are_refused(make_dataset, tmp_path, kind):
    from parcelfit.runs import load_dataset

    root = _dataset_with_outside_file(make_dataset, tmp_path)
    if kind == "symlink":
        (root / "runs" / "link.csv").symlink_to(tmp_path / "outside.csv")
        name = "runs/link.csv"
    else:
        name = "../outside.csv" if kind == "dotdot" else str(tmp_path / "outside.csv")
    _set_file(root, 1, name)
    with pytest.raises(
        ParcelfitError, match=r"runs\[1\]\.file: run file .* lies outside the dataset"
    ):
        load_dataset(root)


def test_a_symlink_inside_the_dataset_is_fine_but_two_runs_cannot_share_a_file(
    make_dataset, tmp_path
):
    from parcelfit.runs import load_dataset

    root = _dataset_with_outside_file(make_dataset, tmp_path)
    (root / "runs" / "b.csv").rename(root / "b-real.csv")
    (root / "runs" / "b.csv").symlink_to(root / "b-real.csv")
    assert len(load_dataset(root).runs()) == 2
    _set_file(root, 1, "runs/./a.csv")
    with pytest.raises(
        ParcelfitError, match=r"runs\[1\]\.file: .* is also the file of .*runs\[0\]"
    ):
        load_dataset(root)


def test_a_line_break_in_a_name_cannot_add_lines_to_a_solver_parameter_file(tmp_path):
    from pathlib import Path

    from parcelfit.runs import TestCase
    from parcelfit.sim import SimStatus, defaults_si
    from parcelfit.sim.executors import Task, simulate_task
    from parcelfit.sim.external import ExternalSimulator, load_external_solver

    solver = Path(__file__).parent / "data" / "external" / "solver.yaml"
    sim = ExternalSimulator(load_external_solver(solver), workroot=tmp_path)
    case = TestCase("E1\nmu_d_BePa = 9", "KPBW", 1)
    with pytest.raises(ParcelfitError, match=r"\$\{rig\}.*line break"):
        sim.run(defaults_si("rigid"), case)
    result = simulate_task(sim, Task(defaults_si("rigid"), case, "r"))  # as the loop runs it
    assert result.status is SimStatus.FAILED and "line break" in result.diagnostics["message"]
    assert not list(tmp_path.glob("*/params.txt"))  # nothing was written, nothing ran


@pytest.mark.parametrize(
    "brk", ["\u2028", "\u2029", "\u0085", "\r", "\x0b", "\x0c", "\x1c", "\x1e"]
)
def test_no_unicode_line_break_can_add_lines_to_a_solver_parameter_file(tmp_path, brk):
    from parcelfit.runs import TestCase
    from parcelfit.sim import defaults_si
    from parcelfit.sim.external import ExternalSimulator, load_external_solver

    assert len(f"a{brk}b".splitlines()) == 2  # a line break to str.splitlines
    solver = Path(__file__).parent / "data" / "external" / "solver.yaml"
    sim = ExternalSimulator(load_external_solver(solver), workroot=tmp_path)
    for case, params in (
        (TestCase(f"E1{brk}mu_d_BePa = 9", "KPBW", 1), defaults_si("rigid")),
        (TestCase("E1", f"KPBW{brk}E_Pa = 1", 1), defaults_si("rigid")),
        (TestCase("E1", "KPBW", 1), {**defaults_si("rigid"), f"x{brk}y": 1.0}),
    ):
        with pytest.raises(ParcelfitError, match="line break"):
            sim.run(params, case)
    assert not list(tmp_path.glob("*/params.txt"))  # nothing was written, nothing ran


@pytest.mark.parametrize(
    "char", ["\u2028", "\u2029", "\u0085", "\u200b", "\u200f", "\u202e", "\u2066", "\ufeff"]
)
def test_a_unicode_separator_or_format_character_in_a_name_is_refused(tmp_path, char):
    """U+2028 passed the control-character check and became a line of the parameter file."""
    from parcelfit.runs import TestCase
    from parcelfit.sim import defaults_si
    from parcelfit.sim.external import ExternalSimulator, load_external_solver

    solver = Path(__file__).parent / "data" / "external" / "solver.yaml"
    sim = ExternalSimulator(load_external_solver(solver), workroot=tmp_path)
    case = TestCase(f"E1{char}mu_d_BePa = 9", "KPBW", 1)
    with pytest.raises(ParcelfitError) as err:
        sim.run(defaults_si("rigid"), case)
    assert err.value.message == (
        f"the value of ${{rig}} ({f'E1{char}mu_d_BePa = 9'!r}) holds a line break or another "
        f"control or invisible format character (U+{ord(char):04X}), which would change the "
        "parameter template"
    )
    assert not list(tmp_path.glob("*/params.txt"))  # nothing was written, nothing ran


@pytest.mark.slow
def test_a_validation_killed_midway_is_run_again_on_resume(finished, tmp_path):
    study, out = _copy(finished, tmp_path)
    first = study_status(out)
    con = sqlite3.connect(out / "study.sqlite", isolation_level=None)
    (last,) = con.execute("SELECT max(id) FROM evaluations WHERE kind = 'validation'").fetchone()
    # the state a kill during that validation leaves: its row pending, no run file, no stop
    con.execute(
        "UPDATE evaluations SET status = 'pending', details = NULL, finished_at = NULL, "
        "run_file = NULL WHERE id = ?",
        (last,),
    )
    con.execute("DELETE FROM meta WHERE key = 'stop_reason'")
    con.close()
    again = Calibration(study, out, figures=False).run()
    info = study_status(out)
    assert again.evaluations == first.evaluations == _fits(out)  # no extra fitting runs
    assert info.validations == first.validations  # simulated again, same verdict
    assert info.validations[-1].status == "ok" and info.stop_reason is not None


@pytest.mark.slow
def test_a_dying_local_worker_costs_time_not_results(tmp_path):
    import random
    import signal
    import threading

    from parcelfit.runs import TestCase
    from parcelfit.sim.executors import Task, local_executor

    from .fake_sim import AnalyticSimulator, trajectory

    executor = local_executor(workers=2)
    tasks = [
        Task({"mu_d_BePa": 0.4 + 0.01 * i, "mu_d_MePa": 0.2}, TestCase("R", "P", 1), f"t{i}")
        for i in range(6)
    ]
    victims = []

    def kill_a_worker() -> None:  # SIGKILL one busy worker at a random moment of the batch
        time.sleep(random.Random(7).uniform(0.6, 1.0))
        pid = next(iter(executor._pool._processes))
        victims.append(pid)
        os.kill(pid, signal.SIGKILL)

    killer = threading.Thread(target=kill_a_worker)
    try:
        killer.start()
        results = dict(executor.simulate(AnalyticSimulator(delay=0.4), tasks))
        killer.join()
    finally:
        executor.close()
    assert victims and sorted(results) == list(range(6))
    assert all(r.ok for r in results.values())
    for i, r in results.items():  # the right result for every task
        assert r.run.transit_time == pytest.approx(trajectory(tasks[i].params, 1)[1])
    assert executor.restarts == 1
    assert any(r.diagnostics.get("worker_restarts") == 1 for r in results.values())


@pytest.mark.slow
def test_a_worker_killed_during_a_calibration_leaves_no_failed_evaluation(tmp_path, monkeypatch):
    monkeypatch.setenv("FAKE_SIM_CRASH_ONCE", str(tmp_path / "crashed"))
    study = load_study(write_study(tmp_path, budget=8, validation={}))
    result = Calibration(study, tmp_path / "out", figures=False).run()
    assert (tmp_path / "crashed").exists()  # one simulation killed its worker
    info = study_status(tmp_path / "out")
    assert result.evaluations == 8 and info.by_status == {"ok": 8}
    store = Store(tmp_path / "out" / "study.sqlite", readonly=True)
    restarted = [e for e in store.evaluations("fit") if e.details.worker_restarts]
    store.close()
    assert len(restarted) >= 1


def _gone(pids, timeout):
    """Wait until none of ``pids`` runs any more (a zombie counts as gone); the ones left."""
    import psutil

    deadline = time.time() + timeout
    alive = set(pids)
    while alive and time.time() < deadline:
        for pid in list(alive):
            try:
                if psutil.Process(pid).status() == psutil.STATUS_ZOMBIE:
                    alive.discard(pid)
            except psutil.NoSuchProcess:
                alive.discard(pid)
        time.sleep(0.1)
    return alive


@pytest.mark.slow
def test_pool_workers_die_when_the_main_process_is_killed(tmp_path):
    import signal
    import subprocess
    import sys

    import psutil

    from .helpers import ROOT

    study = write_study(tmp_path, budget=8, validation={})
    log = tmp_path / "log"
    env = {**os.environ, "FAKE_SIM_DELAY": "30", "FAKE_SIM_LOG": str(log)}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    cmd = [sys.executable, "-m", "parcelfit", "calibrate", str(study), "--workers", "2"]
    proc = subprocess.Popen(
        [*cmd, "--out", str(tmp_path / "out")],
        cwd=ROOT,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        deadline = time.time() + 60
        while time.time() < deadline and len(log.read_text().split() if log.exists() else []) < 2:
            time.sleep(0.1)
        workers = [c.pid for c in psutil.Process(proc.pid).children(recursive=True)]
        assert len(workers) >= 2  # both workers are simulating
        os.kill(proc.pid, signal.SIGKILL)  # the main process only, not its process group
        proc.wait()
        assert not _gone(workers, timeout=10)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)


@pytest.mark.slow
def test_a_timed_out_solver_is_killed_with_its_children(tmp_path):
    from parcelfit.runs import TestCase
    from parcelfit.sim import SimStatus, defaults_si
    from parcelfit.sim.external import ExternalSimulator, load_external_solver

    (tmp_path / "spawner.py").write_text(
        "import pathlib, subprocess, sys, time\n"
        "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\n"
        "pathlib.Path(sys.argv[1], 'child.pid').write_text(str(child.pid))\n"
        "time.sleep(60)\n"
    )
    (tmp_path / "p.tmpl").write_text("mu = ${mu_d_BePa}\n")
    (tmp_path / "solver.yaml").write_text(
        yaml.safe_dump(
            {
                "name": "spawner",
                "command": ["python3", "${solver_dir}/spawner.py", "${workdir}"],
                "template": "p.tmpl",
                "timeout": 2,
            }
        )
    )
    sim = ExternalSimulator(load_external_solver(tmp_path / "solver.yaml"), tmp_path / "w")
    result = sim.run(defaults_si("rigid"), TestCase("E1", "KPBW", 1))
    assert result.status is SimStatus.TIMEOUT
    child = int((Path(result.diagnostics["workdir"]) / "child.pid").read_text())
    assert not _gone([child], timeout=5)


# A solver whose child escapes into its own session (setsid) or is double-forked away, keeping
# the solver's stdout and stderr open and sleeping for ever; in mode "fail" the solver exits 1
# at once after starting it, else it sleeps for ever itself.
ESCAPER = """
import os, subprocess, sys, time
workdir, mode, how = sys.argv[1], sys.argv[2], sys.argv[3]
forever = [sys.executable, "-c", "import time; time.sleep(1e9)"]
if how == "setsid":
    pids = [subprocess.Popen(forever, start_new_session=True).pid]
else:  # a daemon: the middle process exits at once, its child is orphaned
    r, w = os.pipe()
    if os.fork() == 0:
        os.setsid()
        pid = os.fork()
        if pid == 0:
            os.execv(sys.executable, forever)
        os.write(w, str(pid).encode())
        os._exit(0)
    pids = [int(os.read(r, 32))]
with open(os.path.join(workdir, "pids"), "w") as fh:
    fh.write(" ".join(map(str, [os.getpid(), *pids])))
if mode == "fail":
    print("solver: licence server not reachable", file=sys.stderr, flush=True)
    sys.exit(1)
time.sleep(1e9)
"""


def _escaper(tmp_path, mode, how, timeout):
    import sys

    from parcelfit.sim.external import ExternalSimulator, load_external_solver

    (tmp_path / "escaper.py").write_text(ESCAPER)
    (tmp_path / "p.tmpl").write_text("mu = ${mu_d_BePa}\n")
    (tmp_path / "solver.yaml").write_text(
        yaml.safe_dump(
            {
                "name": "escaper",
                "command": [sys.executable, "${solver_dir}/escaper.py", "${workdir}", mode, how],
                "template": "p.tmpl",
                "timeout": timeout,
            }
        )
    )
    return ExternalSimulator(load_external_solver(tmp_path / "solver.yaml"), tmp_path / "w")


def _running(pid):
    """Whether ``pid`` is a live process (not a zombie), read from /proc."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in "ZX"


LINUX_ONLY = pytest.mark.skipif(
    not os.path.isdir("/proc/self"), reason="escaped descendants are found through Linux's /proc"
)


@LINUX_ONLY
@pytest.mark.parametrize("how", ["setsid", "double-fork"])
def test_a_solver_whose_child_escapes_its_session_times_out_on_time_leaving_nothing(tmp_path, how):
    from parcelfit.runs import TestCase
    from parcelfit.sim import SimStatus, defaults_si

    sim = _escaper(tmp_path, "hang", how, timeout=2)
    t0 = time.perf_counter()
    result = sim.run(defaults_si("rigid"), TestCase("E1", "KPBW", 1))
    elapsed = time.perf_counter() - t0
    pids = [int(p) for p in (Path(result.diagnostics["workdir"]) / "pids").read_text().split()]
    assert result.status is SimStatus.TIMEOUT
    assert result.diagnostics["message"] == "killed after the timeout of 2 s"
    assert 2.0 <= elapsed < 3.0  # was 61 s with a child sleeping 60 s, for ever with this one
    assert [p for p in pids if _running(p)] == []  # the solver and its escaped child: gone


@LINUX_ONLY
def test_a_solver_and_its_escaped_child_die_when_the_process_running_it_is_killed(tmp_path):
    import signal
    import subprocess
    import sys

    import parcelfit

    (tmp_path / "escaper.py").write_text(ESCAPER)
    code = (
        "import sys; from parcelfit.sim.lifetime import run_command; "
        "run_command([sys.executable, sys.argv[1], sys.argv[2], 'hang', 'setsid'], sys.argv[2], 600)"
    )
    env = {**os.environ, "PYTHONPATH": str(Path(parcelfit.__file__).parents[1])}
    runner_proc = subprocess.Popen(
        [sys.executable, "-c", code, str(tmp_path / "escaper.py"), str(tmp_path)], env=env
    )
    pids_file = tmp_path / "pids"
    deadline = time.time() + 30
    while time.time() < deadline and not pids_file.is_file():
        time.sleep(0.05)
    time.sleep(0.2)  # the file is written; the solver sleeps
    pids = [int(p) for p in pids_file.read_text().split()]
    try:
        assert all(_running(p) for p in pids)
        runner_proc.kill()  # SIGKILL, as the out-of-memory killer does: no cleanup of its own
        runner_proc.wait()
        deadline = time.time() + 2
        while time.time() < deadline and any(_running(p) for p in pids):
            time.sleep(0.05)
        assert [p for p in pids if _running(p)] == []
    finally:
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


@LINUX_ONLY
def test_a_solver_that_fails_at_once_is_failed_at_once_with_its_message(tmp_path):
    from parcelfit.runs import TestCase
    from parcelfit.sim import SimStatus, defaults_si

    sim = _escaper(tmp_path, "fail", "setsid", timeout=30)
    t0 = time.perf_counter()
    result = sim.run(defaults_si("rigid"), TestCase("E1", "KPBW", 1))
    elapsed = time.perf_counter() - t0
    pids = [int(p) for p in (Path(result.diagnostics["workdir"]) / "pids").read_text().split()]
    assert result.status is SimStatus.FAILED  # not a timeout after 30 s
    assert elapsed < 1.0
    assert result.diagnostics["message"] == (
        "the solver exited with status 1: solver: licence server not reachable "
        f"(its output: parcelfit-solver.stderr in {result.diagnostics['workdir']})"
    )
    assert result.diagnostics["output_tail"] == "solver: licence server not reachable"
    assert [p for p in pids if _running(p)] == []


@pytest.mark.parametrize(
    ("module", "extra", "study", "args", "what"),
    [
        (
            "distributed",
            "dask",
            {"executor": {"kind": "serial"}},
            ["--executor", "dask", "--scheduler", "tcp://127.0.0.1:9"],
            "the dask executor",
        ),
        (
            "optuna",
            "optuna",
            {"optimizer": {"sampler": "tpe"}, "executor": {"kind": "serial"}},
            [],
            "the tpe optimizer",
        ),
    ],
)
def test_a_missing_optional_dependency_names_the_extra_to_install(
    tmp_path, monkeypatch, module, extra, study, args, what
):
    import sys

    study_file = write_study(tmp_path, initial=4, batch_size=2, budget=8, **study)
    monkeypatch.setitem(sys.modules, module, None)  # as if not installed: import fails
    result = runner.invoke(app, ["calibrate", str(study_file), "--out", str(tmp_path / "o"), *args])
    assert result.exit_code == 2 and isinstance(result.exception, SystemExit), result.output
    error = " ".join(result.output[result.output.index("error:") :].split())
    assert error.startswith(f"error: {what} needs the '{extra}' extra ({module} cannot be")
    assert error.endswith(
        f'Fix: pip install "parcelfit[{extra}]" (in a clone of the repository: '
        f'pip install -e ".[{extra}]")'
    )


def test_an_unreachable_scheduler_or_one_without_workers_is_a_clear_error():
    distributed = pytest.importorskip("distributed")
    from parcelfit.sim.executors import dask_executor

    with pytest.raises(ParcelfitError, match="cannot reach the Dask scheduler"):
        dask_executor("tcp://127.0.0.1:9", connect_timeout=1)
    with (
        distributed.LocalCluster(n_workers=0, dashboard_address=None, processes=False) as cluster,
        pytest.raises(ParcelfitError, match="no Dask worker is attached"),
    ):
        dask_executor(cluster.scheduler_address, worker_wait=1)


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_losing_the_dask_scheduler_stops_cleanly_and_the_study_resumes(tmp_path, no_study_figures):
    pytest.importorskip("distributed")
    import random
    import signal
    import subprocess
    import sys

    from .helpers import ROOT, finished_fits

    study = write_study(
        tmp_path,
        parameters={"mu_d_BePa": [0.3, 0.58], "mu_d_MePa": [0.15, 0.35]},
        budget=16,
        validation={},
    )
    out = tmp_path / "out"
    env = {**os.environ, "FAKE_SIM_DELAY": "0.3"}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    address = f"tcp://127.0.0.1:{_free_port()}"
    dask = [sys.executable, "-m", "distributed.cli"]
    spawned = []

    def start(args):
        p = subprocess.Popen(
            args,
            env=env,
            cwd=ROOT,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        spawned.append(p)
        return p

    calibrate = [sys.executable, "-m", "parcelfit", "calibrate", str(study), "--out", str(out)]
    try:
        scheduler = start(
            [
                *dask[:2],
                "distributed.cli.dask_scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                address.rsplit(":", 1)[1],
                "--no-dashboard",
            ]
        )
        start(
            [
                *dask[:2],
                "distributed.cli.dask_worker",
                address,
                "--nworkers",  # one worker process (and its nanny) running two tasks at a time
                "1",
                "--nthreads",
                "2",
                "--no-dashboard",
            ]
        )
        proc = subprocess.Popen(
            [*calibrate, "--executor", "dask", "--scheduler", address],
            cwd=ROOT,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        spawned.append(proc)
        deadline = time.time() + 120
        while len(finished_fits(out / "study.sqlite")) < 3 and time.time() < deadline:
            assert proc.poll() is None, proc.stderr.read()
            time.sleep(0.05)
        time.sleep(random.Random(11).uniform(0.0, 0.4))
        os.killpg(scheduler.pid, signal.SIGKILL)  # the scheduler is lost mid-batch
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 2, err
        # one line: no traceback of parcelfit, and distributed's own reconnection attempts and
        # tracebacks are silenced
        (line,) = [line for line in err.splitlines() if line.strip()]
        assert line.startswith(f"error: lost the Dask scheduler at {address}"), err
    finally:
        for p in spawned:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGKILL)
    info = study_status(out)
    assert set(info.by_status) <= {"ok", "pending"}  # nothing stored as failed
    before = finished_fits(out / "study.sqlite")
    done = runner.invoke(app, [*calibrate[3:], "--executor", "local", "--workers", "2"])
    assert done.exit_code == 0, done.output
    after = finished_fits(out / "study.sqlite")
    assert len(after) == 16 and all(after[k] == v for k, v in before.items())


# -- bad input: one clear line and exit status 2 ------------------------------------------------


def _dataset(tmp_path, edit=None, scale_t=1.0, edit_run=None):
    from .fake_sim import write_reference_dataset

    write_reference_dataset(tmp_path / "data", n_runs=3)
    if edit_run is not None:  # the first run file
        edit_run(tmp_path / "data" / "runs" / "R-P-1-0.csv")
    if scale_t != 1.0:  # times written in milliseconds
        for f in (tmp_path / "data" / "runs").glob("*.csv"):
            text = f.read_text().splitlines()
            rows = [text[0]] + [
                ",".join([repr(float(r.split(",")[0]) * scale_t), *r.split(",")[1:]])
                for r in text[1:]
            ]
            f.write_text("\n".join(rows) + "\n")
    if edit is not None:
        path = tmp_path / "data" / "dataset.yaml"
        doc = yaml.safe_load(path.read_text())
        edit(doc)
        path.write_text(yaml.safe_dump(doc))
    return ["reference", str(tmp_path / "data")]


def _study(tmp_path, **change):
    return ["calibrate", str(write_study(tmp_path, **change)), "--out", str(tmp_path / "o")]


def _study_sim(tmp_path, **sim):
    simulator = {"backend": "python", "factory": "tests.fake_sim:make", **sim}
    return _study(tmp_path, simulator=simulator)


def _screen(tmp_path, **change):
    from .fake_sim import write_reference_dataset

    write_reference_dataset(tmp_path / "data", n_runs=3)
    doc = {
        "name": "s",
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make"},
        "reference": {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
        "parameters": {"mu_d_BePa": [0.3, 0.58], "mu_d_MePa": [0.15, 0.35]},
        "stages": ["full"],
        **change,
    }
    (tmp_path / "screen.yaml").write_text(yaml.safe_dump(doc))
    return ["screen", str(tmp_path / "screen.yaml"), "--out", str(tmp_path / "o")]


def _twin_spec(tmp_path, **doc):
    path = tmp_path / "twin.yaml"
    path.write_text(yaml.safe_dump({"cases": ["E1/BW/1"], **doc}))
    return ["synth", str(path), "--out", str(tmp_path / "o")]


def _not_utf8(tmp_path):
    (tmp_path / "ds").mkdir()
    (tmp_path / "ds" / "dataset.yaml").write_bytes("name: caf\u00e9\n".encode("latin-1"))
    return ["reference", str(tmp_path / "ds")]


def _out_is_a_file(tmp_path):
    args = _study(tmp_path, budget=8)
    (tmp_path / "o").write_text("not a folder")
    return args


def _report_out_is_a_folder(tmp_path):
    Store(tmp_path / "study" / "study.sqlite").close()
    (tmp_path / "folder").mkdir()
    return ["report", str(tmp_path / "study"), "--out", str(tmp_path / "folder")]


def _study_with_text(tmp_path, text, drop=()):
    """A study file whose keys ``drop`` are replaced by the YAML ``text`` as written."""
    path = write_study(tmp_path)
    doc = {k: v for k, v in yaml.safe_load(path.read_text()).items() if k not in drop}
    path.write_text(yaml.safe_dump(doc) + text)
    return ["calibrate", str(path), "--out", str(tmp_path / "o")]


def _alias_bomb(tmp_path):
    lines = ["parameters:", "  a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    for prev, name in zip("abcdefgh", "bcdefghi", strict=True):
        lines.append(f"  {name}: &{name} [{', '.join([f'*{prev}'] * 9)}]")
    return _study_with_text(tmp_path, "\n".join(lines) + "\n", drop=("parameters",))


def _log_false(tmp_path):
    bounds = {"mu_d_BePa": {"low": 0.3, "high": 0.6, "log": "false"}, "mu_d_MePa": [0.15, 0.35]}
    return _study(tmp_path, parameters=bounds)


BAD_INPUTS = {
    "times in milliseconds": (
        lambda p: _dataset(p, scale_t=1000.0),
        r"R-P-1-0\.csv: column 't': samples are 16\.67 s apart .* divide by 1000",
    ),
    "transit_time 1e300": (
        lambda p: _dataset(p, lambda d: d["test_cases"][0]["runs"][0].update(transit_time=1e300)),
        r"runs\[0\]\.transit_time: transit_time must be positive and at most 600 s",
    ),
    "dataset.yaml not UTF-8": (
        _not_utf8,
        r"dataset\.yaml: not UTF-8 text .*save the file as UTF-8",
    ),
    "seed -1": (lambda p: _study(p, seed=-1), r"seed: -1 is out of range"),
    "seed 1e30": (lambda p: _study(p, seed=1e30), r"seed: .* is out of range"),
    "workers -1": (
        lambda p: _study(p, executor={"kind": "local", "workers": -1}),
        r"executor\.workers: -1 is out of range",
    ),
    "workers two": (
        lambda p: _study(p, executor={"kind": "local", "workers": "two"}),
        r"executor\.workers: expected a whole number, got 'two'",
    ),
    "timestep fast": (
        lambda p: _study_sim(p, timestep="fast"),
        r"simulator\.timestep: expected a number in s, got 'fast'",
    ),
    "belt friction sticky": (
        lambda p: _study_sim(p, belt_friction="sticky"),
        r"simulator\.belt_friction: unknown belt friction law 'sticky'.*mujoco, coulomb",
    ),
    "roller surface spinning": (
        lambda p: _study_sim(p, roller_surface="spinning"),
        r"simulator\.roller_surface: unknown roller surface motion 'spinning'.*linear, turning",
    ),
    "shell diagonals crossed": (
        lambda p: _study_sim(p, shell_diagonals="crossed"),
        r"simulator\.shell_diagonals: unknown split of the shell's cells 'crossed'.*radiating",
    ),
    "mass lumping by volume": (
        lambda p: _study_sim(p, mass_lumping="volume"),
        r"simulator\.mass_lumping: unknown spread of the packaging's mass 'volume'.*area, equal",
    ),
    "shell dof floppy": (
        lambda p: _study_sim(p, shell_dof="floppy"),
        r"simulator\.shell_dof: unknown shell degrees of freedom 'floppy'.*auto, full",
    ),
    "shell cells two": (
        lambda p: _study_sim(p, shell_cells=[4, 4]),
        r"simulator\.shell_cells: shell cells must be three whole numbers from 1 to 12",
    ),
    "shell cells zero": (
        lambda p: _study_sim(p, shell_cells=[0, 4, 1]),
        r"simulator\.shell_cells\[0\]: 0 is outside \[1, 12\]",
    ),
    "slip speed below the stick speed": (
        lambda p: _study_sim(p, stick_speed=0.1, slip_speed=0.05),
        r"simulator\.slip_speed: slip_speed \(0\.05 m/s\) must exceed stick_speed \(0\.1 m/s\)",
    ),
    "rig time step of a second": (
        lambda p: _study_sim(p, rig_timesteps={"E1": 1}),
        r"simulator\.rig_timesteps\.E1: 1 is outside \[1e-05, 0\.01\] s",
    ),
    "screen string bounds": (
        lambda p: _screen(p, parameters={"mu_d_BePa": ["a", "b"], "mu_d_MePa": [0.15, 0.35]}),
        r"parameters\.mu_d_BePa: expected \[low, high\] with low < high, got \['a', 'b'\]",
    ),
    "screen fixed big": (
        lambda p: _screen(p, fixed={"E_Pa": "big"}),
        r"fixed\.E_Pa: expected a number, got 'big'",
    ),
    "screen stages 5": (lambda p: _screen(p, stages=5), r"stages: unknown stages \[5\]"),
    "output folder is a file": (_out_is_a_file, r"/o: the output folder is a file"),
    "report --out a folder": (_report_out_is_a_folder, r"/folder: the report's path is a folder"),
    "log 'false'": (_log_false, r"parameters\.mu_d_BePa\.log: expected true or false"),
    "budget 2.9": (lambda p: _study(p, budget=2.9), r"budget: expected a whole number, got 2\.9"),
    "batch size 2.7": (
        lambda p: _study(p, batch_size=2.7),
        r"batch_size: expected a whole number, got 2\.7",
    ),
    "speed setting 1.9": (
        lambda p: _study(
            p, reference={"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1.9}
        ),
        r"reference\.speed_setting: expected a whole number, got 1\.9",
    ),
    "weights 0/0": (
        lambda p: _study(p, weights={"xy": 0, "theta": 0}),
        r"weights: both weights are zero",
    ),
    "screen executor slurm": (
        lambda p: _screen(p, executor={"kind": "slurm"}),
        r"executor\.kind: unknown executor 'slurm'.*use one of serial, local",
    ),
    "screen without a name": (
        lambda p: _screen(p, name=["x"]),
        r"name: expected a non-empty text",
    ),
    "alias bomb": (
        _alias_bomb,
        r"study\.yaml: line \d+, column \d+: aliases \(\*name\) expand the document to more "
        r"than 100000 values Fix: write the values out",
    ),
    "key written twice": (
        lambda p: _study_with_text(p, "budget: 12\n"),
        r"study\.yaml: line 30, column 1: the key 'budget' is written twice \(lines 2 and 30\)",
    ),
    "initial 1e9": (
        lambda p: _study(p, initial=1e9),
        r"study\.yaml: initial: 1000000000 is out of range Fix: use a whole number in \[1, 10000\]",
    ),
    "budget below initial": (
        lambda p: _study(p, initial=8, budget=4),
        r"study\.yaml: budget: budget 4 is below initial 8: .* Fix: raise budget to 8 or more",
    ),
    "calibrate --workers 100000": (
        lambda p: [*_study(p), "--workers", "100000"],
        r"^error: --workers 100000 is more than 256 Fix: use --workers 256 or less$",
    ),
    "simulate --repeat 1000000": (
        lambda p: ["simulate", "--repeat", "1000000", "--out", str(p / "o" / "r.csv")],
        r"^error: --repeat 1000000 is more than 1000 Fix: use --repeat 1000 or less$",
    ),
    "precision --placements 5000": (
        lambda p: ["precision", _study(p)[1], "--placements", "5000", "--out", str(p / "o")],
        r"5000 placements per case and parameter end, more than 1000",
    ),
    "precision --candidate with a superscript setting": (
        lambda p: ["precision", _study(p)[1], "--candidate", "R/P/\u00b2", "--out", str(p / "o")],
        r"cannot read test case 'R/P/\u00b2'",
    ),
    "dataset speed setting 1e30": (
        lambda p: _dataset(p, lambda d: d["test_cases"][0].update(speed_setting=10**30)),
        r"test_cases\[0\]\.speed_setting: speed_setting must be an integer from 1 to 1000, got "
        r"1000000000000000000000000000000 Fix",
    ),
    "mujoco study with negative friction": (
        lambda p: _study(
            p,
            simulator={"backend": "mujoco", "rig": "E3", "consignment": "KPBW"},
            parameters={"mu_d_BePa": [-0.5, -0.1]},
            reference={"dataset": "data", "speed_setting": 1},
        ),
        r"study\.yaml: parameters\.mu_d_BePa: mu_d_BePa = -0\.5 is outside its physical range "
        r"\[0, 2\] Fix",
    ),
    "simulate --set a negative friction": (
        lambda p: ["simulate", "--set", "mu_d_BePa=-1", "--out", str(p / "o" / "r.csv")],
        r"^error: --set: mu_d_BePa = -1 is outside its physical range \[0, 2\] Fix: give "
        r"dynamic friction belt/packaging from 0 to 2 \(dimensionless\)$",
    ),
    "simulate --set nan": (
        lambda p: ["simulate", "--set", "mu_d_BePa=nan", "--out", str(p / "o" / "r.csv")],
        r"^error: --set: 'mu_d_BePa=nan' is not a finite number",
    ),
    "precision --at outside the physical range": (
        lambda p: ["precision", _study(p)[1], "--at", "mu_d_BePa=3", "--out", str(p / "o")],
        r"^error: --at mu_d_BePa: mu_d_BePa = 3 is outside its physical range \[0, 2\]",
    ),
    "validation setting the dataset lacks": (
        lambda p: _study(p, validation={"speed_setting": 7}),
        r"study\.yaml: validation\.speed_setting: the dataset has no runs of test case R/P/7 "
        r"\(dataset .*data\) Fix: name a test case the dataset holds",
    ),
    "transfer case the dataset lacks": (
        lambda p: _study(p, transfer=[{"rig": "Q", "consignment": "P", "speed_setting": 1}]),
        r"study\.yaml: transfer\[0\]: the dataset has no runs of test case Q/P/1",
    ),
    "twin spec with an unknown rig": (
        lambda p: _twin_spec(p, cases=["E9/BW/1"]),
        r"twin\.yaml: cases\[0\]: unknown rig 'E9' Fix: use one of E1, E2a, E2b, E3",
    ),
    "empty run file": (
        lambda p: _dataset(p, edit_run=lambda f: f.write_bytes(b"")),
        r"R-P-1-0\.csv: the file is empty \(0 bytes\) Fix: write the run's samples into it",
    ),
    "run file not UTF-8": (
        lambda p: _dataset(
            p, edit_run=lambda f: f.write_bytes(f.read_bytes() + b"0,caf\xe9,0,0\n")
        ),
        r"R-P-1-0\.csv: not UTF-8 text \(byte \d+: b'\\xe9'\) Fix: save the file as UTF-8",
    ),
    "python factory that cannot be imported": (
        lambda p: _study_sim(p, factory="nowhere.sim:make"),
        r"study\.yaml: simulator: cannot import the simulator factory 'nowhere\.sim:make'",
    ),
    "screen unknown soft_content": (
        lambda p: _screen(p, soft_content=["E_Cox"]),
        r"soft_content\[0\]: unknown parameter 'E_Cox'.*did you mean 'E_Co'",
    ),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_stops_with_one_clear_line_and_status_2(tmp_path, case):
    make, pattern = BAD_INPUTS[case]
    args = make(tmp_path)
    t0 = time.perf_counter()
    result = runner.invoke(app, args)
    assert result.exit_code == 2, (result.output, result.exception)
    assert time.perf_counter() - t0 < 30  # stops at once, never after simulating
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    assert re.search(pattern, lines[0]), lines[0]
    assert not (tmp_path / "o").is_dir() or not any((tmp_path / "o").rglob("*.csv"))
    assert not list(tmp_path.rglob("*.tmp"))  # nothing half-written left behind


@pytest.mark.slow
def test_evaluations_once_stored_failed_by_a_lost_worker_run_again(finished, tmp_path):
    study, out = _copy(finished, tmp_path)
    n = _fits(out)
    con = sqlite3.connect(out / "study.sqlite", isolation_level=None)
    lost = '{"message": "worker failed: BrokenProcessPool(\'A child process terminated\')"}'
    con.execute(
        "UPDATE evaluations SET status = 'failed', cost = NULL, details = ? "
        "WHERE kind = 'fit' AND slot IN (1, 2) AND iteration = 0",
        (lost,),
    )
    con.close()
    assert study_status(out).by_status == {"failed": 2, "ok": n - 2}
    Calibration(study, out, figures=False).run()
    assert study_status(out).by_status == {"ok": n}


@pytest.mark.slow
def test_calibrate_on_a_read_only_folder_says_so_and_keeps_the_results(
    finished, tmp_path, monkeypatch
):
    _, out = _copy(finished, tmp_path)
    before = (out / "study.sqlite").read_bytes()
    writable = os.access
    monkeypatch.setattr(
        os, "access", lambda p, mode: False if mode == os.W_OK else writable(p, mode)
    )
    result = runner.invoke(
        app, ["calibrate", str(tmp_path / "s" / "study.yaml"), "--out", str(out)]
    )
    assert result.exit_code == 2
    assert "read-only" in result.output and "results already in it are intact" in result.output
    assert "move" not in result.output and (out / "study.sqlite").read_bytes() == before


# -- runtime failures: nothing hangs, nothing is lost, one clear line (issue 51) --------------


def _error_lines(result) -> list[str]:
    """The non-empty lines a command printed on stderr."""
    return [line for line in result.stderr.splitlines() if line.strip()]


@pytest.mark.slow
def test_a_study_whose_every_simulation_fails_stops_after_8_and_quotes_the_first(
    tmp_path, monkeypatch, no_study_figures
):
    study = write_study(
        tmp_path,
        simulator={"backend": "python", "factory": "tests.fake_sim:make_broken"},
        executor={"kind": "serial"},
        initial=8,
        batch_size=4,
        budget=12,
        validation={},
    )
    out = tmp_path / "o"
    result = runner.invoke(app, ["calibrate", str(study), "--out", str(out)])
    assert result.exit_code == 2, result.output
    assert _error_lines(result) == [
        f"error: {out}: 8 simulations in a row failed, so the run stopped early; the first: "
        "failed: RuntimeError: solver licence expired ask the licence server's admin Fix: fix "
        "the cause the first failure names, then rerun the same command to resume (what "
        "failed is run again while nothing has succeeded yet)"
    ]
    info = study_status(out)
    assert info.by_status == {"failed": 8} and info.stop_reason is None
    assert not (out / "results.json").exists()
    # the set-up fixed, the same command runs the 8 failed simulations again and goes on
    monkeypatch.setenv("FAKE_SIM_FIXED", "1")
    result = runner.invoke(app, ["calibrate", str(study), "--out", str(out)])
    assert result.exit_code == 0, result.output
    info = study_status(out)
    assert info.evaluations == 12 and "failed" not in info.by_status
    assert info.stop_reason == "budget spent"


def test_a_small_study_whose_every_simulation_fails_stops_at_its_budget(tmp_path):
    study = write_study(
        tmp_path,
        simulator={"backend": "python", "factory": "tests.fake_sim:make_broken"},
        executor={"kind": "serial"},
        initial=4,
        batch_size=2,
        budget=5,
        validation={},
    )
    with pytest.raises(ParcelfitError, match=r"^\S+: 5 simulations in a row failed"):
        Calibration(load_study(study), tmp_path / "o").run()
    assert study_status(tmp_path / "o").by_status == {"failed": 5}


def test_a_screen_whose_every_simulation_fails_stops_after_8_and_resumes_once_fixed(
    tmp_path, monkeypatch
):
    args = _screen(
        tmp_path,
        simulator={"backend": "python", "factory": "tests.fake_sim:make_broken"},
        parameters={
            "mu_d_BePa": [0.3, 0.58],
            "mu_d_MePa": [0.15, 0.35],
            "E_Pa": [400, 1600],
            "mu_d_PaPa": [0.2, 0.6],
        },
        executor="serial",
    )
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    (line,) = _error_lines(result)
    assert line.startswith(
        f"error: {tmp_path / 'o'}: 8 simulations in a row failed, so the run stopped early; the "
        "first: failed: RuntimeError: solver licence expired"
    )
    store = Store(tmp_path / "o" / "screen.sqlite", readonly=True)
    statuses = [e.status for e in store.evaluations("screen")]
    store.close()
    assert len(statuses) == 16 and statuses.count("failed") == 8  # a 2^4 design, 8 tried
    monkeypatch.setenv("FAKE_SIM_FIXED", "1")
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    store = Store(tmp_path / "o" / "screen.sqlite", readonly=True)
    assert {e.status for e in store.evaluations("screen")} == {"ok"}
    store.close()


def _long(tmp_path, kind: str) -> Path:
    """A path the file system refuses: one 300-character name, or 20 names of 250 characters
    (5000 characters in all, beyond PATH_MAX)."""
    return tmp_path / ("a" * 300 if kind == "name" else "/".join(["b" * 250] * 20))


LONG_PATHS = {
    "calibrate --out": lambda p, long: [*_study(p, budget=8)[:2], "--out", str(long)],
    "reference": lambda p, long: ["reference", str(long)],
    "stats --out": lambda p, long: ["stats", _dataset(p)[1], "--out", str(long)],
    "screen --out": lambda p, long: [*_screen(p)[:2], "--out", str(long)],
    "simulate --out": lambda p, long: ["simulate", "--out", str(long / "run.csv")],
}


@pytest.mark.parametrize("kind", ["name", "total"])
@pytest.mark.parametrize("command", list(LONG_PATHS))
def test_a_path_too_long_for_the_system_is_one_clear_line(tmp_path, command, kind):
    long = _long(tmp_path, kind)
    t0 = time.perf_counter()
    result = runner.invoke(app, LONG_PATHS[command](tmp_path, long))
    assert result.exit_code == 2, (result.output, result.exception)
    assert time.perf_counter() - t0 < 5  # refused before simulating (simulate: 11 s before)
    (line,) = _error_lines(result)
    head, _, rest = line.partition(": the path is too long for the file system: ")
    name = "a" * 300 if kind == "name" else "b" * 250
    assert head.startswith(f"error: {str(tmp_path)[:20]}") and "..." in head, line
    assert len(head) <= len("error: ") + 80  # the path shortened to fit one line
    assert re.fullmatch(
        rf"\d+ characters with a name of {len(name)}, where names may have at most \d+ and "
        r"paths \d+ Fix: choose a shorter path: a folder nearer the root, or shorter names",
        rest,
    ), line


def test_a_calibration_into_a_path_too_long_raises_a_parcelfit_error(tmp_path):
    study = load_study(write_study(tmp_path, budget=8))
    with pytest.raises(ParcelfitError, match="the path is too long for the file system"):
        Calibration(study, _long(tmp_path, "name")).run()


class _FillingDisk:
    """An SQLite connection whose disk fills up: the write of the result after ``room`` stored
    ones fails as SQLite fails it, at the UPDATE (``where`` "update") or at its COMMIT."""

    def __init__(self, db, room: int, where: str) -> None:
        self._db, self.room, self.where = db, room, where
        self.results = 0  # UPDATEs of a result seen
        self.failing = False

    def execute(self, sql, *args):
        if sql.startswith("UPDATE evaluations SET status = ?"):
            self.results += 1
            self.failing = self.results > self.room
            if self.failing and self.where == "update":
                raise sqlite3.OperationalError("database or disk is full")
        if sql == "COMMIT" and self.failing:
            raise sqlite3.OperationalError("database or disk is full")
        return self._db.execute(sql, *args)

    def __getattr__(self, name):
        return getattr(self._db, name)


@pytest.mark.slow
@pytest.mark.parametrize("where", ["update", "commit"])
def test_a_full_disk_while_storing_a_result_is_one_line_and_loses_nothing(
    tmp_path, monkeypatch, where, no_study_figures
):
    study = write_study(tmp_path, executor={"kind": "serial"}, budget=12, validation={})
    out = tmp_path / "o"
    opened = Store.__init__

    def filling(self, path, **kw):
        opened(self, path, **kw)
        if not self.readonly:
            self._db = _FillingDisk(self._db, 5, where)

    monkeypatch.setattr(Store, "__init__", filling)
    result = runner.invoke(app, ["calibrate", str(study), "--out", str(out)])
    assert result.exit_code == 2, (result.output, result.exception)
    assert _error_lines(result) == [
        f"error: {short_path(out / 'study.sqlite')}: disk full while writing study.sqlite; "
        "nothing stored "
        "is lost Fix: free space on its disk, then rerun the same command: it resumes"
    ]
    monkeypatch.setattr(Store, "__init__", opened)
    info = study_status(out)
    assert info.by_status == {"ok": 5, "pending": 3}  # the sixth result rolled back
    kept = finished_fits(out / "study.sqlite")
    result = runner.invoke(app, ["calibrate", str(study), "--out", str(out)])  # space freed
    assert result.exit_code == 0, result.output
    after = finished_fits(out / "study.sqlite")
    assert len(after) == 12 and all(after[k] == v for k, v in kept.items())


@pytest.mark.slow
def test_a_full_disk_while_writing_a_run_file_is_one_line_and_loses_nothing(
    tmp_path, monkeypatch, no_study_figures
):
    import errno

    import pandas as pd

    study = write_study(tmp_path, executor={"kind": "serial"}, budget=12, validation={})
    out = tmp_path / "o"
    to_csv, written = pd.DataFrame.to_csv, []

    def filling(self, path, *args, **kw):
        if len(written) == 5:
            Path(path).write_text("half")  # what a full disk leaves: part of a file
            raise OSError(errno.ENOSPC, "No space left on device")
        written.append(path)
        return to_csv(self, path, *args, **kw)

    monkeypatch.setattr(pd.DataFrame, "to_csv", filling)
    result = runner.invoke(app, ["calibrate", str(study), "--out", str(out)])
    assert result.exit_code == 2, (result.output, result.exception)
    assert _error_lines(result) == [
        f"error: {short_path(out / 'runs' / 'fit-000-05.csv')}: disk full while writing "
        "fit-000-05.csv; "
        "nothing stored is lost Fix: free space on its disk, then rerun the same command: it "
        "resumes"
    ]
    assert sorted(p.name for p in (out / "runs").iterdir()) == [
        f"fit-000-0{k}.csv" for k in range(5)
    ]  # no half-written file
    monkeypatch.setattr(pd.DataFrame, "to_csv", to_csv)
    assert study_status(out).by_status == {"ok": 5, "pending": 3}
    result = runner.invoke(app, ["calibrate", str(study), "--out", str(out)])
    assert result.exit_code == 0, result.output
    info = study_status(out)
    assert info.evaluations == 12 and not {"pending", "failed"} & set(info.by_status)
    assert all((out / "runs" / f"fit-000-0{k}.csv").stat().st_size > 100 for k in range(8))


def _snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path: bytes), but the folder's lock."""
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != ".parcelfit.lock"
    }


@pytest.mark.slow
def test_a_study_folder_without_its_store_is_refused_until_restart(tmp_path, request):
    study = write_study(tmp_path, executor={"kind": "serial"}, budget=8, validation={})
    out = tmp_path / "o"
    args = ["calibrate", str(study), "--out", str(out)]
    assert runner.invoke(app, args).exit_code == 0
    first = _snapshot(out)
    assert "results.json" in first and any(n.startswith("runs/") for n in first)
    assert any(n.startswith("figures/") for n in first)
    request.getfixturevalue("no_study_figures")  # the studies run from here on draw none
    (out / "study.sqlite").unlink()  # deleted by hand, the outputs left
    del first["study.sqlite"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert _error_lines(result) == [
        f"error: {out}: this folder holds an earlier study's outputs (runs/, results.json, "
        "figures/) but no study.sqlite, so a new study would overwrite them Fix: restore "
        "study.sqlite to resume that study, use a new output folder, or rerun with --restart "
        "to move them into earlier-TIME/ in the folder and start afresh"
    ]
    assert _snapshot(out) == first  # nothing written, nothing overwritten
    result = runner.invoke(app, [*args, "--restart"])
    assert result.exit_code == 0, result.output
    (earlier,) = out.glob("earlier-*")
    assert re.fullmatch(r"earlier-\d{8}-\d{6}", earlier.name)
    said = "".join(result.output.split())  # unwrapped
    assert "".join(f"the earlier study's outputs are in {earlier}".split()) in said
    assert _snapshot(earlier) == first  # moved as they were
    assert study_status(out).evaluations == 8  # a new study, run in full
    # --restart on a folder with its store sets the store aside as well
    again = runner.invoke(app, [*args, "--restart"])
    assert again.exit_code == 0, again.output
    assert len(list(out.glob("earlier-*/study.sqlite"))) == 1
    assert study_status(out).evaluations == 8


@pytest.mark.slow
def test_a_killed_precision_check_keeps_every_finished_simulation(tmp_path):
    import signal
    import subprocess
    import sys

    from parcelfit.study.precision_check import run_precision_check

    from .helpers import ROOT
    from .test_precision import _two_rig_study

    study = _two_rig_study(tmp_path)
    out = tmp_path / "check"
    log = tmp_path / "log"
    env = {**os.environ, "FAKE_SIM_DELAY": "0.3", "FAKE_SIM_LOG": str(log)}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    cmd = [sys.executable, "-m", "parcelfit", "precision", str(study), "--placements", "2"]
    proc = subprocess.Popen(
        [*cmd, "--executor", "serial", "--out", str(out)],
        cwd=ROOT,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.time() + 60
        while time.time() < deadline and len(log.read_text().split() if log.exists() else []) < 5:
            time.sleep(0.01)
        os.kill(proc.pid, signal.SIGKILL)  # 4 simulations finished, the fifth running
    finally:
        proc.kill()
        proc.wait()
    started = log.read_text().split()
    assert len(started) == 5
    store = Store(out / "precision.sqlite", readonly=True)
    rows = store.evaluations("precision")
    store.close()
    # each finished one kept, not one of 20 lost; the one running still pending
    assert sum(e.status == "ok" for e in rows) == 4
    assert sum(e.status == "pending" for e in rows) == len(rows) - 4 == 2 * 7 * 2 - 4
    assert [e.status for e in rows[:5]] == ["ok"] * 4 + ["pending"]
    resumed = run_precision_check(study, out, placements=2, executor="serial")
    assert resumed.simulated_now == resumed.simulations - 4  # the four are reused


@pytest.mark.slow
def test_simulate_repeat_runs_its_placements_in_spawned_workers(tmp_path, monkeypatch):
    """MuJoCo and numba are not fork-safe: the ensemble runs in the project's spawned worker
    processes (`parcelfit.sim.executors`), never in forks of the command's process."""
    import parcelfit.sim.factory
    import parcelfit.sim.mujoco

    from . import fake_sim

    probe = tmp_path / "probe"
    monkeypatch.setattr(fake_sim, "PARENT_MARK", "inherited")
    monkeypatch.setattr(parcelfit.sim.mujoco, "MujocoSimulator", fake_sim.EnsembleProbe)
    monkeypatch.setattr(
        parcelfit.sim.factory, "make_simulator", lambda config: fake_sim.EnsembleProbe(str(probe))
    )
    out = tmp_path / "run.csv"
    args = ["simulate", "--rig", "E1", "--consignment", "BW", "--out", str(out)]
    result = runner.invoke(app, [*args, "--repeat", "3", "--workers", "2"])
    assert result.exit_code == 0, (result.output, result.exception)
    runs = [line.split() for line in probe.read_text().splitlines()]
    assert len(runs) == 3 and all(pid != str(os.getpid()) for pid, _ in runs)
    assert {mark for _, mark in runs} == {"None"}  # a fresh interpreter, not a fork
    table = (tmp_path / "run-ensemble.csv").read_text().splitlines()
    assert [line.split(",")[:2] for line in table[1:]] == [["0", "ok"], ["1", "ok"], ["2", "ok"]]
    assert all((tmp_path / f"run-s{seed}.csv").is_file() for seed in range(3))


def test_an_error_during_the_live_display_starts_on_a_line_of_its_own(tmp_path):
    """Outside a terminal (a log, CI) the calibration's live table is printed when it stops,
    without ending its last line: the error must not run onto it."""
    study = write_study(
        tmp_path,
        simulator={"backend": "python", "factory": "tests.fake_sim:make_broken"},
        executor={"kind": "serial"},
        budget=8,
        validation={},
    )
    result = runner.invoke(app, ["calibrate", str(study), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    lines = result.output.splitlines()  # stdout and stderr as a log holding both has them
    assert lines[-1].startswith("error: ") and lines[-2].startswith("└") and lines[-2][-1] == "┘"


@pytest.mark.slow
def test_ctrl_c_stops_the_workers_quietly_and_says_how_to_resume(
    tmp_path, ctrl_c, no_study_figures
):
    import signal
    import subprocess
    import sys

    import psutil

    from .helpers import ROOT

    study = write_study(tmp_path, budget=12, initial=4, batch_size=2, validation={})
    out, log, hang = tmp_path / "out", tmp_path / "log", tmp_path / "hang"
    env = {
        **os.environ,
        "FAKE_SIM_DELAY": "0.2",
        "FAKE_SIM_LOG": str(log),
        "FAKE_SIM_HANG": str(hang),
    }
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    calibrate = [sys.executable, "-m", "parcelfit", "calibrate", str(study), "--out", str(out)]
    proc = subprocess.Popen(
        [*calibrate, "--workers", "3"],  # a batch of 2 leaves one worker idle
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, as a terminal's foreground job
    )
    try:
        deadline = time.time() + 90
        while len(finished_fits(out / "study.sqlite")) < 4 and time.time() < deadline:
            time.sleep(0.05)
        hang.touch()  # from now on a simulation runs for minutes
        started = len(log.read_text().split())
        while len(log.read_text().split()) == started and time.time() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        workers = [c.pid for c in psutil.Process(proc.pid).children(recursive=True)]
        t0 = time.time()
        os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C: the whole foreground process group
        stdout, stderr = proc.communicate(timeout=100)
        waited = time.time() - t0
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    stored = len(finished_fits(out / "study.sqlite"))
    assert proc.returncode == 130, stderr
    assert [line for line in stderr.splitlines() if line.strip()] == [
        f"interrupted: {stored} evaluations stored; rerun the same command to resume"
    ]
    assert "Traceback" not in stdout + stderr
    # the simulation running (120 s) was stopped, not waited for (a bound with room for a busy
    # machine: stopping takes a second or two)
    assert waited < 60
    assert not _gone(workers, timeout=10)
    kept = finished_fits(out / "study.sqlite")
    hang.unlink()
    done = runner.invoke(app, calibrate[3:])  # the same command, in this process
    assert done.exit_code == 0, done.output
    after = finished_fits(out / "study.sqlite")
    assert len(after) == 12 and all(after[k] == v for k, v in kept.items())


@pytest.mark.parametrize("command", ["calibrate", "screen", "precision"])
def test_ctrl_c_says_what_each_resumable_command_stored(tmp_path, monkeypatch, command):
    from . import fake_sim
    from .test_precision import _two_rig_study

    monkeypatch.setattr(fake_sim, "started", 0)
    monkeypatch.setenv("FAKE_SIM_INTERRUPT_AFTER", "3")
    if command == "calibrate":
        args = [*_study(tmp_path, executor={"kind": "serial"}, validation={})]
        what = "evaluations"
    elif command == "screen":
        args = _screen(tmp_path, executor="serial")
        what = "simulations"
    else:
        args = ["precision", str(_two_rig_study(tmp_path)), "--placements", "2"]
        args += ["--executor", "serial", "--out", str(tmp_path / "o")]
        what = "simulations"
    result = runner.invoke(app, args)
    assert result.exit_code == 130, (result.output, result.exception)
    assert _error_lines(result) == [
        f"interrupted: 3 {what} stored; rerun the same command to resume"
    ]


def _sleep(seconds: float) -> float:
    time.sleep(seconds)
    return seconds


@pytest.mark.slow
def test_a_dask_cluster_left_without_workers_is_reported_not_waited_on(capfd):
    distributed = pytest.importorskip("distributed")
    import threading

    from parcelfit.sim.executors import dask_executor

    outcome = []
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        executor = dask_executor(cluster.scheduler_address, worker_wait=2)

        def run() -> None:
            try:
                outcome.append(list(executor.map(_sleep, [1.0, 1.0, 1.0])))
            except ParcelfitError as exc:
                outcome.append(exc)

        waiting = threading.Thread(target=run, daemon=True)
        waiting.start()
        time.sleep(0.3)
        cluster.scale(0)  # the only worker leaves while the tasks wait
        t0 = time.perf_counter()
        waiting.join(timeout=30)
        waited = time.perf_counter() - t0
        still_waiting = waiting.is_alive()
        executor.close()
    assert not still_waiting, "after 30 s still waiting for a worker, without a word"
    (error,) = outcome
    assert isinstance(error, ParcelfitError)
    assert str(error).startswith(
        f"no Dask worker has been attached to the scheduler at {cluster.scheduler_address} for "
        "2 s, so nothing runs; the simulations in flight were not recorded and stay pending"
    )
    assert waited < 10
    assert "distributed" not in capfd.readouterr().err  # its own log lines are silenced


def test_a_full_disk_during_a_precision_check_keeps_what_it_saved(tmp_path, monkeypatch):

    from .test_precision import _two_rig_study

    study, out = _two_rig_study(tmp_path), tmp_path / "o"
    opened = Store.__init__

    def filling(self, path, **kw):
        opened(self, path, **kw)
        if not self.readonly:
            self._db = _FillingDisk(self._db, 3, "commit")

    monkeypatch.setattr(Store, "__init__", filling)
    args = ["precision", str(study), "--placements", "2", "--executor", "serial"]
    result = runner.invoke(app, [*args, "--out", str(out)])
    assert result.exit_code == 2, (result.output, result.exception)
    assert _error_lines(result) == [
        f"error: {short_path(out / 'precision.sqlite')}: disk full while writing "
        "precision.sqlite; nothing stored is lost Fix: free space on its disk, then rerun the "
        "same command: it resumes"
    ]
    monkeypatch.setattr(Store, "__init__", opened)
    store = Store(out / "precision.sqlite", readonly=True)
    assert sum(e.status == "ok" for e in store.evaluations("precision")) == 3
    store.close()
    result = runner.invoke(app, [*args, "--out", str(out)])  # space freed
    assert result.exit_code == 0, result.output
    assert "(3 kept)" in result.output


def test_a_failure_streak_quotes_the_first_failure_s_own_fix_once():
    """A simulation's error carries its own 'Fix:'; quoted in the streak's message it read as a
    second 'Fix:' beside the streak's."""
    from parcelfit.study.loop import FailureStreak

    streak = FailureStreak(2, Path("out"))
    streak.add(1, "failed", "rig S1 has no speed setting 3 Fix: use one of [1, 2]")
    with pytest.raises(ParcelfitError) as caught:
        streak.add(2, "failed", "again")
    text = str(caught.value)
    assert "the first: failed: rig S1 has no speed setting 3; its fix: use one of [1, 2]" in text
    assert text.count("Fix:") == 1
