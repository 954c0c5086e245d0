"""Which experiment to run next: ``parcelfit design`` ranks candidate test cases by how much
each would narrow the intervals of the parameters a calibration leaves open.

**Candidates.** Every rig x its speed settings x every consignment type: the rigs are the
bundled ones, the study's own rig file (a MuJoCo or rigid-box study's) and the rig files given
with ``--rig``, the types the bundled ones and the study's own consignment file. Or only the
candidates named with ``--candidate RIG/TYPE/SETTING`` (bundled names or those files' names).
Rig files for ``--rig`` are for instance the bench tests in ``examples/bench/``: a belt step
(a parcel carried from a slow belt onto a fast one: how fast it takes up the speed is set by
the packaging-belt friction) and a plate impact (a belt carries the parcel into a metal plate
across it: how it slides off is set by the packaging-steel friction and the contact).

**What a candidate would tell.** Each candidate is simulated at the same N parameter sets
drawn from the study's plausible set (`parcelfit.study.plausible.draw_sets`) times the same K
seeded placements, and summarised by the quantities of `parcelfit.study.predict` (transit
time, rotation, exit position and heading). For quantity q:

* its sensitivity J_qp to parameter p is the change of q's per-set mean over p's plausible
  interval, from the least-squares fit of the per-set means on all parameters scaled to their
  intervals (`parcelfit.study.spread.effects_of`); an effect counts only when its t value
  reaches Student's two-sided quantile for a 5 % chance that any of the case's quantities x
  parameters shows an effect it does not have (Bonferroni; `resolved_t`: 3.5 standard errors
  with 20 sets and 4 parameters, 5.3 with 10), else it counts as zero. Where a quantity bends
  over the interval, the linear fit lends one parameter's effect to another at random; twice
  the standard error let such false effects through;
* its run-to-run scatter is s_q^2 = W_q + max(f_q, e_q)^2: W_q one run's variance about its
  set's mean over the placements, unbiased (`parcelfit.study.spread.Decomposition.run_variance`;
  0 with one placement); f_q a measurement floor (`FLOOR`: the band test's tolerances, 3 mm
  and 1 degree, for the exit position and the angles, 2 ms for the transit time, assumed), so
  that a quantity the placements do not scatter is not taken as exact; and e_q the real runs'
  own scatter beyond the model's, from the study's fitted cases as `parcelfit predict`
  estimates it (`parcelfit.study.run_scatter`: each real parcel is its own specimen, and
  tracking measures with noise; the transit time's as a share of the candidate's mean;
  `real_run_scatter`, 0 where the calibration simulated one placement per case). Each
  placement runs the rig's drives off their mean speeds as `parcelfit predict` does
  (``speed_deviation``, default 3 %).

The rotation |theta(end) - theta(start)| and the exit heading theta(end) are one angle
measured twice when the start heading scatters little (a placement's sd is 1 degree), and
the formula below takes its quantities as independent: so the rotation (`REPEATED`) gives no
information of its own, and each run's angle counts once, through the exit heading.

The signal-to-noise of p on the candidate is max_q |J_qp| / s_q: how many run-to-run standard
deviations the outcome moves as p crosses its plausible interval.

**The simulations' own scatter.** A calibration compares the real runs' mean with the mean of
the few placements it simulates per case, the same seeds in every evaluation (the ensemble
cost's K per case, `parcelfit.study.joint.placement_seeds`). That simulated mean misses the
model's own mean by a fixed amount, which the fit can only take up in the parameters, as it
would the real runs' scatter: its variance is m_q = W_q / K (`model_variance`; W_q one run's
variance over the placements). With antithetic placements (``cost.mirrored``) a run's
first-order offset cancels in its pair's mean: m_q = 4 P V_q / K^2, V_q the variance of a
pair's mean, P the pairs (the nominal run of an odd K counted exact); design then simulates its
own placements in mirrored pairs and estimates V_q from them (with fewer than two complete pairs
per set, V_q = W_q / 2, its value for independent draws; with two pairs, as from
``--placements`` 4 or 5, from one degree of freedom of placement: take more for a steady
ranking), and W_q as V_q plus a pair's mean squared half-difference (the pooled estimate would
run high by K / (K - 1)). The published cost's one nominal run is counted exact (its offset
from the mean is of second order in the placement and is not estimated). m_q enters only where
design's own runs scatter as the fit's do: not where they run the drives off their mean speeds
(``speed_deviation``, MuJoCo and rigid-box rigs by default), which the calibration's runs do
not; there m_q = 0 and the widths are optimistic (``fit_scatter`` in design.json). Assumed:
M diagonal, and each case's offset independent of the others', though one set of seeds moves a
case's quantities together and the cases share seed numbers; both make the widths optimistic
once M dominates. So a candidate whose quantities the placements scatter, measured by an effect
the size of that scatter, tells less than its real runs alone would say, however many runs are
taken.

**What the fitted cases tell.** The study's fitted test cases are simulated at the same sets
and placements and give their own J_f, s_f and M_f: they hold the information
F = sum_f J_f^T (S_f / n_f + M_f)^-1 J_f (n_f: the real runs each was fitted on: its
dataset's runs with the ensemble cost, the reference run with the published cost; M_f from its
own placements). A candidate on which an open parameter and a parameter the fitted cases fix
act alike thus tells the open one.

**Expected interval after n real runs** (a linear-Gaussian experimental design). In interval
units (each parameter's plausible interval mapped to [0, 1]), n real runs of the candidate,
fitted with the study's K placements, measure each quantity's mean against the simulations'
with variance s_q^2 / n + m_q; with the uniform prior over the interval (variance 1/12,
precision 12) and the fitted cases' F, the posterior covariance is

    C(n) = ( J^T (S / n + M)^-1 J + F + 12 I )^-1,   S = diag(s_q^2),  M = diag(m_q),

and the expected interval of p after the runs, as a share of its current interval, is
w_p(n) = sqrt(C_pp(n) / C_pp(0)) (1: no narrowing). Today's interval is wider than F alone
says (the plausible set allows for the misfit of real runs), so the share is what the
candidate adds to what the fitted cases tell, applied to today's interval. A candidate that
moves two parameters alike cannot tell them apart unless F fixes one, and C says so. The runs
a candidate needs for p are the smallest n (up to `MAX_RUNS`) at which w_p(n) times the
current interval is at most 20 % of p's range, the width `parcelfit.study.identify` calls
determined (none: not within `MAX_RUNS`, or never where M caps what runs can tell).

**Ranking.** Per parameter, the candidates by the expected width after ``--runs`` real runs
(ties by the signal-to-noise). Overall, greedily: first the candidate with the smallest mean
share over the open parameters, then each time the one whose runs, added to those of the
candidates above it, leave the smallest mean share (``with_above``), so that the second
experiment is the best one given the first, not the first rig at another setting.

**Resumable** like a prediction: every simulation is recorded in ``design.sqlite`` in the output
folder (rows of kind ``screen``; slot = candidate x N x K + set x K + placement), the inputs in
its meta record ``design``; rerunning the same command runs only what is pending.

Outputs (docs/data.md, Experiment design): ``candidates.csv`` (one row per candidate and open
parameter) and ``ranking.csv`` (one row per candidate) (or ``.parquet``), and
``design.json``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from parcelfit.atomic import write_text_atomic
from parcelfit.errors import ParcelfitError, shown
from parcelfit.progress import ProgressCallback, ProgressEvent, ignore_progress
from parcelfit.sim.ensemble import MAX_PLACEMENTS
from parcelfit.sim.executors import Executor, Task
from parcelfit.sim.factory import make_simulator
from parcelfit.study.defaults import DESIGN_PLACEMENTS
from parcelfit.study.folderlock import check_writable, lock_folder
from parcelfit.study.identify import DETERMINED_WIDTH, Identifiability
from parcelfit.study.information import (
    MAX_RUNS,
    PRIOR_PRECISION,
    expected_width,
    greedy_sequence,
    information,
    resolved_t,
    runs_needed,
    shares_of,
)
from parcelfit.study.joint import (
    SPEED_DEVIATION,
    check_speed_deviation,
    placements_for,
    places_runs,
    require_placements,
    simulate_items,
    varies_drives,
)
from parcelfit.study.joint import placement_seeds as fit_placement_seeds
from parcelfit.study.plausible import (
    Design,
    check_design,
    design_simulator,
    draw_sets,
    load_inputs,
    placement_seeds,
)
from parcelfit.study.predict import (
    MAX_SETS,
    QUANTITIES,
    TABLE_FORMATS,
    cost_line,
    finish_run,
    open_executor,
)
from parcelfit.study.run_scatter import RELATIVE, estimate_run_scatter
from parcelfit.study.spread import FLOOR, decompose, effects_of
from parcelfit.study.store import Store
from parcelfit.study.studyfile import Study

DESIGN_STORE = "design.sqlite"
DESIGN_FILE = "design.json"
PLACEMENTS = DESIGN_PLACEMENTS  # seeded placements per set and candidate by default
NARROWS = 0.99  # an expected interval share below this counts as narrowing the parameter
# quantities that measure what another does again (module docstring): no information of their own
REPEATED = frozenset({"rotation"})


def candidate_designs(
    only: Sequence[str] = (),
    rig_files: Sequence[str] = (),
    own_rig: str | None = None,
    own_type: str | None = None,
) -> list[Design]:
    """The candidates (module docstring): every rig x setting x type, the rigs being the
    bundled ones, ``own_rig`` (the study's own rig file) and ``rig_files``, the types the
    bundled ones and ``own_type`` (the study's own consignment file); or, with ``only``
    (``RIG/TYPE/SETTING`` labels, each rig and type a bundled name or the name of one of those
    files), just those. Each is checked (`parcelfit.study.plausible.check_design`)."""
    from parcelfit.sim.mujoco import (
        bundled_consignment_names,
        bundled_rig_names,
        load_consignment,
        load_rig,
    )

    types = list(bundled_consignment_names())
    rigs = list(bundled_rig_names())
    files: dict[str, str] = {}  # the files' names -> paths
    if own_type is not None and own_type.lower().endswith((".yaml", ".yml")):
        files[load_consignment(own_type).name] = own_type
        types.append(own_type)
    if own_rig is not None and own_rig.lower().endswith((".yaml", ".yml")):
        files[load_rig(own_rig).name] = own_rig
        rigs.append(own_rig)
    for path in rig_files:
        if not str(path).lower().endswith((".yaml", ".yml")):
            raise ParcelfitError(
                f"--rig {shown(str(path))} is not a rig .yaml file",
                fix="give a rig file (bundled rigs are candidates already)",
            )
        try:
            name = load_rig(str(Path(path).resolve())).name
        except ParcelfitError as exc:
            raise ParcelfitError(
                exc.message,
                file=exc.file or str(path),
                where=exc.where or "--rig",  # a mistake inside the file: the key there
                fix=exc.fix,
            ) from None
        if name in files or name in bundled_rig_names():
            raise ParcelfitError(
                f"--rig {shown(str(path))}: a rig named {name} is a candidate already",
                fix="give each rig once; rename a rig file that shares another rig's name",
            )
        files[name] = str(Path(path).resolve())
        rigs.append(files[name])
    out: list[Design] = []
    if only:
        for label in only:
            parts = label.split("/")
            if len(parts) != 3 or not parts[2].isdigit():
                raise ParcelfitError(
                    f"--candidate {shown(label)} is not RIG/TYPE/SETTING",
                    fix="write e.g. E1/KPBW/2 (names: bundled ones, the study's own files' or "
                    "those of the --rig files)",
                )
            rig, kind = (files.get(x, x) for x in parts[:2])
            out.append(check_design(rig, kind, int(parts[2])))
    else:
        for rig in rigs:
            for setting in sorted(load_rig(rig).speeds):
                out += [check_design(rig, t, setting) for t in types]
    labels = [d.label for d in out]
    if len(set(labels)) != len(labels):
        raise ParcelfitError("a candidate is named twice", fix="give each candidate once")
    return out


@dataclass(frozen=True)
class CandidateScore:
    """What one candidate would tell about one open parameter (module docstring): the
    signal-to-noise and the quantity it comes from, the expected width after the asked runs
    (share of the current interval and SI) and the runs needed to determine it."""

    candidate: Design
    parameter: str
    verdict: str
    interval: tuple[float, float]
    snr: float
    quantity: str | None
    share: float
    width: float
    runs_needed: int | None
    simulations_ok: int


@dataclass(frozen=True, eq=False)
class DesignResult:
    """A finished ranking: the open parameters, the candidates' scores, the runs assumed,
    where it was written, the greedy order (candidate label, mean share with the ones before;
    empty: by the mean share alone), the fitted cases taken into account (labels), the real
    runs' own scatter used and whether the simulated means' variance m_q entered (module
    docstring; not where design's runs vary the drives, which the calibration's do not)."""

    parameters: list[str]
    scores: list[CandidateScore]
    runs: int
    sets: int
    placements: int
    out: Path | None = None
    sequence: list[tuple[str, float]] = field(default_factory=list)
    fitted: list[str] = field(default_factory=list)
    real_scatter: dict[str, float] = field(default_factory=dict)
    fit_scatter: bool = False
    notes: list[str] = field(default_factory=list)

    def candidates_table(self) -> pd.DataFrame:
        """One row per candidate and open parameter, ranked per parameter (docs/data.md)."""
        rows = []
        for p in self.parameters:
            mine = sorted(
                (s for s in self.scores if s.parameter == p), key=lambda s: (s.share, -s.snr)
            )
            for rank, s in enumerate(mine, 1):
                d = s.candidate
                rows.append(
                    {
                        "parameter": p,
                        "rank": rank,
                        "candidate": d.label,
                        "rig": d.rig_name,
                        "consignment": d.consignment_name,
                        "setting": d.setting,
                        "verdict": s.verdict,
                        "interval_low": s.interval[0],
                        "interval_high": s.interval[1],
                        "snr": s.snr,
                        "quantity": s.quantity,
                        "expected_share": s.share,
                        "expected_width": s.width,
                        "runs_needed": s.runs_needed,
                        "simulations_ok": s.simulations_ok,
                    }
                )
        df = pd.DataFrame(rows)
        if len(df):
            df["runs_needed"] = df["runs_needed"].astype("Int64")
        return df

    def ranking_table(self) -> pd.DataFrame:
        """One row per candidate in the greedy order of the module docstring (without one: by
        the mean expected width share over the open parameters) (docs/data.md)."""
        by: dict[str, list[CandidateScore]] = {}
        for s in self.scores:
            by.setdefault(s.candidate.label, []).append(s)
        rows = []
        for label, mine in by.items():
            best = min(mine, key=lambda s: s.share)
            rows.append(
                {
                    "candidate": label,
                    "mean_share": float(np.mean([s.share for s in mine])),
                    "narrows_most": best.parameter if best.share < NARROWS else None,
                    "determines": ", ".join(
                        s.parameter
                        for s in mine
                        if s.runs_needed is not None and s.runs_needed <= self.runs
                    ),
                }
            )
        cols = ["candidate", "mean_share", "narrows_most", "determines"]
        df = pd.DataFrame(rows, columns=cols)
        if self.sequence:
            order = {label: i for i, (label, _) in enumerate(self.sequence)}
            df["with_above"] = df["candidate"].map(dict(self.sequence)).astype(float)
            df = df.sort_values("candidate", key=lambda c: c.map(order), kind="stable")
        else:
            df["with_above"] = df["mean_share"]
            df = df.sort_values(["mean_share", "candidate"], kind="stable")
        df = df.reset_index(drop=True)
        df.insert(0, "rank", range(1, len(df) + 1))
        return df

    def best(self, parameter: str) -> CandidateScore | None:
        """The first-ranked candidate for ``parameter`` (None without candidates)."""
        mine = [s for s in self.scores if s.parameter == parameter]
        return min(mine, key=lambda s: (s.share, -s.snr)) if mine else None


def sensitivity(
    ident: Identifiability,
    sets: Sequence[dict[str, float]],
    grids: dict[str, np.ndarray],
    real_scatter: Mapping[str, float] | None = None,
    mirrored: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """One case's sensitivities J (quantities x parameters: the change of each quantity's
    per-set mean over each parameter's current interval, zero where unresolved) and
    run-to-run scatter s_q (module docstring), from its simulated quantities ``grids``
    (quantity -> n sets x K placements, NaN where a run has none; with ``mirrored`` the
    placements in pairs s, -s, `run_variance`) at ``sets``."""
    names = ident.names
    intervals = [p.interval for p in ident.parameters]
    X = np.array([[s[n] for n in names] for s in sets], float)
    J = np.zeros((len(QUANTITIES), len(names)))
    scatter = np.ones(len(QUANTITIES))
    for k, q in enumerate(QUANTITIES):
        grid = grids[q]
        floor = FLOOR[q]
        within = run_variance(grid, mirrored)
        within = within if math.isfinite(within) else 0.0
        extra = (real_scatter or {}).get(q, 0.0)
        if q in RELATIVE and extra:
            extra *= float(np.nanmean(grid)) if np.isfinite(grid).any() else 0.0
        scatter[k] = math.sqrt(within + max(floor, extra) ** 2)
        if q in REPEATED:
            continue  # measured again by another quantity: its row of J stays 0
        with np.errstate(invalid="ignore"):
            means = (
                np.nanmean(grid, axis=1) if np.isfinite(grid).any() else np.full(len(grid), np.nan)
            )
        eff, se = effects_of(means, X, intervals)
        resolved = resolved_t(int(np.isfinite(means).sum()), len(names))  # the fitted sets
        ok = np.isfinite(eff) & (np.abs(eff) >= resolved * np.where(np.isfinite(se), se, np.inf))
        J[k] = np.where(ok, eff, 0.0)
    return J, scatter


def run_variance(grid: np.ndarray, mirrored: bool = False) -> float:
    """One run's variance about its set's mean over the placements of ``grid`` (n sets x
    placements, NaN where a run has none; units of the quantity squared), unbiased
    (`parcelfit.study.spread.Decomposition.run_variance`); NaN when no set has two runs. With
    ``mirrored`` (columns in pairs s, -s, design's placements of a mirrored study) the pairs'
    means are not independent draws and that estimate would run high by K / (K - 1): then the
    variance of a pair's mean plus the mean squared half-difference of a pair, where the sets
    hold two complete pairs or more."""
    q = np.asarray(grid, float)
    pairs = _mirrored_pairs(q) if mirrored else None
    if pairs is not None:
        a, b = pairs
        between = decompose(0.5 * (a + b)).run_variance
        half = 0.5 * (a - b)
        if math.isfinite(between) and np.isfinite(half).any():
            return between + float(np.nanmean(half**2))
    return decompose(q).run_variance


def _mirrored_pairs(grid: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The columns of ``grid`` (sets x placements s, -s, t, -t, ...) split into each pair's
    first and second runs (sets x pairs each; an odd last column left out); None with fewer
    than two pairs, from which no pair-to-pair variance can be estimated."""
    pairs = grid.shape[1] // 2
    if pairs < 2:
        return None
    return grid[:, 0 : 2 * pairs : 2], grid[:, 1 : 2 * pairs : 2]


def model_variance(
    grids: dict[str, np.ndarray], fit_seeds: Sequence[int | None], mirrored: bool
) -> np.ndarray:
    """Per quantity (`QUANTITIES` order) m_q, the variance of the simulated mean a calibration
    fits a case with (module docstring; units of the quantity squared), from design's runs of
    the case ``grids`` (quantity -> n sets x placements, NaN: no value) and the placement seeds
    the fit simulates it at, ``fit_seeds`` (`parcelfit.study.joint.placement_seeds`; None the
    nominal start, counted as exact). Independent placements: R W_q / K^2 (R seeded runs of K,
    W_q / K without a nominal one). ``mirrored``: 4 P V_q / K^2 with P pairs s, -s and V_q the
    variance of a pair's mean, from ``grids``' columns in pairs where the sets hold two complete
    pairs or more, else W_q / 2 (its value for independent draws). 0 where nothing estimates
    it."""
    K = len(fit_seeds)
    seeded = [s for s in fit_seeds if s is not None]
    out = np.zeros(len(QUANTITIES))
    if K == 0 or not seeded:
        return out
    for k, q in enumerate(QUANTITIES):
        grid = np.asarray(grids[q], float)
        W = run_variance(grid, mirrored)
        if not mirrored:
            v = len(seeded) * W / K**2
        else:
            pairs = _mirrored_pairs(grid)
            V = math.nan if pairs is None else decompose(0.5 * (pairs[0] + pairs[1])).run_variance
            if not math.isfinite(V):
                V = W / 2
            v = 4 * sum(s > 0 for s in seeded) * V / K**2
        out[k] = v if math.isfinite(v) else 0.0
    return out


def design_placement_seeds(placements: int, seed: int, mirrored: bool) -> list[int]:
    """The placement seeds design simulates every case at: ``placements`` seeds drawn from
    ``seed`` (`parcelfit.study.plausible.placement_seeds`), or with ``mirrored`` half as many
    each beside its mirror image (s, -s, ...; the last unpaired when ``placements`` is odd)."""
    if not mirrored:
        return placement_seeds(placements, seed)
    out: list[int] = []
    for s in placement_seeds((placements + 1) // 2, seed):
        out += [s, -s]
    return out[:placements]


def score_candidate(
    design: Design,
    ident: Identifiability,
    sets: Sequence[dict[str, float]],
    grids: dict[str, np.ndarray],
    runs: int,
    known: np.ndarray | None = None,
    real_scatter: Mapping[str, float] | None = None,
    model: np.ndarray | None = None,
    mirrored: bool = False,
) -> list[CandidateScore]:
    """The scores of one candidate from its simulated quantities ``grids`` (quantity -> n sets
    x K placements, NaN where a run has none), for every parameter the data do not determine,
    given the information ``known`` the fitted cases hold (None: nothing), the real runs'
    own scatter ``real_scatter`` (`sensitivity`) and the variance ``model`` of the simulated
    means the calibration would fit them with (`model_variance`; None: exact); ``mirrored``:
    the placements in pairs s, -s."""
    J, scatter = sensitivity(ident, sets, grids, real_scatter, mirrored)
    shares = expected_width(J, scatter, runs, known, model)
    target = np.array(
        [
            DETERMINED_WIDTH * (p.high - p.low) / max(p.interval[1] - p.interval[0], 1e-300)
            for p in ident.parameters
        ]
    )
    needed = runs_needed(J, scatter, target, known, model)
    snr = np.abs(J) / scatter[:, None]
    n_ok = int(np.isfinite(grids["rotation"]).sum())
    out = []
    for j, p in enumerate(ident.parameters):
        if p.determined:
            continue
        best_q = int(np.argmax(snr[:, j]))
        out.append(
            CandidateScore(
                design,
                p.name,
                p.verdict,
                p.interval,
                float(snr[best_q, j]),
                QUANTITIES[best_q] if snr[best_q, j] > 0 else None,
                float(shares[j]),
                float(shares[j] * (p.interval[1] - p.interval[0])),
                needed[j],
                n_ok,
            )
        )
    return out


def real_run_scatter(folder: Path, study: Study) -> dict[str, float]:
    """The real runs' own scatter beyond the model's (`parcelfit.study.run_scatter`; SI, the
    transit time's a share of its value) from the calibration's recommended evaluation, where
    it simulated each fitted case at two placements or more; empty otherwise (with one
    simulation per case the excess would hold the placements' scatter, which the candidates'
    own placements give already)."""
    scatter = estimate_run_scatter(folder, study)
    if scatter is None or scatter.simulations < 2:
        return {}
    return {q: float(v) for q, v in scatter.sd.items()}


def rank_experiments(
    folder: str | Path,
    *,
    candidates: Sequence[str] = (),
    rig_files: Sequence[str] = (),
    sets: int = 20,
    placements: int | None = None,
    runs: int = 10,
    seed: int = 0,
    speed_deviation: float = SPEED_DEVIATION,
    out: str | Path | None = None,
    executor: str = "local",
    workers: int | None = None,
    scheduler: str | None = None,
    table_format: str = "csv",
    progress: ProgressCallback | None = None,
    make: Callable[[], Executor] | None = None,
    on_cost: Callable[[str], None] | None = None,
) -> DesignResult:
    """Rank the candidate experiments for the calibration in ``folder`` (module docstring):
    each simulated at ``sets`` plausible parameter sets x ``placements`` seeded placements
    (default `PLACEMENTS`, 1 where a simulator cannot place its runs; each with its drives
    ``speed_deviation`` [-] off their mean speeds) in ``executor``, scored for ``runs`` real
    runs, recorded in ``out``/design.sqlite (resumable, default ``design`` in the
    study folder) and written there; ``on_cost`` receives the expected cost of the simulations
    still to run before they start. Seeded."""
    progress = progress or ignore_progress
    if not 2 <= sets <= MAX_SETS:
        raise ParcelfitError(f"--sets {sets}: give from 2 to {MAX_SETS} parameter sets")
    if placements is not None and not 1 <= placements <= MAX_PLACEMENTS:
        raise ParcelfitError(f"--placements {placements}: give from 1 to {MAX_PLACEMENTS}")
    if not 1 <= runs <= MAX_RUNS:
        raise ParcelfitError(f"--runs {runs}: give from 1 to {MAX_RUNS} real runs")
    check_speed_deviation(speed_deviation)
    if table_format not in TABLE_FORMATS:
        raise ParcelfitError(
            f"unknown table format {shown(table_format)}", fix=f"use one of {list(TABLE_FORMATS)}"
        )
    inputs = load_inputs(folder)
    study = inputs.study
    ident = inputs.identifiability
    if sets < len(ident.names) + 2:
        n = len(ident.names)
        raise ParcelfitError(
            f"--sets {sets}: the effects of {n} parameter{'s' if n != 1 else ''} need at least "
            f"{n + 2} parameter sets (with fewer nothing could narrow anything)",
            fix=f"give --sets {n + 2} or more ({n + 5} or more for a steadier ranking; "
            "the default is 20)",
        )
    config = study.simulator
    mine = config.backend in ("mujoco", "rigidbox")
    # the study's own further rig files (simulator.rigs) are candidates too
    given = {Path(r).resolve() for r in rig_files}
    own_files = [r for r in (config.rigs or ()) if mine and Path(r).resolve() not in given]
    designs = candidate_designs(
        candidates,
        [*rig_files, *own_files],
        config.rig if mine else None,
        config.consignment if mine else None,
    )
    open_ = [p.name for p in ident.parameters if not p.determined]
    out_dir = Path(out) if out is not None else inputs.folder / "design"
    if not open_:
        # nothing simulated: the placements are nominal (the default where none were given)
        return DesignResult([], [], runs, sets, placements or PLACEMENTS, out_dir)
    fitted = fitted_cases(study)
    cases = designs + [d for d, _, _ in fitted]  # the fitted cases simulated after the candidates
    own = make_simulator(config) if fitted else None
    simulators = [design_simulator(study, d) for d in designs] + [own for _ in fitted]
    placements = min(placements_for(sim, placements, PLACEMENTS) for sim in simulators)
    for sim in simulators:
        require_placements(sim, placements, file=None, where="--placements")
    placed = places_runs(simulators[0])
    varied = placed and all(varies_drives(s) for s in simulators)
    deviation = speed_deviation if varied else 0.0
    drawn = draw_sets(ident, sets, seed)
    seeds = design_placement_seeds(placements, seed, study.mirrored) if placed else [0]
    full = [{**study.fixed, **s} for s in drawn]
    check_writable(out_dir, (DESIGN_STORE,))
    out_dir.mkdir(parents=True, exist_ok=True)
    lock = lock_folder(out_dir, "an experiment design")
    try:
        store = Store(out_dir / DESIGN_STORE)
        try:
            record = {
                "study": str(inputs.folder.resolve()),
                "candidates": [[d.rig, d.consignment, d.setting] for d in designs],
                "fitted": [[d.rig, d.consignment, d.setting, n] for d, n, _ in fitted],
                "seed": seed,
                "sets": drawn,
                "placements": seeds,
                "speed_deviation": deviation,
            }
            if not store.claim_meta("design", record):
                raise ParcelfitError(
                    "this folder holds an experiment design with other inputs (study, "
                    "candidates, --sets, --placements, --seed, --speed-deviation or the "
                    "study's cost.mirrored, which places design's runs in mirrored pairs; or "
                    "one made by an earlier version)",
                    file=out_dir,
                    fix="give another --out, or the same inputs to resume it",
                )
            have = {e.iteration for e in store.evaluations("screen")}
            for c, d in enumerate(cases):
                if c not in have:  # one transaction per candidate: all its rows or none
                    store.add_pending(
                        "screen",
                        c,
                        [full[i] for i in range(len(full)) for _ in seeds],
                        d.setting,
                        [s for _ in full for s in seeds],
                    )
            if on_cost is not None:
                on_cost(cost_line(study, cases, store, executor, workers, make is not None))
            rows = store.evaluations("screen")
            total = len(rows)
            done = sum(e.status != "pending" for e in rows)
            progress(
                ProgressEvent(
                    "design", f"{done} of {total} simulations stored", done=done, total=total
                )
            )
            todo = [e for e in rows if e.status == "pending"]
            if todo:
                with open_executor(executor, workers, scheduler, len(todo), make) as pool:
                    for c, (d, sim) in enumerate(zip(cases, simulators, strict=True)):
                        mine = [e for e in todo if e.iteration == c]
                        items = [
                            (
                                Task(
                                    e.params,
                                    d.case,
                                    f"design-{c}-set{e.slot // len(seeds)}-p{e.seed}",
                                ),
                                e.seed if placed else None,
                            )
                            for e in mine
                        ]
                        for i, result in simulate_items(pool, sim, items, deviation):
                            finish_run(store, mine[i].id, result)
                            done += 1
                            progress(
                                ProgressEvent(
                                    "design",
                                    f"{d.label}: {done} of {total} simulations",
                                    done=done,
                                    total=total,
                                )
                            )
            rows = store.evaluations("screen")
        finally:
            store.close()
        grids = [_grids(rows, c, len(full), len(seeds)) for c in range(len(cases))]
        real = real_run_scatter(inputs.folder, study)
        mirrored = placed and study.mirrored
        sens = [sensitivity(ident, drawn, g, real, mirrored) for g in grids]
        # a candidate joins the fit with the study's placements, a fitted case keeps its own;
        # m only where design's runs scatter as the fit's do: placed, at the drives' mean speeds
        as_fitted = placed and deviation == 0.0
        per_case = [fit_placement_seeds(study)] * len(designs) + [k for *_, k in fitted]
        models = [
            model_variance(g, k, mirrored) if as_fitted else None
            for g, k in zip(grids, per_case, strict=True)
        ]
        # reported as entered only where it did (the published cost's nominal run: exact)
        fit_scatter = any(m is not None and bool(m.any()) for m in models)
        known = sum(
            (
                information(*sens[len(designs) + f], n, models[len(designs) + f])
                for f, (_, n, _) in enumerate(fitted)
            ),
            np.zeros((len(ident.names),) * 2),
        )
        scores: list[CandidateScore] = []
        for c, d in enumerate(designs):
            scores += score_candidate(
                d, ident, drawn, grids[c], runs, known, real, models[c], mirrored
            )
        open_idx = [j for j, p in enumerate(ident.parameters) if not p.determined]
        infos = [information(*sens[c], runs, models[c]) for c in range(len(designs))]
        sequence = [
            (designs[c].label, share) for c, share in greedy_sequence(infos, known, open_idx)
        ]
        result = DesignResult(
            open_,
            scores,
            runs,
            sets,
            placements,
            out_dir,
            sequence,
            [d.label for d, _, _ in fitted],
            dict(real),
            fit_scatter,
            few_sets_notes(sets, len(ident.names)),
        )
        write_design(result, out_dir, table_format)
    finally:
        lock.release()
    return result


def few_sets_notes(sets: int, n_parameters: int) -> list[str]:
    """A note when ``sets`` leave the effects' regression so few degrees of freedom that only
    large effects count (fewer than the parameters + 5 sets): a candidate scored 0 may still
    act."""
    if sets >= n_parameters + 5:
        return []
    t = resolved_t(sets, n_parameters)
    return [
        f"with {sets} parameter sets and {n_parameters} calibrated parameters an effect counts "
        f"only from {t:.1f} standard errors: a signal/noise of 0.0 may hide an effect, and the "
        f"ranking is rough (give --sets {n_parameters + 5} or more; the default is 20)"
    ]


def _grids(rows: Sequence[Any], c: int, n_sets: int, n_seeds: int) -> dict[str, np.ndarray]:
    """Case ``c``'s simulated quantities from the store's ``rows``: quantity -> sets x
    placements (NaN where a run failed or has none)."""
    grids = {q: np.full((n_sets, n_seeds), np.nan) for q in QUANTITIES}
    for e in rows:
        if e.iteration != c or e.status != "ok":
            continue
        i, j = divmod(e.slot, n_seeds)
        values = {**e.details.quantities, "transit_time": e.transit_time}
        for q in QUANTITIES:
            v = values.get(q)
            if v is not None and math.isfinite(float(v)):
                grids[q][i, j] = float(v)
    return grids


def fitted_cases(study: Study) -> list[tuple[Design, int, list[int | None]]]:
    """The study's fitted test cases as designs (run by the study's own simulator) with the
    real runs each was fitted on (all of its dataset's runs with the ensemble cost, the one
    reference run with the published cost) and the placement seeds it was fitted with in every
    evaluation (`parcelfit.study.joint.placement_seeds`; [None] with the published cost)."""
    from parcelfit.runs.dataset import load_dataset

    out = []
    for spec in study.cases:
        c = spec.case
        n = 1
        if study.cost_kind == "ensemble":
            try:
                n = max(1, len(load_dataset(spec.dataset)[c].runs))
            except ParcelfitError:
                n = 1
        design = Design(c.rig, c.consignment, c.rig, c.consignment, c.speed_setting)
        out.append((design, n, fit_placement_seeds(study, spec)))
    return out


def write_design(result: DesignResult, out: Path, table_format: str = "csv") -> list[Path]:
    """Write ``candidates`` and ``ranking`` (.csv or .parquet) and ``design.json`` into
    ``out``; returns their paths."""
    paths = []
    tables = (("candidates", result.candidates_table()), ("ranking", result.ranking_table()))
    for name, df in tables:
        path = out / f"{name}.{table_format}"
        if table_format == "parquet":
            df.to_parquet(path, index=False)
        else:
            df.to_csv(path, index=False)
        paths.append(path)

    def records(df: pd.DataFrame) -> list[dict[str, Any]]:
        return json.loads(df.to_json(orient="records"))

    doc = {
        "parameters": result.parameters,
        "runs": result.runs,
        "sets": result.sets,
        "placements": result.placements,
        "fitted": result.fitted,
        "real_scatter": result.real_scatter,
        "fit_scatter": result.fit_scatter,
        "notes": result.notes,
        "candidates": records(tables[0][1]),
        "ranking": records(tables[1][1]),
    }
    path = out / DESIGN_FILE
    write_text_atomic(path, json.dumps(doc))
    paths.append(path)
    return paths


__all__ = [
    "DESIGN_FILE",
    "DESIGN_STORE",
    "FLOOR",
    "MAX_RUNS",
    "PRIOR_PRECISION",
    "CandidateScore",
    "DesignResult",
    "candidate_designs",
    "design_placement_seeds",
    "expected_width",
    "fitted_cases",
    "greedy_sequence",
    "information",
    "model_variance",
    "rank_experiments",
    "resolved_t",
    "runs_needed",
    "score_candidate",
    "sensitivity",
    "shares_of",
    "write_design",
]
