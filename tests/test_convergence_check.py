"""The convergence check: the recommended parameters simulated again by a refined model (every
mesh spacing and the time step divided), and the verdict failing where the refined model's
outcome (published criteria; the band test on a validation case) differs from the model's own."""

import pytest

from parcelfit.errors import ParcelfitError
from parcelfit.metrics.envelope import EnvelopeCheck
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


def _record(case, passed=True, params=PARAMS, after=None, band=None):
    """A record whose published criteria pass or not; ``band``: its band test's outcome (None:
    no band)."""
    inside = None if band is None else (1.0 if band else 0.9)
    verdict = Validation(
        TransitTimeCheck(2.0, 1.9, 2.1, True),
        MeanDistanceCheck("xy", 1e-4, (2e-4,), 2e-4, True),
        MeanDistanceCheck("theta", 1e-2 if passed else 3e-2, (2e-2,), 2e-2, passed),
        None if band is None else EnvelopeCheck(inside, 1.0, 0.01, 0.02, 0.95, band),
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
        "convergence check: passed (E3/KPBW/2, E1/KPBW/1: the same outcomes with every mesh "
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
        "convergence check: failed (E1/KPBW/1 passes on the model, fails (DTW_theta) refined, "
        "every mesh spacing and the time step halved)"
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
    assert all(r.status == "ok" and (out / r.run_file).is_file() for r in record.runs)
    verdict = study_verdict(results, results.cases, stopped=True)
    assert verdict.criteria.outcome == "passed"  # the model itself passes its validation
    assert verdict.convergence.outcome == outcome
    if outcome == "failed":
        assert verdict.level == "not trustworthy"
        assert "R/P/2 passes on the model, fails (DTW_theta) refined" in (
            verdict.convergence.detail
        )
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


@pytest.mark.parametrize(("rig", "kind"), [("E1", "PB"), ("E1", "KPBW"), ("E3", "KP")])
def test_the_refined_scene_is_the_scene_of_the_divided_values(rig, kind):
    """The scene built at refinement 2 is, character for character, the one built with every
    spacing and the step halved by hand (the film's and the soft content's too)."""
    from parcelfit.sim.mujoco.scene import build_scene

    sim = MujocoSimulator()
    r, c = sim.rig(rig), sim.consignment(kind)
    params = c.parameter_values(si_values={})
    base = SceneOptions()
    by_hand = SceneOptions(
        timestep=base.step_for(c.soft, r, c.shell) / 2,
        spacing=None if c.soft else base.spacing_of(c) / 2,
        soft_shell_spacing=base.soft_shell_spacing / 2,
        soft_spacing=base.soft_spacing / 2,
    )
    refined = build_scene(r, c, params, 1, SceneOptions(refinement=2))
    assert refined.xml == build_scene(r, c, params, 1, by_hand).xml
    assert refined.n_shell_vertices > build_scene(r, c, params, 1, base).n_shell_vertices


def test_a_validation_case_s_band_test_is_compared_a_transfer_case_s_not():
    """The band test decides the verdict on the validation cases only: there a band that
    passes on the model and fails refined fails the check; on a transfer case it does not."""
    own = [_record("E3/KPBW/2", after=4, band=True), _record("E1/KPBW/1", band=True)]
    runs = (_record("E3/KPBW/2", band=False), _record("E1/KPBW/1", band=True))
    check = convergence_check(ConvergenceRecord(refinement=2, runs=runs), own, True)
    assert check.line() == (
        "convergence check: failed (E3/KPBW/2's band test passes on the model, fails refined, "
        "every mesh spacing and the time step halved)"
    )
    runs = (_record("E3/KPBW/2", band=True), _record("E1/KPBW/1", band=False))
    check = convergence_check(ConvergenceRecord(refinement=2, runs=runs), own, True)
    assert check.outcome == "passed"


def test_a_case_without_a_verdict_on_either_model_is_not_compared():
    def ended(case, status):
        return _record(case).model_copy(update={"status": status, "verdict": None})

    both = ConvergenceRecord(refinement=2, runs=(ended("E1/PB/1", "unstable"),))
    check = convergence_check(both, [ended("E1/PB/1", "timeout")], True)
    assert check.line() == (
        "convergence check: not run (E1/PB/1: the model's run ended timeout, the refined run "
        "ended unstable)"
    )
    # a case that differs fails the check, and the detail names the cases not compared too
    runs = (_record("E3/KPBW/2", passed=False), ended("E1/PB/1", "unstable"))
    own = [_record("E3/KPBW/2", after=4), _record("E1/PB/1")]
    check = convergence_check(ConvergenceRecord(refinement=2, runs=runs), own, True)
    assert check.outcome == "failed"
    assert check.detail.endswith("; not compared: E1/PB/1: the refined run ended unstable")


def test_the_refinement_alone_does_not_change_a_study_s_fingerprint(tmp_path):
    import yaml

    plain = write_study(tmp_path / "a")
    doc = yaml.safe_load(plain.read_text())
    del doc["validation"]
    plain.write_text(yaml.safe_dump(doc))
    refined = tmp_path / "a" / "refined.yaml"
    refined.write_text(yaml.safe_dump({**doc, "validation": {"refinement": 3}}))
    assert load_study(refined).refinement == 3
    assert load_study(refined).fingerprint == load_study(plain).fingerprint
    doc["validation"] = {"speed_setting": 2}
    other = tmp_path / "a" / "other.yaml"
    other.write_text(yaml.safe_dump(doc))
    assert load_study(other).fingerprint != load_study(plain).fingerprint


def test_a_refined_run_that_did_not_finish_is_not_compared():
    own = [_record("E1/PB/1")]
    broken = _record("E1/PB/1").model_copy(
        update={"status": "timeout", "verdict": None, "message": "wall-clock limit reached"}
    )
    check = convergence_check(ConvergenceRecord(refinement=2, runs=(broken,)), own, True)
    assert check.line() == (
        "convergence check: not run (E1/PB/1: the refined run ended timeout (wall-clock limit "
        "reached))"
    )
    # a case validated and transferred is paired with its validation
    judged = [_record("E3/KPBW/2", after=4), _record("E3/KPBW/2", passed=False)]
    same = ConvergenceRecord(refinement=2, runs=(_record("E3/KPBW/2"),))
    assert convergence_check(same, judged, True).outcome == "passed"


def test_a_simulator_that_cannot_be_refined_leaves_the_check_not_run(tmp_path, monkeypatch):
    monkeypatch.setenv("FAKE_SIM_FIXED", "1")  # runs as the analytic simulator, no refinement
    path = write_study(
        tmp_path, simulator={"backend": "python", "factory": "tests.fake_sim:make_broken"}
    )
    out = tmp_path / "out"
    Calibration(load_study(path), out, figures=False).run()
    results = read_results(out)
    verdict = study_verdict(results, results.cases, stopped=True)
    assert verdict.convergence.outcome == "not run"
    assert "BrokenSimulator simulator cannot be refined" in verdict.convergence.detail
    assert verdict.level == "incomplete"


def test_the_check_runs_again_for_other_parameters_or_another_refinement(tmp_path, monkeypatch):
    """A stored check is reused only for the same parameters and refinement; the refinement
    may change on a finished study (it is not part of the study's fingerprint)."""
    from parcelfit.study.store import STORE_FILE, Store

    path = write_study(tmp_path)
    out = tmp_path / "out"
    Calibration(load_study(path), out, figures=False).run()
    log = tmp_path / "log.txt"
    monkeypatch.setenv("FAKE_SIM_LOG", str(log))
    store = Store(out / STORE_FILE)
    try:
        doc = store.get_meta("convergence")
        doc["runs"][0]["params"]["mu_d_BePa"] += 0.01  # as if other parameters were checked
        store.set_meta("convergence", doc)
    finally:
        store.close()
    Calibration(load_study(path), out, figures=False).run()
    assert log.read_text().count("refined-R-P-2") == 1
    assert read_results(out).convergence.refinement == 2
    finer = write_study(
        tmp_path / "finer", validation={"speed_setting": 2, "every": 2, "refinement": 3}
    )
    assert load_study(finer).fingerprint == load_study(path).fingerprint
    Calibration(load_study(finer), out, figures=False).run()
    assert log.read_text().count("refined-R-P-2") == 2
    assert read_results(out).convergence.refinement == 3


def test_the_cost_estimate_counts_the_refined_runs():
    from parcelfit.sim.cost import refined_seconds, run_seconds
    from parcelfit.sim.factory import SimulatorConfig

    rigid = SimulatorConfig("mujoco", rig="E3", consignment="KPBW")
    assert refined_seconds(rigid, 2) == pytest.approx(2 * run_seconds(rigid))  # measured
    soft = SimulatorConfig("mujoco", rig="E3", consignment="PB")
    assert refined_seconds(soft, 2) == pytest.approx(8 * run_seconds(soft))  # not measured
    box = SimulatorConfig("rigidbox", rig="E3", consignment="KPBW")
    assert refined_seconds(box, 2) == pytest.approx(8 * run_seconds(box))
    full = SimulatorConfig("mujoco", rig="E3", consignment="KPBW", shell_dof="full")
    assert refined_seconds(full, 2) == pytest.approx(8 * run_seconds(full))
    python = SimulatorConfig("python", factory="tests.fake_sim:make")
    assert refined_seconds(python, 2) == pytest.approx(2 * run_seconds(python))


def test_the_calibration_estimate_adds_one_run_per_judged_case_where_it_can_refine(tmp_path):
    from dataclasses import replace

    from parcelfit.study.estimate import calibration_estimate

    study = load_study(write_study(tmp_path))  # python backend: its factory's may refine
    assert (
        calibration_estimate(study, 2).simulations
        == calibration_estimate(replace(study, refinement=1), 2).simulations + 1
    )
    solver = replace(study.simulator, backend="external", external="solver.yaml", factory=None)
    external = replace(study, simulator=solver)
    assert (
        calibration_estimate(external, 2).simulations
        == calibration_estimate(replace(external, refinement=1), 2).simulations
    )
    mujoco = replace(
        study, simulator=replace(study.simulator, backend="mujoco", rig="E3", consignment="KPBW")
    )
    assert (
        calibration_estimate(mujoco, 2).simulations
        == calibration_estimate(replace(mujoco, refinement=1), 2).simulations + 1
    )
