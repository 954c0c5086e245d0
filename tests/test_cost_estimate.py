"""The expected cost long commands print before they start (parcelfit.sim.cost,
parcelfit.study.estimate)."""

import pytest
from typer.testing import CliRunner

from parcelfit.cli import app
from parcelfit.sim.cost import RUN_SECONDS, duration_text, estimate, run_seconds
from parcelfit.sim.factory import SimulatorConfig
from parcelfit.study.estimate import calibration_estimate, precision_estimate, validation_checks
from parcelfit.study.studyfile import load_study

from .helpers import ROOT, write_study

runner = CliRunner()


def test_per_run_seconds_follow_the_content_the_rig_and_the_step():
    e3 = run_seconds(SimulatorConfig("mujoco", rig="E3", consignment="BW"))
    assert e3 == RUN_SECONDS["rigid"]  # over 4 x 4 x 1 cells (5 x 5 x 2 nodes), 30 mm mesh
    # the mesh is not counted (KP's 22.5 mm cost 1.01 times 30 mm in bench_sim.py)
    assert run_seconds(SimulatorConfig("mujoco", rig="E3", consignment="KP")) == e3
    # KP/BW's 5 x 5 x 1 cells: in proportion to the nodes, 72 against 50 (12.1 s measured)
    kpbw = run_seconds(SimulatorConfig("mujoco", rig="E3", consignment="KPBW"))
    assert kpbw == pytest.approx(RUN_SECONDS["rigid"] * 72 / 50, rel=1e-12)
    cells4 = SimulatorConfig("mujoco", rig="E3", consignment="KPBW", shell_cells=(4, 4, 1))
    assert run_seconds(cells4) == e3
    coarse = SimulatorConfig("mujoco", rig="E3", consignment="BW", shell_cells=(2, 2, 1))
    assert run_seconds(coarse) == e3  # not counted as cheaper
    # E1 halves the step (step_refinement 2) and runs longer than E3
    e1 = run_seconds(SimulatorConfig("mujoco", rig="E1", consignment="KPBW"))
    assert e1 > 2 * e3
    assert run_seconds(SimulatorConfig("mujoco", rig="E3", consignment="PB")) == RUN_SECONDS["soft"]
    fine = SimulatorConfig("mujoco", rig="E3", consignment="KPBW", timestep=1 / 4800)
    assert run_seconds(fine) == pytest.approx(2 * kpbw, rel=1e-12)
    assert run_seconds(SimulatorConfig("external", external="x.yaml")) is None


def test_estimate_spreads_runs_over_workers_and_says_so():
    e = estimate([(10, 6.0), (2, 30.0)], workers=2)
    assert e.simulations == 12 and e.seconds == (60 + 60) / 2
    assert e.text() == "expected cost: 12 simulations on 2 processes, about 60 s"
    assert estimate([(1, 30.0)], workers=4).seconds == 30.0  # one run does not split
    unknown = estimate([(3, None)], workers=1).text()
    assert "3 simulations on 1 process," in unknown and "time unknown" in unknown
    assert duration_text(3 * 3600) == "3.0 h" and duration_text(600) == "10 min"


def test_the_example_study_counts_its_budget_validations_and_key_frames():
    study = load_study(ROOT / "examples" / "e3-kpbw" / "study.yaml")
    # budget 60, initial 16, batches of 4: 11 batches, a validation after the 5th, the 10th
    # and the last; the convergence check's one refined run of the validation case
    assert validation_checks(study) == 3
    e = calibration_estimate(study, 2)
    assert e.simulations == 60 + 3 + 1 + 1
    # KP/BW over 5 x 5 x 1 cells: 72 nodes against the 50 that RUN_SECONDS["rigid"] is for;
    # the refined run (half the step) counts twice
    assert e.seconds == pytest.approx((e.simulations + 1) * RUN_SECONDS["rigid"] * 72 / 50 / 2)
    p = precision_estimate(study, 10, ["E3/KPBW/1", "E1/KPBW/3"], 2)
    # (point + 2 ends x 4 parameters) x 10 placements on the fitted, validation and new case
    assert p.simulations == 9 * 10 * 3


@pytest.mark.slow
def test_precision_prints_its_expected_cost_before_it_starts(tmp_path):
    study = write_study(tmp_path)
    out = tmp_path / "p"
    result = runner.invoke(app, ["precision", str(study), "--placements", "2", "--out", str(out)])
    # (the point and both ends of 2 parameters) x 2 placements x (fitted and validation case)
    text = " ".join(result.output.split())
    assert text.startswith("expected cost: 20 simulations on 2 processes, about 5 s"), text
