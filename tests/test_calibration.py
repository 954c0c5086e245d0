import os
import signal
import sqlite3
import subprocess
import sys
import time

import pytest

from parcelfit import ParcelfitError
from parcelfit.study.calibration import Calibration
from parcelfit.study.status import study_status
from parcelfit.study.studyfile import load_study

from .fake_sim import TRUTH
from .helpers import ROOT, finished_fits, write_study


@pytest.mark.slow
def test_calibration_recovers_the_truth_and_validates(tmp_path):
    study = load_study(write_study(tmp_path, executor={"kind": "serial"}))
    seen = []
    result = Calibration(study, tmp_path / "out", progress=seen.append, figures=False).run()
    assert result.stop_reason == "validation passed" and result.validated
    # validation passes after iteration 4 (24 evaluations), before the optimiser has homed in:
    # the recommended mu_d_BePa is then 12 % of its range from the truth with the default
    # optimiser (9.5 % with the one before it), mu_d_MePa 1 %
    for name, (low, high) in {"mu_d_BePa": (0.3, 0.6), "mu_d_MePa": (0.15, 0.35)}.items():
        assert abs(result.best_params[name] - TRUTH[name]) < 0.15 * (high - low)
    assert seen and seen[-1].last_validation is True
    info = study_status(tmp_path / "out")
    assert info.evaluations == result.evaluations and info.pending == 0
    assert info.validations[-1].passed is True
    assert (tmp_path / "out" / "runs" / "fit-000-00.csv").is_file()
    from parcelfit.study.plots import study_figures

    names = sorted(p.name for p in study_figures(tmp_path / "out"))
    assert names == sorted(
        f"{n}.{ext}" for n in ("history", "traces", "partial_dependence") for ext in ("png", "svg")
    )
    # a finished study resumed does nothing more
    again = Calibration(study, tmp_path / "out", figures=False).run()
    assert again.evaluations == result.evaluations and again.stop_reason == "validation passed"


@pytest.mark.slow
def test_failed_simulations_are_recorded_and_do_not_stop_the_loop(tmp_path):
    study = load_study(
        write_study(
            tmp_path,
            parameters={"mu_d_BePa": [0.45, 0.7], "mu_d_MePa": [0.15, 0.35]},
            validation={},
            budget=16,
            executor={"kind": "serial"},
        )
    )
    result = Calibration(study, tmp_path / "out", figures=False).run()
    info = study_status(tmp_path / "out")
    assert result.evaluations == 16 and result.stop_reason == "budget spent"
    assert info.by_status.get("unstable", 0) > 0 and info.by_status["ok"] > 0


@pytest.mark.slow
def test_a_changed_study_file_is_refused_for_the_same_folder(tmp_path):
    path = write_study(tmp_path, budget=8, validation={}, executor={"kind": "serial"})
    Calibration(load_study(path), tmp_path / "out", figures=False).run()
    write_study(tmp_path, budget=12, validation={}, executor={"kind": "serial"})
    calibration = Calibration(load_study(path), tmp_path / "out")  # opens nothing yet
    with pytest.raises(ParcelfitError, match="different study file"):
        calibration.run()


@pytest.mark.parametrize(
    ("change", "pattern"),
    [
        ({"simulator": {"backend": "fortran"}}, r"simulator\.backend: unknown backend 'fortran'"),
        ({"parameters": {"mu_d_BePa": [0.6, 0.3]}}, r"parameters\.mu_d_BePa: .*low < high"),
        ({"parameters": {"mu_d_BePa": "wide"}}, r"parameters\.mu_d_BePa: expected \[low, high\]"),
        (
            {"validation": {"speed_setting": 1}},
            r"validation\.speed_setting: validation must use a speed setting",
        ),
        ({"optimizer": {"lambda": 2}}, r"optimizer: unknown key 'lambda'"),
        ({"budgett": 3}, r"top level: unknown key 'budgett'.*did you mean 'budget'"),
    ],
)
def test_bad_study_files(tmp_path, change, pattern):
    with pytest.raises(ParcelfitError, match=pattern):
        load_study(write_study(tmp_path, **change))


@pytest.mark.slow
def test_sigkill_at_any_moment_then_rerun_resumes_without_losing_or_repeating(
    tmp_path, monkeypatch, no_study_figures
):
    from typer.testing import CliRunner

    from parcelfit.cli import app

    study = write_study(tmp_path, budget=24, validation={})
    out = tmp_path / "out"
    log = tmp_path / "simulated.log"
    env = {
        **os.environ,
        "FAKE_SIM_DELAY": "0.15",
        "FAKE_SIM_LOG": str(log),
        "PYTHONPATH": str(ROOT),
    }
    cmd = [
        sys.executable,
        "-m",
        "parcelfit",
        "calibrate",
        str(study),
        "--out",
        str(out),
        "--workers",
        "2",
    ]
    proc = subprocess.Popen(
        cmd,
        cwd=ROOT,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    deadline = time.time() + 120
    while (
        len(finished_fits(out / "study.sqlite")) < 10
        and time.time() < deadline
        and proc.poll() is None
    ):
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)  # the loop and its workers, mid-batch
    proc.wait()
    before = finished_fits(out / "study.sqlite")
    assert 10 <= len(before) < 24
    monkeypatch.setenv("FAKE_SIM_LOG", str(log))  # the workers of the rerun log there too
    done = CliRunner().invoke(app, cmd[3:])  # the same command, in this process
    assert done.exit_code == 0, done.output
    after = finished_fits(out / "study.sqlite")
    assert len(after) == 24
    assert all(after[k] == v for k, v in before.items())  # nothing finished was lost or redone
    runs = log.read_text().split()
    con = sqlite3.connect(out / "study.sqlite")
    labels = {
        row[0]: f"fit-{row[1]:03d}-{row[2]:02d}"
        for row in con.execute("SELECT id, iteration, slot FROM evaluations")
    }
    con.close()
    for row_id in before:  # every evaluation finished before the kill was simulated exactly once
        assert runs.count(labels[row_id]) == 1


@pytest.mark.slow
def test_validation_records_the_envelope_beside_the_published_verdict(tmp_path):
    from parcelfit.study.store import Store

    study = load_study(
        write_study(
            tmp_path,
            budget=12,
            validation={"speed_setting": 2, "every": 1},
            executor={"kind": "serial"},
        )
    )
    Calibration(study, tmp_path / "out", figures=False).run()
    v = Store(tmp_path / "out" / "study.sqlite").evaluations("validation")[-1]
    env = v.details.envelope
    assert env is not None
    assert set(env.to_json()) == {
        "inside_y",
        "inside_theta",
        "worst_y_m",
        "worst_theta_rad",
        "passed",
    }
    assert env.inside_y is not None and 0.0 <= env.inside_y <= 1.0


@pytest.mark.slow
def test_figures_refit_the_surrogate_with_the_study_s_own_optimizer_settings(tmp_path):
    from parcelfit.optimize.bo import BOSettings
    from parcelfit.study.plots import study_optimizer
    from parcelfit.study.results import read_results

    study = write_study(
        tmp_path,
        optimizer={"sampler": "published", "n_samples": 1000, "n_restarts": 1},
        initial=4,
        batch_size=2,
        budget=4,
        executor={"kind": "serial"},
    )
    calibration = Calibration(load_study(study), tmp_path / "out")
    used = calibration.bo.settings
    calibration.run()
    rebuilt = study_optimizer(tmp_path / "out")
    assert rebuilt is not None and rebuilt.settings == used
    assert used.batch == "kmeans" and used.noise == "fixed" and used != BOSettings()
    assert rebuilt.n_told == 4
    # the surrogate the calibration stores for the report was fitted with the same settings
    surrogate = read_results(tmp_path / "out").surrogate
    assert surrogate.optimizer.sampler == "published" and surrogate.optimizer.recorded
    assert BOSettings(**surrogate.optimizer.settings) == used and surrogate.evaluations == 4


def test_study_results_round_trip_through_results_json(tmp_path):
    import numpy as np

    from parcelfit.metrics import select_reference
    from parcelfit.runs import TestCase, load_dataset
    from parcelfit.study.identify import Advice, Identifiability, ParameterInterval
    from parcelfit.study.results import (
        DependenceCurve,
        KeyFramesRecord,
        ReferenceRecord,
        SurrogateRecord,
        new_results,
        read_results,
        validation_record,
        write_results,
    )
    from parcelfit.study.store import OptimizerRecord

    from .fake_sim import trajectory, write_reference_dataset

    write_reference_dataset(tmp_path / "data")
    sel = select_reference(load_dataset(tmp_path / "data")[TestCase("R", "P", 2)])
    traj, transit = trajectory({"mu_d_BePa": 0.5, "mu_d_MePa": 0.2}, 2)
    val = validation_record(sel, traj, transit, params={"mu_d_BePa": 0.5}, after_iteration=3)
    failed = validation_record(sel, None, None, status="unstable", message="blew up")
    assert val.verdict is not None and val.band is not None and failed.verdict is None
    curve = DependenceCurve(
        name="E_Pa", values=np.linspace(200, 1600, 5), cost=np.arange(5.0), sd=np.ones(5), log=True
    )
    opt = OptimizerRecord(sampler="published", settings={"batch": "kmeans"})
    written = new_results(
        {"validation": ReferenceRecord.from_selection(sel)},
        [failed, val],
        stop_reason="validation passed",
        surrogate=SurrogateRecord(optimizer=opt, evaluations=12, curves=(curve,)),
        key_frames=KeyFramesRecord(case="R/P/2", params={"mu_d_BePa": 0.5}, note="MuJoCo only"),
        figures=["figures/history.png"],
        identifiability=Identifiability(
            parameters=(
                ParameterInterval(
                    name="E_Pa",
                    low=2e8,
                    high=1.6e9,
                    interval=(3e8, 1.5e9),
                    median=9e8,
                    verdict="narrowed",
                    rhat=1.01,
                ),
            ),
            correlation=np.eye(1),
            sample=np.linspace(3e8, 1.5e9, 7)[:, None],
            threshold=0.9,
            threshold_source="largest equation (3) of a real run",
            evaluations=12,
            noise_sd=0.1,
        ),
        transfer=[val],
        advice=Advice(
            changes={"R/P/2": {"E_Pa": 0.3}},
            best="R/P/2",
            parameters=("E_Pa",),
            params={"E_Pa": 9e8},
        ),
        cases=[{"case": "R/P/2", "role": "validation", "weight": 1.0}],
    )
    assert read_results(tmp_path) is None  # none written yet
    write_results(tmp_path, written)
    back = read_results(tmp_path)
    assert back.to_json() == written.to_json()  # every field survives, arrays included
    ref = back.references["validation"]
    assert ref.reference_id == sel.reference_id and np.array_equal(ref.d_xy, sel.d_xy)
    assert all(np.array_equal(a, b) for a, b in zip(ref.xy_series, sel.xy_series, strict=True))
    shown = back.shown_validation()
    assert shown.after_iteration == 3 and shown.verdict == val.verdict
    assert np.array_equal(shown.sim_xy, val.sim_xy) and np.array_equal(
        shown.band.grid, val.band.grid
    )
    assert back.surrogate.optimizer == opt and back.surrogate.curves[0].name == "E_Pa"
    assert back.key_frames.note == "MuJoCo only" and back.stop_reason == "validation passed"
    assert back.identifiability.parameters[0].verdict == "narrowed"
    assert back.transfer[0].verdict == val.verdict and back.advice.best == "R/P/2"
    (tmp_path / "results.json").write_text("{")
    with pytest.raises(ParcelfitError, match="results file is unreadable"):
        read_results(tmp_path)


@pytest.mark.slow
def test_rerunning_a_finished_study_writes_its_missing_results_without_simulating(
    tmp_path, monkeypatch
):
    from parcelfit.study.results import read_results

    study = load_study(
        write_study(
            tmp_path,
            initial=4,
            batch_size=2,
            budget=6,
            validation={"speed_setting": 2, "every": 1},
            executor={"kind": "serial"},
        )
    )
    out = tmp_path / "out"
    Calibration(study, out, figures=False).run()
    first = read_results(out)
    assert first.stop_reason is not None and first.validations and first.surrogate.curves
    # a folder as an earlier parcelfit left it: no results.json
    (out / "results.json").unlink()
    log = tmp_path / "sims.log"
    monkeypatch.setenv("FAKE_SIM_LOG", str(log))
    Calibration(study, out, figures=False).run()
    assert not log.exists()  # nothing simulated again
    again = read_results(out)
    assert again.surrogate.to_json() == first.surrogate.to_json()
    # judged again from the run files: the same records, numbers and all (a run file keeps
    # every digit of the run)
    assert len(again.validations) == len(first.validations)
    for a, b in zip(again.validations, first.validations, strict=True):
        assert a.verdict is not None and a.sim_xy is not None and a.band is not None
        assert a.to_json() == b.to_json()
    # with its results file in place, a resumed study keeps the records as they were
    Calibration(study, out, figures=False).run()
    kept = read_results(out)
    assert [v.to_json() for v in kept.validations] == [v.to_json() for v in again.validations]


def _tree(folder):
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*"))


def test_constructing_a_calibration_reads_and_writes_nothing(tmp_path):
    """A missing dataset, an output folder that cannot be made, a simulator factory that does
    not import: the constructor keeps its inputs; `run` (through `prepare`) meets each one."""
    study_file = write_study(
        tmp_path / "study",
        reference={"dataset": "nowhere", "rig": "R", "consignment": "P", "speed_setting": 1},
        simulator={"backend": "python", "factory": "tests.no_such_module:make"},
    )
    study = load_study(study_file)
    (tmp_path / "blocked").write_text("a file where the output folder's parent would be")
    before = _tree(tmp_path)
    outs = [tmp_path / "out" / "deeper", tmp_path / "blocked" / "out"]
    calibrations = [Calibration(study, out) for out in outs]
    assert _tree(tmp_path) == before  # no folder, store or lock file
    with pytest.raises(RuntimeError, match="not open"):
        calibrations[0].store  # noqa: B018
    with pytest.raises(ParcelfitError, match=r"no dataset\.yaml here") as missing:
        calibrations[0].run()
    assert missing.value.file == str(study.dataset)
    with pytest.raises(ParcelfitError, match="cannot create the study folder"):
        calibrations[1].run()  # under a file
    assert (tmp_path / "blocked").is_file()


def test_prepare_opens_the_study_and_run_closes_it(tmp_path):
    from parcelfit.study.folderlock import lock_folder
    from parcelfit.study.store import STORE_FILE

    study = load_study(write_study(tmp_path, simulator={"backend": "python", "factory": "x:y"}))
    calibration = Calibration(study, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(ParcelfitError, match="cannot import the simulator factory"):
        calibration.prepare()
    lock_folder(tmp_path / "out", "a test").release()  # the failed prepare released it
    study = load_study(write_study(tmp_path / "good"))
    calibration = Calibration(study, tmp_path / "good" / "out", figures=False)
    calibration.prepare()
    assert (tmp_path / "good" / "out" / STORE_FILE).is_file()
    assert calibration.reference.reference_id == calibration.store.get_meta("reference_run")
    assert calibration.val_reference is not None and calibration.simulator is not None
    calibration.prepare()  # once open, nothing more to do
    calibration.close()
    with pytest.raises(RuntimeError, match="make a new one"):
        calibration.run()
