"""The convergence check: the recommended parameters simulated again by a refined model (every
mesh spacing and the time step divided), and the verdict failing where the refined model's
published-criteria outcome differs from the model's own."""

import pytest

from parcelfit.errors import ParcelfitError
from parcelfit.metrics.validation import MeanDistanceCheck, TransitTimeCheck, Validation
from parcelfit.sim.mujoco import MujocoSimulator, SceneOptions
from parcelfit.sim.mujoco.options import DEFAULT_SPACING, INTERPOLATED_SHELL_STEP
from parcelfit.sim.rigidbox import RigidBoxOptions, RigidBoxSimulator
from parcelfit.study.calibration import Calibration
from parcelfit.study.results import ConvergenceRecord, ValidationRecord, read_results
from parcelfit.study.studyfile import load_study
from parcelfit.study.verdict import convergence_check, study_verdict

from .helpers import write_study

PARAMS = {"mu_d_BePa": 0.45}


def _record(case, passed=True, params=PARAMS, after=None):
    verdict = Validation(
        TransitTimeCheck(2.0, 1.9, 2.1, True),
        MeanDistanceCheck("xy", 1e-4, (2e-4,), 2e-4, True),
        MeanDistanceCheck("theta", 1e-2 if passed else 3e-2, (2e-2,), 2e-2, passed),
    )
    return ValidationRecord(
        case=case,
        after_iteration=after,
        params=dict(params),
        status="ok",
        transit_time=2.0,
        verdict=verdict,
    )


def test_a_refined_scene_divides_every_mesh_spacing_and_the_step():
    sim = MujocoSimulator()
    kpbw, pb, e1, e3 = (
        sim.consignment("KPBW"),
        sim.consignment("PB"),
        sim.rig("E1"),
        sim.rig("E3"),
    )
    base = SceneOptions()
    twice = SceneOptions(refinement=2)
    assert twice.spacing_of(kpbw) == pytest.approx((kpbw.mesh_spacing or DEFAULT_SPACING) / 2)
    assert twice.spacing_of(pb) == pytest.approx(base.spacing_of(pb) / 2)
    assert twice.content_spacing() == pytest.approx(base.soft_spacing / 2)
    for rig in (e1, e3):  # the rig's own refinement (E1's 2) and the scene's multiply
        assert twice.step_for(False, rig, "trilinear") == pytest.approx(
            base.step_for(False, rig, "trilinear") / 2
        )
    assert base.step_for(False, e3, "trilinear") == pytest.approx(INTERPOLATED_SHELL_STEP)
    # a step or spacing the scene sets is divided too, and a rig's own step
    given = SceneOptions(timestep=1 / 1200, spacing=0.02, rig_timesteps={"E1": 1 / 4800})
    finer = SceneOptions(
        timestep=1 / 1200, spacing=0.02, rig_timesteps={"E1": 1 / 4800}, refinement=4
    )
    assert finer.step_for(False, e3) == pytest.approx(given.step_for(False, e3) / 4)
    assert finer.step_for(False, e1) == pytest.approx(1 / 19200)
    assert finer.spacing_of(kpbw) == pytest.approx(0.005)
    # the simulator's refinement composes with the refinement it has
    refined = sim.with_refinement(2).with_refinement(2)
    assert refined.options.scene.refinement == 4
    assert sim.options.scene.refinement == 1  # the original is unchanged
    for bad in (0, 1.5, 5):
        with pytest.raises(ParcelfitError, match="refinement must be a whole number from 1 to 4"):
            SceneOptions(refinement=bad)


def test_the_rigid_box_reference_refines_its_points_and_its_step():
    ref = RigidBoxSimulator(RigidBoxOptions(spacing=0.01)).with_refinement(2)
    assert (ref.options.spacing, ref.options.step_divisor) == (0.005, 2)
    fixed = RigidBoxSimulator(RigidBoxOptions(timestep=1e-5)).with_refinement(4)
    assert fixed.options.timestep == pytest.approx(2.5e-6) and fixed.options.step_divisor == 1


def test_the_check_compares_each_case_s_outcome_with_the_model_s_own():
    own = [_record("E3/KPBW/2", after=4), _record("E1/KPBW/1")]
    same = ConvergenceRecord(refinement=2, runs=(_record("E3/KPBW/2"), _record("E1/KPBW/1")))
    assert convergence_check(same, own, True).line() == (
        "convergence check: passed (E3/KPBW/2, E1/KPBW/1: the same outcome with every mesh "
        "spacing and the time step halved)"
    )
    # a case that fails on the model and on the refined one alike: the same outcome (the
    # published criteria check fails the verdict, not this one)
    both = ConvergenceRecord(refinement=3, runs=(_record("E1/KPBW/1", passed=False),))
    check = convergence_check(both, [_record("E1/KPBW/1", passed=False)], True)
    assert check.outcome == "passed" and "divided by 3" in check.detail
    flipped = ConvergenceRecord(
        refinement=2, runs=(_record("E3/KPBW/2"), _record("E1/KPBW/1", passed=False))
    )
    assert convergence_check(flipped, own, True).line() == (
        "convergence check: failed (E1/KPBW/1: passes, refined fails (DTW_theta) (every mesh "
        "spacing and the time step halved))"
    )
    # a refined run without the model's own run of the same parameters: nothing to compare
    other = ConvergenceRecord(refinement=2, runs=(_record("E3/KPBW/2", params={"x": 1.0}),))
    assert convergence_check(other, own, True).outcome == "not run"
    off = ConvergenceRecord(refinement=1, reason="switched off (validation.refinement: 1)")
    assert convergence_check(off, own, True).line() == (
        "convergence check: not run (switched off (validation.refinement: 1))"
    )
    assert convergence_check(None, own, False).detail == "it runs when the study stops"
    assert convergence_check(None, own, True).outcome == "not run"


@pytest.mark.parametrize(("mesh_error", "outcome"), [(0.0, "passed"), (-0.3, "failed")])
def test_a_calibration_that_absorbed_a_discretisation_error_fails_the_check(
    tmp_path, monkeypatch, mesh_error, outcome
):
    """The analytic simulator with a heading error that halves on a refined model: the
    calibration absorbs it into mu_d_MePa and passes its validation, the refined model's run
    turns 0.15 rad less and fails it; without the error the check passes. A rerun simulates
    nothing again."""
    monkeypatch.setenv("FAKE_SIM_MESH_ERROR", str(mesh_error))
    path = write_study(tmp_path)
    out = tmp_path / "out"
    Calibration(load_study(path), out, figures=False).run()
    results = read_results(out)
    assert results is not None and results.convergence is not None
    record = results.convergence
    assert record.refinement == 2 and [r.case for r in record.runs] == ["R/P/2"]
    assert all((out / r.run_file).is_file() for r in record.runs if r.run_file)
    verdict = study_verdict(results, results.cases, stopped=True)
    assert verdict.criteria.outcome == "passed"  # the model itself passes its validation
    assert verdict.convergence.outcome == outcome
    if outcome == "failed":
        assert verdict.level == "not trustworthy"
        assert "refined fails (DTW_theta)" in verdict.convergence.detail
    # the rerun keeps the stored record (no refined simulation again)
    monkeypatch.setenv("FAKE_SIM_LOG", str(tmp_path / "log.txt"))
    Calibration(load_study(path), out, figures=False).run()
    log = tmp_path / "log.txt"
    assert not log.exists() or "refined" not in log.read_text()


def test_a_study_can_switch_the_check_off_and_its_verdict_says_so(tmp_path):
    path = write_study(tmp_path, validation={"speed_setting": 2, "every": 2, "refinement": 1})
    assert load_study(path).refinement == 1
    out = tmp_path / "out"
    Calibration(load_study(path), out, figures=False).run()
    results = read_results(out)
    verdict = study_verdict(results, results.cases, stopped=True)
    assert verdict.convergence.line() == (
        "convergence check: not run (switched off (validation.refinement: 1))"
    )
    assert verdict.level != "trustworthy"
    bad = write_study(tmp_path / "bad", validation={"speed_setting": 2, "refinement": 5})
    with pytest.raises(ParcelfitError, match="refinement"):
        load_study(bad)
