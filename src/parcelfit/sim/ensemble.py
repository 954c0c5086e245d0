"""Ensembles of seeded placements: the distribution of outcomes a model gives for one test case.

Real test cases are repeated ten times with ten specimens placed by hand, so a model is judged
by the distribution of its outcomes over placements, not by one run. An ensemble simulates one
parameter set for a list of placement seeds (each reproducible on its own: the rig's
``start.scatter`` draws the start pose from the seed, see `parcelfit.sim.mujoco.rig`) and
summarises, per run:

* the transit time T [s] between the two light barriers;
* the rotation, the net change of the unwrapped heading from the first to the last sample,
  |theta(t_end) - theta(t_0)| [rad];
* the outcome: ``spin`` when the rotation exceeds 90 degrees (the parcel turned round a corner
  or flipped), ``slide`` otherwise (it kept its orientation up to an alignment with a plate or
  the belt).

Summary statistics: median and quartiles of rotation and transit time, the shares of runs
rotating more than 90 and 180 degrees, the standard error of the mean transit time
s / sqrt(n), and Spearman's rank correlation between rotation and transit time.

**How a change of parameters moves an ensemble** (`ensemble_shift`): two ensembles a and b over
the same placement seeds (matched pairs: placement i starts both runs from the same pose) are
compared by the differences of their ensemble statistics

    d_rot = median_b(rotation) - median_a(rotation)  [rad]
    d_T   = median_b(T) - median_a(T)                [s]
    d_spin = share_b(spin) - share_a(spin)           [-]

over the seeds where both runs ended ok, each with its bootstrap standard error (the seeds
resampled with replacement, both members of a pair together; `scipy.stats.bootstrap` with
``paired=True``): how far the difference would move with another draw of placements. A single
placement near the spin/slide threshold can change branch with a 0.1 % parameter change, so on
a rig such as E3 the statistics of an ensemble, not one run, are what a parameter must move.

**Which of two types turns further** (`paired_order`): over the seeds where both ended ok, the
placements at which b turns further than a (n_b), less (n_a) and as far to the printed
resolution (ties, |difference| below 0.5 degrees), and the two-sided sign test on the untied
pairs: p = P(|K - m/2| >= |n_b - m/2|), K ~ Binomial(m = n_a + n_b, 1/2)
(`scipy.stats.binomtest`). Unlike the difference of two medians it uses every matched
placement, and it says whether the order could be a draw of placements.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np
from scipy import stats

from parcelfit.runs import Run, TestCase, Trajectory
from parcelfit.sim.protocol import SimResult, SimStatus

# the most seeded placements of one ensemble (a study's cost, `simulate --repeat`, the precision
# check); each is a whole simulation
MAX_PLACEMENTS = 1000

SPIN_ANGLE = math.pi / 2  # rotation [rad] above which a run counts as a spin
# one colour per bundled consignment type in the ensemble figures (matplotlib colour names)
TYPE_COLOURS = {"BW": "tab:orange", "KPBW": "tab:blue", "KP": "tab:green", "PB": "tab:red"}


def signed_rotation(trajectory: Trajectory) -> float:
    """Net rotation [rad] of a run, signed: theta(t_end) - theta(t_0) of the unwrapped heading."""
    theta = np.unwrap(np.asarray(trajectory.theta, dtype=float))
    return float(theta[-1] - theta[0])


def rotation(trajectory: Trajectory) -> float:
    """Net rotation [rad] of a run: |theta(t_end) - theta(t_0)| of the unwrapped heading."""
    return abs(signed_rotation(trajectory))


def outcome_line(result: SimResult) -> str:
    """One line on a run's outcome, for diagnostic scripts: its signed net rotation [deg]
    (a trajectory's heading is unwrapped: theta at the end minus at the start) and its transit
    time [s], or the status of a run that failed (with MuJoCo's message where there is one)."""
    run = result.run
    if run is None:
        message = result.diagnostics.get("message")
        return f"run failed: {result.status.value}" + (f" ({message})" if message else "")
    theta = run.trajectory.theta
    return f"rotation {math.degrees(theta[-1] - theta[0]):+.2f} deg, transit " + (
        f"{run.transit_time:.4f} s" if run.transit_time is not None else "none"
    )


@dataclass(frozen=True)
class Member:
    """One placement of an ensemble: its seed, status, transit time [s], rotation [rad], run."""

    seed: int
    status: SimStatus
    transit_time: float | None
    rotation: float | None
    run: Run | None
    wall_time: float

    @property
    def outcome(self) -> str:
        """``spin`` (rotation above 90 degrees), ``slide``, or ``failed``."""
        if self.rotation is None:
            return "failed"
        return "spin" if self.rotation > SPIN_ANGLE else "slide"


@dataclass(frozen=True)
class EnsembleSummary:
    """Statistics of an ensemble (angles in rad, times in s); NaN where nothing was measured."""

    n: int
    n_ok: int
    rotation_median: float
    rotation_q25: float
    rotation_q75: float
    rotation_max: float
    share_over_90: float
    share_over_180: float
    spins: int
    slides: int
    transit_median: float
    transit_mean: float
    transit_sem: float
    rank_correlation: float  # Spearman's rho between rotation and transit time
    # runs that ended ok without crossing both light barriers (the transit statistics leave
    # them out: a parcel held at a plate until the run's end is slower than every median)
    no_transit: int = 0


def summarise(members: Sequence[Member]) -> EnsembleSummary:
    """Summary statistics of ``members`` (see the module docstring)."""
    rot = np.array([m.rotation for m in members if m.rotation is not None], dtype=float)
    pairs = [
        (m.rotation, m.transit_time)
        for m in members
        if m.rotation is not None and m.transit_time is not None
    ]
    tt = np.array([t for _, t in pairs], dtype=float)
    nan = float("nan")
    rho = nan
    if len(pairs) >= 3 and np.ptp(tt) > 0 and np.ptp([r for r, _ in pairs]) > 0:
        rho = float(stats.spearmanr([r for r, _ in pairs], tt).statistic)
    return EnsembleSummary(
        n=len(members),
        n_ok=int(rot.size),
        rotation_median=float(np.median(rot)) if rot.size else nan,
        rotation_q25=float(np.percentile(rot, 25)) if rot.size else nan,
        rotation_q75=float(np.percentile(rot, 75)) if rot.size else nan,
        rotation_max=float(rot.max()) if rot.size else nan,
        share_over_90=float(np.mean(rot > math.pi / 2)) if rot.size else nan,
        share_over_180=float(np.mean(rot > math.pi)) if rot.size else nan,
        spins=sum(m.outcome == "spin" for m in members),
        slides=sum(m.outcome == "slide" for m in members),
        transit_median=float(np.median(tt)) if tt.size else nan,
        transit_mean=float(np.mean(tt)) if tt.size else nan,
        transit_sem=float(np.std(tt, ddof=1) / math.sqrt(tt.size)) if tt.size > 1 else nan,
        rank_correlation=rho,
        no_transit=sum(m.rotation is not None and m.transit_time is None for m in members),
    )


@dataclass(frozen=True)
class EnsembleShift:
    """Differences b - a of the ensemble statistics over matched placements, with bootstrap
    standard errors: median rotation [rad], median transit time [s], share of spins [-]; NaN
    where fewer than two matched pairs have the quantity."""

    n_pairs: int
    rotation_median: float
    rotation_median_se: float
    transit_median: float
    transit_median_se: float
    spin_share: float
    spin_share_se: float


def paired_difference(
    a: np.ndarray, b: np.ndarray, statistic: Callable[[np.ndarray], float], seed: int
) -> tuple[float, float]:
    """statistic(b) - statistic(a) over the pairs (a_i, b_i) where both are finite, and its
    paired bootstrap standard error (2000 resamples seeded by ``seed``); in the units of the
    statistic."""
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    if a.size < 2:
        return float("nan"), float("nan")
    diff = float(statistic(b) - statistic(a))
    if np.all(a == a[0]) and np.all(b == b[0]):
        return diff, 0.0  # every resample gives the same difference
    res = stats.bootstrap(
        (a, b),
        lambda x, y: statistic(y) - statistic(x),
        paired=True,
        vectorized=False,
        n_resamples=2000,
        method="basic",
        rng=np.random.default_rng(seed),
    )
    return diff, float(res.standard_error)


def ensemble_shift(a: Sequence[Member], b: Sequence[Member], seed: int = 0) -> EnsembleShift:
    """How ensemble ``b`` differs from ensemble ``a`` over the placement seeds they share (see
    the module docstring); ``seed`` seeds the bootstrap."""
    by_seed = {m.seed: m for m in b}
    pairs = [(m, by_seed[m.seed]) for m in a if m.seed in by_seed]

    def column(attr: str, which: int) -> np.ndarray:
        values = [getattr(p[which], attr) for p in pairs]
        return np.array([np.nan if v is None else v for v in values], dtype=float)

    rot_a, rot_b = column("rotation", 0), column("rotation", 1)
    tt_a, tt_b = column("transit_time", 0), column("transit_time", 1)
    spin_a = np.where(np.isfinite(rot_a), rot_a > SPIN_ANGLE, np.nan)
    spin_b = np.where(np.isfinite(rot_b), rot_b > SPIN_ANGLE, np.nan)
    rot = paired_difference(rot_a, rot_b, np.median, seed)
    tt = paired_difference(tt_a, tt_b, np.median, seed)
    spin = paired_difference(spin_a, spin_b, np.mean, seed)
    n_pairs = int(np.sum(np.isfinite(rot_a) & np.isfinite(rot_b)))
    return EnsembleShift(n_pairs, *rot, *tt, *spin)


TIE_ANGLE = math.radians(0.5)  # rotations closer than this [rad] count as a tie


@dataclass(frozen=True)
class PairedOrder:
    """How often ensemble b turns further than ensemble a over matched placements (see the
    module docstring): pairs compared, b further, a further, ties, the sign test's two-sided p
    (NaN without untied pairs) and the median of the paired differences b - a [rad]."""

    n_pairs: int
    b_further: int
    a_further: int
    ties: int
    p_value: float
    median_difference: float


def paired_order(a: Sequence[Member], b: Sequence[Member]) -> PairedOrder:
    """Seed by seed, does ``b`` turn further than ``a``? The counts and the sign test over the
    placement seeds both ensembles ended ok (rotations in rad)."""
    by_seed = {m.seed: m.rotation for m in b}
    diffs = np.array(
        [
            by_seed[m.seed] - m.rotation
            for m in a
            if m.rotation is not None and by_seed.get(m.seed) is not None
        ],
        dtype=float,
    )
    b_further = int(np.sum(diffs >= TIE_ANGLE))
    a_further = int(np.sum(diffs <= -TIE_ANGLE))
    untied = b_further + a_further
    p = float(stats.binomtest(b_further, untied, 0.5).pvalue) if untied else float("nan")
    median = float(np.median(diffs)) if diffs.size else float("nan")
    return PairedOrder(diffs.size, b_further, a_further, diffs.size - untied, p, median)


def member_of(seed: int, result: SimResult) -> Member:
    """The ensemble member of placement ``seed`` from its simulation's result."""
    run = result.run if result.ok else None
    return Member(
        seed=seed,
        status=result.status,
        transit_time=run.transit_time if run is not None else None,
        rotation=rotation(run.trajectory) if run is not None else None,
        run=run,
        wall_time=result.wall_time,
    )


def _member(
    factory: Callable[[int], object], params: Mapping[str, float], case: TestCase, seed: int
) -> Member:
    return member_of(seed, factory(seed).run(params, case))  # type: ignore[attr-defined]


def simulate_ensemble(
    factory: Callable[[int], object],
    params: Mapping[str, float],
    case: TestCase,
    seeds: Sequence[int],
    executor: Executor | None = None,
    progress: Callable[[Member], None] | None = None,
) -> list[Member]:
    """Simulate ``case`` with SI ``params`` once per placement seed, in seed order.

    ``factory(seed)`` returns a simulator whose placement is drawn from ``seed`` (for MuJoCo:
    ``MujocoSimulator(...).with_placement``; it must be picklable to run in ``executor``).
    Without an executor the runs go one after the other in this process.
    """
    members: list[Member] = []
    if executor is None:
        for seed in seeds:
            members.append(_member(factory, params, case, seed))
            if progress is not None:
                progress(members[-1])
        return members
    futures = [executor.submit(_member, factory, params, case, s) for s in seeds]
    for f in futures:
        members.append(f.result())
        if progress is not None:
            progress(members[-1])
    return members


__all__ = [
    "SPIN_ANGLE",
    "TIE_ANGLE",
    "TYPE_COLOURS",
    "EnsembleShift",
    "EnsembleSummary",
    "Member",
    "PairedOrder",
    "ensemble_shift",
    "member_of",
    "paired_order",
    "rotation",
    "signed_rotation",
    "simulate_ensemble",
    "summarise",
]
