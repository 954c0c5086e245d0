"""scripts/threshold_truth.py: the identifiability threshold beside the twin's truth's own cost
(docs/research/identify-threshold.md)."""

import re

import pytest

from parcelfit.sim.executors import Task, serial_executor
from parcelfit.sim.factory import make_simulator
from parcelfit.study.joint import (
    CaseRun,
    evaluation_outcome,
    placement_seeds,
    simulate_items,
    threshold,
)
from parcelfit.study.objective import select_references
from parcelfit.study.studyfile import load_study

from .helpers import load_file_module
from .test_joint import _joint_study

TRUTH = ["mu_d_BePa=0.45", "mu_d_MePa=0.25", "E_Pa=1000"]


@pytest.fixture(scope="module")
def script():
    return load_file_module("scripts/threshold_truth.py")


def _args(path, *extra):
    sets = [a for t in TRUTH for a in ("--set", t)]
    return [str(path), *sets, "--executor", "serial", *extra]


def test_the_first_draw_is_an_evaluation_at_the_study_s_own_seeds(script, tmp_path, capsys):
    path = _joint_study(tmp_path)
    assert script.main(_args(path, "--draws", "3")) == 0
    out = capsys.readouterr().out
    cells = re.search(r"\| all \(weighted\) \| ([0-9.e+-]+) \| ([0-9.e+-]+) \|", out)
    study = load_study(path)
    refs = select_references(study)
    eps, _ = threshold(refs, study)
    assert float(cells.group(1)) == pytest.approx(eps, rel=6e-3)  # printed to 3 digits
    # the same evaluation made here: the truth at placements 1..K of every case
    params = {**study.fixed, "mu_d_BePa": 0.45, "mu_d_MePa": 0.25, "E_Pa": 1e9}
    items = [
        (Task(params, spec.case, f"t{i}-{seed}"), seed)
        for i, spec in enumerate(study.cases)
        for seed in placement_seeds(study, spec)
    ]
    sim = make_simulator(study.simulator)
    got = sorted(simulate_items(serial_executor(), sim, items), key=lambda t: t[0])
    runs = [
        CaseRun(next(s for s in study.cases if s.case == items[j][0].case), items[j][1], r)
        for j, r in got
    ]
    cost = evaluation_outcome(runs, refs, study)["cost"]
    assert float(cells.group(2)) == pytest.approx(cost, rel=6e-3)
    assert "3 sets of placements" in out and "of 3 |" in out


def test_every_fitted_parameter_needs_its_truth(script, tmp_path, capsys):
    path = _joint_study(tmp_path)
    with pytest.raises(SystemExit):
        script.main([str(path), "--set", "mu_d_BePa=0.45", "--executor", "serial"])
    err = capsys.readouterr().err
    assert "--set gives no truth for the fitted" in err
    assert "mu_d_MePa" in err and "E_Pa" in err and "mu_d_BePa" not in err.split("fitted")[1]
