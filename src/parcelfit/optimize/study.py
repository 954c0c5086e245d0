"""Study files: what to calibrate, against what, with which budget (YAML, validated on load).

::

    name: e3-kpbw                      # required
    simulator:                         # required
      backend: mujoco                  # mujoco | external | python
      rig: E3                          # mujoco: bundled name or .yaml path (relative to this file)
      consignment: KPBW                # mujoco: bundled name or .yaml path
      timestep: 0.0016667              # mujoco, optional [s]
      spacing: 0.03                    # mujoco, optional shell mesh spacing [m]
      wall_limit: 600                  # optional, per simulation [s]
      # external: solver.yaml          # external: solver description (parcelfit.sim.external)
      # factory: package.module:make   # python: a callable returning a Simulator
    parameters:                        # required: what to fit, in the catalogue's units
      mu_d_BePa: [0.3, 0.6]
      E_Pa: {low: 200, high: 1600, log: true}
    fixed: {mu_s_MePa: 0.15}           # optional, catalogue units; the rest take defaults
    reference:                         # required
      dataset: data/e3                 # dataset folder, relative to this file
      rig: E3                          # optional, default: simulator.rig
      consignment: KPBW                # optional, default: simulator.consignment
      speed_setting: 1
    validation: {speed_setting: 2, every: 5}   # validation case and how often (iterations)
    weights: {xy: 1.0, theta: 1.0}     # optional, equation (3)
    batch_size: 4                      # optional
    initial: 16                        # optional, Latin hypercube size
    budget: 80                         # optional, most fitting evaluations
    seed: 0                            # optional
    optimizer: {sampler: gp, ucb_lambda: 2.0}   # optional: gp | published | tpe, BOSettings
    executor: {kind: local, workers: 2}   # optional: local (processes) | serial (this process,
                                       # for debugging; also executor: serial) | dask (scheduler: tcp://...)

**A study file can run code.** ``backend: python`` imports the module named in ``factory`` and
calls it, and ``backend: external`` runs the solver description's command: run only study (and
screen) files you trust, as you would a script.

Parameter values in the file are in the catalogue's user units (N/mm, N/mm^2, mm, g; see
``parcelfit params``) for the catalogue's parameters and converted to SI on load; parameters a
``python`` or ``external`` backend defines itself are taken as given.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from parcelfit.config import (
    check_keys,
    get_bool,
    get_choice,
    get_int,
    get_number,
    get_str,
    load_config,
    require_mapping,
)
from parcelfit.errors import ParcelfitError
from parcelfit.optimize.bo import BOSettings
from parcelfit.optimize.sampler import SAMPLERS
from parcelfit.optimize.space import Dimension, Space

_TOP = (
    "name",
    "simulator",
    "parameters",
    "fixed",
    "reference",
    "validation",
    "weights",
    "batch_size",
    "initial",
    "budget",
    "seed",
    "optimizer",
    "executor",
)
_SIM = ("backend", "rig", "consignment", "timestep", "spacing", "wall_limit", "external", "factory")
_SIM_UNITS = {"timestep": "s", "spacing": "m", "wall_limit": "s"}


@dataclass(frozen=True)
class Study:
    """A parsed, checked study file (SI units for the catalogue's parameters)."""

    name: str
    folder: Path
    simulator: Mapping[str, Any]
    space: Space
    fixed: Mapping[str, float]
    dataset: Path
    rig: str
    consignment: str
    fit_setting: int
    validation_setting: int | None
    validate_every: int
    w_xy: float
    w_theta: float
    batch_size: int
    initial: int
    budget: int
    seed: int
    bo: BOSettings
    sampler: str = "gp"  # gp | published | tpe (see optimize.sampler)
    executor: Mapping[str, Any] = field(default_factory=dict)
    fingerprint: str = ""
    path: Path | None = None  # the study file


def _to_si(name: str, value: float, backend: str) -> float:
    from parcelfit.sim.params import CATALOGUE

    spec = next((p for p in CATALOGUE if p.name == name), None)
    if spec is None:
        if backend == "mujoco":
            from parcelfit.sim.params import parameter

            parameter(name)  # raises with a suggestion
        return float(value)
    return spec.to_si(float(value))


def load_study(path: str | Path) -> Study:
    """Read and check a study file; every error names the file, the key and the fix."""
    path = Path(path)
    doc = load_config(path, allowed=_TOP, required=("name", "simulator", "parameters", "reference"))
    folder = path.parent.resolve()
    sim = parse_simulator(doc["simulator"], path, folder)
    backend = sim["backend"]

    params = require_mapping(doc["parameters"], file=path, where="parameters")
    if not params:
        raise ParcelfitError(
            "no parameters to fit", file=path, where="parameters", fix="list at least one"
        )
    dims = []
    for name, spec in params.items():
        where = f"parameters.{name}"
        if isinstance(spec, Mapping):
            check_keys(
                spec,
                allowed=("low", "high", "log"),
                required=("low", "high"),
                file=path,
                where=where,
            )
            low = get_number(spec, "low", file=path, where=where)
            high = get_number(spec, "high", file=path, where=where)
            log = get_bool(spec, "log", file=path, where=where, default=False)
        elif isinstance(spec, list) and len(spec) == 2:
            low = get_number({"low": spec[0]}, "low", file=path, where=where)
            high = get_number({"high": spec[1]}, "high", file=path, where=where)
            log = False
        else:
            raise ParcelfitError(
                f"expected [low, high] or {{low, high, log}}, got {spec!r}",
                file=path,
                where=where,
                fix="write e.g. mu_d_BePa: [0.3, 0.6]",
            )
        try:
            dims.append(
                Dimension(
                    str(name),
                    _to_si(str(name), low, backend),
                    _to_si(str(name), high, backend),
                    log,
                )
            )  # type: ignore[arg-type]
        except ParcelfitError as exc:
            raise ParcelfitError(
                exc.message, file=path, where=where, fix=exc.fix or "give low < high"
            ) from None
    fixed_doc = require_mapping(doc.get("fixed") or {}, file=path, where="fixed")
    fixed = {
        str(k): _to_si(str(k), get_number(fixed_doc, k, file=path, where="fixed"), backend)  # type: ignore[arg-type]
        for k in fixed_doc
    }
    overlap = set(fixed) & {d.name for d in dims}
    if overlap:
        raise ParcelfitError(
            f"{sorted(overlap)} are both fitted and fixed",
            file=path,
            where="fixed",
            fix="remove them from one of the two",
        )

    dataset, rig, consignment, fit_setting = parse_reference(doc["reference"], path, folder, sim)
    val = require_mapping(doc.get("validation") or {}, file=path, where="validation")
    check_keys(val, allowed=("speed_setting", "every"), file=path, where="validation")
    val_setting = val.get("speed_setting")
    if val_setting is not None:
        val_setting = get_int(val, "speed_setting", file=path, where="validation", minimum=1)
        if val_setting == fit_setting:
            raise ParcelfitError(
                "validation must use a speed setting not used for fitting",
                file=path,
                where="validation.speed_setting",
                fix=f"use a setting other than {fit_setting}",
            )
    every = get_int(val, "every", file=path, where="validation", default=5, minimum=1)
    weights = require_mapping(doc.get("weights") or {}, file=path, where="weights")
    check_keys(weights, allowed=("xy", "theta"), file=path, where="weights")
    opt_doc = dict(require_mapping(doc.get("optimizer") or {}, file=path, where="optimizer"))
    sampler = get_choice(
        opt_doc, "sampler", SAMPLERS, what="optimizer", file=path, where="optimizer", default="gp"
    )
    opt_doc.pop("sampler", None)
    known = set(BOSettings.__dataclass_fields__) - {"n_initial"}
    if sampler == "tpe":
        known = set()  # TPE takes none of the GP's settings
    check_keys(opt_doc, allowed=sorted(known), file=path, where="optimizer")
    initial = get_int(doc, "initial", file=path, where="", default=16, minimum=1)
    try:
        make = BOSettings.published if sampler == "published" else BOSettings
        bo = make(n_initial=initial, **opt_doc)  # type: ignore[arg-type]
    except (ParcelfitError, TypeError) as exc:
        raise ParcelfitError(
            str(exc), file=path, where="optimizer", fix="see BOSettings for the allowed values"
        ) from None
    execu = parse_executor(doc.get("executor"), ("serial", "local", "dask"), path)
    w_xy = get_number(weights, "xy", file=path, where="weights", default=1.0, minimum=0) or 0.0
    w_theta = get_number(weights, "theta", file=path, where="weights", default=1.0, minimum=0)
    if w_xy + (w_theta or 0.0) <= 0:
        raise ParcelfitError(
            "both weights are zero, so every simulation would cost nothing",
            file=path,
            where="weights",
            fix="give xy or theta a positive weight",
        )
    fingerprint = hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[
        :16
    ]
    return Study(
        name=get_str(doc, "name", file=path, where=""),
        folder=folder,
        simulator=sim,
        space=Space(dims),
        fixed=fixed,
        dataset=dataset,
        rig=rig,
        consignment=consignment,
        fit_setting=fit_setting,
        validation_setting=val_setting,
        validate_every=every,
        w_xy=w_xy,
        w_theta=w_theta or 0.0,
        batch_size=get_int(doc, "batch_size", file=path, where="", default=4, minimum=1),
        initial=initial,
        budget=get_int(doc, "budget", file=path, where="", default=80, minimum=1),
        seed=get_int(doc, "seed", file=path, where="", default=0, minimum=0, maximum=2**32 - 1),
        bo=bo,
        sampler=sampler,
        executor=dict(execu),
        fingerprint=fingerprint,
        path=Path(path).resolve(),
    )


def parse_simulator(section: Any, path: Path, folder: Path) -> dict[str, Any]:
    """The ``simulator`` section of a study or screen file, with file paths made absolute."""
    sim = dict(require_mapping(section, file=path, where="simulator"))
    check_keys(sim, allowed=_SIM, required=("backend",), file=path, where="simulator")
    backend = get_choice(
        sim,
        "backend",
        ("mujoco", "external", "python"),
        what="backend",
        file=path,
        where="simulator",
    )
    needed = {"mujoco": ("rig", "consignment"), "external": ("external",), "python": ("factory",)}[
        backend
    ]
    for key in needed:
        if key not in sim:
            raise ParcelfitError(
                f"the {backend} backend needs {key!r}",
                file=path,
                where="simulator",
                fix=f"add `{key}:`",
            )
    for key in ("timestep", "spacing", "wall_limit"):
        if key in sim:
            get_number(sim, key, file=path, where="simulator", minimum=1e-9, unit=_SIM_UNITS[key])
    for key in ("rig", "consignment", "external", "factory"):
        if key in sim:
            get_str(sim, key, file=path, where="simulator")
    for key in ("rig", "consignment", "external"):
        if key in sim and str(sim[key]).lower().endswith((".yaml", ".yml")):
            sim[key] = str((folder / str(sim[key])).resolve())
    return sim


def parse_reference(
    section: Any, path: Path, folder: Path, sim: Mapping[str, Any]
) -> tuple[Path, str, str, int]:
    """The ``reference`` section: dataset folder, rig, consignment and speed setting."""
    ref = require_mapping(section, file=path, where="reference")
    check_keys(
        ref,
        allowed=("dataset", "rig", "consignment", "speed_setting"),
        required=("dataset", "speed_setting"),
        file=path,
        where="reference",
    )
    dataset = (folder / get_str(ref, "dataset", file=path, where="reference")).resolve()
    rig = str(ref.get("rig") or _name(sim.get("rig"), path, "reference.rig"))
    consignment = str(
        ref.get("consignment") or _name(sim.get("consignment"), path, "reference.consignment")
    )
    setting = get_int(ref, "speed_setting", file=path, where="reference", minimum=1)
    return dataset, rig, consignment, setting


def parse_executor(value: Any, kinds: tuple[str, ...], path: Path) -> dict[str, Any]:
    """An ``executor`` entry, checked: ``{kind: KIND, workers: N, scheduler: ADDRESS}`` or just
    ``KIND``, where KIND is one of ``kinds`` (default local); ``scheduler`` only for dask."""
    if isinstance(value, str):
        value = {"kind": value}
    execu = require_mapping(value or {"kind": "local"}, file=path, where="executor")
    allowed = ("kind", "workers", "scheduler") if "dask" in kinds else ("kind", "workers")
    check_keys(execu, allowed=allowed, file=path, where="executor")
    check_executor(execu, kinds, path)
    return dict(execu)


def check_executor(section: Mapping[str, Any], kinds: tuple[str, ...], path: Path) -> None:
    """Check an ``executor`` section: its kind is one of ``kinds``, ``workers`` a whole number
    >= 1, ``scheduler`` a text."""
    get_choice(
        section, "kind", kinds, what="executor", file=path, where="executor", default="local"
    )
    if section.get("workers") is not None:
        get_int(section, "workers", file=path, where="executor", minimum=1)
    if "scheduler" in section:
        get_str(section, "scheduler", file=path, where="executor")


def _name(value: Any, path: Path, where: str) -> str:
    if value is None:
        raise ParcelfitError(
            "cannot tell which test case to compare with",
            file=path,
            where=where,
            fix="give reference.rig and reference.consignment",
        )
    return Path(str(value)).stem if str(value).lower().endswith((".yaml", ".yml")) else str(value)
