import math

import numpy as np
import pytest
from typer.testing import CliRunner

from parcelfit.cli import app
from parcelfit.runs import read_trajectory

runner = CliRunner()


@pytest.mark.slow
@pytest.mark.mujoco
def test_simulate_writes_run_and_animation(tmp_path):
    out, gif = tmp_path / "run.csv", tmp_path / "run.gif"
    result = runner.invoke(
        app,
        [
            "simulate",
            "--rig",
            "E1",
            "--consignment",
            "BW",
            "--setting",
            "2",
            "--set",
            "mu_d_BePa=0.4",
            "--out",
            str(out),
            "--video",
            str(gif),
            # the command's files, not the physics: a coarse step and mesh keep it quick
            "--timestep",
            "0.00083333",
            "--spacing",
            "0.05",
        ],
    )
    assert result.exit_code == 0, result.output
    assert "ok:" in result.output and "transit time:" in result.output
    traj = read_trajectory(out)
    turned = math.degrees(np.unwrap(traj.theta)[-1] - np.unwrap(traj.theta)[0])
    assert f"rotation: {turned:+.2f} degrees" in result.output
    assert traj.sample_rate() == pytest.approx(60.0, rel=0.01)
    assert traj.x[-1] > traj.x[0] + 1.0
    assert gif.read_bytes()[:6] in (b"GIF89a", b"GIF87a")


@pytest.mark.slow
@pytest.mark.mujoco
def test_simulate_says_when_its_start_lies_across_the_first_light_barrier(tmp_path):
    from parcelfit.sim.mujoco.bundled import resolve_file

    text = resolve_file("rigs", "E1", "rig").read_text()
    assert "start: {position: [-0.6, 0.0]" in text
    rig = tmp_path / "E1-late.yaml"  # LS1 lies at x = -0.3
    rig.write_text(
        text.replace("name: E1", "name: E1-late").replace(
            "start: {position: [-0.6, 0.0]", "start: {position: [-0.3, 0.0]"
        )
    )
    result = runner.invoke(
        app,
        ["simulate", "--rig", str(rig), "--consignment", "KP", "--out", str(tmp_path / "r.csv"),
         "--timestep", "0.00083333", "--spacing", "0.05"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert (
        "transit time: not measured (LS1 already broken at the start, the parcel's start lying "
        "across it: move the rig file's start.position back)"
    ) in " ".join(result.output.split())


@pytest.mark.slow
@pytest.mark.mujoco
def test_simulate_repeat_on_a_rig_without_scatter_says_its_runs_are_alike(tmp_path):
    from parcelfit.sim.mujoco.bundled import resolve_file

    text = resolve_file("rigs", "E1", "rig").read_text()
    scatter = "\n        scatter: {along: 0.005, across: 0.005, heading: 1.5}}"
    assert scatter in text
    rig = tmp_path / "E1-fixed.yaml"
    rig.write_text(text.replace("name: E1", "name: E1-fixed").replace(scatter, "}"))
    result = runner.invoke(
        app,
        ["simulate", "--rig", str(rig), "--consignment", "KP", "--out", str(tmp_path / "r.csv"),
         "--repeat", "2", "--workers", "1", "--timestep", "0.00083333", "--spacing", "0.05"],
    )  # fmt: skip
    said = " ".join(result.output.split())
    assert result.exit_code == 0, result.output
    assert (
        "rig E1-fixed has no start.scatter: every placement starts at the nominal pose, so the 2 "
        "runs are alike"
    ) in said
    assert "rank correlation with rotation none (no spread in one of the two)" in said


def test_simulate_bad_input_is_one_message(tmp_path):
    for args, text in (
        (["--rig", "E7"], "unknown rig 'E7'"),
        (["--consignment", "XX"], "unknown consignment type 'XX'"),
        (["--setting", "4"], "rig E3 has no speed setting 4"),
        (["--set", "mu_d_BePa=7"], "outside its physical range"),
        (["--set", "E_Co=0.1"], "E_Co does not apply to rigid contents"),
        (["--rig", str(tmp_path / "nope.yaml")], "file not found"),
        (["--film-spacing", "0.001"], "film mesh spacing around a soft content must lie in"),
    ):
        result = runner.invoke(app, ["simulate", *args, "--out", str(tmp_path / "r.csv")])
        assert result.exit_code == 2, (args, result.output)
        assert text in result.output and "Traceback" not in result.output


def test_malformed_rig_yaml(tmp_path):
    bad = tmp_path / "rig.yaml"
    bad.write_text("name: X\nspeeds: {1: {a: 1}\n")
    result = runner.invoke(app, ["simulate", "--rig", str(bad)])
    assert result.exit_code == 2 and "malformed YAML" in result.output


def test_rigs_and_params_listings():
    result = runner.invoke(app, ["rigs"])
    assert result.exit_code == 0
    for name in ("E1", "E2a", "E2b", "E3", "KPBW", "PB"):
        assert name in result.output
    text = " ".join(result.output.split())
    for unit in ("[m/s]", "[g]", "[mm]"):  # units are shown, not eaten as markup
        assert unit in text
    result = runner.invoke(app, ["params", "--consignment", "PB"])
    assert (
        result.exit_code == 0
        and "18 parameters for PB" in result.output
        and "E_Co" in result.output
    )
    result = runner.invoke(app, ["params"])
    assert "16 parameters for KPBW" in result.output


@pytest.mark.slow
@pytest.mark.mujoco
def test_simulate_refined_is_the_run_at_the_divided_step_and_spacing(tmp_path):
    """--refinement 2 runs the scene with its step and mesh spacing halved: the same run, to
    the bit, as giving the halved values (the convergence check's refined model)."""
    # BW (its shell's contact points follow the spacing) from a coarse start: the test is about the
    # refinement's arithmetic, not convergence
    common = ["simulate", "--rig", "E3", "--consignment", "BW", "--setting", "2"]
    refined, given = tmp_path / "refined.csv", tmp_path / "given.csv"
    for out, flags in (
        (refined, ["--timestep", repr(1 / 600), "--spacing", "0.1", "--refinement", "2"]),
        (given, ["--timestep", repr(1 / 1200), "--spacing", "0.05"]),
    ):
        result = runner.invoke(app, [*common, *flags, "--out", str(out)])
        assert result.exit_code == 0, result.output
    a, b = read_trajectory(refined), read_trajectory(given)
    assert len(a.t) == len(b.t) > 30
    for name in ("t", "x", "y", "theta"):
        assert (getattr(a, name) == getattr(b, name)).all(), name
    result = runner.invoke(app, [*common, "--refinement", "5", "--out", str(tmp_path / "r.csv")])
    assert result.exit_code == 2 and "--refinement" in result.output
