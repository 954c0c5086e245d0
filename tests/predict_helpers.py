"""A finished calibration of the analytic test simulator written by hand (no optimisation), for
the prediction and design tests: the study file, its store's source record and a
``results.json`` whose plausible set fixes the two frictions and leaves E_Pa open."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .helpers import write_study

BOUNDS = {"mu_d_BePa": (0.44, 0.46), "mu_d_MePa": (0.19, 0.21), "E_Pa": (2e8, 1.6e9)}


def write_finished_study(tmp_path: Path, rows: int = 400, **study: object) -> Path:
    """A study folder (``tmp_path/study``) whose stored sample of the plausible set is uniform
    on `BOUNDS` (seeded), its study file's keys ``study`` replaced (`write_study`); returns the
    folder."""
    from parcelfit.study.identify import Identifiability, ParameterInterval, verdict
    from parcelfit.study.results import new_results, write_results
    from parcelfit.study.store import SourceRecord, Store

    path = write_study(
        tmp_path,
        parameters={"mu_d_BePa": [0.3, 0.6], "mu_d_MePa": [0.15, 0.35], "E_Pa": [200, 1600]},
        **study,
    )
    folder = tmp_path / "study"
    folder.mkdir()
    store = Store(folder / "study.sqlite")
    store.write_source(SourceRecord(study_file=str(path), dataset=str(tmp_path / "data")))
    store.close()
    ranges = {"mu_d_BePa": (0.3, 0.6), "mu_d_MePa": (0.15, 0.35), "E_Pa": (2e8, 1.6e9)}
    rng = np.random.default_rng(7)
    sample = np.column_stack([rng.uniform(lo, hi, rows) for lo, hi in BOUNDS.values()])
    params = tuple(
        ParameterInterval(
            name=name,
            low=ranges[name][0],
            high=ranges[name][1],
            interval=BOUNDS[name],
            median=float(np.mean(BOUNDS[name])),
            verdict=verdict(*ranges[name], BOUNDS[name]),
            rhat=1.0,
        )
        for name in BOUNDS
    )
    ident = Identifiability(
        parameters=params,
        correlation=np.eye(3),
        sample=sample,
        threshold=1.0,
        threshold_source="by hand",
        evaluations=40,
        noise_sd=0.1,
    )
    write_results(folder, new_results({}, [], stop_reason="budget", identifiability=ident))
    return folder


def write_rig_q(folder: Path) -> Path:
    """A rig file named Q (the bundled E3 under another name): the analytic simulator turns
    the parcel by E_Pa on rig Q."""
    from parcelfit.sim.mujoco.bundled import resolve_file

    text = resolve_file("rigs", "E3", "rig").read_text(encoding="utf-8")
    path = folder / "Q.yaml"
    path.write_text(text.replace("name: E3", "name: Q", 1), encoding="utf-8")
    return path
