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
    placements: 1                # seeded placements per design row (1-50; 1: the nominal one)
    executor: {kind: local}      # or serial (in this process), or just executor: serial

Responses of every run: DTW_xy [m] and DTW_theta [rad] between the simulated run and the
reference run of the test case (the same preparation as the calibration cost), and the transit
time [s]. After each stage the effects on DTW_xy and DTW_theta are analysed
(`parcelfit.doe.analyse_effects`); a parameter survives if any of its effects is significant.
Outputs in the screen folder: ``stageN-effects.csv``, ``stageN-pareto-<response>.png/.svg``,
``stageN-design.csv`` (parameters in catalogue units and responses per run) and ``selection.yaml`` (the ranked
recommendation with reasons, and the parameters with their ranges ready for a study file).

**Placements.** With ``placements: 1`` (the default) every design row is one simulation at the
rig's nominal placement. On a rig such as E3 a single placement near the spin/slide threshold
changes branch with any small parameter change, so one run per row can judge the branch
instead of the parameter. With ``placements: K`` (K > 1) every design row is simulated at the
seeded placements 1..K, the same seeds for every row (common random numbers, as the
calibration's ensemble cost, `parcelfit.study.joint`: the placements' scatter leaves the
differences between rows), and the row's responses are ensemble statistics of its K runs:

* ``dtw_xy``, ``dtw_theta``: the means over the K runs of each run's DTW distance to the
  reference run;
* ``transit_time``: the mean over the runs that crossed both light barriers (a run without a
  transit, a parcel held at a plate, is left out of it; ``transits`` counts those in it);
* ``spin_share``: the share of the K runs whose net rotation exceeds 90 degrees
  (`parcelfit.sim.ensemble.rotation`, ``SPIN_ANGLE``), and ``median_rotation`` [rad];
* ``placements_ok``: how many of the K runs succeeded. A row with a failed run takes that run's
  status (the first in seed order) and no responses, as a joint evaluation does: its means
  would be over other placements than the other rows'.

Survivors and the selection are judged on DTW_xy and DTW_theta as with one placement; the
spin share, the median rotation and the mean transit time (over the rows that have one) are
analysed too (their effects in ``stageN-effects.csv``,
their Pareto charts, `StageResult.ensemble_analyses`), to be read beside them, but select
nothing. A simulator without seeded placements (``with_placement``) is refused for K > 1.
Each of a row's K simulations is a row of the store (slot = design row x K + seed - 1, the
store's ``seed`` the placement seed) written the moment it arrives, with its run in
``runs/screen-STAGE-ROW-pSEED.csv``, so a kill loses only the simulations running then.

The final selection ranks the last stage's parameters by their largest standardised effect, as
the method asks ("by effect size, not blindly by significance"); the reasons say which effects
were significant. A stage whose first 8 simulations all fail stops at once, quoting the first
failure (`parcelfit.study.loop.FailureStreak`); the failed runs of a stage none of whose
runs succeeded run again on a rerun. A rerun resumes stage by stage and refuses a stage whose
stored factors differ from the ones it would run now, and a folder screened with other
``placements`` (use a new folder after changing the screen file).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from types import MappingProxyType
from typing import Annotated, Any

import numpy as np
import pandas as pd
import yaml
from pydantic import AfterValidator, BeforeValidator, Field

from parcelfit.config import load_yaml
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
from parcelfit.errors import ParcelfitError, os_error, shown
from parcelfit.figures import save_figure
from parcelfit.metrics import ReferenceSelection, select_reference
from parcelfit.progress import ProgressCallback, ProgressEvent, ignore_progress
from parcelfit.runs import TestCase, load_dataset, read_trajectory
from parcelfit.schema import FileModel, Number, Pair, Text, Whole, or_default, parse
from parcelfit.sim.ensemble import SPIN_ANGLE, rotation
from parcelfit.sim.executors import Executor, Task, make_executor
from parcelfit.sim.factory import SimulatorConfig, SimulatorSection, content_kind, make_simulator
from parcelfit.sim.params import (
    SOFT,
    content_parameters,
    parameter,
    parameters_for,
    to_catalogue_units,
)
from parcelfit.study.folderlock import check_writable, lock_folder
from parcelfit.study.joint import require_placements, simulate_items
from parcelfit.study.loop import DesignLoop, FixedDesign
from parcelfit.study.objective import Evaluated, record_result
from parcelfit.study.store import Evaluation, Store
from parcelfit.study.studyfile import (
    _to_si,
    check_simulator_files,
    check_speed_settings,
    fixed_to_si,
    reference_case,
    require_dataset,
)
from parcelfit.study.studyschema import ReferenceSection, ScreenExecutorSection

RESPONSES = ("dtw_xy", "dtw_theta")  # the responses the survivors and the selection are judged on
# analysed too with several placements, shown but not selecting (see the module docstring)
ENSEMBLE_RESPONSES = ("spin_share", "median_rotation", "transit_time")
MAX_PLACEMENTS = 50
_STAGES = ("fractional", "full")

_Range = Annotated[
    tuple[float, float] | None,
    Pair(
        what="[low, high] with low < high",
        fix="write two numbers, or leave it empty for the screening range",
        increasing=True,
        nullable=True,
    ),
]


def _parameters(value: Any) -> Any:
    """``all`` -> None (every candidate), a list of names -> {name: None}, else as written."""
    if value == "all":
        return None
    if isinstance(value, list):
        return {str(n): None for n in value}
    if value is None or isinstance(value, str):
        raise ParcelfitError(
            f"expected all, a list of names or {{name: [low, high]}}, got {shown(value)}",
            fix="write parameters: all",
        )
    return value


def _stages(value: Any) -> tuple[Any, ...]:
    stages = tuple(value) if isinstance(value, list) else (value,)
    if any(s not in _STAGES for s in stages):
        raise ParcelfitError(f"unknown stages {list(stages)}", fix="use fractional and/or full")
    return stages


def _soft_list(value: Any) -> Any:
    if not isinstance(value, list):
        raise ParcelfitError(
            f"expected a list of parameter names, got {shown(value)}",
            fix="write e.g. soft_content: [E_Co, zeta_Co]",
        )
    return [str(n) for n in value]


def _soft_parameter(name: str) -> str:
    """A catalogue parameter that applies to soft contents (checked now, not after stage 1)."""
    try:
        parameter(name).range_for(SOFT)
    except ParcelfitError as exc:
        raise ParcelfitError(
            exc.message,
            fix=exc.fix or "name a soft-content parameter (see parcelfit params --consignment PB)",
        ) from None
    return name


class ScreenFile(FileModel):
    """A screen file as written (see the module docstring; ranges in catalogue units)."""

    name: Annotated[str, Text()]
    """The screen's name."""
    simulator: SimulatorSection
    """The simulator and its settings, as in a study file."""
    reference: ReferenceSection
    """The test case whose reference run the responses compare with, as in a study file."""
    parameters: Annotated[dict[Any, _Range] | None, BeforeValidator(_parameters)] = None
    """all (the consignment's catalogue candidates), a list of names, or {name: [low, high]} in
    catalogue units (default: the screening ranges)."""
    fixed: Annotated[dict[Any, Annotated[float, Number()]], or_default(dict)] = Field(
        default_factory=dict
    )
    """Parameters held at a value other than their default, in catalogue units."""
    stages: Annotated[
        tuple[str, ...], BeforeValidator(_stages), or_default(lambda: list(_STAGES))
    ] = _STAGES  # before-validators run last-written first: the default, then the check
    """The stages in order: fractional (resolution IV) and/or full (full factorial on the
    survivors)."""
    soft_content: Annotated[
        tuple[Annotated[str, AfterValidator(_soft_parameter)], ...],
        BeforeValidator(_soft_list),
        or_default(list),
    ] = ()
    """A soft content's parameters added in a third full-factorial stage (e.g. [E_Co, zeta_Co])."""
    resolution: Annotated[int, Whole(ge=3, le=5)] = 4
    """Resolution of the fractional design (3 to 5)."""
    centre_points: Annotated[int, Whole(ge=0, le=50)] = 0
    """Runs with every factor at mid-range added to each stage."""
    alpha: Annotated[float, Number(ge=1e-6, le=0.5)] = 0.05
    """Significance level of the effects [-]."""
    max_full_factors: Annotated[int, Whole(ge=2, le=10)] = 6
    """The full factorial keeps at most this many survivors."""
    min_full_factors: Annotated[int, Whole(ge=1, le=10)] = 3
    """... and at least this many (fewer survivors are topped up by effect size)."""
    select: Annotated[int, Whole(ge=1, le=100)] = 4
    """Parameters recommended for calibration in selection.yaml."""
    placements: Annotated[int, Whole(ge=1, le=MAX_PLACEMENTS)] = 1
    """Placements each design row is simulated at (seeds 1..K; 1: the nominal placement)."""
    executor: Annotated[ScreenExecutorSection, or_default(dict)] = Field(
        default_factory=ScreenExecutorSection
    )
    """Where simulations run: local or serial (the command line wins)."""


@dataclass(frozen=True)
class Screen:
    """A parsed screen file (SI units for the catalogue's parameters).

    ``parameters`` are the first stage's factors; ``ranges`` holds their ranges and those of the
    ``soft_content`` parameters of the last stage.
    """

    name: str
    folder: Path
    simulator: SimulatorConfig
    parameters: tuple[str, ...]
    ranges: Mapping[str, tuple[float, float]]
    fixed: Mapping[str, float]
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
    executor: Mapping[str, Any] = field(default_factory=dict)
    placements: int = 1  # seeded placements per design row (1: the nominal placement)
    path: Path | None = None  # the screen file


def load_screen(path: str | Path) -> Screen:
    """Read and check a screen file; ranges and fixed values are converted from catalogue units
    to SI here (a parameter left empty takes the catalogue's screening range)."""
    path = Path(path)
    f = parse(ScreenFile, load_yaml(path), file=path)
    folder = path.parent.resolve()
    sim = f.simulator.to_config(folder)
    rigs = check_simulator_files(sim, path)
    backend = f.simulator.backend
    dataset, rig, cons = reference_case(f.reference, f.simulator, path, folder, rigs)
    check_speed_settings(
        sim, [(TestCase(rig, cons, f.reference.speed_setting), "reference.speed_setting")], path
    )
    kind = content_kind(sim)
    spec = f.parameters
    if spec is None:  # the consignment's candidates; its content's own are the soft_content stage
        own = content_parameters(kind)
        spec = {p.name: None for p in parameters_for(kind) if p not in own}
    user: dict[str, tuple[float, float]] = {}
    for name, bounds in spec.items():
        if bounds is None:
            r = _screening_range(str(name), kind, path, f"parameters.{name}")
            user[str(name)] = (r.low, r.high)
        else:
            user[str(name)] = bounds
    if len(user) < 2:
        raise ParcelfitError(
            "a screen needs at least two parameters",
            file=path,
            where="parameters",
            fix="list two or more (or write parameters: all)",
        )
    _check_plan(f, user, kind, backend, path)
    for extra in f.soft_content:  # the last stage's extra factors, unless already listed
        r = parameter(extra).range_for(SOFT)
        user.setdefault(extra, (r.low, r.high))
    ranges = {}
    for name, (low, high) in user.items():
        try:
            ranges[name] = (_to_si(name, low, backend), _to_si(name, high, backend))
        except ParcelfitError as exc:
            raise ParcelfitError(
                exc.message, file=path, where=f"parameters.{name}", fix=exc.fix
            ) from None
    fixed = fixed_to_si(f.fixed, backend, path)
    return Screen(
        name=f.name,
        folder=folder,
        simulator=sim,
        parameters=tuple(str(n) for n in spec),
        ranges=MappingProxyType(ranges),
        fixed=MappingProxyType(fixed),
        dataset=dataset,
        case=TestCase(rig, cons, f.reference.speed_setting),
        stages=f.stages,
        soft_content=f.soft_content,
        resolution=f.resolution,
        centre_points=f.centre_points,
        alpha=f.alpha,
        max_full_factors=f.max_full_factors,
        min_full_factors=f.min_full_factors,
        select=f.select,
        executor=MappingProxyType(f.executor.model_dump()),
        placements=f.placements,
        path=path,
    )


def _check_plan(
    f: ScreenFile, factors: Mapping[str, Any], kind: str, backend: str, path: Path
) -> None:
    """What the screen file's keys cannot say alone: no parameter both screened and fixed; a
    soft content's stage only on a soft content (where the backend knows the content); a
    first stage that is a full factorial over no more parameters than it keeps (nothing ranks
    them before it); min_full_factors <= max_full_factors."""
    both = sorted(set(factors) & set(map(str, f.fixed)))
    if both:
        every = " (parameters: all takes every candidate: list the others instead)"
        raise ParcelfitError(
            f"{both} are both screened and fixed",
            file=path,
            where="fixed",
            fix="remove them from fixed, or from parameters"
            + (every if f.parameters is None else ""),
        )
    if f.soft_content and backend in ("mujoco", "rigidbox") and kind != SOFT:
        raise ParcelfitError(
            f"soft_content {list(f.soft_content)} on a consignment with a rigid content",
            file=path,
            where="soft_content",
            fix="leave soft_content out, or screen a soft-content type (e.g. PB)",
        )
    if len(f.soft_content) >= f.max_full_factors:
        raise ParcelfitError(
            f"the soft content's stage would keep only its {len(f.soft_content)} parameters "
            f"(max_full_factors {f.max_full_factors}), no survivor beside them",
            file=path,
            where="max_full_factors",
            fix=f"set max_full_factors: {len(f.soft_content) + 2} or more, or list fewer "
            "soft_content parameters",
        )
    if f.stages and f.stages[0] == "full" and len(factors) > f.max_full_factors:
        n = len(factors)
        raise ParcelfitError(
            f"the first stage is a full factorial over {n} parameters, which keeps at most "
            f"max_full_factors = {f.max_full_factors} and has nothing to rank them by yet",
            file=path,
            where="stages",
            fix=f"start with a fractional stage (stages: [fractional, full]), list at most "
            f"{f.max_full_factors} parameters, or set max_full_factors: {n} ({2**n} runs)"
            if n <= 10
            else f"start with a fractional stage (stages: [fractional, full]) or list at most "
            f"{f.max_full_factors} parameters",
        )
    if f.min_full_factors > f.max_full_factors:
        raise ParcelfitError(
            f"min_full_factors {f.min_full_factors}"
            + (" (its default)" if "min_full_factors" not in f.model_fields_set else "")
            + f" exceeds max_full_factors {f.max_full_factors}",
            file=path,
            where="min_full_factors",
            fix="give min_full_factors at most max_full_factors",
        )


def _user(name: str, si_value: float) -> float:
    """A value from SI back to its catalogue unit for the outputs (12 significant digits, so
    that 0.35 mm does not come back as 0.35000000000000003)."""
    return float(f"{float(to_catalogue_units(name, si_value)):.12g}")


@dataclass(frozen=True)
class StageResult:
    """One stage: the factors, the analyses per response (those the survivors and the
    selection are judged on), the survivors, and with several placements the analyses of the
    ensemble responses (`ENSEMBLE_RESPONSES`, shown, not selecting)."""

    kind: str
    factors: list[str]
    analyses: list[EffectAnalysis]
    survivors: list[str]
    ensemble_analyses: list[EffectAnalysis] = field(default_factory=list)


def _reference_run(screen: Screen) -> ReferenceSelection:
    """The reference run of the screen's test case; a dataset folder without its dataset.yaml,
    or a dataset without the case, is refused naming the screen file and its key."""
    require_dataset(
        screen.dataset,
        screen.case.label,
        file=screen.path,
        where="reference.dataset",
        kind="screen",
    )
    dataset = load_dataset(screen.dataset)
    try:
        runs = dataset[screen.case]
    except ParcelfitError as exc:
        raise ParcelfitError(
            exc.message, file=screen.path, where="reference", fix=exc.fix
        ) from None
    return select_reference(runs)


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
    ``total`` counting the stage's simulations: design rows times placements)."""
    out = Path(out)
    check_writable(out, ("screen.sqlite",))
    reference = _reference_run(screen)  # before the output folder: a missing dataset leaves none
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
    n_place = screen.placements
    # the placement seeds of every design row: 1..K for every row (common random numbers), or
    # the nominal placement alone (None, stored as seed 0 as before placements existed)
    seeds: list[int | None] = list(range(1, n_place + 1)) if n_place > 1 else [None]
    try:
        simulator = make_simulator(screen.simulator)
        require_placements(simulator, n_place, file=screen.path, where="placements")
        _check_stored_placements(store, n_place, out / "screen.sqlite")
    except BaseException:
        store.close()
        lock.release()
        raise
    runner = make_executor(
        executor or screen.executor.get("kind", "local"),
        workers=workers or screen.executor.get("workers"),
    )
    results: list[StageResult] = []
    factors = list(screen.parameters)
    try:
        plan = list(screen.stages) + (["full"] if screen.soft_content else [])
        for stage, kind in enumerate(plan):
            if stage == len(screen.stages) and screen.soft_content:
                factors = list(dict.fromkeys([*factors, *screen.soft_content]))
            if kind == "full" and len(factors) > screen.max_full_factors:
                n_max = screen.max_full_factors
                # the soft content's stage keeps its own parameters, which it exists for, and
                # the strongest survivors beside them (survivors come strongest first)
                own = [f for f in factors if f in screen.soft_content]
                own = own[:n_max] if stage == len(screen.stages) else []
                rest = [f for f in factors if f not in own][: n_max - len(own)]
                say(
                    f"stage {stage + 1}: {len(factors)} survivors, keeping the {len(rest)} "
                    "strongest" + (f" and the soft content's {', '.join(own)}" if own else "")
                )
                factors = [f for f in factors if f in rest or f in own]
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
            # one store row per simulation: design row i at placement k is slot i * K + k - 1
            batch = [{f: float(v) for f, v in zip(factors, run, strict=True)} for run in values]
            stage_seeds = [seed or 0 for _ in batch for seed in seeds]
            loop = DesignLoop(
                FixedDesign([p for p in batch for _ in seeds]),
                partial(_stage_rows, store, stage),
                partial(
                    store.add_pending,
                    "screen",
                    stage,
                    speed_setting=screen.case.speed_setting,
                    seeds=stage_seeds,
                ),
                partial(
                    _simulate,
                    stage=stage,
                    screen=screen,
                    store=store,
                    out=out,
                    simulator=simulator,
                    runner=runner,
                    reference=reference,
                    n_rows=len(values),
                ),
                lambda k, n, done: say(f"{done.status}: {done.label} ({k} of {n} done)", k, n),
                out,
                reopen=store.reopen,
            )
            rows = loop.rows()
            if rows and sorted(rows[0].params) != sorted(factors):
                raise ParcelfitError(
                    f"stage {stage + 1} was run over {sorted(rows[0].params)}, now it would be over {sorted(factors)}",
                    file=out / "screen.sqlite",
                    fix="use a new output folder after changing the screen file",
                )
            todo = loop.replay()
            n_sims = len(values) * n_place
            say(
                f"stage {stage + 1} ({kind}, {len(factors)} factors): {n_sims} runs, {len(todo)} to simulate"
                if n_place == 1
                else f"stage {stage + 1} ({kind}, {len(factors)} factors): {len(values)} runs x "
                f"{n_place} placements = {n_sims} simulations, {len(todo)} to simulate"
            )
            loop.evaluate(todo)
            rows = sorted(
                (e for e in store.evaluations("screen") if e.iteration == stage),
                key=lambda e: e.slot,
            )
            points = [
                {f: _user(f, v) for f, v in zip(factors, values[i], strict=True)}
                for i in range(len(values))
            ]
            if n_place == 1:
                frame = pd.DataFrame(
                    [
                        {
                            **points[r.slot],
                            "status": r.status,
                            "dtw_xy": r.dtw_xy,
                            "dtw_theta": r.dtw_theta,
                            "transit_time": r.transit_time,
                        }
                        for r in rows
                    ]
                )
            else:
                frame = pd.DataFrame(
                    [
                        {
                            **points[i],
                            **_ensemble_responses(rows[i * n_place : (i + 1) * n_place], out),
                        }
                        for i in range(len(values))
                    ]
                )
            frame.to_csv(out / f"stage{stage + 1}-design.csv", index=False)
            ok = frame["status"].eq("ok").to_numpy()
            if ok.sum() <= len(factors):
                first = next((r.details.message for r in rows if r.status != "ok"), "")
                raise ParcelfitError(
                    f"stage {stage + 1}: only {int(ok.sum())} of {len(frame)} runs succeeded, too few to estimate "
                    f"{len(factors)} effects (first failure: {first})",
                    file=out / "screen.sqlite",
                    fix="fix the failing simulations (see stageN-design.csv), then rerun",
                )
            analyses = []
            extra = []
            run_ok, centre_ok = ok[:n_runs], ok[n_runs:]
            for resp in RESPONSES + (ENSEMBLE_RESPONSES if n_place > 1 else ()):
                y = frame[resp].to_numpy(dtype=float)
                use, use_centre = run_ok, centre_ok
                if resp in ENSEMBLE_RESPONSES:
                    # a row whose every placement ended without a transit has no mean transit
                    use = run_ok & np.isfinite(y[:n_runs])
                    use_centre = centre_ok & np.isfinite(y[n_runs:])
                    if use.sum() <= len(factors):
                        continue  # too few rows have this response to estimate the effects
                sub = design if use.all() else _subset(design, use)
                centre = y[n_runs:][use_centre] if screen.centre_points else None
                a = analyse_effects(
                    sub, factors, y[:n_runs][use], name=resp, alpha=screen.alpha, centre=centre
                )
                (analyses if resp in RESPONSES else extra).append(a)
                save_figure(pareto_chart(a), out / f"stage{stage + 1}-pareto-{resp}")
            table = pd.concat(
                [a.table.assign(response=a.response, method=a.method) for a in analyses + extra]
            )
            table.to_csv(out / f"stage{stage + 1}-effects.csv", index=False)
            significant = select_parameters(analyses, max_parameters=len(factors)).parameters
            by_size = select_parameters(
                analyses, max_parameters=len(factors), only_significant=False
            ).parameters
            top_up = [f for f in by_size if f not in significant]
            survivors = significant + top_up[: max(0, screen.min_full_factors - len(significant))]
            results.append(StageResult(kind, factors, analyses, survivors, extra))
            say(
                f"stage {stage + 1}: {len(significant)} of {len(factors)} parameters have a significant effect"
                + (
                    f"; topped up to {len(survivors)} by effect size"
                    if len(survivors) > len(significant)
                    else ""
                )
            )
            factors = survivors
    except OSError as exc:  # a full disk while writing a run or a table
        raise os_error(exc, resumes=True) or exc from None
    finally:
        runner.close()
        store.close()
        lock.release()
    sel = select_parameters(
        results[-1].analyses, max_parameters=screen.select, only_significant=False
    )
    significant = set(
        select_parameters(results[-1].analyses, max_parameters=len(screen.ranges)).parameters
    )
    doc = {
        "screen": screen.name,
        "test_case": screen.case.label,
        "method": results[-1].analyses[0].method,
        "selected": sel.parameters,
        "significant": [p for p in sel.parameters if p in significant],
        "reasons": sel.reasons,
        "parameters": {p: [_user(p, v) for v in screen.ranges[p]] for p in sel.parameters},
    }
    (out / "selection.yaml").write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return results, doc


def _stage_rows(store: Store, stage: int) -> list[Evaluation]:
    """The store rows of screening stage ``stage``, in the order they were asked."""
    return [e for e in store.evaluations("screen") if e.iteration == stage]


def _simulate(
    todo: list[Evaluation],
    stage: int,
    screen: Screen,
    store: Store,
    out: Path,
    simulator: Any,
    runner: Executor,
    reference: ReferenceSelection,
    n_rows: int,
) -> Iterator[Evaluated]:
    """Simulate a stage's pending store rows through ``runner`` (each at its placement seed
    with several placements), store each result as it arrives (`record_result`), and yield it
    with a progress label; ``n_rows`` is the number of design rows of the stage."""
    n_place = screen.placements
    tasks = [
        Task({**screen.fixed, **r.params}, screen.case, _run_id(stage, r, n_place)) for r in todo
    ]
    if n_place == 1:
        arrivals = runner.simulate(simulator, tasks)
    else:
        placed = [(t, r.seed) for t, r in zip(tasks, todo, strict=True)]
        arrivals = simulate_items(runner, simulator, placed)
    for i, res in arrivals:
        row = todo[i]
        if n_place == 1:
            outcome = record_result(store, out, row, res, reference)
            what = tasks[i].run_id
        else:
            if res.ok and res.run is not None:  # for the spin share, kept in details
                rot = rotation(res.run.trajectory)
                res = replace(res, diagnostics={**res.diagnostics, "rotation": rot})
            run_file = f"runs/{tasks[i].run_id}.csv"
            outcome = record_result(store, out, row, res, reference, run_file=run_file)
            what = (
                f"{tasks[i].run_id}, run {row.slot // n_place + 1} of {n_rows} at "
                f"placement {row.seed} of {n_place}"
            )
        yield Evaluated(row, outcome["status"], outcome["cost"], outcome["message"], what)


def _check_stored_placements(store: Store, placements: int, db: Path) -> None:
    """Record the screen's placements in a store without simulations; refuse one whose
    simulations were run with other placements (a store from before placements existed holds
    nominal runs: 1)."""
    if not store.evaluations("screen"):
        store.set_meta("placements", placements)
        return
    stored = store.get_meta("placements")
    stored = 1 if stored is None else stored
    if stored != placements:
        raise ParcelfitError(
            f"the screen was run with placements: {stored}, now it would be run with "
            f"placements: {placements}",
            file=db,
            fix="use a new output folder after changing the screen file",
        )


def _run_id(stage: int, row: Evaluation, placements: int) -> str:
    """A simulation's run id: screen-STAGE-SLOT (nominal placement), else
    screen-STAGE-ROW-pSEED (design row ROW at placement seed SEED)."""
    if placements == 1:
        return f"screen-{stage}-{row.slot}"
    return f"screen-{stage:03d}-{row.slot // placements:02d}-p{row.seed}"


def _ensemble_responses(runs: list[Evaluation], folder: Path) -> dict[str, Any]:
    """A design row's responses over its placements (``runs``, in seed order): the means of
    DTW_xy [m] and DTW_theta [rad], the mean transit time [s] over the runs with a transit
    and how many had one, the share of spins (net rotation above 90 degrees) and the median
    rotation [rad], and how many placements succeeded. A row with a failed placement takes
    that run's status (the first in seed order) and no responses, as a joint evaluation does."""
    bad = next((r for r in runs if r.status != "ok"), None)
    out: dict[str, Any] = {
        "status": "ok" if bad is None else bad.status,
        "dtw_xy": None,
        "dtw_theta": None,
        "transit_time": None,
        "transits": None,
        "spin_share": None,
        "median_rotation": None,
        "placements_ok": sum(r.status == "ok" for r in runs),
    }
    if bad is not None:
        return out
    transits = [r.transit_time for r in runs if r.transit_time is not None]
    rot = np.array([_rotation(r, folder) for r in runs], dtype=float)
    out.update(
        dtw_xy=float(np.mean([r.dtw_xy for r in runs])),
        dtw_theta=float(np.mean([r.dtw_theta for r in runs])),
        transit_time=float(np.mean(transits)) if transits else None,
        transits=len(transits),
        spin_share=float(np.mean(rot > SPIN_ANGLE)),
        median_rotation=float(np.median(rot)),
    )
    return out


def _rotation(run: Evaluation, folder: Path) -> float:
    """A stored run's net rotation [rad]: kept in its details when it arrived, else from its
    run file."""
    value = run.details.rotation
    if value is None:
        if run.run_file is None:
            raise ParcelfitError(
                f"the successful run {run.slot} of stage {run.iteration + 1} has no run file",
                file=folder / "screen.sqlite",
                fix="use a new output folder",
            )
        value = rotation(read_trajectory(folder / run.run_file))
    return float(value)


def _screening_range(name: str, kind: str, path: Path, where: str) -> Any:
    """The catalogue's screening range of ``name`` for ``kind`` contents (catalogue units); an
    unknown parameter, or one that does not apply, is an error naming the file and key."""
    try:
        return parameter(name).range_for(kind)
    except ParcelfitError as exc:
        raise ParcelfitError(
            exc.message, file=path, where=where, fix=exc.fix or f"remove it from a {kind} screen"
        ) from None


def _subset(design: Any, keep: np.ndarray) -> Any:
    return replace(design, matrix=design.matrix[keep])
