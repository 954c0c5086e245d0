"""Twin experiments: "real-like" datasets made with the simulator from hidden true parameters.

Every run is a separate specimen and a separate placement, so the runs scatter the way real
experiments do (method.md sections 2 and 3):

* specimen: every friction coefficient x (1 + N(0, friction_cv)), every contact stiffness and
  Young's modulus x (1 + N(0, stiffness_cv));
* placement jitter at the start guide: N(0, placement_sd) [m] in x and y, N(0, angle_sd) [deg];
* belt speeds: every drive x (1 + U(-speed_dev, speed_dev)) (real belts deviate up to 3 %);
* tracking noise: N(0, tracking_sd) [m] on x and y, N(0, heading_sd) [rad] on theta;
* model-form difference: the "real" runs use a finer shell mesh (``real_spacing``) than the
  model that will be calibrated, so a calibration cannot reach zero cost.

The truth (parameters in the catalogue's units, and every setting above) is written beside the
dataset as ``truth.yaml``; the dataset is marked ``synthetic: true``.

Every finished run is stored at once in ``<folder>/.twin-runs/`` (keyed by its job), so an
interrupted generation resumes where it stopped; the folder is removed when the dataset is
complete.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import shutil
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import yaml
from pydantic import BeforeValidator, Field, PlainValidator

from parcelfit.config import load_yaml
from parcelfit.errors import ParcelfitError
from parcelfit.runs import (
    Box,
    CaseData,
    Run,
    TestCase,
    Trajectory,
    read_trajectory,
    save_dataset,
    write_trajectory,
)
from parcelfit.schema import FileModel, Number, Text, Whole, keys_in, or_default, parse
from parcelfit.sim.mujoco import MujocoSimulator, SceneOptions, SimOptions
from parcelfit.sim.params import CATALOGUE, resolve


@dataclass(frozen=True)
class TwinSettings:
    """How real-like the twin runs are (see the module docstring for each quantity)."""

    runs: int = 10
    friction_cv: float = 0.03
    stiffness_cv: float = 0.05
    placement_sd: float = 0.005
    angle_sd: float = 1.5
    speed_dev: float = 0.03
    tracking_sd: float = 0.001
    heading_sd: float = 0.003
    real_spacing: float = 0.02


def _specimen(
    truth: Mapping[str, float], rng: np.random.Generator, s: TwinSettings
) -> dict[str, float]:
    out = dict(truth)
    for name in out:
        if name.startswith(("mu_d_", "mu_CoPa")):
            out[name] *= 1 + rng.normal(0, s.friction_cv)
        elif name.startswith(("k_", "E_")):
            out[name] *= 1 + rng.normal(0, s.stiffness_cv)
    return out


def _twin_run(job: dict[str, Any]) -> tuple[Run, float]:
    """Simulate one twin run in a worker process; returns the noisy run and its wall time [s]."""
    s: TwinSettings = job["settings"]
    rng = np.random.default_rng(job["seed"])
    rig, cons, case = job["rig"], job["consignment"], job["case"]
    params = _specimen(job["truth"], rng, s)
    drives = sorted({d for sp in rig.speeds.values() for d in sp})
    scene = SceneOptions(
        spacing=s.real_spacing,
        soft_shell_spacing=max(s.real_spacing, 0.03),
        speed_factors={d: 1 + rng.uniform(-s.speed_dev, s.speed_dev) for d in drives},
        start_offset=(
            rng.normal(0, s.placement_sd),
            rng.normal(0, s.placement_sd),
            rng.normal(0, s.angle_sd),
        ),
    )
    twin = MujocoSimulator(
        SimOptions(scene=scene), rigs={rig.name: rig}, consignments={cons.name: cons}
    )
    run_id = job["run_id"]
    res = twin.run(params, case, run_id=run_id)
    if not res.ok or res.run is None:
        raise ParcelfitError(
            f"twin run {run_id} ended {res.status.value}: {res.diagnostics.get('message')}"
        )
    tr = res.run.trajectory
    n = len(tr)
    noisy = Trajectory(
        t=tr.t,
        x=tr.x + rng.normal(0, s.tracking_sd, n),
        y=tr.y + rng.normal(0, s.tracking_sd, n),
        theta=tr.theta + rng.normal(0, s.heading_sd, n),
    )
    return Run(run_id, case, noisy, res.run.transit_time), res.wall_time


def make_twin_dataset(
    folder: str | Path,
    cases: Sequence[TestCase],
    truth_user: Mapping[str, Mapping[str, float]],
    *,
    settings: TwinSettings | None = None,
    seed: int = 0,
    name: str = "twin",
    workers: int = 1,
    progress: Callable[[str], None] | None = None,
) -> Path:
    """Simulate ``settings.runs`` real-like runs per test case; returns the dataset.yaml path.

    ``truth_user`` maps a consignment type to its true parameters in the catalogue's units; the
    others take their defaults. Every run draws from its own child of ``seed``, so the dataset is
    the same whatever ``workers`` (processes) is.
    """
    s = settings or TwinSettings()
    if s.runs < 1:
        raise ParcelfitError("a twin dataset needs at least one run per test case", fix="runs >= 1")
    sim = MujocoSimulator()
    truth_si: dict[str, dict[str, float]] = {}
    jobs: list[dict[str, Any]] = []
    seeds = np.random.SeedSequence(seed).spawn(len(cases) * s.runs)
    for i, case in enumerate(cases):
        cons = sim.consignment(case.consignment)
        if case.consignment not in truth_si:
            truth_si[case.consignment] = resolve(
                cons.content_kind, user_values=truth_user.get(case.consignment, {})
            )
        rig = sim.rig(case.rig)
        for k in range(s.runs):
            jobs.append(
                {
                    "settings": s,
                    "seed": seeds[i * s.runs + k],
                    "rig": rig,
                    "consignment": cons,
                    "case": case,
                    "truth": truth_si[case.consignment],
                    "run_id": f"{case.rig}-{case.consignment}-{case.speed_setting}-{k + 1:02d}",
                }
            )
    results: dict[str, Run] = {}
    # every finished run is kept in a cache folder at once, so a crash or Ctrl-C loses nothing:
    # rerunning the same command reuses the runs whose job (spec, seed, run) is unchanged
    cache = Path(folder) / ".twin-runs"
    cache.mkdir(parents=True, exist_ok=True)

    def key(job: dict[str, Any]) -> str:
        text = repr(
            (
                asdict(s),
                job["case"].label,
                sorted(job["truth"].items()),
                job["seed"].entropy,
                job["seed"].spawn_key,
                job["rig"],
                job["consignment"],
            )
        )
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def done(run: Run, wall: float, job: dict[str, Any], cached: bool = False) -> None:
        results[run.id] = run
        if not cached:
            base = cache / f"{run.id}-{job['key']}"
            write_trajectory(run.trajectory, base.with_suffix(".csv"))
            base.with_suffix(".json").write_text(json.dumps({"transit_time": run.transit_time}))
        if progress:
            how = "from the cache" if cached else f"{wall:.1f} s"
            progress(f"{run.id}: {how} ({len(results)}/{len(jobs)})")

    todo = []
    for job in jobs:
        job["key"] = key(job)
        base = cache / f"{job['run_id']}-{job['key']}"
        if base.with_suffix(".json").is_file() and base.with_suffix(".csv").is_file():
            meta = json.loads(base.with_suffix(".json").read_text())
            run = Run(
                job["run_id"],
                job["case"],
                read_trajectory(base.with_suffix(".csv")),
                meta["transit_time"],
            )
            done(run, 0.0, job, cached=True)
        else:
            todo.append(job)
    if workers <= 1:
        for job in todo:
            done(*_twin_run(job), job)
    else:
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
            futures = {pool.submit(_twin_run, job): job for job in todo}
            for fut in as_completed(futures):
                done(*fut.result(), futures[fut])
    out_cases = []
    for case in cases:
        rig = sim.rig(case.rig)
        runs = tuple(
            results[f"{case.rig}-{case.consignment}-{case.speed_setting}-{k + 1:02d}"]
            for k in range(s.runs)
        )
        regions = tuple(r for r in rig.regions if isinstance(r, Box)) or rig.regions
        out_cases.append(CaseData(case, runs, regions, rig.margin))
    path = save_dataset(
        folder,
        name,
        out_cases,
        synthetic=True,
        description=(
            f"SYNTHETIC twin-experiment data, not measured: simulated with parcelfit's MuJoCo model from hidden "
            f"true parameters (truth.yaml), {s.runs} specimens per test case with friction, stiffness, placement, "
            f"belt-speed and tracking variation, and a finer shell mesh ({s.real_spacing * 1e3:g} mm) than the default."
        ),
    )
    units = {p.name: p for p in CATALOGUE}
    truth_doc = {
        "synthetic": True,
        "seed": seed,
        "settings": asdict(s),
        "truth": {
            c: {k: float(units[k].from_si(v)) for k, v in p.items()} for c, p in truth_si.items()
        },
        "units": {k: units[k].unit for k in units},
    }
    (Path(folder) / "truth.yaml").write_text(
        yaml.safe_dump(truth_doc, sort_keys=False), encoding="utf-8"
    )
    shutil.rmtree(cache, ignore_errors=True)  # the dataset is complete
    return path


@dataclass(frozen=True)
class TwinSpec:
    """A twin dataset to make: its name, test cases, true parameters (catalogue units), seed."""

    name: str
    cases: tuple[TestCase, ...]
    truth: dict[str, dict[str, float]]
    settings: TwinSettings
    seed: int


def _test_case(value: Any) -> TestCase:
    try:
        return TestCase.parse(str(value))
    except ParcelfitError as exc:
        raise ParcelfitError(exc.message, fix="write RIG/CONSIGNMENT/SETTING") from exc


def _cases(value: Any) -> Any:
    if not isinstance(value, list) or not value:
        raise ParcelfitError(
            "expected a non-empty list of test cases",
            fix='write e.g. cases: ["E3/KPBW/1", "E3/KPBW/2"]',
        )
    return value


class TwinSettingsSection(FileModel):
    """``settings``: `TwinSettings` as written (each >= 0; ``runs`` a whole number >= 1)."""

    runs: Annotated[int, Whole(ge=1)] = TwinSettings.runs
    friction_cv: Annotated[float, Number(ge=0)] = TwinSettings.friction_cv
    stiffness_cv: Annotated[float, Number(ge=0)] = TwinSettings.stiffness_cv
    placement_sd: Annotated[float, Number(unit="m", ge=0)] = TwinSettings.placement_sd
    angle_sd: Annotated[float, Number(unit="deg", ge=0)] = TwinSettings.angle_sd
    speed_dev: Annotated[float, Number(ge=0)] = TwinSettings.speed_dev
    tracking_sd: Annotated[float, Number(unit="m", ge=0)] = TwinSettings.tracking_sd
    heading_sd: Annotated[float, Number(unit="rad", ge=0)] = TwinSettings.heading_sd
    real_spacing: Annotated[float, Number(unit="m", ge=0)] = TwinSettings.real_spacing


_Truth = Annotated[
    dict[str, Annotated[float, Number()]], keys_in(lambda: (p.name for p in CATALOGUE))
]


class TwinSpecFile(FileModel):
    """A twin specification file as written (true parameters in catalogue units)."""

    name: Annotated[str, Text()] = "twin"
    seed: Annotated[int, Whole(ge=0)] = 0
    cases: Annotated[list[Annotated[TestCase, PlainValidator(_test_case)]], BeforeValidator(_cases)]
    truth: Annotated[dict[Any, _Truth], or_default(dict)] = Field(default_factory=dict)
    settings: Annotated[TwinSettingsSection, or_default(dict)] = Field(
        default_factory=TwinSettingsSection
    )


def load_twin_spec(path: str | Path) -> TwinSpec:
    """Read a twin specification YAML (keys: name, seed, cases, truth, settings) and check it;
    the truth stays in catalogue units (`make_twin_dataset` converts it)."""
    f = parse(TwinSpecFile, load_yaml(path), file=path)
    truth = {str(cons): dict(values) for cons, values in f.truth.items()}
    return TwinSpec(f.name, tuple(f.cases), truth, TwinSettings(**f.settings.model_dump()), f.seed)


__all__ = ["TwinSettings", "TwinSpec", "load_twin_spec", "make_twin_dataset"]
