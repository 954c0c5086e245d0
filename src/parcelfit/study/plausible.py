"""What a prediction (`parcelfit.study.predict`) and a ranking of experiments
(`parcelfit.study.design`) take from a finished calibration, and how they set up a design: the
study and its stored sample of the plausible parameter sets (`load_inputs`), a design checked
before anything runs (`check_design`) and the study's simulator set up for it
(`design_simulator`), parameter sets drawn from the sample (`draw_sets`) and the placement seeds
(`placement_seeds`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim.factory import SimulatorConfig, make_simulator
from parcelfit.sim.protocol import Simulator
from parcelfit.study.identify import Identifiability
from parcelfit.study.results import read_results
from parcelfit.study.status import study_folder
from parcelfit.study.store import STORE_FILE, Store
from parcelfit.study.studyfile import Study, load_study


@dataclass(frozen=True, eq=False)
class StudyInputs:
    """What a prediction takes from a finished calibration: its folder, the study (simulator,
    fixed parameters) and the stored identifiability analysis (the sample of S)."""

    folder: Path
    study: Study
    identifiability: Identifiability


def find_study(folder: str | Path) -> Path:
    """The study folder in ``folder`` (holding ``study.sqlite``) or in ``folder/calibration``
    (as ``parcelfit demo`` writes); a clear error when there is none."""
    folder = Path(folder)
    if not folder.exists():
        raise ParcelfitError(
            "no such study folder", file=folder, fix="give the folder `parcelfit calibrate` wrote"
        )
    found = study_folder(folder)
    if (found / STORE_FILE).is_file():
        return found
    raise ParcelfitError(
        f"no calibration study here (no {STORE_FILE}, nor calibration/{STORE_FILE})",
        file=folder,
        fix="point at the folder `parcelfit calibrate` or `parcelfit demo` wrote",
    )


def load_inputs(folder: str | Path) -> StudyInputs:
    """Read a finished calibration: its study file (found through the store's source record)
    and its identifiability analysis (``results.json``). Refused with a clear message when the
    folder holds no study, the study file has gone or the study has no analysis yet."""
    study_dir = find_study(folder)
    store = Store(study_dir / STORE_FILE, readonly=True)
    try:
        source = store.read_source()
    finally:
        store.close()
    if source is None or not source.study_file:
        raise ParcelfitError(
            "the study's store does not say which study file it was made from",
            file=study_dir,
            fix="rerun `parcelfit calibrate` on the study file and this folder (it resumes)",
        )
    path = Path(source.study_file)
    if not path.is_file():
        raise ParcelfitError(
            "the study file this study was made from is not there any more (it names the "
            "simulator to predict with)",
            file=path,
            fix="put the study file back where it was",
        )
    study = load_study(path)
    results = read_results(study_dir)
    ident = None if results is None else results.identifiability
    if ident is None:
        raise ParcelfitError(
            "the study has no stored analysis of what its data determine (the plausible "
            "parameter sets a prediction draws from)",
            file=study_dir,
            fix="let the calibration finish (rerun `parcelfit calibrate` on the same study file "
            "and folder: a finished study writes its results without simulating again)",
        )
    return StudyInputs(study_dir, study, ident)


@dataclass(frozen=True)
class Design:
    """The design to predict: ``rig`` and ``consignment`` as given (bundled names or
    ``.yaml`` files, made absolute), their names and the speed setting."""

    rig: str
    consignment: str
    rig_name: str
    consignment_name: str
    setting: int

    @property
    def case(self) -> TestCase:
        """The test case the simulator is asked to run."""
        return TestCase(self.rig_name, self.consignment_name, self.setting)

    @property
    def label(self) -> str:
        """The design's label, e.g. ``E1/KPBW/2``."""
        return self.case.label


def _given(value: str) -> str:
    """A rig or consignment as given: a ``.yaml`` file made absolute, a name as it is."""
    if value.lower().endswith((".yaml", ".yml")):
        return str(Path(value).resolve())
    return value


def check_design(rig: str, consignment: str, setting: int) -> Design:
    """The design ``rig`` x ``consignment`` x ``setting`` checked before anything runs: the rig
    (a bundled name, see `parcelfit rigs`, or a rig file) and consignment type must load and
    the rig must have the speed setting; each error says which and what to use."""
    from parcelfit.sim.mujoco import (
        bundled_consignment_names,
        bundled_rig_names,
        load_consignment,
        load_rig,
    )

    try:
        rig_obj = load_rig(_given(rig))
    except ParcelfitError as exc:
        raise ParcelfitError(
            exc.message,
            file=exc.file,
            where=exc.where or "--rig",  # a mistake inside the file: the key there
            fix=exc.fix
            if exc.file
            else f"use a bundled rig ({', '.join(bundled_rig_names())}; `parcelfit rigs` lists "
            "them) or a rig .yaml file",
        ) from None
    try:
        cons = load_consignment(_given(consignment))
    except ParcelfitError as exc:
        raise ParcelfitError(
            exc.message,
            file=exc.file,
            where=exc.where or "--consignment",
            fix=exc.fix
            if exc.file
            else f"use a bundled type ({', '.join(bundled_consignment_names())}) or a "
            "consignment .yaml file",
        ) from None
    if setting not in rig_obj.speeds:
        raise ParcelfitError(
            f"rig {rig_obj.name} has no speed setting {setting}",
            where="--setting",
            fix=f"use one of {sorted(rig_obj.speeds)} (`parcelfit rigs` lists them)",
        )
    return Design(_given(rig), _given(consignment), rig_obj.name, cons.name, setting)


def design_simulator(study: Study, design: Design) -> Simulator:
    """The study's simulator set up for ``design``: a MuJoCo or rigid-box configuration with
    the design's rig and consignment in place of the study's (every other setting kept); a
    python or external simulator as it is (it is given the design's test case)."""
    config: SimulatorConfig = study.simulator
    if config.backend in ("mujoco", "rigidbox"):
        config = SimulatorConfig(
            **{**dict(config), "rig": design.rig, "consignment": design.consignment},
            folder=config.folder,
        )
    return make_simulator(config)


def draw_sets(ident: Identifiability, n: int, seed: int) -> list[dict[str, float]]:
    """``n`` parameter sets (SI) drawn from the stored sample of the plausible set: rows
    chosen at random (seeded), without replacement while the sample has ``n`` rows."""
    sample = np.asarray(ident.sample, float)
    if not len(sample):
        raise ParcelfitError("the study's stored sample of plausible parameter sets is empty")
    rng = np.random.default_rng([seed, 0x9D])
    rows = rng.choice(len(sample), n, replace=n > len(sample))
    return [{name: float(sample[r, j]) for j, name in enumerate(ident.names)} for r in sorted(rows)]


def placement_seeds(k: int, seed: int) -> list[int]:
    """``k`` distinct placement seeds drawn from ``seed`` (ascending)."""
    rng = np.random.default_rng([seed, 0x51])
    return sorted(int(s) for s in rng.choice(2**31 - 1, k, replace=False) + 1)


__all__ = [
    "Design",
    "StudyInputs",
    "check_design",
    "design_simulator",
    "draw_sets",
    "find_study",
    "load_inputs",
    "placement_seeds",
]
