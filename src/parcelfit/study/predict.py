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
crossed both light barriers).

**Parameters versus placements** (a two-way decomposition, the law of total variance). With
q_ij the run of set i at placement j, n_i the runs of set i that have q, N = sum_i n_i, the
set means m_i = (1/n_i) sum_j q_ij and the grand mean m = (1/N) sum_ij q_ij:

    V = (1/N) sum_ij (q_ij - m)^2                      total variance
    B = (1/N) sum_i n_i (m_i - m)^2                    variance of the per-set means
    W = (1/N) sum_i sum_j (q_ij - m_i)^2               mean within-set variance
    V = B + W,   parameter share = B / V,   placement share = W / V.

With every run ok (n_i = K) B is the variance of the per-set means and W the mean of the
within-set variances (both with divisor n, resp. K). Because every set sees the same K
placements, a quantity that is a sum of a parameter part and a placement part,
q_ij = a_i + b_j, splits exactly: B = var(a), W = var(b). An interaction of parameters and
placements counts as placement spread (W); B also holds 1/K of the placements' scatter of each
set mean when the parts do not add, so with few placements the parameter share is an upper
estimate.

**How far each parameter moves a prediction** (from the draws, no further simulation): the
per-set means m_i of q are regressed (ordinary least squares, with an intercept) on all
calibrated parameters at once, each scaled to its plausible interval, z = (p - a) / (b - a)
for the interval [a, b]. The coefficient of a parameter is then the change of the predicted
mean over its plausible interval with the other parameters varying over the plausible set as
they do in use (so a parameter correlated with another in S is credited only with its own
part), and its standard error is the regression's. A one-at-a-time sweep was not chosen: it
costs 2 x K more simulations per parameter and moves the parameter from one calibrated set that
may lie outside S at the interval's ends. An effect counts as resolved when it is at least
twice its standard error (with N sets and d parameters the regression needs N > d + 1; for
parameters spread evenly over their intervals and uncorrelated, the standard error is about
s sqrt(12 / N), s the scatter of the set means about the fit: 0.77 s with the default 20
sets). For each calibrated parameter the data do not determine, the quantity it moves most
(as a share of that quantity's 5-95 % band) is named in one sentence, e.g. "E_Pa is
undetermined and moves the transit time by 40 ms here: run `parcelfit design` to find the
experiment that fixes it".

**Resumable.** The simulations are recorded in their own store, ``predict.sqlite`` in the
output folder (`parcelfit.study.store`, rows of kind ``screen``: slot = set x K + placement
index, ``seed`` the placement seed, ``transit_time`` [s], ``details`` the rotation, exit
position and heading), all written as pending before any runs and each finished in one
transaction the moment it arrives; rerunning the same command runs only what is still pending.
The inputs (study, design, N, K, seed, the drawn sets and the placement seeds) are stored in
the meta record ``predict``: a folder holding a prediction with other inputs is refused.

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
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from parcelfit.atomic import write_text_atomic
from parcelfit.errors import ParcelfitError, shown
from parcelfit.progress import ProgressCallback, ProgressEvent, ignore_progress
from parcelfit.runs import Run, TestCase
from parcelfit.sim.ensemble import MAX_PLACEMENTS, rotation
from parcelfit.sim.executors import Executor, Task, make_executor
from parcelfit.sim.factory import SimulatorConfig, make_simulator
from parcelfit.sim.protocol import SimResult, Simulator
from parcelfit.study.folderlock import check_writable, lock_folder
from parcelfit.study.identify import Identifiability
from parcelfit.study.joint import require_placements, simulate_items
from parcelfit.study.results import read_results
from parcelfit.study.store import STORE_FILE, Store
from parcelfit.study.studyfile import Study, load_study

PREDICT_STORE = "predict.sqlite"
PREDICTION_FILE = "prediction.json"
TABLE_FORMATS = ("csv", "parquet")
MAX_SETS = 1000  # parameter sets of one prediction (each simulated at every placement)
RESOLVED = 2.0  # an effect is resolved when it is at least this many standard errors
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


# -- the inputs ----------------------------------------------------------------------------------


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
    for candidate in (folder, folder / "calibration"):
        if (candidate / STORE_FILE).is_file():
            return candidate
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
            where="--rig",
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
            where="--consignment",
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


# -- the statistics ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Decomposition:
    """The two-way split of the module docstring: total variance V, between-set B and
    within-set W (units of the quantity squared), runs N and sets counted."""

    total: float
    between: float
    within: float
    runs: int
    sets: int

    @property
    def parameter_share(self) -> float:
        """B / V (NaN when V is 0 or nothing was measured)."""
        return self.between / self.total if self.total > 0 else math.nan

    @property
    def placement_share(self) -> float:
        """W / V (NaN when V is 0 or nothing was measured)."""
        return self.within / self.total if self.total > 0 else math.nan


def decompose(values: np.ndarray) -> Decomposition:
    """The decomposition of ``values`` (n sets x K placements; NaN where a run has no value)
    into the variance of the per-set means and the mean within-set variance (module
    docstring)."""
    q = np.asarray(values, float)
    ok = np.isfinite(q)
    n_i = ok.sum(axis=1)
    N = int(n_i.sum())
    if N == 0:
        return Decomposition(math.nan, math.nan, math.nan, 0, 0)
    grand = float(q[ok].mean())
    have = n_i > 0
    means = np.where(have, np.nansum(np.where(ok, q, 0.0), axis=1) / np.maximum(n_i, 1), np.nan)
    between = float(np.sum(n_i[have] * (means[have] - grand) ** 2) / N)
    dev = np.where(ok, q - means[:, None], 0.0)
    within = float(np.sum(dev[have] ** 2) / N)
    total = float(np.sum((q[ok] - grand) ** 2) / N)
    return Decomposition(total, between, within, N, int(have.sum()))


@dataclass(frozen=True)
class Effect:
    """How far one parameter moves one quantity's predicted mean over the parameter's
    plausible interval [low, high] (SI), with its standard error (module docstring); NaN when
    the regression has too few sets."""

    parameter: str
    verdict: str
    quantity: str
    low: float
    high: float
    effect: float
    se: float

    @property
    def resolved(self) -> bool:
        """True when the effect is at least `RESOLVED` standard errors."""
        return math.isfinite(self.effect) and abs(self.effect) >= RESOLVED * self.se


def effects_of(
    means: np.ndarray, X: np.ndarray, intervals: Sequence[tuple[float, float]]
) -> tuple[np.ndarray, np.ndarray]:
    """OLS of the per-set means (n,) on the parameters X (n, d; SI) scaled to their
    ``intervals``: each parameter's effect over its interval and its standard error (NaN
    where the regression cannot be made: fewer than d + 2 sets with a mean)."""
    means = np.asarray(means, float)
    X = np.asarray(X, float)
    d = X.shape[1]
    nan = np.full(d, math.nan)
    ok = np.isfinite(means)
    if ok.sum() < d + 2:
        return nan, nan.copy()
    lo = np.array([a for a, _ in intervals], float)
    width = np.array([b - a for a, b in intervals], float)
    Z = (X[ok] - lo) / np.where(width > 0, width, 1.0)
    A = np.column_stack([np.ones(int(ok.sum())), Z])
    y = means[ok]
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    dof = len(y) - A.shape[1]
    resid = y - A @ coef
    s2 = float(resid @ resid) / dof
    cov = s2 * np.linalg.pinv(A.T @ A)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    effect, se = coef[1:], se[1:]
    flat = width <= 0  # a parameter the sample holds at one value moves nothing
    return np.where(flat, 0.0, effect), np.where(flat, 0.0, se)


@dataclass(frozen=True)
class QuantitySummary:
    """The predictive distribution of one quantity (SI): runs with a value, median, the 5-95 %
    band and the decomposition of its spread."""

    quantity: str
    runs: int
    median: float
    q05: float
    q95: float
    decomposition: Decomposition


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
            "effects": records(self.effects_table()),
            "sentences": self.sentences,
            "notes": self.notes,
            "runs": records(self.runs),
        }


def run_values(run: Run | None) -> dict[str, float | None]:
    """The quantities of one run (SI; None where it has none): transit time, rotation, exit
    x, y and heading (module docstring)."""
    if run is None:
        return {k: None for k in ("transit_time", "rotation", "exit_x", "exit_y", "exit_heading")}
    tr = run.trajectory
    theta = np.unwrap(np.asarray(tr.theta, float))
    return {
        "transit_time": None if run.transit_time is None else float(run.transit_time),
        "rotation": rotation(tr),
        "exit_x": float(np.asarray(tr.x, float)[-1]),
        "exit_y": float(np.asarray(tr.y, float)[-1]),
        "exit_heading": float(theta[-1]),
    }


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
) -> tuple[list[QuantitySummary], list[Effect], list[str]]:
    """The summaries, effects and sentences of a runs table (module docstring)."""
    n, k = len(sets), len(seeds)
    summaries, effects = [], []
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
        summaries.append(QuantitySummary(q, int(vals.size), med, q05, q95, decompose(grid)))
        with np.errstate(invalid="ignore"):
            means = np.nanmean(np.where(np.isfinite(grid), grid, np.nan), axis=1)
        eff, se = effects_of(means, X, intervals)
        for j, p in enumerate(ident.parameters):
            effects.append(
                Effect(
                    p.name, p.verdict, q, p.interval[0], p.interval[1], float(eff[j]), float(se[j])
                )
            )
    band = {s.quantity: s.q95 - s.q05 for s in summaries}
    sentences = []
    for p in ident.parameters:
        if p.determined:
            continue
        mine = [e for e in effects if e.parameter == p.name and e.resolved]
        if not mine:
            sentences.append(
                f"{p.name} {_VERDICT_WORDS.get(p.verdict, p.verdict)} but moves none of these "
                f"predictions here by more than {RESOLVED:g} standard errors of the "
                "placements' noise: for this design it does not matter"
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
) -> dict[str, Any]:
    return {
        "study": str(study_dir.resolve()),
        "rig": design.rig,
        "consignment": design.consignment,
        "setting": design.setting,
        "seed": seed,
        "sets": [dict(s) for s in sets],
        "placements": list(seeds),
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
    placements: int = 10,
    seed: int = 0,
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
    ``sets`` parameter sets of its plausible set times ``placements`` seeded placements,
    simulated in ``executor`` (serial, local with ``workers`` processes, dask at
    ``scheduler``), recorded in ``out``/predict.sqlite (resumable), summarised and written
    (module docstring). ``progress`` receives one event per finished simulation; ``on_cost``
    the expected cost of the simulations still to run (one line, `parcelfit.sim.cost`), before
    they start; ``make`` (tests) replaces the executor factory. Seeded: the same inputs give
    the same tables."""
    progress = progress or ignore_progress
    if not 1 <= sets <= MAX_SETS:
        raise ParcelfitError(f"--sets {sets}: give from 1 to {MAX_SETS} parameter sets")
    if not 1 <= placements <= MAX_PLACEMENTS:
        raise ParcelfitError(f"--placements {placements}: give from 1 to {MAX_PLACEMENTS}")
    if table_format not in TABLE_FORMATS:
        raise ParcelfitError(
            f"unknown table format {shown(table_format)}", fix=f"use one of {list(TABLE_FORMATS)}"
        )
    inputs = load_inputs(folder)
    design = check_design(rig, consignment, setting)
    simulator = design_simulator(inputs.study, design)
    require_placements(simulator, placements, file=None, where="--placements")
    drawn = draw_sets(inputs.identifiability, sets, seed)
    seeds = placement_seeds(placements, seed) if placements > 1 or _placed(simulator) else [0]
    full = [{**inputs.study.fixed, **s} for s in drawn]
    out_dir = Path(out) if out is not None else default_out(inputs.folder, design)
    check_writable(out_dir, (PREDICT_STORE,))
    out_dir.mkdir(parents=True, exist_ok=True)
    lock = lock_folder(out_dir, "a prediction")
    try:
        store = Store(out_dir / PREDICT_STORE)
        try:
            record = _inputs_record(inputs.folder, design, drawn, seeds, seed)
            known = store.get_meta("predict")
            if known is None:
                store.set_meta("predict", record)
            elif json.loads(json.dumps(known)) != json.loads(json.dumps(record)):
                raise ParcelfitError(
                    "this folder holds a prediction with other inputs (study, design, --sets, "
                    "--placements or --seed)",
                    file=out_dir,
                    fix="give another --out, or the same inputs to resume it",
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
            if on_cost is not None:
                on_cost(
                    cost_line(inputs.study, [design], store, executor, workers, make is not None)
                )
            _simulate(
                store,
                simulator,
                design,
                seeds,
                placed=_placed(simulator) or placements > 1,
                executor=executor,
                workers=workers,
                scheduler=scheduler,
                make=make,
                progress=progress,
            )
            runs = _runs_table(store, drawn, len(seeds), inputs.identifiability.names)
        finally:
            store.close()
        summaries, effects, sentences = summarise_prediction(
            inputs.identifiability, drawn, seeds, runs
        )
        notes = []
        if not inputs.identifiability.reached:
            notes.append(
                "no parameter set of the calibration reached the real runs' scatter: the sets "
                "are drawn from the whole parameter box, not from a plausible set"
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
        )
        write_prediction(prediction, out_dir, table_format)
    finally:
        lock.release()
    return prediction


def _placed(simulator: Simulator) -> bool:
    return callable(getattr(simulator, "with_placement", None))


def _simulate(
    store: Store,
    simulator: Simulator,
    design: Design,
    seeds: Sequence[int],
    *,
    placed: bool,
    executor: str,
    workers: int | None,
    scheduler: str | None,
    make: Callable[[], Executor] | None,
    progress: ProgressCallback,
) -> None:
    """Run the store's pending simulations, each recorded the moment it arrives."""
    rows = store.evaluations("screen")
    pending = [e for e in rows if e.status == "pending"]
    total, done = len(rows), len(rows) - len(pending)
    progress(
        ProgressEvent(
            "predict",
            f"{design.label}: {done} of {total} simulations stored, {len(pending)} to run",
            done=done,
            total=total,
        )
    )
    if not pending:
        return
    k = len(seeds)
    items = [
        (
            Task(e.params, design.case, f"predict-set{e.slot // k}-p{e.seed}"),
            e.seed if placed else None,
        )
        for e in pending
    ]
    with open_executor(executor, workers, scheduler, len(items), make) as pool:
        for i, result in simulate_items(pool, simulator, items):
            finish_run(store, pending[i].id, result)
            done += 1
            progress(
                ProgressEvent(
                    "predict",
                    f"{design.label}: {done} of {total} simulations",
                    done=done,
                    total=total,
                )
            )


def cost_line(
    study: Study,
    designs: Sequence[Design],
    store: Store,
    executor: str,
    workers: int | None,
    custom: bool = False,
) -> str:
    """The expected cost of the store's pending simulations (rows of kind ``screen``; with
    several designs, ``iteration`` is the design's index) on the executor's processes, as one
    line (`parcelfit.sim.cost.Estimate.text`)."""
    from parcelfit.sim.cost import estimate, run_seconds

    pending = [e for e in store.evaluations("screen") if e.status == "pending"]
    runs = []
    for c, d in enumerate(designs):
        n = sum(1 for e in pending if len(designs) == 1 or e.iteration == c)
        runs.append((n, run_seconds(study.simulator, d.rig, d.consignment)))
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
    details: dict[str, Any] = {k: v for k, v in values.items() if k != "transit_time"}
    message = result.diagnostics.get("message")
    if not result.ok and message:
        details["message"] = str(message)
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
    for e in sorted(store.evaluations("screen"), key=lambda e: e.slot):
        s, j = divmod(e.slot, k)
        d = e.details or {}
        row: dict[str, Any] = {"set": s, "placement": j, "seed": e.seed}
        row.update({name: float(sets[s][name]) for name in names})
        row.update(
            {
                "status": e.status,
                "transit_time": e.transit_time,
                "rotation": d.get("rotation"),
                "exit_x": d.get("exit_x"),
                "exit_y": d.get("exit_y"),
                "exit_heading": d.get("exit_heading"),
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
    "Decomposition",
    "Design",
    "Effect",
    "Prediction",
    "QuantitySummary",
    "StudyInputs",
    "check_design",
    "cost_line",
    "decompose",
    "default_out",
    "design_simulator",
    "draw_sets",
    "effects_of",
    "find_study",
    "finish_run",
    "load_inputs",
    "open_executor",
    "placement_seeds",
    "predict",
    "quantity_unit",
    "quantity_words",
    "run_values",
    "sentence",
    "shown_value",
    "summarise_prediction",
    "write_prediction",
]
