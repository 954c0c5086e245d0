from dataclasses import replace
from pathlib import Path

import pytest

from parcelfit import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim import SimStatus, Simulator, defaults_si
from parcelfit.sim.external import ExternalSimulator, load_external_solver

SOLVER = Path(__file__).parent / "data" / "external" / "solver.yaml"
CASE = TestCase("E1", "KPBW", 1)


@pytest.fixture
def sim(tmp_path):
    return ExternalSimulator(load_external_solver(SOLVER), workroot=tmp_path)


def test_runs_the_solver_and_reads_the_trajectory(sim):
    assert isinstance(sim, Simulator)
    params = {**defaults_si("rigid"), "mu_d_BePa": 0.5}
    res = sim.run(params, CASE)
    assert res.status is SimStatus.OK, res.diagnostics
    traj = res.run.trajectory
    # the fake solver accelerates at a = mu * g in steps of 1/60 s: x_2 = (1 + 2) a / 60^2
    assert traj.x[2] == pytest.approx(3 * 0.5 * 9.81 / 60**2, rel=1e-6)
    assert res.run.transit_time == pytest.approx(1.0)
    rendered = (Path(res.diagnostics["workdir"]) / "params.txt").read_text()
    assert "mu_d_BePa = 0.5" in rendered and "E1 / KPBW / setting 1" in rendered
    assert res.run.case == CASE


def test_a_run_without_a_transit_file_has_no_transit_time(sim):
    res = sim.run({**defaults_si("rigid"), "mu_d_BePa": 0.13}, CASE)
    assert res.status is SimStatus.OK, res.diagnostics
    assert res.run.transit_time is None and len(res.run.trajectory.t) == 61


def test_failures_and_timeouts_become_statuses(sim):
    res = sim.run({**defaults_si("rigid"), "mu_d_BePa": 0.11}, CASE)
    assert res.status is SimStatus.FAILED
    assert "exited with status 3" in res.diagnostics["message"]
    assert "diverged at step 42" in res.diagnostics["output_tail"]
    quick = ExternalSimulator(replace(sim.solver, timeout=0.5), workroot=sim.workroot)
    res = quick.run({**defaults_si("rigid"), "mu_d_BePa": 0.12}, CASE)
    assert res.status is SimStatus.TIMEOUT and res.wall_time < 5


def test_missing_output_and_missing_program(sim):
    writes_elsewhere = (*sim.solver.command[:3], "elsewhere.csv")
    broken = ExternalSimulator(replace(sim.solver, command=writes_elsewhere), workroot=sim.workroot)
    res = broken.run(defaults_si("rigid"), CASE)
    assert res.status is SimStatus.FAILED
    # the missing file named as the solver description calls it, with the folder it is missing in
    assert res.diagnostics["message"] == (
        f"the solver exited 0 but wrote no {sim.solver.output_file} in its work folder "
        f"{res.diagnostics['workdir']} (output_file in the solver description; its own output "
        "is in parcelfit-solver.stdout and parcelfit-solver.stderr there)"
    )
    absent = ExternalSimulator(
        replace(sim.solver, command=("no-such-solver-binary",)), workroot=sim.workroot
    )
    assert absent.run(defaults_si("rigid"), CASE).status is SimStatus.FAILED


def test_arguments_are_not_passed_through_a_shell(sim, tmp_path):
    marker = tmp_path / "pwned"
    evil = ExternalSimulator(
        replace(
            sim.solver,
            command=("python3", "-c", "import sys; print(sys.argv)", f"; touch {marker}"),
        ),
        workroot=sim.workroot,
    )
    evil.run(defaults_si("rigid"), CASE)
    assert not marker.exists()


def test_unknown_placeholder_and_bad_description(sim, tmp_path):
    bad = ExternalSimulator(
        replace(sim.solver, template="mu = ${mu_dynamic}"), workroot=sim.workroot
    )
    with pytest.raises(ParcelfitError, match=r"unknown placeholder \$\{mu_dynamic\}"):
        bad.run(defaults_si("rigid"), CASE)
    desc = tmp_path / "s.yaml"
    desc.write_text("name: x\ncommand: run.sh --fast\ntemplate: t.tmpl\n")
    with pytest.raises(ParcelfitError, match="command must be a non-empty list"):
        load_external_solver(desc)
    desc.write_text("name: x\ncommand: [run]\ntemplate: missing.tmpl\n")
    with pytest.raises(ParcelfitError, match=r"template 'missing\.tmpl' not found"):
        load_external_solver(desc)


def test_output_goes_to_files_stdin_is_empty_and_a_signal_is_named(sim):
    import sys

    says = (
        "import os, signal, sys; print('stdin:', repr(sys.stdin.read())); sys.stdout.flush(); "
        "print('solver: out of memory', file=sys.stderr); sys.stderr.flush(); "
        "os.kill(os.getpid(), signal.SIGTERM)"
    )
    killed = ExternalSimulator(
        replace(sim.solver, command=(sys.executable, "-c", says)), workroot=sim.workroot
    )
    res = killed.run(defaults_si("rigid"), CASE)
    assert res.status is SimStatus.FAILED
    workdir = Path(res.diagnostics["workdir"])
    assert res.diagnostics["message"] == (
        "the solver was killed by signal SIGTERM: solver: out of memory "
        f"(its output: parcelfit-solver.stderr in {workdir})"
    )
    assert (workdir / "parcelfit-solver.stdout").read_text() == "stdin: ''\n"
    assert (workdir / "parcelfit-solver.stderr").read_text() == "solver: out of memory\n"
    clash = ExternalSimulator(
        replace(sim.solver, output_file="parcelfit-solver.stdout"), workroot=sim.workroot
    )
    with pytest.raises(ParcelfitError, match=r"may not be named parcelfit-solver\.stderr or"):
        clash.run(defaults_si("rigid"), CASE)


def _copy_solver(tmp_path: Path, template: str | None = None, command=None) -> Path:
    import shutil

    import yaml

    folder = tmp_path / "solver"
    shutil.copytree(SOLVER.parent, folder)
    if template is not None:
        (folder / "params.tmpl").write_text(template)
    if command is not None:
        doc = yaml.safe_load((folder / "solver.yaml").read_text())
        doc["command"] = command
        (folder / "solver.yaml").write_text(yaml.safe_dump(doc))
    return folder / "solver.yaml"


def test_placeholders_are_checked_before_anything_runs(tmp_path):
    from parcelfit.sim.external import check_placeholders

    # a placeholder that names nothing the study has: refused, naming the key and the fix
    bad = _copy_solver(tmp_path, template="x = ${k_MePaa}\nd = ${damping}\n$$5\n")
    solver = load_external_solver(bad)  # well formed: unknown names need the study's
    with pytest.raises(ParcelfitError) as err:
        check_placeholders(solver, bad, ["mu_d_BePa", "damping"])
    text = str(err.value)
    assert text.startswith(f"{bad}: template: the parameter template uses the unknown")
    assert "placeholder ${k_MePaa}" in text and "a parameter the study fits or fixes" in text
    # the solver's own parameter (one the study fits), a catalogue one, $$: all taken
    fine = _copy_solver(tmp_path / "f", template="d = ${damping}\nk = ${k_MePa}\n$$5\n")
    check_placeholders(load_external_solver(fine), fine, ["damping"])
    command = _copy_solver(tmp_path / "c", command=["python3", "${solver_dirr}/fake_solver.py"])
    with pytest.raises(ParcelfitError, match=r"command: .*unknown placeholder \$\{solver_dirr\}"):
        check_placeholders(load_external_solver(command), command, [])
    # a malformed placeholder is refused as soon as the description is read
    broken = _copy_solver(tmp_path / "b", template="x = ${mu_d_BePa\n")
    with pytest.raises(ParcelfitError, match=r"template: the parameter template has a malformed"):
        load_external_solver(broken)


def test_a_study_with_a_solver_refuses_an_unknown_placeholder_on_load(tmp_path):
    import shutil

    from parcelfit.study.studyfile import load_study

    root = Path(__file__).resolve().parents[1] / "examples" / "own-solver"
    folder = tmp_path / "own-solver"
    shutil.copytree(root, folder)
    study = next(folder.glob("*study*.yaml"))
    template = next(folder.glob("*.tmpl"))
    template.write_text(template.read_text() + "extra = ${not_a_parameter}\n")
    with pytest.raises(ParcelfitError, match=r"unknown placeholder \$\{not_a_parameter\}"):
        load_study(study)


@pytest.mark.parametrize(
    "encoded",
    [
        "'\\ufeff1.25'.encode('utf-8')",
        "'1.25'.encode('utf-16')",
        "'1.25'.encode('utf-32')",
        "b'1.25'",
    ],
)
def test_a_transit_file_in_utf16_or_with_a_byte_order_mark_is_read(tmp_path, encoded):
    import sys

    writes = (
        "import sys\n"
        "rows = ['t,x,y,theta'] + [f'{k / 60},{k / 100},0,0' for k in range(30)]\n"
        "open(sys.argv[1], 'w').write('\\n'.join(rows) + '\\n')\n"
        f"open('transit.txt', 'wb').write({encoded})\n"
    )
    solver = _copy_solver(tmp_path, command=[sys.executable, "-c", writes, "${output_file}"])
    res = ExternalSimulator(load_external_solver(solver), workroot=tmp_path / "runs").run(
        {"mu_d_BePa": 0.5}, CASE
    )
    assert res.status is SimStatus.OK, res.diagnostics
    assert res.run.transit_time == 1.25


def test_a_catalogue_parameter_neither_fitted_nor_fixed_takes_its_default(tmp_path):
    from parcelfit.sim.params import parameter

    solver = _copy_solver(tmp_path, template="k = ${k_MePa}\nE = ${E_Co}\nmu = ${mu_d_BePa}\n")
    sim = ExternalSimulator(load_external_solver(solver), workroot=tmp_path / "runs")
    res = sim.run({"mu_d_BePa": 0.5}, CASE)  # the study fits mu_d_BePa alone
    rendered = (Path(res.diagnostics["workdir"]) / "params.txt").read_text().splitlines()
    k = parameter("k_MePa")
    assert rendered[0] == f"k = {k.to_si(k.range_for('rigid').default)}"
    assert rendered[1].startswith("E = ") and rendered[2] == "mu = 0.5"


@pytest.mark.parametrize(
    ("write", "said"),
    [
        (
            "open('transit.txt', 'w').write('1.2 s\\n')\n",
            "its transit file holds '1.2 s', not a number of seconds Fix: write the transit time "
            "in seconds alone, e.g. 1.234",
        ),
        (
            "open('transit.txt', 'wb').write(b'\\x80\\x811.2')\n",
            "its transit file is not text (neither UTF-8 nor UTF-16 with a byte-order mark) Fix: "
            "write the transit time in seconds alone as UTF-8 text, e.g. 1.234",
        ),
        (  # UTF-16 without its byte-order mark
            "open('transit.txt', 'wb').write('1.2'.encode('utf-16-le'))\n",
            "its transit file is not text (neither UTF-8 nor UTF-16 with a byte-order mark) Fix: "
            "write the transit time in seconds alone as UTF-8 text, e.g. 1.234",
        ),
    ],
)
def test_a_transit_file_that_is_not_a_number_is_named(tmp_path, write, said):
    import sys

    writes = (
        "import sys\n"
        "rows = ['t,x,y,theta'] + [f'{k / 60},{k / 100},0,0' for k in range(30)]\n"
        "open(sys.argv[1], 'w').write('\\n'.join(rows) + '\\n')\n" + write
    )
    solver = _copy_solver(tmp_path, command=[sys.executable, "-c", writes, "${output_file}"])
    res = ExternalSimulator(load_external_solver(solver), workroot=tmp_path / "runs").run(
        {"mu_d_BePa": 0.5}, CASE
    )
    assert res.status is SimStatus.FAILED
    transit = Path(res.diagnostics["workdir"]) / "transit.txt"
    assert res.diagnostics["message"] == f"unusable solver output: {transit}: {said}"
