"""Helpers shared by test modules: study files for the fake simulator, store reads, a DTW peer."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import dtw as dtw_python
import numpy as np
import yaml

from .fake_sim import write_reference_dataset

ROOT = Path(__file__).resolve().parents[1]


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
