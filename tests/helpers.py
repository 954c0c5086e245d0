"""Helpers shared by test modules: study files for the fake simulator, store reads, a DTW peer,
and the scripts and benchmarks loaded as modules."""

from __future__ import annotations

import importlib.util
import sqlite3
import sys
from pathlib import Path
from types import ModuleType

import dtw as dtw_python
import numpy as np
import yaml

from .fake_sim import write_reference_dataset

ROOT = Path(__file__).resolve().parents[1]


def load_file_module(relative: str) -> ModuleType:
    """Import a script or benchmark of the repository (``relative`` to its root, e.g.
    ``scripts/catch_window.py``) as a module named after its file; it is registered in
    ``sys.modules`` first, since dataclasses look their module up there."""
    path = ROOT / relative
    spec = importlib.util.spec_from_file_location(path.stem, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def write_study(tmp_path: Path, **overrides) -> Path:
    """Write a study file for the analytic fake simulator (keys in ``overrides`` replace its own)."""
    write_reference_dataset(tmp_path / "data")
    doc = {
        "name": "fake",
        "simulator": {"backend": "python", "factory": "tests.fake_sim:make"},
        "parameters": {"mu_d_BePa": [0.3, 0.6], "mu_d_MePa": [0.15, 0.35]},
        "reference": {"dataset": "data", "rig": "R", "consignment": "P", "speed_setting": 1},
        "validation": {"speed_setting": 2, "every": 2},
        "batch_size": 4,
        "initial": 8,
        "budget": 40,
        "seed": 3,
        "optimizer": {"n_samples": 1000, "n_restarts": 1},
        "executor": {"kind": "local", "workers": 2},
    }
    doc.update(overrides)
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def finished_fits(db: Path) -> dict[int, tuple]:
    """Finished fit evaluations in a study store: {id: (params, cost, finished_at)}."""
    if not db.exists():
        return {}
    con = sqlite3.connect(db, timeout=10)
    try:
        rows = con.execute(
            "SELECT id, params, cost, finished_at FROM evaluations "
            "WHERE kind = 'fit' AND status != 'pending'"
        ).fetchall()
    except sqlite3.OperationalError:
        return {}
    finally:
        con.close()
    return {r[0]: r[1:] for r in rows}


def reference_dtw(a, b, window=None) -> float:
    """DTW distance from the dtw-python package, the peer our implementation is checked against."""
    kwargs = {"distance_only": True}
    if window is not None:
        kwargs.update(window_type="sakoechiba", window_args={"window_size": window})
    return dtw_python.dtw(np.asarray(a, float), np.asarray(b, float), **kwargs).distance


def write_study_store(folder: Path, dataset: Path | None) -> Path:
    """A finished study's store written by hand, no simulation: the initial design (iteration 0:
    one ok, one failed), iteration 1 (two ok), a passed validation after iteration 1, and a
    recommended point that is not the one with the lowest cost. Values are SI."""
    from parcelfit.study.details import EvaluationDetails
    from parcelfit.study.store import RecommendedRecord, Store

    folder.mkdir(parents=True, exist_ok=True)
    store = Store(folder / "study.sqlite")
    # the study and source records as an earlier version wrote them (no optimiser settings)
    old_meta(
        store,
        study={
            "name": "hand",
            "parameters": ["mu_d_BePa", "E_Pa"],
            "bounds": [[0.3, 0.6], [2e8, 1.6e9]],
            "log": [False, False],
            "batch_size": 2,
            "seed": 1,
            "fit_setting": 1,
            "validation_setting": 2,
        },
        source={
            "study_file": None,
            "dataset": None if dataset is None else str(dataset),
            "rig": "R",
            "consignment": "P",
        },
    )
    store.set_meta("reference_run", "R-P-1-0")
    points = [{"mu_d_BePa": 0.3 + 0.05 * k, "E_Pa": 6e8 + 1e8 * k} for k in range(4)]
    ids = store.add_pending("fit", 0, points[:2], 1, [0, 1])
    ids += store.add_pending("fit", 1, points[2:], 1, [2, 3])
    for row, status, cost in zip(
        ids, ["ok", "failed", "ok", "ok"], [0.5, None, 0.2, 0.3], strict=True
    ):
        store.finish(row, status=status, cost=cost)
    (val,) = store.add_pending("validation", 1, [points[3]], 2, [0])
    store.finish(val, status="ok", details=EvaluationDetails(passed=True))
    store.write_recommended(RecommendedRecord(params=points[3], cost=0.3))
    store.set_meta("stop_reason", "validation passed")
    store.close()
    return folder


def old_meta(store, **records) -> None:
    """Write meta records as raw JSON, the way a store of an earlier version holds them."""
    import json

    with store._transaction() as db:
        for key, value in records.items():
            db.execute(
                "INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, json.dumps(value))
            )


def write_study_results(folder: Path, dataset: Path, optimizer=None) -> None:
    """``results.json`` for the store of `write_study_store`, made here without a calibration:
    the reference runs of the fake dataset's R/P/1 and R/P/2, a validation after iteration 1 of
    the analytic run at the truth (the transfer check's and the convergence check's run too), a
    surrogate (sharp along mu_d_BePa, flat along E_Pa) said to
    be fitted with ``optimizer`` (default: the published configuration), no key frames."""
    from dataclasses import asdict

    from parcelfit.metrics import select_reference
    from parcelfit.optimize.bo import BOSettings
    from parcelfit.runs import TestCase, load_dataset
    from parcelfit.study.identify import Advice, Identifiability, ParameterInterval
    from parcelfit.study.results import (
        ConvergenceRecord,
        DependenceCurve,
        KeyFramesRecord,
        ReferenceRecord,
        SurrogateRecord,
        new_results,
        validation_record,
        write_results,
    )
    from parcelfit.study.store import OptimizerRecord

    from .fake_sim import TRUTH, trajectory

    ds = load_dataset(dataset)
    fit, val = (select_reference(ds[TestCase("R", "P", k)]) for k in (1, 2))
    traj, transit = trajectory(TRUTH, 2)
    params = {"mu_d_BePa": 0.45, "E_Pa": 9e8}
    record = validation_record(
        val, traj, transit, params=params, after_iteration=1, run_file="runs/validation-001.csv"
    )
    xs = np.linspace(0.3, 0.6, 31)
    curves = (
        DependenceCurve(
            name="mu_d_BePa",
            values=xs,
            cost=(xs - 0.45) ** 2 * 100,
            sd=np.full(31, 0.05),
            log=False,
        ),
        DependenceCurve(
            name="E_Pa",
            values=np.linspace(200, 1600, 31),
            cost=np.full(31, 0.5),
            sd=np.full(31, 0.05),
            log=False,
        ),
    )
    optimizer = optimizer or OptimizerRecord(
        sampler="published", settings=asdict(BOSettings.published())
    )
    write_results(
        folder,
        new_results(
            {
                "fit": ReferenceRecord.from_selection(fit),
                "validation": ReferenceRecord.from_selection(val),
            },
            [record],
            stop_reason="validation passed",
            surrogate=SurrogateRecord(optimizer=optimizer, evaluations=3, curves=curves),
            key_frames=KeyFramesRecord(
                case="R/P/2",
                params=params,
                note="Key frames are drawn for the MuJoCo backend only.",
            ),
            identifiability=Identifiability(
                parameters=(
                    ParameterInterval(
                        name="mu_d_BePa",
                        low=0.3,
                        high=0.6,
                        interval=(0.43, 0.47),
                        median=0.45,
                        verdict="determined",
                        rhat=1.0,
                    ),
                    ParameterInterval(
                        name="E_Pa",
                        low=2e8,
                        high=1.6e9,
                        interval=(2.1e8, 1.59e9),
                        median=9e8,
                        verdict="undetermined",
                        rhat=1.0,
                    ),
                ),
                correlation=np.array([[1.0, 0.1], [0.1, 1.0]]),
                sample=np.column_stack(
                    [np.linspace(0.43, 0.47, 50), np.linspace(2.1e8, 1.59e9, 50)]
                ),
                threshold=1.2,
                threshold_source="largest equation (3) of a real run: 1.2 (R/P/1)",
                evaluations=3,
                noise_sd=0.1,
            ),
            transfer=[record.model_copy(update={"after_iteration": None})],
            convergence=ConvergenceRecord(
                refinement=2, runs=(record.model_copy(update={"after_iteration": None}),)
            ),
            advice=Advice(
                changes={"R/P/2": {"E_Pa": 0.02}},
                best="R/P/2",
                parameters=("E_Pa",),
                params=params,
            ),
        ),
    )


def intervals_of(names, low=0.0, high=1.0, verdict="undetermined"):
    """An analysis of what the data determine in which every parameter of ``names`` has the
    plausible interval [low, high] (SI) and ``verdict``: the input `design` and `predict` read."""
    from parcelfit.study.identify import Identifiability, ParameterInterval

    return Identifiability(
        parameters=tuple(
            ParameterInterval(
                name=n,
                low=low,
                high=high,
                interval=(low, high),
                median=(low + high) / 2,
                verdict=verdict,
                rhat=1.0,
            )
            for n in names
        ),
        correlation=np.eye(len(names)),
        sample=np.zeros((1, len(names))),
        threshold=1.0,
        threshold_source="by hand",
        evaluations=10,
        noise_sd=0.1,
    )


class CountedExecutors:
    """Wraps an executor factory (called like it): how many executors it made, and how many
    of them were closed; ``calls`` holds the positional arguments of each call."""

    def __init__(self, make):
        self.make, self.made, self.closed, self.calls = make, 0, 0, []

    def __call__(self, *args, **kwargs):
        self.made += 1
        self.calls.append(args)
        executor = self.make(*args, **kwargs)
        close = executor.close

        def counted_close():
            self.closed += 1
            close()

        executor.close = counted_close
        return executor
