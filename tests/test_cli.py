import json
import os
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from parcelfit.cli import app

from .conftest import line_trajectory

runner = CliRunner()


def _small(make_dataset, extra=None):
    runs = [
        (f"r{i}", line_trajectory(30, y0=0.001 * i, turn=0.05 * i), 1.0 + 0.01 * i)
        for i in range(4)
    ]
    return make_dataset(
        {
            ("E1", "KP", 1): runs,
            ("E1", "BW", 1): [(f"b{i}", line_trajectory(30), 1.2 + 0.01 * i) for i in range(4)],
        },
        extra,
    )


def test_reference_json(make_dataset):
    result = runner.invoke(app, ["reference", str(_small(make_dataset)), "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert [d["test_case"] for d in doc] == ["E1/BW/1", "E1/KP/1"]
    assert doc[1]["reference_run"] in ("r1", "r2")
    assert len(doc[1]["row_sums"]) == 4


def test_reference_table(make_dataset):
    result = runner.invoke(app, ["reference", str(_small(make_dataset))])
    assert result.exit_code == 0
    assert "E1/KP/1: reference run" in result.stdout


@pytest.mark.parametrize("synthetic", [True, False])
def test_reference_and_stats_say_synthetic_for_synthetic_data(make_dataset, tmp_path, synthetic):
    data = str(_small(make_dataset, {"synthetic": synthetic}))
    note = "(SYNTHETIC: simulated from hidden true parameters, not measured)"
    table = runner.invoke(app, ["reference", data])
    stats = runner.invoke(app, ["stats", data, "--out", str(tmp_path / "st")])
    as_json = runner.invoke(app, ["reference", data, "--json"])
    assert table.exit_code == stats.exit_code == as_json.exit_code == 0
    for result in (table, stats):
        text = " ".join(result.stdout.split())
        assert text.startswith("dataset test: 2 test cases, 8 runs")
        assert (note in text) is synthetic
    doc = json.loads(as_json.stdout)
    assert [(d["dataset"], d["synthetic"]) for d in doc] == [("test", synthetic)] * 2
    assert ("SYNTHETIC" in as_json.stderr) is synthetic


def test_stats_writes_files(make_dataset, tmp_path):
    out = tmp_path / "st"
    result = runner.invoke(app, ["stats", str(_small(make_dataset)), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert (out / "transit_time_tests.csv").is_file() and (out / "transit_times.png").is_file()


def test_stats_says_what_it_cannot_compare(make_dataset, tmp_path):
    """4 against 4 runs can reach p = 0.029, 3 against 3 no lower than 0.1: the table gives the
    counts and says which pairs cannot reach alpha; a dataset without transit times is an error
    naming its file, where it printed an empty table; alpha outside (0, 1) names the option."""
    from parcelfit.stats.transit import smallest_p_value

    result = runner.invoke(app, ["stats", str(_small(make_dataset)), "--out", str(tmp_path / "a")])
    text = " ".join(result.output.split())
    assert result.exit_code == 0 and "n A" in text and "too few runs" not in text
    three = make_dataset(
        {
            ("E1", "KP", 1): [(f"k{i}", line_trajectory(30), 1.0 + 0.01 * i) for i in range(3)],
            ("E1", "BW", 1): [(f"b{i}", line_trajectory(30), 1.2 + 0.01 * i) for i in range(3)],
        }
    )
    result = runner.invoke(app, ["stats", str(three), "--out", str(tmp_path / "b")])
    text = " ".join(result.output.split())
    assert result.exit_code == 0
    assert (
        "too few runs to reach 0.05 whatever the data" in text and "BW (3) vs KP (3): 0.1" in text
    )
    assert smallest_p_value(3, 3) == pytest.approx(0.1) and smallest_p_value(4, 4) < 0.05
    none = make_dataset({("E1", "KP", 1): [(f"n{i}", line_trajectory(30), None) for i in range(3)]})
    result = runner.invoke(app, ["stats", str(none), "--out", str(tmp_path / "c")])
    text = " ".join(result.output.split())
    assert result.exit_code == 2
    assert "no run of this dataset has a transit time: nothing to compare" in text
    assert str(none / "dataset.yaml") in text
    assert not (tmp_path / "c").exists()  # refused before any file is written
    # tied runs take the asymptotic test, which can go below the exact test's floor: no note
    tied = make_dataset(
        {
            ("E1", "KP", 1): [(f"t{i}", line_trajectory(30), 1.1) for i in range(2)],
            ("E1", "BW", 1): [(f"u{i}", line_trajectory(30), 1.2) for i in range(5)],
        }
    )
    result = runner.invoke(app, ["stats", str(tied), "--out", str(tmp_path / "d")])
    assert result.exit_code == 0 and "too few runs" not in result.output
    result = runner.invoke(app, ["stats", str(three), "--alpha", "5"])
    assert result.exit_code == 2 and "--alpha" in result.output


def test_regions_that_select_nothing_name_the_case_and_run(make_dataset):
    """Regions written in mm keep no sample of a run in metres: the error names the test case
    and the run, where it named neither."""
    root = _small(make_dataset)
    doc = yaml.safe_load((root / "dataset.yaml").read_text())
    doc["test_cases"][0]["regions"] = [{"x": [200, 1400]}]
    (root / "dataset.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    result = runner.invoke(app, ["reference", str(root)])
    text = " ".join(result.output.split())
    assert result.exit_code == 2
    assert "test case E1/KP/1, run r0: only 0 samples remain after selection, 3 needed" in text
    assert "(metres in the rig frame, as the runs' x and y)" in text


def test_reference_says_when_a_case_has_one_run(make_dataset):
    one = make_dataset({("E1", "KP", 1): [("only", line_trajectory(30), 1.0)]})
    result = runner.invoke(app, ["reference", str(one)])
    text = " ".join(result.output.split())
    assert result.exit_code == 0
    assert "E1/KP/1 has one run: it is the reference without a comparison" in text


def test_bad_input_gives_message_not_traceback(tmp_path):
    result = runner.invoke(app, ["reference", str(tmp_path)])
    assert result.exit_code == 2
    assert "error:" in result.output and "no dataset.yaml here" in result.output
    assert "Traceback" not in result.output


@pytest.mark.slow
@pytest.mark.longest
@pytest.mark.mujoco
def test_demo_quick_end_to_end_on_bundled_data(tmp_path):
    """The README's main job in its quick form. `scripts/test.sh` has just run exactly this in
    the fresh base install (`parcelfit demo --quick --no-animation`): it hands over that folder
    and output (PARCELFIT_DEMO_QUICK_DIR, PARCELFIT_DEMO_QUICK_LOG), which are checked instead
    of running the same minutes again; without them the demo runs here."""
    given = os.environ.get("PARCELFIT_DEMO_QUICK_DIR")
    if given:
        out = Path(given)
        output = Path(os.environ["PARCELFIT_DEMO_QUICK_LOG"]).read_text(encoding="utf-8")
    else:
        out = tmp_path / "demo"
        result = runner.invoke(app, ["demo", "--quick", "--no-animation", "--out", str(out)])
        assert result.exit_code == 0, result.output
        output = result.output
    assert "SYNTHETIC" in output
    refs = json.loads((out / "reference_runs.json").read_text())
    assert len(refs) == 16  # E3 KPBW and PB at two settings, E1 four types at three
    assert (out / "stats" / "transit_times.png").is_file()
    assert (out / "screen" / "selection.yaml").is_file()
    assert (out / "calibration" / "study.sqlite").is_file()
    report = out / "report.html"
    text = report.read_text()
    assert "SYNTHETIC DATA" in text and 'id="stricter"' in text and 'id="frames"' in text
    # the joint calibration: both fitted cases, the transfer check, what the data determine
    assert 'id="transfer"' in text and "E1/KPBW/3" in text and "What the data determine" in text
    assert "report:" in output and report.name in output.replace("\n", "")
    # every check on its own line, then the one verdict
    for check in (
        "published criteria: ",
        "band test: ",
        "transfer check: ",
        "parameters determined",
    ):
        assert check in output
    assert "verdict: " in output and "verdict: validation" not in output
    example = json.loads((out / "stricter-criterion.json").read_text())
    assert example["published_passed"] and not example["stricter_passed"]


def test_help_keeps_units_in_square_brackets_and_shows_the_timestep_readably():
    result = runner.invoke(app, ["simulate", "--help"], terminal_width=200)
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "Time step [s]; replaces the rig's step_refinement." in text
    assert "Wall-clock limit [s]." in text
    default = "1/2400 s (interpolated shell), 1/1200 s (full shell), divided by the rig's"
    assert default in text and "0.00041667" not in text
    result = runner.invoke(app, ["camera-calibrate", "--help"], terminal_width=200)
    assert "Side of one square [m], the tag map's unit (e.g. 0.04)." in " ".join(
        result.output.split()
    )


COMMANDS = sorted(app.registered_commands, key=lambda c: c.name or c.callback.__name__)


def _help(command) -> str:
    name = command.name or command.callback.__name__.replace("_", "-")
    if name == "track-all-command":
        name = "track-all"
    result = runner.invoke(app, [name, "--help"], terminal_width=120)
    assert result.exit_code == 0, result.output
    return " ".join(result.output.split())


def test_help_shows_no_python_types_no_dates_and_one_workers_default():
    import re

    for command in COMMANDS:
        text = _help(command)
        assert "list[" not in text and "<list" not in text, text
        assert not re.search(r"20\d\d-\d\d-\d\d", text), text  # no dates in help texts
        if "--workers" in text:
            assert "Worker processes simulating in parallel (default: one per core" in text, text
        if "--executor" in text:
            assert "--executor [serial|local" in text, text  # the choices are listed


def test_help_names_list_options_and_the_demo_default():
    simulate = " ".join(
        runner.invoke(app, ["simulate", "--help"], terminal_width=120).output.split()
    )
    assert "--set NAME=VALUE" in simulate and "--speed-setting, --setting" in simulate
    assert "speed_setting in dataset, study and screen files" in simulate
    precision = " ".join(
        runner.invoke(app, ["precision", "--help"], terminal_width=120).output.split()
    )
    assert (
        "--candidate RIG/CONSIGNMENT/SPEED_SETTING" in precision and "--at NAME=VALUE" in precision
    )
    calibrate = " ".join(
        runner.invoke(app, ["calibrate", "--help"], terminal_width=120).output.split()
    )
    assert "--executor [serial|local|dask]" in calibrate
    demo = " ".join(runner.invoke(app, ["demo", "--help"], terminal_width=120).output.split())
    assert "Without a flag: the published 32-run screen" in demo and "about 25 minutes" in demo
    assert "the file's executor" not in demo


def test_camera_calibrate_square_is_in_metres(tmp_path):
    result = runner.invoke(
        app, ["camera-calibrate", str(tmp_path / "board.mp4"), "--tags", "t.yaml", "--square", "40"]
    )
    assert result.exit_code == 2
    assert "--square 40 m is not a checkerboard square" in result.output
    assert "e.g. 0.04 for 40 mm" in " ".join(result.output.split())


def test_the_old_setting_flag_still_works(tmp_path):
    result = runner.invoke(app, ["simulate", "--setting", "9", "--out", str(tmp_path / "r.csv")])
    assert result.exit_code == 2 and "rig E3 has no speed setting 9" in result.output


def test_demo_stages_are_library_calls(tmp_path):
    from parcelfit import ParcelfitError
    from parcelfit.demo import STAGES, Demo

    with pytest.raises(ParcelfitError, match="unknown demo profile 'fast'"):
        Demo(tmp_path, "fast")
    d = Demo(tmp_path / "demo", "quick", executor="serial")
    assert d.dataset.synthetic and len(STAGES) == 6
    refs = d.reference_runs()
    assert (
        len(refs) == 16
        and len(json.loads((tmp_path / "demo" / "reference_runs.json").read_text())) == 16
    )
    screen_file, study_file = d.files
    study = yaml.safe_load(study_file.read_text())
    assert study["budget"] == 16
    assert [(c["rig"], c["speed_setting"]) for c in study["cases"]] == [("E3", 1), ("E1", 3)]
    assert study["transfer"] == [{"rig": "E1", "speed_setting": 1}]
    # the smoke run coarsens E1 to the other rigs' step, the other profiles keep E1's own
    from parcelfit.demo import PROFILES, SMOKE_E1_TIMESTEP, demo_dataset, write_demo_files

    assert study["simulator"]["rig_timesteps"] == {"E1": SMOKE_E1_TIMESTEP}
    _, full_study = write_demo_files(tmp_path / "full", PROFILES["full"], demo_dataset())
    assert "rig_timesteps" not in yaml.safe_load(full_study.read_text())["simulator"]
    assert yaml.safe_load(screen_file.read_text())["stages"] == ["fractional"]
    # the files say how to rerun each stage into the folder the demo used, so that it resumes
    assert "#   parcelfit calibrate study.yaml --out calibration\n" in study_file.read_text()
    assert "#   parcelfit screen screen.yaml --out screen\n" in screen_file.read_text()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--out", "run.txt"], "unknown file type '.txt'"),
        (["--video", "run.avi"], "unknown video type '.avi'"),
        (["--video", "run.gif", "--repeat", "2"], "--video works with one run only"),
    ],
)
def test_simulate_refuses_bad_output_names_before_it_simulates(
    tmp_path, monkeypatch, args, message
):
    import parcelfit.simulate

    def never(*a, **k):
        raise AssertionError("simulated before the output names were checked")

    monkeypatch.setattr(parcelfit.simulate, "case_simulation", never)
    argv = [*args] if "--out" in args else [*args, "--out", str(tmp_path / "run.csv")]
    result = runner.invoke(app, ["simulate", *argv])
    assert result.exit_code == 2, result.output
    assert message in " ".join(result.output.split())


def test_rigs_says_where_the_bundled_files_lie():
    from importlib.resources import files

    result = runner.invoke(app, ["rigs"], terminal_width=400)
    assert result.exit_code == 0, result.output
    for kind in ("rigs", "consignments"):
        folder = files("parcelfit.sim.mujoco").joinpath(kind)
        assert (
            f"{folder}" in result.output
            and (folder / "E3.yaml" if kind == "rigs" else folder / "KPBW.yaml").is_file()
        )
