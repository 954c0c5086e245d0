import json
import re
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from parcelfit.cli import app
from parcelfit.errors import ParcelfitError

from .helpers import write_study, write_study_store

runner = CliRunner()


@pytest.mark.slow
def test_calibrate_then_status_json(tmp_path):
    study = write_study(tmp_path, budget=12, validation={"speed_setting": 2, "every": 1})
    out = tmp_path / "out"
    result = runner.invoke(app, ["calibrate", str(study), "--out", str(out), "--workers", "2"])
    assert result.exit_code == 0, result.output
    assert "figures in" in result.output
    # the test's dataset is synthetic (fake_sim.write_reference_dataset), and calibrate says so
    assert "(SYNTHETIC: simulated from hidden true parameters, not measured)" in " ".join(
        result.output.split()
    )
    status = runner.invoke(app, ["status", str(out), "--json"])
    info = json.loads(status.stdout)
    assert info["evaluations"] <= 12 and info["pending"] == 0 and info["validations"]
    assert (out / "figures" / "history.png").is_file()
    # one numbering: iteration 0 is the initial design (8 here), then batches of 4
    last = info["last_iteration"]
    assert info["evaluations"] == 8 + 4 * last and last >= 1
    span = "iteration 1" if last == 1 else f"iterations 1-{last}"
    said = " ".join(result.output.split())
    assert (
        f"after {info['evaluations']} evaluations: the initial design (iteration 0) and {span};"
        in said
    )
    assert info["validations"][-1]["after_iteration"] == last
    # not a terminal: one progress line per finished evaluation
    lines = re.findall(
        r"^\w+: fit-\d{3}-\d{2} \((\d+)/12 evaluations, best cost ", result.stdout, re.M
    )
    assert [int(k) for k in lines] == list(range(1, info["evaluations"] + 1))
    # calibrate and status show the same point, under the same name
    rec = info["recommended"]
    title = f"recommended parameters (cost {rec['cost']:.4g}, evaluated in iteration {rec['iteration']})"
    assert title in said
    assert title in " ".join(runner.invoke(app, ["status", str(out)]).stdout.split())


@pytest.mark.slow
def test_screen_cli(tmp_path):
    from .fake_sim import write_reference_dataset

    write_reference_dataset(tmp_path / "data")
    doc = {
        "name": "s",
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make"},
        "reference": {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
        "parameters": {"mu_d_BePa": [0.3, 0.58], "E_Pa": [200, 1600], "t_Pa": [0.2, 1.0]},
        "fixed": {"mu_d_MePa": 0.2},
        "stages": ["fractional"],
        "resolution": 3,
        "select": 1,
    }
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    result = runner.invoke(
        app, ["screen", str(path), "--out", str(tmp_path / "o"), "--workers", "2"]
    )
    assert result.exit_code == 0, result.output
    assert "selected for calibration: mu_d_BePa" in result.output
    # the line says how many of the selected have a significant effect, as selection.yaml does
    selection = yaml.safe_load((tmp_path / "o" / "selection.yaml").read_text())
    n = len(selection["significant"])
    assert set(selection["significant"]) <= set(selection["selected"])
    assert f"(the largest effects, at most `select` of them; {n} of the 1 significant" in " ".join(
        result.output.split()
    )
    # not a terminal: one progress line per finished run
    runs = len((tmp_path / "o" / "stage1-design.csv").read_text().splitlines()) - 1
    lines = re.findall(
        r"^screening: \w+: screen-0-\d+ \((\d+) of (\d+) done\)$", result.stdout, re.M
    )
    assert lines == [(str(k), str(runs)) for k in range(1, runs + 1)]
    doc["fixed"] = {}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    result = runner.invoke(
        app, ["screen", str(path), "--out", str(tmp_path / "o2"), "--workers", "2"]
    )
    assert (
        result.exit_code == 2
        and "too few to estimate" in result.output
        and "KeyError" in result.output
    )


def test_bad_study_and_missing_status_folder(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nsimulator: {backend: mujoco}\nparameters: {}\nreference: {}\n")
    result = runner.invoke(app, ["calibrate", str(bad)])
    assert (
        result.exit_code == 2
        and "needs 'rig'" in result.output
        and "Traceback" not in result.output
    )
    result = runner.invoke(app, ["status", str(tmp_path)])
    assert result.exit_code == 2 and "no study.sqlite here" in result.output


def test_status_in_plain_words_with_the_recommended_point_and_synthetic_data(tmp_path):
    from .fake_sim import write_reference_dataset

    write_reference_dataset(tmp_path / "data")  # a synthetic dataset
    study = write_study_store(tmp_path / "demo" / "calibration", tmp_path / "data")
    result = runner.invoke(app, ["status", str(study)], terminal_width=200)
    assert result.exit_code == 0, result.output
    text = " ".join(result.stdout.split())
    assert "(SYNTHETIC: simulated from hidden true parameters, not measured)" in text
    assert (
        "hand: 4 evaluations (1 failed, 3 ok), the initial design (iteration 0) and iteration 1, "
        "reference run R-P-1-0, stopped: validation passed" in text
    )
    assert "validation after iteration 1: passed" in text
    assert "recommended parameters (cost 0.3, evaluated in iteration 1)" in text
    assert "the lowest single cost was 0.2 (iteration 1)" in text
    # a store of an earlier version: no optimiser settings, and status says what stands in
    assert "did not record the optimiser settings: the default GP settings are used" in text
    assert re.search(r"E_Pa\W+900\W+N/mm\^2", text)  # the table in catalogue units
    assert "{'" not in result.stdout and "passed=" not in result.stdout  # no Python reprs


def test_status_json_is_si_with_its_units(tmp_path):
    study = write_study_store(tmp_path / "study", None)
    result = runner.invoke(app, ["status", str(study), "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    assert info["units"] == {"mu_d_BePa": "-", "E_Pa": "Pa", "cost": "-"}
    rec = info["recommended"]
    assert rec["params"] == pytest.approx({"mu_d_BePa": 0.45, "E_Pa": 9e8})
    assert (rec["cost"], rec["iteration"]) == (0.3, 1)
    assert info["lowest_cost"]["cost"] == 0.2 and info["lowest_cost"]["iteration"] == 1
    assert info["last_iteration"] == 1 and info["synthetic"] is None
    assert info["validations"] == [
        {"after_iteration": 1, "case": None, "status": "ok", "passed": True}
    ]
    assert info["cases"] is None and rec["parts"] is None  # a one-case study
    assert "SYNTHETIC" not in runner.invoke(app, ["status", str(study)]).stdout


def test_status_of_a_demo_folder_shows_its_calibration_subfolder(tmp_path):
    # as report, predict and design take a demo's folder, status reads its calibration/
    study = write_study_store(tmp_path / "demo" / "calibration", None)
    direct = runner.invoke(app, ["status", str(study), "--json"])
    demo = runner.invoke(app, ["status", str(tmp_path / "demo"), "--json"])
    assert direct.exit_code == 0 and demo.exit_code == 0, demo.output
    assert json.loads(demo.stdout) == json.loads(direct.stdout)
    # a folder with neither is refused, naming the store
    (tmp_path / "empty").mkdir()
    empty = runner.invoke(app, ["status", str(tmp_path / "empty")])
    assert empty.exit_code == 2 and "no study.sqlite here" in " ".join(empty.output.split())


@pytest.mark.parametrize("terminal", [True, False])
def test_progress_updates_the_spinner_on_a_terminal_and_prints_lines_elsewhere(
    monkeypatch, terminal
):
    import io

    from rich.console import Console

    from parcelfit.cli import output
    from parcelfit.progress import ProgressEvent

    out = io.StringIO()
    monkeypatch.setattr(output, "console", Console(file=out, force_terminal=terminal, width=100))
    shown = []

    class Spinner:
        def update(self, text):
            shown.append(text)

    say = output.status_progress(Spinner(), "screening: ")
    say(ProgressEvent("screening", "ok: screen-0-1 (1 of 2 done)", 1, 2))
    say(ProgressEvent("screening", "ok: screen-0-0 (2 of 2 done)", 2, 2))
    printed = ["screening: ok: screen-0-1 (1 of 2 done)", "screening: ok: screen-0-0 (2 of 2 done)"]
    assert shown == (printed if terminal else [])
    assert out.getvalue().splitlines() == ([] if terminal else printed)


def test_an_executor_a_command_cannot_use_is_one_clear_error(tmp_path):
    study = write_study(tmp_path)
    result = runner.invoke(app, ["calibrate", str(study), "--executor", "cloud"])
    assert result.exit_code == 2 and "unknown executor 'cloud'" in result.output
    assert "serial or local or dask" in " ".join(result.output.split())
    result = runner.invoke(app, ["screen", str(study), "--executor", "dask"])
    assert result.exit_code == 2 and "unknown executor 'dask'" in result.output
    assert "Traceback" not in result.output


def test_the_calibration_table_shows_nothing_running_once_the_job_ended():
    # the last stage's event (the key frames: one simulation) said "1 running"; the table left
    # on the screen after the job must not
    import io

    from rich.console import Console

    from parcelfit.cli.output import CalibrationDisplay
    from parcelfit.progress import ProgressEvent
    from parcelfit.study.outcome import CalibrationStart

    out = io.StringIO()
    with CalibrationDisplay(Console(file=out, force_terminal=True, width=100)) as display:
        display.started(CalibrationStart("s", Path("s"), None))
        display.update(
            ProgressEvent("calibration", "drawing the key frames", 16, 16, iteration=3, running=1)
        )
    last = out.getvalue().rsplit("evaluations", 1)[1].splitlines()[0]
    assert "16 done, 0 running, budget 16" in last


def test_a_study_whose_dataset_is_not_made_yet_names_the_study_file_and_key(tmp_path):
    # the own-rig example run in the wrong order: calibrate before synth
    study = write_study(tmp_path)
    import shutil

    data = tmp_path / "data"
    shutil.rmtree(data)
    result = runner.invoke(app, ["calibrate", str(study), "--out", str(tmp_path / "out")])
    text = " ".join(result.output.split())
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"{study}: reference.dataset:" in text and "holds no dataset.yaml" in text
    assert "parcelfit synth" in text and not (tmp_path / "out" / "study.sqlite").exists()


def test_a_dataset_given_as_its_dataset_yaml_is_taken(tmp_path):
    # load_dataset takes a folder or its dataset.yaml; the check before the start takes both
    from parcelfit.study.outcome import check_datasets
    from parcelfit.study.studyfile import load_study

    study = write_study(tmp_path)
    text = study.read_text().replace("dataset: data", "dataset: data/dataset.yaml")
    assert text != study.read_text()
    study.write_text(text)
    check_datasets(load_study(study))  # no error
    (tmp_path / "data" / "dataset.yaml").unlink()
    with pytest.raises(ParcelfitError, match=r"data/dataset\.yaml does not exist"):
        check_datasets(load_study(study))
