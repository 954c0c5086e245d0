"""What a calibration predicts for a design it was not fitted on: ``parcelfit predict``.

A calibration leaves a plausible set S of parameter sets the data cannot tell apart
(`parcelfit.study.identify`, stored in the study's ``results.json`` as a sample of S in SI).
A prediction simulates a design (a bundled rig or a rig file, a consignment type and a speed
setting) at N parameter sets drawn from that sample (seeded, without replacement while the
sample has enough rows) times K seeded placements (the rig's hand-placement scatter, the same K
placement seeds for every set: common random numbers), and reports for every quantity q of a
run:

* the **transit time** T [s] between the rig's first and last light barrier;
* the **rotation** |theta(t_end) - theta(t_0)| [rad] (`parcelfit.sim.ensemble.rotation`);
* the **exit position** y(t_end) [m] and the **exit heading** theta(t_end) [rad]: the parcel's
  lateral coordinate (the rig's frame) and unwrapped heading at the run's last sample, where it
  leaves the rig (a rig ends a run shortly after its last light barrier, ``end`` in its file).
  The exit's x [m] is kept in the run table too.

**Predictive distribution.** The runs of all sets and placements pooled: the median and the
5-95 % band (the 5th and 95th percentiles) of q over the runs that ended ok (and, for T,
crossed both light barriers): the model's band. Real runs scatter further, specimen by
specimen and by their measurement noise; the **band of a real run** adds that scatter,
estimated from the calibration's fitted and validation cases (`parcelfit.study.run_scatter`,
formulas there).

**Parameters versus placements** and **how far each parameter moves a prediction**: the
decomposition of the spread and the effects of `parcelfit.study.spread` (its docstring gives
the formulas). For each calibrated parameter the data do not determine, the quantity it moves
most (as a share of that quantity's 5-95 % band) is named in one sentence, e.g. "E_Pa is
undetermined and moves the transit time by 40 ms here: run `parcelfit design` to find the
experiment that fixes it" (among its resolved effects that are not negligible). A parameter
all of whose effects are negligible (`Effect.negligible`: |effect| + threshold x SE below the
measurement floor `spread.FLOOR`) is said not to matter for this design; one with no resolved
effect that is not negligible, but some effect that is not negligible, is said not to be
resolved, with its clearest such effect (the largest t), the sets its regression had and the
advice to draw more sets.

**Drives.** A placement is also the moment the run happens: each drive of the rig runs at its
mean speed times 1 + U(-D, D), drawn from the placement seed (`Rig.speed_factors`; method.md:
real belt speeds deviate up to 3 % short-term, D = 0.03 by default), so a placement's runs share
their drive speeds across sets as they share the start pose.

**The real runs' scatter** is estimated against the recommended parameters simulated at
`SCATTER_RUNS` (or ``scatter_runs``) seeded placements (drives as above) on every fitted and
validation case of the study (`parcelfit.study.run_scatter`). They do not depend on the design:
those another prediction of the study finished are taken from its store, not simulated again
(`parcelfit.study.shared_runs`).

**The model's numerical error** at the design is estimated from the recommended parameters
simulated on the design at `NUMERICAL_RUNS` (or ``numerical_runs``) seeded placements by the
model and by the model refined ``validation.refinement`` times over (matched pairs,
`parcelfit.study.numerical_error`); it widens the band of a real run with the real runs'
scatter. Not estimated where the study switches the refinement off, the simulator cannot be
refined or ``numerical_runs`` is 0 (the prediction's notes say so). Its runs do not depend on
the sets or placements: those another prediction of the same design finished (with the same
seed, study and drive deviation) are taken from its store, as are the design's own runs where
they are the same simulations (`parcelfit.study.shared_runs`).

**Resumable.** The simulations are recorded in their own store, ``predict.sqlite`` in the
output folder (`parcelfit.study.store`, rows of kind ``screen``: iteration 0 the prediction's,
slot = set x K + placement index; iteration i >= 1 the scatter runs of the study's i-th case;
``seed`` the placement seed, ``transit_time`` [s], ``details`` the rotation, exit position and
heading; iteration -1 the numerical error's runs on the model, -2 on the refined model), all
written as pending before any runs and each finished in one transaction the
moment it arrives; rerunning the same command runs only what is still pending. The inputs
(study, design, N, K, seed, the drawn sets, the placement seeds and D) are stored in the meta
record ``predict``, the numerical error's (refinement, parameters, ``at``, placement seeds) in
``numerical``: a folder holding a prediction with other inputs is refused.

Outputs in the output folder (schemas in docs/data.md, Predictions): ``runs.csv`` (one row per
simulation), ``summary.csv`` (one row per quantity), ``effects.csv`` (one row per parameter and
quantity) (or ``.parquet``), and ``prediction.json`` (all of it, for the HTML page
`parcelfit.report.prediction`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from parcelfit.atomic import write_text_atomic
from parcelfit.errors import ParcelfitError, shown
from parcelfit.progress import ProgressCallback, ProgressEvent, ignore_progress
from parcelfit.runs import Run, TestCase, is_synthetic
from parcelfit.runs.dataset import SYNTHETIC_NOTE
from parcelfit.sim.ensemble import MAX_PLACEMENTS
from parcelfit.sim.executors import Executor, SharedExecutor, Task, make_executor
from parcelfit.sim.factory import make_simulator
from parcelfit.sim.protocol import SimResult, Simulator
from parcelfit.study.defaults import PREDICT_PLACEMENTS, SCATTER_RUNS
from parcelfit.study.details import EvaluationDetails
from parcelfit.study.folderlock import check_writable, lock_folder
from parcelfit.study.identify import Identifiability
from parcelfit.study.joint import (
    SPEED_DEVIATION,
    check_speed_deviation,
    placements_for,
    places_runs,
    require_placements,
    simulate_items,
    varies_drives,
)
from parcelfit.study.numerical_error import (
    NUMERICAL_RUNS,
    NumericalError,
    estimate_numerical_error,
    numerical_notes,
)
from parcelfit.study.plausible import (
    Design,
    check_design,
    design_simulator,
    draw_sets,
    load_inputs,
    placement_seeds,
)
from parcelfit.study.run_scatter import QUANTITIES as RUN_QUANTITIES
from parcelfit.study.run_scatter import (
    RunScatter,
    estimate_run_scatter,
    quantities,
    real_run_band,
    scatter_note,
    stored_recommendation,
)
from parcelfit.study.shared_runs import (
    DESIGN,
    SCATTER,
    STORE_NAME,
    Reused,
    candidate_stores,
    claim_record,
    design_record,
    reuse_runs,
    scatter_record,
)
from parcelfit.study.spread import (
    FLOOR,
    Decomposition,
    Effect,
    decompose,
    effects_of,
    t_threshold,
)
from parcelfit.study.store import Evaluation, Store
from parcelfit.study.studyfile import CaseSpec, Study

PREDICT_STORE = STORE_NAME  # the file shared_runs looks for in other predictions' folders
PREDICTION_FILE = "prediction.json"
TABLE_FORMATS = ("csv", "parquet")
MAX_SETS = 1000  # parameter sets of one prediction (each simulated at every placement)
PLACEMENTS = PREDICT_PLACEMENTS  # seeded placements per set by default
MODEL_ITERATION, REFINED_ITERATION = -1, -2  # the numerical error's rows in predict.sqlite
QUANTITIES = ("transit_time", "rotation", "exit_y", "exit_heading")
# per quantity: words, SI unit, the unit a person reads and its factor from SI
_SHOW = {
    "transit_time": ("transit time", "s", "ms", 1e3),
    "rotation": ("rotation", "rad", "deg", 180 / math.pi),
    "exit_y": ("exit position", "m", "mm", 1e3),
    "exit_heading": ("exit heading", "rad", "deg", 180 / math.pi),
}
_VERDICT_WORDS = {
    "undetermined": "is undetermined",
    "lower bound": "is only bounded below",
    "upper bound": "is only bounded above",
    "narrowed": "is only narrowed",
    "determined": "is determined",
}


def quantity_words(quantity: str) -> str:
    """How a quantity is called in a sentence (``transit time``)."""
    return _SHOW[quantity][0]


def quantity_unit(quantity: str) -> str:
    """The SI unit of a quantity (``s``, ``rad``, ``m``)."""
    return _SHOW[quantity][1]


def shown_value(quantity: str, value: float, digits: int = 3) -> str:
    """A value (SI) in the unit a person reads: ``40 ms``, ``12.5 deg``, ``3.1 mm``."""
    if not math.isfinite(value):
        return "-"
    unit, factor = _SHOW[quantity][2], _SHOW[quantity][3]
    rounded = float(f"{value * factor:.{digits}g}")  # significant digits, never an exponent
    return f"{rounded:,.{max(0, digits - 1 - _magnitude(rounded))}f} {unit}".replace(",", "")


def _magnitude(value: float) -> int:
    """The decimal exponent of ``value`` (0 for 0)."""
    return 0 if value == 0 else math.floor(math.log10(abs(value)))


# -- the statistics ------------------------------------------------------------------------------


@dataclass(frozen=True)
class QuantitySummary:
    """The predictive distribution of one quantity (SI): runs with a value, median, the 5-95 %
    band of the model's runs, the decomposition of its spread, and the 5-95 % band of a real
    run (with the real runs' own scatter, `parcelfit.study.run_scatter`; the model's band when
    that is not known)."""

    quantity: str
    runs: int
    median: float
    q05: float
    q95: float
    decomposition: Decomposition
    run_q05: float = math.nan
    run_q95: float = math.nan
    numerical_sd: float = math.nan  # the model's numerical error (SI; transit time: a share)


@dataclass(frozen=True, eq=False)
class Prediction:
    """A finished prediction: the design, the study it came from, the drawn sets, placement
    seeds, the runs table (one row per simulation, columns of docs/data.md), the summary per
    quantity, the effects and the sentences naming what the undetermined parameters move."""

    design: Design
    study: str
    sets: list[dict[str, float]]
    seeds: list[int]
    runs: pd.DataFrame
    summaries: list[QuantitySummary]
    effects: list[Effect]
    sentences: list[str]
    notes: list[str] = field(default_factory=list)
    out: Path | None = None
    scatter: RunScatter | None = None
    numerical: NumericalError | None = None

    def summary_table(self) -> pd.DataFrame:
        """One row per quantity (docs/data.md, Predictions)."""
        rows = []
        for s in self.summaries:
            d = s.decomposition
            rows.append(
                {
                    "quantity": s.quantity,
                    "unit": quantity_unit(s.quantity),
                    "runs": s.runs,
                    "median": s.median,
                    "q05": s.q05,
                    "q95": s.q95,
                    "run_q05": s.run_q05,
                    "run_q95": s.run_q95,
                    "numerical_sd": s.numerical_sd,
                    "variance": d.total,
                    "between_sets": d.between,
                    "within_sets": d.within,
                    "parameter_share": d.parameter_share,
                    "placement_share": d.placement_share,
                }
            )
        return pd.DataFrame(rows)

    def effects_table(self) -> pd.DataFrame:
        """One row per parameter and quantity (docs/data.md, Predictions)."""
        return pd.DataFrame(
            [
                {
                    "parameter": e.parameter,
                    "verdict": e.verdict,
                    "interval_low": e.low,
                    "interval_high": e.high,
                    "quantity": e.quantity,
                    "unit": quantity_unit(e.quantity),
                    "effect": e.effect,
                    "se": e.se,
                    "resolved": e.resolved,
                }
                for e in self.effects
            ],
            columns=[
                "parameter",
                "verdict",
                "interval_low",
                "interval_high",
                "quantity",
                "unit",
                "effect",
                "se",
                "resolved",
            ],
        )

    def to_json(self) -> dict[str, Any]:
        """Everything, JSON-ready (SI; NaN as null)."""

        def clean(v: Any) -> Any:
            if isinstance(v, float) and not math.isfinite(v):
                return None
            return v

        def records(df: pd.DataFrame) -> list[dict[str, Any]]:
            return [
                {k: clean(v.item() if hasattr(v, "item") else v) for k, v in r.items()}
                for r in df.to_dict(orient="records")
            ]

        return {
            "design": {
                "rig": self.design.rig_name,
                "consignment": self.design.consignment_name,
                "setting": self.design.setting,
                "label": self.design.label,
            },
            "study": self.study,
            "sets": len(self.sets),
            "placements": len(self.seeds),
            "seeds": self.seeds,
            "summary": records(self.summary_table()),
            "run_scatter": None if self.scatter is None else self.scatter.to_json(),
            "numerical_error": None if self.numerical is None else self.numerical.to_json(),
            "effects": records(self.effects_table()),
            "sentences": self.sentences,
            "notes": self.notes,
            "runs": records(self.runs),
        }


def run_values(run: Run | None) -> dict[str, float | None]:
    """The quantities of one run (SI; None where it has none): transit time, rotation, exit
    x, y and heading (module docstring)."""
    if run is None:
        return {k: None for k in RUN_QUANTITIES}
    return quantities(run.trajectory, run.transit_time)


def sentence(e: Effect) -> str:
    """What a not-determined parameter does here, in one sentence."""
    words = _VERDICT_WORDS.get(e.verdict, f"is {e.verdict}")
    return (
        f"{e.parameter} {words} and moves the {quantity_words(e.quantity)} by "
        f"{shown_value(e.quantity, abs(e.effect), 2)} here: run `parcelfit design` to find the "
        "experiment that fixes it"
    )


def summarise_prediction(
    ident: Identifiability,
    sets: Sequence[Mapping[str, float]],
    seeds: Sequence[int],
    runs: pd.DataFrame,
    scatter: RunScatter | None = None,
    seed: int = 0,
    numerical: NumericalError | None = None,
) -> tuple[list[QuantitySummary], list[Effect], list[str]]:
    """The summaries, effects and sentences of a runs table (module docstring); ``scatter``
    (the real runs' own, seeded by ``seed``) and ``numerical`` (the model's numerical error at
    the design) widen each quantity's band to a real run's."""
    n, k = len(sets), len(seeds)
    summaries, effects = [], []
    with_mean: dict[str, int] = {}  # per quantity, the sets with a mean (the regression's)
    names = ident.names
    intervals = [p.interval for p in ident.parameters]
    X = np.array([[s[name] for name in names] for s in sets], float)
    for q in QUANTITIES:
        grid = np.full((n, k), np.nan)
        for r in runs.itertuples(index=False):
            v = getattr(r, q)
            if v is not None and isinstance(v, float | int) and math.isfinite(v):
                grid[int(r.set), int(r.placement)] = float(v)
        vals = grid[np.isfinite(grid)]
        if vals.size:
            med, q05, q95 = (float(np.percentile(vals, p)) for p in (50, 5, 95))
        else:
            med = q05 = q95 = math.nan
        run_q05, run_q95 = real_run_band(
            vals.tolist(), q, scatter, seed, None if numerical is None else numerical.sd
        )
        num_sd = math.nan if numerical is None else numerical.sd.get(q, math.nan)
        summaries.append(
            QuantitySummary(
                q, int(vals.size), med, q05, q95, decompose(grid), run_q05, run_q95, num_sd
            )
        )
        with np.errstate(invalid="ignore"):
            means = np.nanmean(np.where(np.isfinite(grid), grid, np.nan), axis=1)
        eff, se = effects_of(means, X, intervals)
        # the sets with a mean of q are the regression's
        with_mean[q] = int(np.isfinite(means).sum())
        threshold = t_threshold(with_mean[q], len(names), len(QUANTITIES))
        for j, p in enumerate(ident.parameters):
            effects.append(
                Effect(
                    p.name,
                    p.verdict,
                    q,
                    p.interval[0],
                    p.interval[1],
                    float(eff[j]),
                    float(se[j]),
                    threshold,
                )
            )
    band = {s.quantity: s.q95 - s.q05 for s in summaries}
    # the measurement floors as a person reads them, each unit once: "2 ms, 3 mm and 1 deg"
    shown_floors = list(dict.fromkeys(shown_value(q, f, 1) for q, f in FLOOR.items()))
    floors = ", ".join(shown_floors[:-1]) + " and " + shown_floors[-1]
    sentences = []
    for p in ident.parameters:
        if p.determined:
            continue
        words = _VERDICT_WORDS.get(p.verdict, p.verdict)
        if not any(e.estimated for e in effects if e.parameter == p.name):
            sentences.append(
                f"{p.name} {words}, and what it does here was not estimated: the "
                f"{len(names)} parameter{'s' if len(names) != 1 else ''} need at least "
                f"{len(names) + 2} parameter sets with "
                f"a result (--sets), {n} were drawn"
            )
            continue
        own = [e for e in effects if e.parameter == p.name and e.estimated]
        mine = [e for e in own if e.resolved and not e.negligible]
        if not mine and all(e.negligible for e in own):
            sentences.append(
                f"{p.name} {words} but moves none of these predictions here by as much as a "
                f"run can show (each effect, with its uncertainty, below {floors}): for this "
                "design it does not matter"
            )
            continue
        if not mine:
            open_ = [e for e in own if not e.negligible]
            largest = max(open_, key=lambda e: abs(e.effect) / e.se if e.se > 0 else 0.0)
            sentences.append(
                f"{p.name} {words}, and what it does here is not resolved: with "
                f"{with_mean[largest.quantity]} parameter sets an effect counts from "
                f"{largest.threshold:.1f} "
                f"standard errors, and its clearest, on the "
                f"{quantity_words(largest.quantity)}, is "
                f"{shown_value(largest.quantity, abs(largest.effect), 2)} +- "
                f"{shown_value(largest.quantity, largest.se, 2)}: draw more parameter sets "
                "(--sets) before taking it not to matter for this design"
            )
            continue

        def weight(e: Effect) -> float:
            b = band[e.quantity]
            return abs(e.effect) / b if b > 0 else 0.0

        sentences.append(sentence(max(mine, key=weight)))
    return summaries, effects, sentences


# -- running it ----------------------------------------------------------------------------------


def _inputs_record(
    study_dir: Path,
    design: Design,
    sets: Sequence[Mapping[str, float]],
    seeds: Sequence[int],
    seed: int,
    speed_deviation: float,
    scatter_runs: int = SCATTER_RUNS,
) -> dict[str, Any]:
    # the scatter's run count only where it is not the default, so that a prediction made
    # before the option existed resumes (the numerical error's runs have their own record,
    # `_numerical_record`, so that one made before them resumes with any --numerical-runs)
    extra = {} if scatter_runs == SCATTER_RUNS else {"scatter_runs": scatter_runs}
    return {
        **extra,
        "study": str(study_dir.resolve()),
        "rig": design.rig,
        "consignment": design.consignment,
        "setting": design.setting,
        "seed": seed,
        "sets": [dict(s) for s in sets],
        "placements": list(seeds),
        "speed_deviation": speed_deviation,
    }


def default_out(study_dir: Path, design: Design) -> Path:
    """The default output folder: ``predict-RIG-TYPE-SETTING`` inside the study folder."""
    return study_dir / f"predict-{design.rig_name}-{design.consignment_name}-{design.setting}"


def predict(
    folder: str | Path,
    rig: str,
    consignment: str,
    setting: int,
    *,
    sets: int = 20,
    placements: int | None = None,
    seed: int = 0,
    speed_deviation: float = SPEED_DEVIATION,
    scatter_runs: int = SCATTER_RUNS,
    numerical_runs: int = NUMERICAL_RUNS,
    out: str | Path | None = None,
    executor: str = "local",
    workers: int | None = None,
    scheduler: str | None = None,
    table_format: str = "csv",
    progress: ProgressCallback | None = None,
    make: Callable[[], Executor] | None = None,
    on_cost: Callable[[str], None] | None = None,
) -> Prediction:
    """Predict ``rig`` x ``consignment`` x ``setting`` from the calibration in ``folder``:
    ``sets`` parameter sets of its plausible set times ``placements`` seeded placements
    (default `PLACEMENTS`, 1 for a simulator that cannot place its runs; each
    with its drives ``speed_deviation`` [-] off their mean speeds, seeded the same way) and the
    recommended parameters at ``scatter_runs`` placements per fitted and validation case and at
    ``numerical_runs`` placements on the design by the model and the refined model (0: no
    numerical error), simulated in ``executor`` (serial, local with ``workers`` processes, dask at
    ``scheduler``), recorded in ``out``/predict.sqlite (resumable), summarised and written
    (module docstring). ``progress`` receives one event per finished simulation; ``on_cost``
    the expected cost of the simulations still to run (one line, `parcelfit.sim.cost`), before
    they start; ``make`` (tests) replaces the executor factory. Seeded: the same inputs give
    the same tables."""
    progress = progress or ignore_progress
    if not 1 <= sets <= MAX_SETS:
        raise ParcelfitError(f"--sets {sets}: give from 1 to {MAX_SETS} parameter sets")
    if placements is not None and not 1 <= placements <= MAX_PLACEMENTS:
        raise ParcelfitError(f"--placements {placements}: give from 1 to {MAX_PLACEMENTS}")
    if table_format not in TABLE_FORMATS:
        raise ParcelfitError(
            f"unknown table format {shown(table_format)}", fix=f"use one of {list(TABLE_FORMATS)}"
        )
    check_speed_deviation(speed_deviation)
    if not 2 <= scatter_runs <= MAX_PLACEMENTS:
        raise ParcelfitError(
            f"--scatter-runs {scatter_runs}: give from 2 to {MAX_PLACEMENTS} runs per case"
        )
    if not 0 <= numerical_runs <= MAX_PLACEMENTS:
        raise ParcelfitError(
            f"--numerical-runs {numerical_runs}: give from 0 (no numerical error) to "
            f"{MAX_PLACEMENTS} placements"
        )
    inputs = load_inputs(folder)
    design = check_design(rig, consignment, setting)
    simulator = design_simulator(inputs.study, design)
    placements = placements_for(simulator, placements, PLACEMENTS)
    require_placements(simulator, placements, file=None, where="--placements")
    drawn = draw_sets(inputs.identifiability, sets, seed)
    placed = places_runs(simulator)
    seeds = placement_seeds(placements, seed) if placements > 1 or placed else [0]
    deviation = speed_deviation if placed and varies_drives(simulator) else 0.0
    recommended = stored_recommendation(inputs.folder)  # read once, for both kinds of runs
    scatter_jobs = _scatter_jobs(recommended, inputs.study, seed, scatter_runs)
    numerical_jobs = _numerical_jobs(
        recommended, inputs.study, inputs.identifiability, simulator, numerical_runs, seed
    )
    full = [{**inputs.study.fixed, **s} for s in drawn]
    out_dir = Path(out) if out is not None else default_out(inputs.folder, design)
    check_writable(out_dir, (PREDICT_STORE,))
    out_dir.mkdir(parents=True, exist_ok=True)
    lock = lock_folder(out_dir, "a prediction")
    try:
        store = Store(out_dir / PREDICT_STORE)
        shared: SharedExecutor | None = None
        try:
            record = _inputs_record(
                inputs.folder, design, drawn, seeds, seed, deviation, scatter_runs
            )
            if not store.claim_meta("predict", record):
                raise ParcelfitError(
                    "this folder holds a prediction with other inputs (study, design, --sets, "
                    "--placements, --seed, --speed-deviation or --scatter-runs)",
                    file=out_dir,
                    fix="give another --out, or the same inputs to resume it",
                )
            if isinstance(numerical_jobs, NumericalJobs) and not store.claim_meta(
                "numerical", _numerical_record(numerical_jobs)
            ):
                raise ParcelfitError(
                    "this folder holds the model's numerical error with other inputs "
                    "(--numerical-runs, --seed, the study's validation.refinement or its "
                    "recommended parameters)",
                    file=out_dir,
                    fix="give another --out, the same --numerical-runs as before, or "
                    "--numerical-runs 0 to go without it",
                )
            if not store.evaluations("screen"):  # one transaction: all rows or none
                items = [(s, j) for s in range(len(full)) for j in range(len(seeds))]
                store.add_pending(
                    "screen",
                    0,
                    [full[s] for s, _ in items],
                    design.setting,
                    [seeds[j] for _, j in items],
                )
            # the other predictions' stores, which may hold the same simulations (shared_runs)
            sources = candidate_stores(inputs.folder, out_dir)
            if scatter_jobs is not None:
                if not any(e.iteration > 0 for e in _rows(store, None)):
                    for c, (spec, params, scatter_seeds) in enumerate(scatter_jobs.cases, start=1):
                        store.add_pending(
                            "screen",
                            c,
                            [params] * len(scatter_seeds),
                            spec.case.speed_setting,
                            scatter_seeds,
                        )
                scatter_rec = scatter_record(
                    inputs.folder,
                    inputs.study,
                    [spec.label for spec, _, _ in scatter_jobs.cases],
                    deviation,
                )
                claim_record(store, SCATTER, scatter_rec)
                # the same runs finished by another prediction of this study (shared_runs)
                _say_reused(
                    progress,
                    "the real runs' scatter",
                    reuse_runs(store, SCATTER, scatter_rec, sources),
                )
            if isinstance(numerical_jobs, NumericalJobs):
                have = {e.iteration for e in _rows(store, None)}
                for it in (MODEL_ITERATION, REFINED_ITERATION):
                    if it not in have:  # one transaction each: all its rows or none
                        store.add_pending(
                            "screen",
                            it,
                            [numerical_jobs.params] * len(numerical_jobs.seeds),
                            design.setting,
                            numerical_jobs.seeds,
                        )
            # the design's runs finished by another prediction of this design (shared_runs)
            design_rec = design_record(inputs.folder, inputs.study, design, deviation)
            claim_record(store, DESIGN, design_rec)
            _say_reused(
                progress,
                "the design's runs",
                reuse_runs(store, DESIGN, design_rec, sources),
            )
            if on_cost is not None:
                on_cost(
                    cost_line(
                        inputs.study,
                        [design],
                        store,
                        executor,
                        workers,
                        make is not None,
                        extra=[]
                        if scatter_jobs is None
                        else [s.case for s, _, _ in scatter_jobs.cases],
                        refinement=numerical_jobs.refinement
                        if isinstance(numerical_jobs, NumericalJobs)
                        else 1,
                    )
                )
            # one executor for every phase below, sized for all their simulations
            pending = sum(e.status == "pending" for e in _rows(store, None))
            shared = SharedExecutor(
                lambda: open_executor(executor, workers, scheduler, pending, make)
            )
            run = partial(
                _run_rows,
                store,
                speed_deviation=deviation,
                pool=shared.get,
                progress=progress,
            )
            k, pose = len(seeds), placed or placements > 1
            run(
                _rows(store, 0),
                lambda e: (
                    Task(e.params, design.case, f"predict-set{e.slot // k}-p{e.seed}"),
                    e.seed if pose else None,
                ),
                simulator,
                design.label,
            )
            model_values = None
            if scatter_jobs is not None:
                jobs = scatter_jobs
                run(
                    [e for e in _rows(store, None) if e.iteration > 0],
                    lambda e: (
                        Task(
                            e.params,
                            jobs.cases[e.iteration - 1][0].case,
                            f"scatter-case{e.iteration}-p{e.seed}",
                        ),
                        e.seed if jobs.placed else None,
                    ),
                    jobs.simulator,
                    "the real runs' scatter (the recommended parameters on the study's cases)",
                )
                model_values = _scatter_values(store, jobs)
            numerical = numerical_jobs
            if isinstance(numerical_jobs, NumericalJobs):
                numerical = _run_numerical(store, numerical_jobs, design, simulator, run)
            runs = _runs_table(store, drawn, len(seeds), inputs.identifiability.names)
        finally:
            if shared is not None:
                shared.close()
            store.close()
        scatter = estimate_run_scatter(inputs.folder, inputs.study, model_values)
        summaries, effects, sentences = summarise_prediction(
            inputs.identifiability, drawn, seeds, runs, scatter, seed, numerical
        )
        notes = []
        synthetic = sorted(
            {
                str(c.dataset)
                for c in (*inputs.study.cases, *inputs.study.validation_cases)
                if is_synthetic(c.dataset)
            }
        )
        if synthetic:
            notes.append(
                f"the calibration's real runs are {SYNTHETIC_NOTE} ({', '.join(synthetic)}): "
                "so is this prediction's calibration"
            )
        ident = inputs.identifiability
        if not (ident.reached and ident.supported):
            what = "parameter set" if not ident.reached else "evaluation"
            notes.append(
                f"no {what} of the calibration reached the real runs' scatter: the sets "
                "are drawn from the whole parameter box, not from a plausible set"
            )
        note = scatter_note(scatter)
        if note is not None:
            notes.append(note)
        if len(seeds) == 1:
            notes.append(
                "one placement per parameter set: the spread is not split between the "
                "parameters and the placements (shares shown as -), and each set's mean holds "
                "its one run's scatter, which the parameters' effects are then judged against"
            )
        notes.extend(numerical_notes(numerical))
        calibrated = sorted({c.case.consignment for c in inputs.study.cases})
        if design.consignment_name not in calibrated:
            notes.append(
                f"the parameters were calibrated on {', '.join(calibrated)}, not on "
                f"{design.consignment_name}: the packaging's parameters of one type carry over to "
                "another only as far as the two packagings are alike"
            )
        if speed_deviation > 0 and deviation == 0:
            notes.append(
                "this simulator cannot run its drives off their mean speeds, so the runs hold "
                "no short-term speed deviation (--speed-deviation is ignored)"
            )
        failed = int((runs["status"] != "ok").sum())
        if failed:
            notes.append(f"{failed} of {len(runs)} simulations did not end ok and are left out")
        prediction = Prediction(
            design,
            inputs.study.name,
            drawn,
            seeds,
            runs,
            summaries,
            effects,
            sentences,
            notes,
            out_dir,
            scatter,
            numerical,
        )
        write_prediction(prediction, out_dir, table_format)
    finally:
        lock.release()
    return prediction


def _say_reused(progress: ProgressCallback, what: str, reused: Reused) -> None:
    """Tell ``progress`` how many of ``what``'s simulations were taken from which folders."""
    if reused.rows:
        progress(
            ProgressEvent(
                "predict",
                f"{what}: {reused.rows} simulations taken from {', '.join(reused.sources)}",
            )
        )


def _rows(store: Store, iteration: int | None) -> list[Any]:
    """The store's simulations of the prediction (``iteration`` 0), of the scatter runs of one
    study case (its index from 1), of the numerical error's on the model (-1) or the refined
    model (-2), or all (None)."""
    rows = store.evaluations("screen")
    return rows if iteration is None else [e for e in rows if e.iteration == iteration]


@dataclass(frozen=True)
class ScatterJobs:
    """The simulations behind the real runs' scatter (`parcelfit.study.run_scatter`): the
    study's simulator, whether it takes placements, and per study case with real runs (fitted,
    then validation) the recommended parameters (SI, fixed ones included) and the seeds."""

    simulator: Simulator
    placed: bool
    cases: list[tuple[CaseSpec, dict[str, float], list[int]]]


def _scatter_jobs(
    evaluation: Evaluation | None, study: Study, seed: int, runs: int = SCATTER_RUNS
) -> ScatterJobs | None:
    """The recommended parameters (the calibration's ``evaluation`` of them) at ``runs`` seeded
    placements on every fitted and validation case of ``study``; None without an ok fit."""
    if evaluation is None:
        return None
    simulator = make_simulator(study.simulator)
    placed = places_runs(simulator)
    seeds = placement_seeds(runs, seed) if placed else [0]
    params = {**study.fixed, **evaluation.params}
    specs: dict[str, CaseSpec] = {}
    for spec in (*study.cases, *study.validation_cases):
        specs.setdefault(spec.label, spec)
    return ScatterJobs(simulator, placed, [(c, params, seeds) for c in specs.values()])


def _stored_values(e: Evaluation) -> dict[str, float | None]:
    """The quantities of one stored simulation (`finish_run` keeps all but the transit time in
    its ``details``)."""
    return {"transit_time": e.transit_time, **e.details.quantities}


def _scatter_values(store: Store, jobs: ScatterJobs) -> dict[str, list[dict[str, float | None]]]:
    """Per case label of ``jobs``, the quantities of its finished scatter runs (`run_values`)."""
    return {
        spec.label: [_stored_values(e) for e in _rows(store, c) if e.status == "ok"]
        for c, (spec, _, _) in enumerate(jobs.cases, start=1)
    }


@dataclass(frozen=True)
class NumericalJobs:
    """The simulations behind the model's numerical error at the design
    (`parcelfit.study.numerical_error`): the refined simulator, its ``refinement``, the
    parameters (SI, fixed ones included; ``at``: the ``recommended`` ones or the plausible
    set's ``medians``), the placement seeds and whether the simulator takes them (if not, one
    pair at its own start, seed 0)."""

    refined: Simulator
    refinement: int
    params: dict[str, float]
    seeds: list[int]
    placed: bool
    at: str = "recommended"


def _numerical_record(jobs: NumericalJobs) -> dict[str, Any]:
    """The numerical error's inputs as predict.sqlite's meta value ``numerical`` holds them: a
    rerun must match them to reuse its runs."""
    return {
        "refinement": jobs.refinement,
        "params": dict(jobs.params),
        "at": jobs.at,
        "placements": list(jobs.seeds),
    }


def _numerical_jobs(
    evaluation: Evaluation | None,
    study: Study,
    ident: Identifiability,
    simulator: Simulator,
    runs: int,
    seed: int,
) -> NumericalJobs | NumericalError:
    """The numerical error's simulations on the design (module docstring): the recommended
    parameters (the calibration's ``evaluation`` of them; the plausible set's medians without
    an ok fit) at ``runs`` seeded placements, on the design's ``simulator`` refined by the study's
    ``validation.refinement``; or why there are none."""
    factor = study.refinement
    if runs == 0:
        return NumericalError({}, factor, reason="switched off: --numerical-runs 0")
    if factor <= 1:
        return NumericalError(
            {}, factor, reason="switched off in the study file: validation.refinement is 1"
        )
    refine = getattr(simulator, "with_refinement", None)
    if not callable(refine):
        return NumericalError(
            {},
            factor,
            reason=f"the {type(simulator).__name__} simulator cannot be refined (it has no "
            "with_refinement)",
        )
    try:
        refined = refine(factor)
    except ParcelfitError as exc:  # a refined setting out of its range
        return NumericalError(
            {}, factor, reason=f"the model cannot be refined {factor} times: {exc}"
        )
    found = (
        dict(evaluation.params)
        if evaluation is not None
        else {p.name: float(p.median) for p in ident.parameters}
    )
    placed = places_runs(simulator)
    seeds = placement_seeds(runs, seed) if placed else [0]
    at = "recommended" if evaluation is not None else "medians"
    return NumericalJobs(refined, factor, {**study.fixed, **found}, seeds, placed, at)


def _run_numerical(
    store: Store,
    jobs: NumericalJobs,
    design: Design,
    simulator: Simulator,
    run: Callable[..., None],
) -> NumericalError:
    """Run the numerical error's pending simulations (``run``: `_run_rows` bound to the store
    and executor) and estimate it from the pairs."""
    words = "recommended" if jobs.at == "recommended" else "plausible set's median"
    for it, sim, name, what in (
        (MODEL_ITERATION, simulator, "model", "the model"),
        (REFINED_ITERATION, jobs.refined, "refined", f"the model refined {jobs.refinement} times"),
    ):
        run(
            _rows(store, it),
            lambda e, name=name: (
                Task(e.params, design.case, f"numerical-{name}-p{e.seed}"),
                e.seed if jobs.placed else None,
            ),
            sim,
            f"the numerical error ({what}, the {words} parameters on the design)",
        )

    def values(it: int) -> list[dict[str, float | None] | None]:
        return [
            _stored_values(e) if e.status == "ok" else None
            for e in sorted(_rows(store, it), key=lambda e: e.slot)
        ]

    return estimate_numerical_error(
        values(MODEL_ITERATION), values(REFINED_ITERATION), jobs.refinement, jobs.at
    )


def _run_rows(
    store: Store,
    rows: Sequence[Any],
    item: Callable[[Any], tuple[Task, int | None]],
    simulator: Simulator,
    what: str,
    *,
    speed_deviation: float,
    pool: Callable[[], Executor],
    progress: ProgressCallback,
) -> None:
    """Run the pending ones of ``rows`` on ``simulator`` (``item`` gives each its task and
    placement seed) on the executor ``pool()`` returns, each recorded the moment it arrives;
    ``what`` names them in the progress."""
    pending = [e for e in rows if e.status == "pending"]
    total, done = len(rows), len(rows) - len(pending)
    progress(
        ProgressEvent(
            "predict",
            f"{what}: {done} of {total} simulations stored, {len(pending)} to run",
            done=done,
            total=total,
        )
    )
    if not pending:
        return
    items = [item(e) for e in pending]
    for i, result in simulate_items(pool(), simulator, items, speed_deviation):
        finish_run(store, pending[i].id, result)
        done += 1
        progress(
            ProgressEvent(
                "predict", f"{what}: {done} of {total} simulations", done=done, total=total
            )
        )


def cost_line(
    study: Study,
    designs: Sequence[Design],
    store: Store,
    executor: str,
    workers: int | None,
    custom: bool = False,
    extra: Sequence[TestCase] = (),
    refinement: int = 1,
) -> str:
    """The expected cost of the store's pending simulations (rows of kind ``screen``; with
    several designs, ``iteration`` is the design's index; with ``extra`` test cases, one
    design's runs are iteration 0 and those of extra case i iteration i + 1; with one design,
    the numerical error's runs are iterations -1 and -2, the latter on the model refined
    ``refinement`` times) on the executor's processes, as one line
    (`parcelfit.sim.cost.Estimate.text`)."""
    from parcelfit.sim.cost import estimate, refined_seconds, run_seconds

    pending = [e for e in store.evaluations("screen") if e.status == "pending"]
    runs = []
    for c, d in enumerate(designs):
        one = len(designs) == 1 and not extra
        n = sum(1 for e in pending if (one and e.iteration >= 0) or e.iteration == c)
        runs.append((n, run_seconds(study.simulator, d.rig, d.consignment)))
    for c, case in enumerate(extra, start=1):
        n = sum(1 for e in pending if e.iteration == c)
        runs.append((n, run_seconds(study.simulator, case.rig, case.consignment)))
    if len(designs) == 1 and refinement > 1:  # the numerical error's pairs
        d = designs[0]
        n = sum(1 for e in pending if e.iteration == MODEL_ITERATION)
        runs.append((n, run_seconds(study.simulator, d.rig, d.consignment)))
        n = sum(1 for e in pending if e.iteration == REFINED_ITERATION)
        runs.append((n, refined_seconds(study.simulator, refinement, d.rig, d.consignment)))
    total = sum(n for n, _ in runs)
    local = executor == "local" and not custom
    processes = min(workers or os.cpu_count() or 1, max(total, 1)) if local else 1
    note = "" if total else "nothing left to simulate"
    return estimate(runs, processes).text(note)


def open_executor(
    kind: str,
    workers: int | None,
    scheduler: str | None,
    items: int,
    make: Callable[[], Executor] | None = None,
) -> Executor:
    """The executor for ``items`` simulations: ``make()`` when given (tests), else the one
    named ``kind`` (a local pool of ``workers`` processes, one per core by default, never more
    than ``items``)."""
    if make is not None:
        return make()
    n = min(workers or os.cpu_count() or 1, max(items, 1)) if kind == "local" else workers
    return make_executor(kind, workers=n, scheduler=scheduler)


def finish_run(store: Store, row: int, result: SimResult) -> None:
    """Record one simulation's result in its pending row: status, transit time [s], wall time
    [s] and the other quantities (`run_values`) in ``details``."""
    values = run_values(result.run if result.ok else None)
    details = EvaluationDetails.from_json({k: v for k, v in values.items() if k != "transit_time"})
    message = result.diagnostics.get("message")
    if not result.ok and message:
        details = details.with_message(str(message))
    store.finish(
        row,
        status=result.status.value,
        transit_time=values["transit_time"],
        wall_time=result.wall_time,
        details=details,
    )


def _runs_table(
    store: Store, sets: Sequence[Mapping[str, float]], k: int, names: Sequence[str]
) -> pd.DataFrame:
    """One row per simulation (docs/data.md, Predictions), in set and placement order."""
    rows = []
    for e in sorted(_rows(store, 0), key=lambda e: e.slot):
        s, j = divmod(e.slot, k)
        row: dict[str, Any] = {"set": s, "placement": j, "seed": e.seed}
        row.update({name: float(sets[s][name]) for name in names})
        row.update(
            {
                "status": e.status,
                "transit_time": e.transit_time,
                **e.details.quantities,
                "wall_time": e.wall_time,
            }
        )
        rows.append(row)
    df = pd.DataFrame(rows)
    for col in ("transit_time", "rotation", "exit_x", "exit_y", "exit_heading", "wall_time"):
        df[col] = pd.to_numeric(df[col], errors="coerce").astype(float)
    return df


def write_prediction(prediction: Prediction, out: Path, table_format: str = "csv") -> list[Path]:
    """Write the tables (``runs``, ``summary``, ``effects`` as .csv or .parquet) and
    ``prediction.json`` into ``out``; returns their paths."""
    paths = []
    for name, df in (
        ("runs", prediction.runs),
        ("summary", prediction.summary_table()),
        ("effects", prediction.effects_table()),
    ):
        path = out / f"{name}.{table_format}"
        if table_format == "parquet":
            df.to_parquet(path, index=False)
        else:
            df.to_csv(path, index=False)
        paths.append(path)
    path = out / PREDICTION_FILE
    write_text_atomic(path, json.dumps(prediction.to_json()))
    paths.append(path)
    return paths


__all__ = [
    "PREDICTION_FILE",
    "PREDICT_STORE",
    "QUANTITIES",
    "Prediction",
    "QuantitySummary",
    "cost_line",
    "default_out",
    "finish_run",
    "open_executor",
    "predict",
    "quantity_unit",
    "quantity_words",
    "run_values",
    "sentence",
    "shown_value",
    "summarise_prediction",
    "write_prediction",
]
