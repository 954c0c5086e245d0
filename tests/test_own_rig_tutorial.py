"""The user guide's "Your own rig" tutorial, followed from scratch: a rig file and a consignment
file that are not bundled (examples/own-rig/D1.yaml, envelope.yaml), a SYNTHETIC dataset on
them in the documented format (`parcelfit synth` with the twin spec beside them), the study file
with a small budget, `calibrate` and `report`. MuJoCo, about a minute on 2 cores."""

import json
import shutil

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from parcelfit.cli import app
from parcelfit.runs import load_dataset
from parcelfit.sim.mujoco import (
    bundled_consignment_names,
    bundled_rig_names,
    load_consignment,
    load_rig,
)

from .helpers import ROOT

runner = CliRunner()
FILES = ("D1.yaml", "envelope.yaml", "twin-spec.yaml", "study.yaml")


def test_the_tutorial_files_are_a_rig_and_a_type_of_your_own_named_after_their_files():
    folder = ROOT / "examples" / "own-rig"
    rig, cons = load_rig(folder / "D1.yaml"), load_consignment(folder / "envelope.yaml")
    assert rig.name == "D1" not in bundled_rig_names()
    assert cons.name == "envelope" not in bundled_consignment_names()
    guide = (ROOT / "docs" / "guide" / "rig.md").read_text(encoding="utf-8")
    for name in FILES:  # the page shows the very files this test runs
        assert f'--8<-- "examples/own-rig/{name}"' in guide


@pytest.mark.slow
@pytest.mark.mujoco
def test_own_rig_from_scratch_to_the_report(tmp_path):
    own = tmp_path / "own-rig"
    own.mkdir()
    for name in FILES:
        shutil.copy(ROOT / "examples" / "own-rig" / name, own)

    made = runner.invoke(
        app, ["synth", str(own / "twin-spec.yaml"), "--out", str(own / "data"), "--workers", "2"]
    )
    assert made.exit_code == 0, made.output
    assert "expected cost: 6 simulations on 2 processes" in " ".join(made.output.split())
    # the dataset in the documented format: dataset.yaml, test cases by the files' names
    doc = yaml.safe_load((own / "data" / "dataset.yaml").read_text())
    assert doc["synthetic"] is True
    assert [(c["rig"], c["consignment"], c["speed_setting"]) for c in doc["test_cases"]] == [
        ("D1", "envelope", 1),
        ("D1", "envelope", 2),
    ]
    run = doc["test_cases"][0]["runs"][0]
    frame = pd.read_csv(own / "data" / run["file"])
    assert list(frame.columns) == ["t", "x", "y", "theta"] and run["transit_time"] > 0
    assert len(load_dataset(own / "data").runs()) == 6

    calibrated = runner.invoke(app, ["calibrate", str(own / "study.yaml"), "--workers", "2"])
    assert calibrated.exit_code == 0, calibrated.output
    said = " ".join(calibrated.output.split())
    assert said.startswith("expected cost: 8 simulations on 2 processes")
    assert "mu_d_BePa" in said
    status = runner.invoke(app, ["status", str(own / "study"), "--json"])
    info = json.loads(status.stdout)
    assert info["evaluations"] <= 6 and info["pending"] == 0 and info["validations"]
    assert info["study"]["name"] == "d1-envelope"

    reported = runner.invoke(app, ["report", str(own / "study")])
    assert reported.exit_code == 0, reported.output
    page = (own / "study" / "report.html").read_text()
    assert "SYNTHETIC" in page and "D1/envelope/1" in page and "What the data determine" in page
    assert "published criteria: " in reported.output and "verdict: " in reported.output
