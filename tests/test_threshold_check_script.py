"""scripts/threshold_check.py: the identifiability threshold beside its former form
(docs/research/identify-threshold.md)."""

import re

import pytest

from parcelfit.study.joint import threshold
from parcelfit.study.objective import select_references
from parcelfit.study.studyfile import load_study

from .helpers import ROOT, load_file_module


@pytest.fixture(scope="module")
def script():
    return load_file_module("scripts/threshold_check.py")


def test_it_prints_each_case_and_the_threshold_the_study_uses(script, capsys):
    path = ROOT / "examples" / "e3-e1-kpbw-joint" / "study.yaml"
    assert script.main([str(path)]) == 0
    out = capsys.readouterr().out
    assert "| E3/KPBW/1 | 10 | 3 |" in out and "| E1/KPBW/3 | 10 | 3 |" in out
    study = load_study(path)
    eps, _ = threshold(select_references(study), study)
    printed = float(re.search(r"threshold now: ([0-9.]+)", out).group(1))
    assert printed == pytest.approx(eps, rel=1e-3)
    former = float(re.search(r"former threshold .*: ([0-9.]+)", out).group(1))
    # the single runs' largest costs are the floor (printed to 4 significant digits)
    assert eps >= former * (1 - 5e-4)


def test_folder_takes_one_study_file(script, capsys):
    with pytest.raises(SystemExit):
        script.main(["a.yaml", "b.yaml", "--folder", "x"])
    assert "--folder takes one study file" in capsys.readouterr().err


def test_epsilon_takes_a_folder_and_a_positive_value(script, capsys):
    with pytest.raises(SystemExit):
        script.main(["a.yaml", "--epsilon", "3"])
    with pytest.raises(SystemExit):
        script.main(["a.yaml", "--folder", "x", "--epsilon", "-1"])
    assert "--epsilon takes a positive threshold and --folder" in capsys.readouterr().err


def test_a_finished_study_is_analysed_again_with_a_given_threshold(script, tmp_path, capsys):
    from parcelfit.study.calibration import Calibration

    from .test_joint import _joint_study

    path = _joint_study(tmp_path)
    out = tmp_path / "study"
    Calibration(load_study(path), out, figures=False).run()
    assert script.main([str(path), "--folder", str(out), "--epsilon", "1e9"]) == 0
    text = capsys.readouterr().out
    today = next(line for line in text.splitlines() if line.startswith("today"))
    # a threshold no cost reaches rules nothing out
    assert "(threshold 1e+09)" in today and today.count("undetermined") == 3
