"""Study files: what to calibrate, against what, with which budget (YAML, validated on load).

::

    name: e3-kpbw                      # required
    simulator:                         # required
      backend: mujoco                  # mujoco | rigidbox | external | python
      rig: E3                          # mujoco: bundled name or .yaml path (relative to this file)
      consignment: KPBW                # mujoco: bundled name or .yaml path
      timestep: 0.0016667              # mujoco, optional [s]
      spacing: 0.03                    # mujoco, optional shell mesh spacing [m]
      rig_timesteps: {E1: 0.000208333} # mujoco, optional: a rig's own time step [s]
      # belt_friction: coulomb         # mujoco, optional (default mujoco)
      # roller_surface: turning        # mujoco, optional: flow-splitter rollers (default linear)
      # shell_diagonals: alternating   # mujoco, optional: shell cell split (default radiating)
      # stick_speed: 0.1               # mujoco, optional: the static friction's fade with the
      # slip_speed: 1                  #   slip speed [m/s] (SceneOptions; default 0.005, none)
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
    # a joint study lists its test cases instead of `reference` (each with its weight; dataset,
    # rig and consignment default to the first case's, resp. the simulator's):
    # cases:
    #   - {dataset: data/e3, rig: E3, speed_setting: 1, weight: 1.0}
    #   - {rig: E1, speed_setting: 3, weight: 1.0, placements: 2}   # its own placements
    # validation: {every: 5, cases: [{rig: E3, speed_setting: 2}]}  # all must pass
    # cost: {kind: ensemble, placements: 6, transit_weight: 1.0}   # optional, default published
    #   (add transit: adjusted to compare transit times at the real runs' mean belt speeds)
    # transfer: [{rig: E1, speed_setting: 1}]   # optional: judged once the study stops
    weights: {xy: 1.0, theta: 1.0}     # optional, equation (3)
    batch_size: 4                      # optional, at most 256
    initial: 16                        # optional, Latin hypercube size (at most budget)
    budget: 80                         # optional, most fitting evaluations (<= 10000)
    seed: 0                            # optional
    optimizer: {sampler: gp, ucb_lambda: 2.0}   # optional: gp | published | tpe | optuna-gp | botorch, BOSettings
    executor: {kind: local, workers: 2}   # optional: local (processes) | serial (this process,
                                       # for debugging; also executor: serial) | dask (scheduler: tcp://...)

**A study file can run code.** ``backend: python`` imports the module named in ``factory`` and
calls it, and ``backend: external`` runs the solver description's command: run only study (and
screen) files you trust, as you would a script.

A study file with ``reference`` (one test case) is the published method; ``cases`` fits several
test cases at once: one evaluation simulates every case (in parallel) and its cost is the
weighted sum of the cases' costs. ``cost.kind`` chooses the cost of a case: ``published``
(equation 3 against the reference run, `parcelfit.metrics.cost`) or ``ensemble`` (``placements``
seeded placements against all real runs with a transit-time term, `parcelfit.metrics.ensemble`;
with ``transit: adjusted`` the fitted cases' transit times, real and simulated, are adjusted for
the belt speeds each run rode at, `parcelfit.metrics.transit_adjustment`).
``transfer`` lists test cases (usually on other rigs) that the calibrated parameters are judged
on, with the validation criteria and the band test, once the study stops.

Parameter values in the file are in the catalogue's user units (N/mm, N/mm^2, mm, g; see
``parcelfit params``) for the catalogue's parameters, checked against the catalogue's physical
ranges and converted to SI on load; parameters a ``python`` or ``external`` backend defines
itself are taken as given. Every count has an upper bound (`studyschema.MAX_EVALUATIONS`,
`MAX_BATCH_SIZE`, placements, workers, speed settings), checked on load.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from parcelfit.config import load_yaml
from parcelfit.errors import ParcelfitError, shown
from parcelfit.optimize.bo import BOSettings
from parcelfit.optimize.sampler import SAMPLER_SETTINGS, SAMPLERS, Sampler
from parcelfit.optimize.space import Dimension, Space
from parcelfit.runs import TestCase
from parcelfit.runs.dataset import DATASET_FILE, dataset_file
from parcelfit.schema import (
    parse,
)
from parcelfit.sim.factory import SimulatorConfig, SimulatorSection
from parcelfit.study.studyschema import (
    CaseSection,
    JudgedCaseSection,
    ReferenceSection,
    StudyFile,
)

# -- the parsed study (SI) --------------------------------------------------------------------


@dataclass(frozen=True)
class Study:
    """A parsed, checked study file (SI units for the catalogue's parameters)."""

    name: str
    folder: Path
    simulator: SimulatorConfig
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
    sampler: str = "gp"  # gp | published | tpe | optuna-gp | botorch (see optimize.sampler)
    executor: Mapping[str, Any] = field(default_factory=dict)
    fingerprint: str = ""
    path: Path | None = None  # the study file
    cases: tuple[CaseSpec, ...] = ()  # fitted test cases (one for a `reference` study)
    validation_cases: tuple[CaseSpec, ...] = ()
    transfer: tuple[CaseSpec, ...] = ()
    cost_kind: str = "published"  # published | ensemble
    placements: int = 1  # seeded placements per case and evaluation (ensemble)
    mirrored: bool = False  # antithetic placements: 1, -1, 2, -2, ... (ensemble)
    transit_weight: float = 1.0  # w_T of the ensemble cost
    transit_adjusted: bool = False  # ensemble transit term on belt-speed-adjusted times
    refinement: int = 2  # the convergence check's refinement (1: no check)

    @property
    def joint(self) -> bool:
        """True when an evaluation is more than one simulation against one reference run
        (several cases, or the ensemble cost)."""
        return len(self.cases) > 1 or self.cost_kind != "published"

    def validation_specs(self) -> tuple[CaseSpec, ...]:
        """The cases a validation simulates, in order: ``validation_cases``, else the fitted
        rig and type at ``validation_setting`` from the study's dataset (a study made in code),
        else none."""
        if self.validation_cases:
            return self.validation_cases
        if self.validation_setting is None:
            return ()
        case = TestCase(self.rig, self.consignment, self.validation_setting)
        return (CaseSpec(case, self.dataset),)

    def judged_specs(self) -> tuple[CaseSpec, ...]:
        """The cases the recommended parameters are judged on once the study stops: the
        validation cases, then the transfer cases, each label once (a case both validated and
        transferred is its validation's)."""
        out: dict[str, CaseSpec] = {}
        for spec in (*self.validation_specs(), *self.transfer):
            out.setdefault(spec.label, spec)
        return tuple(out.values())

    def new_sampler(self) -> Sampler:
        """A fresh optimiser of this study: the factory its ``sampler`` names in
        `parcelfit.optimize.sampler.SAMPLERS`, over its space, with its batch size, seed,
        settings and initial design."""
        return SAMPLERS[self.sampler](
            self.space,
            batch_size=self.batch_size,
            seed=self.seed,
            settings=self.bo,
            n_initial=self.initial,
            options={},
        )


@dataclass(frozen=True)
class CaseSpec:
    """A test case of a study with the dataset folder (absolute) holding its real runs and its
    weight in the cost (1 for validation and transfer cases)."""

    case: TestCase
    dataset: Path
    weight: float = 1.0
    placements: int | None = None  # seeded placements per evaluation (None: the study's)
    where: str = ""  # the study file's key naming it (``reference``, ``cases[1]``, ...)

    @property
    def label(self) -> str:
        """The test case's label, e.g. ``E3/KPBW/1``."""
        return self.case.label


def _to_si(name: str, value: float, backend: str) -> float:
    """A parameter value from its catalogue unit to SI, checked against the catalogue's
    physical range (whatever the backend: a catalogue name means the catalogue's quantity); a
    name outside the catalogue is taken as given, except for the mujoco and rigidbox backends
    (which know only the catalogue)."""
    from parcelfit.sim.params import CATALOGUE

    spec = next((p for p in CATALOGUE if p.name == name), None)
    if spec is None:
        if backend in ("mujoco", "rigidbox"):
            from parcelfit.sim.params import parameter

            parameter(name)  # raises with a suggestion
        return float(value)
    return spec.to_si(spec.check_physical(float(value)))


def check_simulator_files(sim: SimulatorConfig, path: Path) -> set[str] | None:
    """For the mujoco and rigidbox backends, load the rig and consignment now (a bundled name or a file), so
    that an unknown name is refused on load naming ``simulator.rig`` (or ``.consignment``) of
    the file at ``path``; a mistake inside a rig or consignment file names that file. Returns
    the rig names the file's cases may use (mujoco and rigidbox, `_rig_names`; None: any)."""
    if sim.backend not in ("mujoco", "rigidbox"):
        return None
    names = _rig_names(sim, path)
    # both backends build their simulator from these files (keyed by their name:)
    from parcelfit.sim.mujoco import load_consignment, load_rig

    for key, load in (("rig", load_rig), ("consignment", load_consignment)):
        given = str(sim[key])
        if given.lower().endswith((".yaml", ".yml")) and not Path(given).is_file():
            raise ParcelfitError(
                f"no {key} file {shown(given)}",
                file=path,
                where=f"simulator.{key}",
                fix="give a bundled name or the path of a .yaml file, relative to this file",
            )
        try:
            loaded = load(given)
        except ParcelfitError as exc:
            if exc.file is not None:
                raise
            raise ParcelfitError(
                exc.message, file=path, where=f"simulator.{key}", fix=exc.fix
            ) from None
        _check_stem(loaded.name, given, path, f"simulator.{key}", key)
    return names


def _check_stem(name: str, given: str, path: Path, where: str, kind: str) -> None:
    """Refuse a rig or consignment file whose ``name:`` is not its file's stem: the study's
    cases and datasets name it by the stem, the simulator by ``name:``, and the two must agree
    for a case to find its rig."""
    if given.lower().endswith((".yaml", ".yml")) and Path(given).stem != name:
        raise ParcelfitError(
            f"the {kind} file {Path(given).name} says name: {name}",
            file=path,
            where=where,
            fix=f"make the {kind} file's name equal its file name without .yaml "
            f"({Path(given).stem}), or rename the file to {name}.yaml",
        )


def require_dataset(given: Path, label: str, *, file: Path | None, where: str, kind: str) -> None:
    """Refuse test case ``label``'s dataset ``given`` (a folder, or its dataset.yaml itself, as
    `load_dataset` takes) where it has no dataset.yaml, naming the ``kind`` of file ("study",
    "screen") at ``file`` and its key ``where``: a dataset not made yet, or a path written
    wrong, found before anything starts."""
    if dataset_file(given).is_file():
        return
    raise ParcelfitError(
        f"{label}: its dataset file {given} does not exist"
        if given.name == DATASET_FILE
        else f"{label}: its dataset {given} holds no {DATASET_FILE}",
        file=file,
        where=where,
        fix="make the dataset first (tracked runs: parcelfit track-all; a SYNTHETIC twin: "
        f"parcelfit synth SPEC --out FOLDER) or correct the path (relative to the {kind} file)",
    )


def check_speed_settings(
    sim: SimulatorConfig, cases: Sequence[tuple[TestCase, str]], path: Path
) -> None:
    """For the mujoco and rigidbox backends, that each case's rig has its speed setting:
    ``cases`` holds (case, the file's key naming it); a setting the rig lacks is refused now,
    naming the file and the key, where it failed every simulation of the case before."""
    if sim.backend not in ("mujoco", "rigidbox"):
        return
    from parcelfit.sim.mujoco import bundled_rig_names, load_rig, load_rig_files

    given = (sim.rig, *(sim.rigs or ()))
    files = load_rig_files([g for g in given if g and g.lower().endswith((".yaml", ".yml"))])
    for case, where in cases:
        rig = files.get(case.rig)
        if rig is None and case.rig in bundled_rig_names():
            rig = load_rig(case.rig)
        if rig is None or case.speed_setting in rig.speeds:
            continue
        raise ParcelfitError(
            f"rig {rig.name} has no speed setting {case.speed_setting} (test case {case.label})",
            file=path,
            where=where,
            fix=f"use one of {sorted(rig.speeds)}, or add the setting to the rig's speeds",
        )


def _rig_names(sim: SimulatorConfig, path: Path) -> set[str]:
    """The rig names a case may use with the mujoco and rigidbox backends: the bundled rigs,
    the simulator's rig and the rigs of ``simulator.rigs``, loaded now: a missing or broken
    file, or a name given twice (also the simulator's rig's or a bundled rig's), is refused
    naming the entry."""
    from parcelfit.sim.mujoco import bundled_rig_names, load_rig

    names = set(bundled_rig_names()) | {_name(sim.rig, path, "simulator.rig")}
    for i, given in enumerate(sim.rigs or ()):
        where = f"simulator.rigs[{i}]"
        if not given.lower().endswith((".yaml", ".yml")) or not Path(given).is_file():
            raise ParcelfitError(
                f"no rig file {shown(given)}",
                file=path,
                where=where,
                fix="give the path of a rig .yaml file, relative to this file (bundled rigs "
                "need no entry)",
            )
        try:
            rig = load_rig(given)
        except ParcelfitError as exc:
            if exc.file is not None:
                raise
            raise ParcelfitError(exc.message, file=path, where=where, fix=exc.fix) from None
        _check_stem(rig.name, given, path, where, "rig")
        if rig.name in names:
            raise ParcelfitError(
                f"a rig named {rig.name} is known already (a bundled rig, the simulator's rig "
                "or an earlier entry)",
                file=path,
                where=where,
                fix="give each rig once; rename a rig file that shares another rig's name",
            )
        names.add(rig.name)
    return names


def fixed_to_si(
    fixed: Mapping[Any, float], backend: str, path: Path | None, where: str = "fixed"
) -> dict[str, float]:
    """A file's ``fixed`` values (catalogue units for MuJoCo) in SI, each error naming its key
    (``where.NAME``; ``where`` e.g. ``--at`` for values given on the command line, ``path``
    then None)."""
    out = {}
    for name, value in fixed.items():
        try:
            out[str(name)] = _to_si(str(name), value, backend)
        except ParcelfitError as exc:
            label = f"{where} {name}" if where.startswith("--") else f"{where}.{name}"
            raise ParcelfitError(exc.message, file=path, where=label, fix=exc.fix) from None
    return out


def load_study(path: str | Path) -> Study:
    """Read and check a study file; every error names the file, the key and the fix. Parameter
    values are converted from catalogue units to SI here."""
    path = Path(path)
    doc = load_yaml(path)
    f = parse(StudyFile, doc, file=path)
    folder = path.parent.resolve()
    sim = f.simulator.to_config(folder)
    rigs = check_simulator_files(sim, path)
    backend = f.simulator.backend
    dims = []
    for name, bounds in f.parameters.items():
        try:
            low = _to_si(str(name), bounds.low, backend)
            high = _to_si(str(name), bounds.high, backend)
            dims.append(Dimension(str(name), low, high, bounds.log))
        except ParcelfitError as exc:
            raise ParcelfitError(
                exc.message,
                file=path,
                where=f"parameters.{name}",
                fix=exc.fix or "give low < high",
            ) from None
    fixed = fixed_to_si(f.fixed, backend, path)
    if backend == "external":  # every placeholder of the solver's files known before a run
        from parcelfit.sim.external import check_placeholders, load_external_solver

        check_placeholders(
            load_external_solver(sim["external"]),
            sim["external"],
            [*(d.name for d in dims), *fixed],
        )
    overlap = set(fixed) & {d.name for d in dims}
    if overlap:
        raise ParcelfitError(
            f"{sorted(overlap)} are both fitted and fixed",
            file=path,
            where="fixed",
            fix="remove them from one of the two",
        )
    cases, validation_cases, transfer = study_cases(f, path, folder, rigs)
    check_speed_settings(
        sim,
        [
            (c.case, c.where if c.where.endswith("speed_setting") else f"{c.where}.speed_setting")
            for c in (*cases, *validation_cases, *transfer)
        ],
        path,
    )
    first = cases[0]
    dataset, rig, consignment = first.dataset, first.case.rig, first.case.consignment
    try:
        make = SAMPLER_SETTINGS.get(f.optimizer.sampler, BOSettings)
        bo = make(n_initial=f.initial, **f.optimizer.settings)
    except (ParcelfitError, TypeError) as exc:
        raise ParcelfitError(
            str(exc),
            file=path,
            where="optimizer",
            fix="change that setting (every optimiser setting and its values: "
            "docs/reference/files.md, optimiser settings)",
        ) from None
    hashed = dict(doc)  # the convergence check's refinement acts once the study stopped: a
    if isinstance(hashed.get("validation"), dict):  # finished study may be checked at another
        rest = {k: v for k, v in hashed["validation"].items() if k != "refinement"}
        if rest:
            hashed["validation"] = rest
        else:  # a section that held only the refinement hashes as none
            del hashed["validation"]
    fingerprint = hashlib.sha256(
        json.dumps(hashed, sort_keys=True, default=str).encode()
    ).hexdigest()[:16]
    return Study(
        name=f.name,
        folder=folder,
        simulator=sim,
        space=Space(dims),
        fixed=fixed,
        dataset=dataset,
        rig=rig,
        consignment=consignment,
        fit_setting=first.case.speed_setting,
        validation_setting=validation_cases[0].case.speed_setting if validation_cases else None,
        validate_every=f.validation.every,
        w_xy=f.weights.xy,
        w_theta=f.weights.theta,
        batch_size=f.batch_size,
        initial=f.initial,
        budget=f.budget,
        seed=f.seed,
        bo=bo,
        sampler=f.optimizer.sampler,
        executor=f.executor.model_dump(),
        fingerprint=fingerprint,
        path=path.resolve(),
        cases=cases,
        validation_cases=validation_cases,
        transfer=transfer,
        cost_kind=f.cost.kind,
        placements=f.cost.placements,
        mirrored=f.cost.mirrored,
        transit_weight=f.cost.transit_weight,
        transit_adjusted=f.cost.transit == "adjusted",
        refinement=f.validation.refinement,
    )


def study_cases(
    f: StudyFile, path: Path, folder: Path, rigs: set[str] | None
) -> tuple[tuple[CaseSpec, ...], tuple[CaseSpec, ...], tuple[CaseSpec, ...]]:
    """The fitted, validation and transfer cases of a study file (datasets absolute); ``rigs``
    the rig names they may use (`check_simulator_files`; None: any). A ``reference`` study has
    one fitted case and at most one validation case, at ``validation.speed_setting`` of the
    same rig and consignment."""
    if f.reference is not None:
        dataset, rig, consignment = reference_case(f.reference, f.simulator, path, folder, rigs)
        cases: tuple[CaseSpec, ...] = (
            CaseSpec(
                TestCase(rig, consignment, f.reference.speed_setting), dataset, where="reference"
            ),
        )
    else:
        first = f.cases[0]
        if first.dataset is None:
            raise ParcelfitError(
                "the first case names no dataset",
                file=path,
                where="cases[0].dataset",
                fix="add dataset: FOLDER (relative to the study file)",
            )
        cases = tuple(
            _case(c, f.simulator, path, folder, folder / first.dataset, f"cases[{i}]", rigs)
            for i, c in enumerate(f.cases)
        )
    default = cases[0].dataset
    if f.validation.cases:
        validation = tuple(
            _case(c, f.simulator, path, folder, default, f"validation.cases[{i}]", rigs)
            for i, c in enumerate(f.validation.cases)
        )
    elif f.validation.speed_setting is not None:
        c0 = cases[0].case
        validation = (
            CaseSpec(
                TestCase(c0.rig, c0.consignment, f.validation.speed_setting),
                default,
                where="validation.speed_setting",
            ),
        )
    else:
        validation = ()
    transfer = tuple(
        _case(c, f.simulator, path, folder, default, f"transfer[{i}]", rigs)
        for i, c in enumerate(f.transfer)
    )
    for i, c in enumerate(cases):
        if c.placements is not None and f.cost.kind != "ensemble":
            raise ParcelfitError(
                "a case's placements belong to the ensemble cost; the published cost simulates "
                "the nominal placement once",
                file=path,
                where=f"cases[{i}].placements",
                fix="use cost: {kind: ensemble, ...}, or leave placements out",
            )
    fitted = {c.case for c in cases}
    for where, group in (("validation.cases", validation), ("transfer", transfer)):
        for i, c in enumerate(group):
            if c.case in fitted:
                raise ParcelfitError(
                    f"{c.label} is also fitted: a case used for fitting cannot judge the fit",
                    file=path,
                    where=f"{where}[{i}]"
                    if where == "transfer" or f.validation.cases
                    else "validation.speed_setting",
                    fix="use a test case not listed under cases",
                )
    if len({c.case for c in cases}) != len(cases):
        raise ParcelfitError(
            "a test case is listed twice", file=path, where="cases", fix="list each case once"
        )
    return cases, validation, transfer


def _case(
    c: JudgedCaseSection,
    sim: SimulatorSection,
    path: Path,
    folder: Path,
    default: Path,
    where: str,
    rigs: set[str] | None,
) -> CaseSpec:
    """One case section as a `CaseSpec` (names default to the simulator's); its rig must be
    one of ``rigs`` (None: any)."""
    dataset = (folder / c.dataset).resolve() if c.dataset is not None else default.resolve()
    rig = c.rig or _name(sim.rig, path, f"{where}.rig")
    consignment = c.consignment or _name(sim.consignment, path, f"{where}.consignment")
    if rigs is not None:
        if rig.lower().endswith((".yaml", ".yml")):
            raise ParcelfitError(
                "a case's rig is a rig's name (a bundled rig's, or that of the simulator's "
                "rig file or of a file in simulator.rigs), not a file",
                file=path,
                where=f"{where}.rig",
                fix="add the file to simulator.rigs and name its rig here, or leave rig out "
                "for the simulator's",
            )
        if rig not in rigs:
            raise ParcelfitError(
                f"no rig named {shown(rig)}: a case's rig is a bundled rig, the simulator's rig or "
                "one of simulator.rigs",
                file=path,
                where=f"{where}.rig",
                fix=f"name one of {sorted(rigs)}, or add the rig's file to simulator.rigs",
            )
    weight, placements = (c.weight, c.placements) if isinstance(c, CaseSection) else (1.0, None)
    return CaseSpec(TestCase(rig, consignment, c.speed_setting), dataset, weight, placements, where)


def reference_case(
    ref: ReferenceSection, sim: SimulatorSection, path: Path, folder: Path, rigs: set[str] | None
) -> tuple[Path, str, str]:
    """The reference dataset folder (absolute), rig and consignment names; the names default to
    the simulator's (a ``.yaml`` file gives its stem), the rig must be one of ``rigs`` (None:
    any)."""
    dataset = (folder / ref.dataset).resolve()
    rig = ref.rig or _name(sim.rig, path, "reference.rig")
    if rigs is not None and rig not in rigs:
        raise ParcelfitError(
            f"no rig named {shown(rig)}: the reference's rig is a bundled rig, the simulator's "
            "rig or one of simulator.rigs",
            file=path,
            where="reference.rig",
            fix=f"name one of {sorted(rigs)}, or add the rig's file to simulator.rigs",
        )
    consignment = ref.consignment or _name(sim.consignment, path, "reference.consignment")
    return dataset, rig, consignment


def _name(value: str | None, path: Path, where: str) -> str:
    if value is None:
        raise ParcelfitError(
            "cannot tell which test case to compare with",
            file=path,
            where=where,
            fix="give reference.rig and reference.consignment",
        )
    return Path(value).stem if value.lower().endswith((".yaml", ".yml")) else value
