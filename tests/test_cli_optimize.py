import json

import pytest
import yaml
from typer.testing import CliRunner

from parcelfit.cli import app

from .helpers import write_study

runner = CliRunner()


@pytest.mark.slow
def test_calibrate_then_status_json(tmp_path):
    study = write_study(tmp_path, budget=12, validation={"speed_setting": 2, "every": 1})
    out = tmp_path / "out"
    result = runner.invoke(app, ["calibrate", str(study), "--out", str(out), "--workers", "2"])
    assert result.exit_code == 0, result.output
    assert "best parameters" in result.output and "figures in" in result.output
    status = runner.invoke(app, ["status", str(out), "--json"])
    info = json.loads(status.stdout)
    assert info["evaluations"] <= 12 and info["pending"] == 0 and info["validations"]
    assert (out / "figures" / "history.png").is_file()


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
