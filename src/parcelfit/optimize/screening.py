"""Screening runs (method.md section 6): designs simulated through the executors and the store.

A screen file (YAML)::

    name: e3-kpbw-screen
    simulator: {backend: mujoco, rig: E3, consignment: KPBW}     # as in a study file
    reference: {dataset: data, speed_setting: 2}                   # as in a study file
    parameters: all              # all catalogue candidates of the consignment, or a list of names,
                                 # or {name: [low, high]} (catalogue units; default: screening range)
    fixed: {}                    # optional, catalogue units
    stages: [fractional, full]   # fractional (resolution IV) -> full factorial on the survivors
    soft_content: [E_Co, zeta_Co]   # optional third stage: survivors + these (polybag PB)
    resolution: 4
    centre_points: 0             # optional runs with every factor at mid-range, added to each stage
    alpha: 0.05
    max_full_factors: 6          # the full factorial keeps at most this many survivors (2^6 = 64 runs)
    min_full_factors: 3          # ... and at least this many: fewer survivors are topped up with the
                                 # next-largest effects (a 2- or 4-run design says nothing)
    select: 4                    # parameters recommended for calibration
    executor: {kind: local}      # or serial (in this process), or just executor: serial

Responses of every run: DTW_xy [m] and DTW_theta [rad] between the simulated run and the
reference run of the test case (the same preparation as the calibration cost), and the transit
time [s]. After each stage the effects on DTW_xy and DTW_theta are analysed
(`parcelfit.doe.analyse_effects`); a parameter survives if any of its effects is significant.
Outputs in the screen folder: ``stageN-effects.csv``, ``stageN-pareto-<response>.png/.svg``,
``stageN-design.csv`` (parameters and responses per run) and ``selection.yaml`` (the ranked
recommendation with reasons, and the parameters with their ranges ready for a study file).

The final selection ranks the last stage's parameters by their largest standardised effect, as
the method asks ("by effect size, not blindly by significance"); the reasons say which effects
were significant. A rerun resumes stage by stage and refuses a stage whose stored factors differ
from the ones it would run now (use a new folder after changing the screen file).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from parcelfit.config import (
    get_int,
    get_number,
    get_pair,
    get_str,
    load_config,
    require_mapping,
)
from parcelfit.doe import (
    EffectAnalysis,
    analyse_effects,
    decode,
    fractional_factorial,
    full_factorial,
    pareto_chart,
    select_parameters,
    with_centre_points,
)
from parcelfit.errors import ParcelfitError
from parcelfit.figures import save_figure
from parcelfit.metrics import select_reference
from parcelfit.optimize.calibration import record_result
from parcelfit.optimize.executors import Task, make_executor
from parcelfit.optimize.folderlock import check_writable, lock_folder
from parcelfit.optimize.store import Store
from parcelfit.optimize.study import _to_si, parse_executor, parse_reference, parse_simulator
from parcelfit.progress import ProgressCallback, ProgressEvent, ignore_progress
from parcelfit.runs import TestCase, load_dataset
from parcelfit.sim.params import CATALOGUE, parameter

_KEYS = (
    "name",
    "simulator",
    "reference",
    "parameters",
    "fixed",
    "stages",
    "soft_content",
    "resolution",
    "centre_points",
    "alpha",
    "max_full_factors",
    "min_full_factors",
    "select",
    "executor",
)
RESPONSES = ("dtw_xy", "dtw_theta")


@dataclass(frozen=True)
class Screen:
    """A parsed screen file: parameter ranges in catalogue (user) units."""

    name: str
    folder: Path
    simulator: dict[str, Any]
    ranges: dict[str, tuple[float, float]]
    fixed: dict[str, float]
    dataset: Path
    case: TestCase
    stages: tuple[str, ...]
    soft_content: tuple[str, ...]
    resolution: int
    centre_points: int
    alpha: float
    max_full_factors: int
    min_full_factors: int
    select: int
    executor: dict[str, Any] = field(default_factory=dict)


def load_screen(path: str | Path) -> Screen:
    """Read and check a screen file."""
    path = Path(path)
    doc = load_config(path, allowed=_KEYS, required=("name", "simulator", "reference"))
    folder = path.parent.resolve()
    sim = parse_simulator(doc["simulator"], path, folder)
    dataset, rig, cons, setting = parse_reference(doc["reference"], path, folder, sim)
    kind = "rigid"
    if sim["backend"] == "mujoco":
        from parcelfit.sim.mujoco import load_consignment

        kind = load_consignment(sim["consignment"]).content_kind
    spec = doc.get("parameters", "all")
    if spec == "all":
        names = [
            p.name for p in CATALOGUE if kind in p.ranges and p.name not in ("E_Co", "zeta_Co")
        ]
        spec = {n: None for n in names}
    elif isinstance(spec, list):
        spec = {str(n): None for n in spec}
    elif isinstance(spec, str):
        raise ParcelfitError(
            f"expected all, a list of names or {{name: [low, high]}}, got {spec!r}",
            file=path,
            where="parameters",
            fix="write parameters: all",
        )
    spec = require_mapping(spec, file=path, where="parameters")
    ranges = {}
    for name, bounds in spec.items():
        if bounds is None:
            r = _known(str(name), path, f"parameters.{name}").range_for(kind)
            ranges[str(name)] = (r.low, r.high)
        else:
            ranges[str(name)] = get_pair(
                bounds,
                file=path,
                where=f"parameters.{name}",
                what="[low, high] with low < high",
                fix="write two numbers, or leave it empty for the screening range",
                increasing=True,
            )
    if len(ranges) < 2:
        raise ParcelfitError(
            "a screen needs at least two parameters", file=path, where="parameters"
        )
    stages_doc = doc.get("stages") or ["fractional", "full"]
    stages = tuple(stages_doc) if isinstance(stages_doc, list) else (stages_doc,)
    if any(s not in ("fractional", "full") for s in stages):
        raise ParcelfitError(
            f"unknown stages {list(stages)}",
            file=path,
            where="stages",
            fix="use fractional and/or full",
        )
    fixed_doc = require_mapping(doc.get("fixed") or {}, file=path, where="fixed")
    fixed = {str(k): get_number(fixed_doc, k, file=path, where="fixed") for k in fixed_doc}
    soft_doc = doc.get("soft_content") or []
    if not isinstance(soft_doc, list):
        raise ParcelfitError(
            f"expected a list of parameter names, got {soft_doc!r}",
            file=path,
            where="soft_content",
            fix="write e.g. soft_content: [E_Co, zeta_Co]",
        )
    for k, extra in enumerate(soft_doc):  # checked now, not after stage 1 has simulated
        try:
            _known(str(extra), path, f"soft_content[{k}]").range_for("soft")
        except ParcelfitError as exc:
            raise ParcelfitError(
                exc.message,
                file=path,
                where=f"soft_content[{k}]",
                fix=exc.fix
                or "name a soft-content parameter (see parcelfit params --consignment PB)",
            ) from None
    execu = parse_executor(doc.get("executor"), ("serial", "local"), path)  # on this machine
    return Screen(
        name=get_str(doc, "name", file=path, where=""),
        folder=folder,
        simulator=sim,
        ranges=ranges,
        fixed=fixed,  # type: ignore[arg-type]
        dataset=dataset,
        case=TestCase(rig, cons, setting),
        stages=stages,
        soft_content=tuple(str(n) for n in soft_doc),
        resolution=get_int(doc, "resolution", file=path, where="", default=4, minimum=3, maximum=5),
        centre_points=get_int(
            doc, "centre_points", file=path, where="", default=0, minimum=0, maximum=50
        ),
        alpha=get_number(doc, "alpha", file=path, where="", default=0.05, minimum=1e-6, maximum=0.5)
        or 0.05,
        max_full_factors=get_int(
            doc, "max_full_factors", file=path, where="", default=6, minimum=2, maximum=10
        ),
        min_full_factors=get_int(
            doc, "min_full_factors", file=path, where="", default=3, minimum=1, maximum=10
        ),
        select=get_int(doc, "select", file=path, where="", default=4, minimum=1),
        executor=execu,
    )


@dataclass(frozen=True)
class StageResult:
    """One stage: the factors, the analyses per response, the survivors."""

    kind: str
    factors: list[str]
    analyses: list[EffectAnalysis]
    survivors: list[str]


def run_screen(
    screen: Screen,
    out: str | Path,
    *,
    executor: str | None = None,
    workers: int | None = None,
    progress: ProgressCallback | None = None,
) -> tuple[list[StageResult], dict[str, Any]]:
    """Run the screen's stages (resumable), write the outputs, return the stages and the selection.

    ``executor`` (serial or local) and ``workers`` override the screen file's ``executor``;
    ``progress`` receives a `ProgressEvent` per stage and per finished simulation (``done`` of
    ``total`` counting the stage's simulations)."""
    from parcelfit.sim.factory import make_simulator

    out = Path(out)
    check_writable(out, ("screen.sqlite",))
    out.mkdir(parents=True, exist_ok=True)
    report = progress or ignore_progress

    def say(message: str, done: int | None = None, total: int | None = None) -> None:
        report(ProgressEvent("screening", message, done, total))

    lock = lock_folder(out, "a screen")
    try:
        store = Store(out / "screen.sqlite")
    except BaseException:
        lock.release()
        raise
    reference = select_reference(load_dataset(screen.dataset)[screen.case])
    simulator = make_simulator(screen.simulator, screen.folder)
    backend = screen.simulator["backend"]
    runner = make_executor(
        executor or screen.executor.get("kind", "local"),
        workers=workers or screen.executor.get("workers"),
    )
    results: list[StageResult] = []
    factors = list(screen.ranges)
    try:
        plan = list(screen.stages) + (["full"] if screen.soft_content else [])
        for stage, kind in enumerate(plan):
            if stage == len(screen.stages) and screen.soft_content:
                for extra in screen.soft_content:
                    r = parameter(extra).range_for("soft")
                    screen.ranges.setdefault(extra, (r.low, r.high))
                factors = list(dict.fromkeys([*factors, *screen.soft_content]))
            if kind == "full" and len(factors) > screen.max_full_factors:
                say(
                    f"stage {stage + 1}: {len(factors)} survivors, keeping the {screen.max_full_factors} strongest"
                )
                factors = factors[: screen.max_full_factors]
            design = (
                fractional_factorial(len(factors), screen.resolution)
                if kind == "fractional"
                else full_factorial(len(factors))
            )
            n_runs = len(design.matrix)
            values = decode(
                with_centre_points(design.matrix, screen.centre_points),
                [screen.ranges[f] for f in factors],
            )
            rows = [e for e in store.evaluations("screen") if e.iteration == stage]
            if rows and sorted(rows[0].params) != sorted(factors):
                raise ParcelfitError(
                    f"stage {stage + 1} was run over {sorted(rows[0].params)}, now it would be over {sorted(factors)}",
                    file=out / "screen.sqlite",
                    fix="use a new output folder after changing the screen file",
                )
            if not rows:
                batch = [
                    {f: _to_si(f, v, backend) for f, v in zip(factors, run, strict=True)}
                    for run in values
                ]
                store.add_pending(
                    "screen", stage, batch, screen.case.speed_setting, [0] * len(batch)
                )
                rows = [e for e in store.evaluations("screen") if e.iteration == stage]
            todo = [r for r in rows if r.status == "pending"]
            say(
                f"stage {stage + 1} ({kind}, {len(factors)} factors): {len(rows)} runs, {len(todo)} to simulate"
            )
            fixed_si = {k: _to_si(k, v, backend) for k, v in screen.fixed.items()}
            tasks = [
                Task({**fixed_si, **r.params}, screen.case, f"screen-{stage}-{r.slot}")
                for r in todo
            ]
            for k, (i, res) in enumerate(runner.simulate(simulator, tasks), start=1):
                record_result(store, out, todo[i], res, reference)
                say(
                    f"{res.status.value}: {tasks[i].run_id} ({k} of {len(tasks)} done)",
                    k,
                    len(tasks),
                )
            rows = sorted(
                (e for e in store.evaluations("screen") if e.iteration == stage),
                key=lambda e: e.slot,
            )
            frame = pd.DataFrame(
                [
                    {
                        **{f: v for f, v in zip(factors, values[r.slot], strict=True)},
                        "status": r.status,
                        "dtw_xy": r.dtw_xy,
                        "dtw_theta": r.dtw_theta,
                        "transit_time": r.transit_time,
                    }
                    for r in rows
                ]
            )
            frame.to_csv(out / f"stage{stage + 1}-design.csv", index=False)
            ok = frame["status"].eq("ok").to_numpy()
            if ok.sum() <= len(factors):
                first = next((r.details.get("message") for r in rows if r.status != "ok"), "")
                raise ParcelfitError(
                    f"stage {stage + 1}: only {int(ok.sum())} of {len(rows)} runs succeeded, too few to estimate "
                    f"{len(factors)} effects (first failure: {first})",
                    file=out / "screen.sqlite",
                    fix="fix the failing simulations (see stageN-design.csv), then rerun",
                )
            analyses = []
            run_ok, centre_ok = ok[:n_runs], ok[n_runs:]
            for resp in RESPONSES:
                y = frame[resp].to_numpy(dtype=float)
                sub = design if run_ok.all() else _subset(design, run_ok)
                centre = y[n_runs:][centre_ok] if screen.centre_points else None
                a = analyse_effects(
                    sub, factors, y[:n_runs][run_ok], name=resp, alpha=screen.alpha, centre=centre
                )
                analyses.append(a)
                save_figure(pareto_chart(a), out / f"stage{stage + 1}-pareto-{resp}")
            table = pd.concat(
                [a.table.assign(response=a.response, method=a.method) for a in analyses]
            )
            table.to_csv(out / f"stage{stage + 1}-effects.csv", index=False)
            significant = select_parameters(analyses, max_parameters=len(factors)).parameters
            by_size = select_parameters(
                analyses, max_parameters=len(factors), only_significant=False
            ).parameters
            top_up = [f for f in by_size if f not in significant]
            survivors = significant + top_up[: max(0, screen.min_full_factors - len(significant))]
            results.append(StageResult(kind, factors, analyses, survivors))
            say(
                f"stage {stage + 1}: {len(significant)} of {len(factors)} parameters have a significant effect"
                + (
                    f"; topped up to {len(survivors)} by effect size"
                    if len(survivors) > len(significant)
                    else ""
                )
            )
            factors = survivors
    finally:
        runner.close()
        store.close()
        lock.release()
    sel = select_parameters(
        results[-1].analyses, max_parameters=screen.select, only_significant=False
    )
    doc = {
        "screen": screen.name,
        "test_case": screen.case.label,
        "method": results[-1].analyses[0].method,
        "selected": sel.parameters,
        "reasons": sel.reasons,
        "parameters": {p: list(screen.ranges[p]) for p in sel.parameters},
    }
    (out / "selection.yaml").write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return results, doc


def _known(name: str, path: Path, where: str) -> Any:
    """The catalogue parameter ``name``; an unknown one is an error naming the file and key."""
    try:
        return parameter(name)
    except ParcelfitError as exc:
        raise ParcelfitError(exc.message, file=path, where=where, fix=exc.fix) from None


def _subset(design: Any, keep: np.ndarray) -> Any:
    from dataclasses import replace

    return replace(design, matrix=design.matrix[keep])
