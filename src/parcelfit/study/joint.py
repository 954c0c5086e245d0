"""Joint and ensemble evaluations, the acceptance threshold, the transfer check and the advice
on which test case to add (method.md sections 7 and 8, extended).

**Joint evaluation.** A study with several fitted cases, or with the ensemble cost, evaluates one
parameter set by simulating every case k (K_k seeded placements each: the case's own
``placements`` or else ``cost.placements``; the published cost simulates the nominal placement
once) and costs it

    c = sum_k w_k c_k

with c_k equation (3) against case k's reference run (``cost.kind: published``) or the ensemble
cost against all of case k's real runs (``ensemble``, `parcelfit.metrics.ensemble`). Each case's
cost is normalised by its own real runs (section 4), so cases of different rigs add on one
scale. The placement seeds are 1..K for every evaluation (common random numbers: two parameter
sets are compared under the same placements, which removes the placements' scatter from their
difference). With ``cost.mirrored`` they are 1, -1, 2, -2, ... (the nominal placement first
when K is odd), seed -s the mirror image of placement s (`parcelfit.sim.mujoco.rig.Rig.placement`):
antithetic placements, whose offsets average to exactly the nominal start, so that the fixed
sample of K placements shifts no mean of the model's runs to first order (none at all where a
run is linear in its placement). Independent draws do: at K = 2
their mean offset is the scatter over sqrt(2), the same in every evaluation, and a parameter
that moves the same quantity weakly takes up that shift (docs/research/design-benchmark.md).
An evaluation whose simulations do not all succeed is a failure (the first failed simulation's
status).

**Threshold.** The identifiability analysis (`parcelfit.study.identify`) accepts a parameter
set when its cost is below epsilon = sum_k w_k q_k, q_k what case k's cost would be, at most,
if the simulations were as good as more real runs: the costs real runs score in the study's own
cost against the case's other real runs, at the 95 % quantile (`THRESHOLD_LEVEL`; the next value
up, numpy's "higher": of at most 20 values the largest, which a new value exceeds about once in
N + 1). For the published cost, equation (3) of each real run against the reference run
(`parcelfit.metrics.cost.real_run_costs`). For the ensemble cost, every set of K_k real runs,
K_k the case's placements, against the other n - K_k in the same formula
(`parcelfit.metrics.ensemble.ensemble_null_costs`), and at least the largest cost of a single
real run against the others (`ensemble_real_costs`: the threshold before 2026-12-04, kept as a
floor; with one placement the threshold is exactly that). The sets matter because at K = 2 a
pair of real runs scores differently from one run, and more in the tail: two runs of a case
whose runs catch or slide can both catch, and two runs that cross in about the same time give
the transit term a small standard error. The floor is an empirical safeguard: without it the
twin benchmark's 10-evaluation test on the analytic simulator left the truth outside two
intervals (docs/research/identify-threshold.md); it keeps the threshold at or above the value
the earlier coverage results were measured with. The cases' q_k are summed, not the quantile
of their sum taken: the placement seeds are the same on every rig, so the cases' costs at the
truth need not be independent, and the sum of the quantiles is the quantile of the sum when
they rise and fall together.

**Transfer check.** The calibrated parameters simulated on other test cases (usually other rigs
with the same consignment), each judged like a validation: the published criteria and the band
test. A bias shared by two speed settings of one rig can pass a validation at the other setting;
it is unlikely to pass on another rig.

**Advice.** For every parameter the data do not determine, the calibrated set is simulated with
that parameter at each end of its interval on every candidate case (the validation and transfer
cases); the change between the two runs, in the candidate's own normalisation,

    Delta_k = w_xy DTW_xy(lo, hi)^2 / max(D_xy) + w_theta DTW_theta(lo, hi)^2 / max(D_theta)
              + (T_lo - T_hi)^2 / s_real^2,

is summed over the undetermined parameters; the case with the largest sum would help most:
there the undetermined values give runs that differ most, measured against the real runs'
own scatter.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.metrics import ReferenceSelection, calibration_cost, real_run_costs
from parcelfit.metrics.dtw import dtw_distance
from parcelfit.metrics.ensemble import (
    effective_set_size,
    ensemble_cost,
    ensemble_null_costs,
    ensemble_real_costs,
)
from parcelfit.runs import Trajectory
from parcelfit.sim.executors import Executor, Task, simulate_task
from parcelfit.sim.protocol import SimResult, SimStatus, Simulator
from parcelfit.study.details import CaseCost, EvaluationDetails, FailedRun
from parcelfit.study.identify import Advice
from parcelfit.study.studyfile import CaseSpec, Study


def placement_seeds(study: Study, spec: CaseSpec | None = None) -> list[int | None]:
    """The placement seeds of a case (``spec``, default the study's setting) in an evaluation:
    1..K for the ensemble cost, K the case's own ``placements`` or else the study's, the
    nominal placement (None) for the published cost. With ``study.mirrored`` the antithetic
    seeds instead: the nominal placement first when K is odd, then 1, -1, 2, -2, ... (module
    docstring)."""
    if study.cost_kind == "ensemble":
        k = study.placements if spec is None or spec.placements is None else spec.placements
        if study.mirrored:
            seeds: list[int | None] = [None] if k % 2 else []
            for s in range(1, k // 2 + 1):
                seeds += [s, -s]
            return seeds
        return list(range(1, k + 1))
    return [None]


def simulations_per_evaluation(study: Study) -> int:
    """How many simulations one fitting evaluation of a joint or ensemble study runs: every
    fitted case times its placements."""
    return sum(len(placement_seeds(study, spec)) for spec in study.cases)


def places_runs(simulator: Simulator) -> bool:
    """Whether ``simulator`` places its runs by a seed (has ``with_placement``)."""
    return callable(getattr(simulator, "with_placement", None))


def require_placements(
    simulator: Simulator, placements: int, *, file: Path | None, where: str
) -> None:
    """Refuse ``placements`` > 1 seeded placements with a simulator that cannot place runs
    (no ``with_placement``); ``file`` and ``where`` name the key that asked for them."""
    if placements > 1 and not places_runs(simulator):
        raise ParcelfitError(
            f"the {type(simulator).__name__} simulator has no seeded placements "
            "(with_placement), so an ensemble of placements would repeat one run",
            file=file,
            where=where,
            fix=(
                f"leave {where} out (one placement is then the default) or give {where} 1"
                if where.startswith("--")
                else "use placements: 1"
            )
            + ", or a simulator with seeded placements (mujoco)",
        )


def placements_for(simulator: Simulator, given: int | None, default: int) -> int:
    """The seeded placements per parameter set a command runs: ``given`` when the user gave a
    number, else ``default`` for a simulator that places its runs (``with_placement``) and 1
    for one that cannot (its runs would only repeat)."""
    if given is not None:
        return given
    return default if places_runs(simulator) else 1


def check_placements(study: Study, simulator: Simulator) -> None:
    """Refuse an ensemble of several placements with a simulator that cannot place runs."""
    if study.cost_kind == "ensemble":
        most = max(len(placement_seeds(study, spec)) for spec in study.cases)
        require_placements(simulator, most, file=study.path, where="cost.placements")


SPEED_DEVIATION = 0.03  # method.md: real belt speeds deviate up to 3 % short-term from their mean


def check_speed_deviation(value: float) -> float:
    """``value`` [-] if it is a fraction from 0 to below 1, else a `ParcelfitError` naming
    ``--speed-deviation``."""
    if not (math.isfinite(value) and 0 <= value < 1):
        raise ParcelfitError(
            f"--speed-deviation {value:g}: give a fraction from 0 to below 1",
            fix=f"e.g. {SPEED_DEVIATION:g} for drives within 3 % of their mean speed",
        )
    return value


def varies_drives(simulator: Simulator) -> bool:
    """Whether ``simulator`` can run its rig's drives off their mean speeds (the MuJoCo model
    and the rigid-box reference can; a python or external simulator cannot)."""
    return callable(getattr(simulator, "with_speed_factors", None))


def simulate_placed(
    simulator: Simulator, item: tuple[Task, int | None], speed_deviation: float = 0.0
) -> SimResult:
    """Simulate a task with the placement seed (None: the nominal placement); with a
    ``speed_deviation`` [-] > 0 the seed also draws each drive's short-term speed factor
    (`parcelfit.sim.mujoco.rig.Rig.speed_factors`), where the simulator can vary them."""
    task, seed = item
    if seed is not None:
        simulator = simulator.with_placement(seed)  # type: ignore[attr-defined]
        if speed_deviation > 0 and varies_drives(simulator):
            rig = simulator.rig(task.case.rig)  # type: ignore[attr-defined]
            factors = rig.speed_factors(seed, speed_deviation)
            simulator = simulator.with_speed_factors(factors)  # type: ignore[attr-defined]
    return simulate_task(simulator, task)


def simulate_items(
    executor: Executor,
    simulator: Simulator,
    items: Sequence[tuple[Task, int | None]],
    speed_deviation: float = 0.0,
) -> Iterator[tuple[int, SimResult]]:
    """Simulate ``(task, placement seed)`` items (`simulate_placed`, with ``speed_deviation``);
    yield ``(index, SimResult)`` as they arrive (a task that could not run is a ``failed``
    result, as `Executor.simulate` gives)."""
    run = partial(simulate_placed, simulator, speed_deviation=speed_deviation)
    for i, out in executor.map(run, items):
        result = out.value
        if result is None:
            result = SimResult(None, SimStatus.FAILED, 0.0, {"message": out.error})
        yield i, result


@dataclass(frozen=True)
class CaseRun:
    """One simulation of an evaluation: its case, placement seed and result, and where its run
    was written (relative to the study folder, None without one)."""

    spec: CaseSpec
    seed: int | None
    result: SimResult
    run_file: str | None = None


def case_cost(
    spec: CaseSpec,
    runs: Sequence[CaseRun],
    reference: ReferenceSelection,
    study: Study,
) -> CaseCost:
    """The cost part of one case (its runs all succeeded): ``cost`` (unweighted), ``weight``
    and the parts of the chosen cost (DTW distances [m], [rad] and transit time [s] for the
    published one; trajectory and transit terms, standard error for the ensemble)."""
    trajs: list[Trajectory] = [r.result.run.trajectory for r in runs]  # type: ignore[union-attr]
    transits = [r.result.run.transit_time for r in runs]  # type: ignore[union-attr]
    out: dict[str, Any] = {
        "case": spec.label,
        "weight": spec.weight,
        "run_files": [r.run_file for r in runs],
        "seeds": [r.seed for r in runs],
        "transit_times": transits,
    }
    adjustment = reference.transit_adjustment
    if adjustment is not None:  # compared with the real runs' adjusted times: adjust alike
        transits = [adjustment.adjust_track(t, tr) for t, tr in zip(transits, trajs, strict=True)]
        out["adjusted_transit_times"] = transits
    if study.cost_kind == "ensemble":
        units = [0 if r.seed is None else abs(r.seed) for r in runs] if study.mirrored else None
        e = ensemble_cost(
            trajs, transits, reference, study.w_xy, study.w_theta, study.transit_weight, units
        )
        out.update(
            cost=e.value,
            trajectory_term=e.trajectory_term,
            transit_term=e.transit_term,
            se=e.se,
            mean_transit_time=e.mean_transit,
        )
    else:
        c = calibration_cost(trajs[0], reference, study.w_xy, study.w_theta)
        out.update(cost=c.value, dtw_xy=c.dtw_xy, dtw_theta=c.dtw_theta)
    return CaseCost.model_validate(out)


def evaluation_outcome(
    runs: Sequence[CaseRun],
    references: Mapping[str, ReferenceSelection],
    study: Study,
) -> dict[str, Any]:
    """The store's fields of a joint evaluation from all its runs (in case order): status,
    cost (the weighted sum), the first case's transit time and run file, and ``details`` with
    the per-case parts under ``cases``."""
    wall = sum(r.result.wall_time for r in runs)
    bad = next((r for r in runs if not (r.result.ok and r.result.run is not None)), None)
    out: dict[str, Any] = {
        "status": "ok",
        "cost": None,
        "transit_time": None,
        "run_file": runs[0].run_file if runs else None,
        "wall_time": wall,
    }
    parts: list[CaseCost] = []
    if bad is not None:
        out["status"] = bad.result.status.value
        msg = bad.result.diagnostics.get("message")
        out["details"] = EvaluationDetails(
            cases=parts,
            message=str(msg or f"the simulation ended {out['status']}"),  # as a worker said
            failed_run=FailedRun(case=bad.spec.label, placement=bad.seed),  # it, so a lost
        )  # worker's message is recognised on resume (loop.LOST_WORKER_MESSAGES)
        return out
    total = 0.0
    try:
        for spec in study.cases:
            mine = [r for r in runs if r.spec.case == spec.case]
            part = case_cost(spec, mine, references[spec.label], study)
            parts.append(part)
            total += spec.weight * part.cost
    except ParcelfitError as exc:
        out["status"] = "failed"
        out["details"] = EvaluationDetails(cases=parts, message=f"cost not computable: {exc}")
        return out
    first = runs[0].result.run
    out.update(cost=total, transit_time=None if first is None else first.transit_time)
    out["details"] = EvaluationDetails(cases=parts)
    return out


THRESHOLD_LEVEL = 0.95  # epsilon: this quantile of each case's cost at the truth, summed


def case_null_costs(
    reference: ReferenceSelection, study: Study, spec: CaseSpec | None = None
) -> np.ndarray:
    """What sets of real runs of this case score in the study's cost against the case's other
    real runs (dimensionless; module docstring): sets of the case's placements (``spec``, default
    the study's) for the ensemble cost, single real runs against the reference run for the
    published one."""
    if study.cost_kind == "ensemble":
        k = len(placement_seeds(study, spec))
        return ensemble_null_costs(
            reference, k, study.w_xy, study.w_theta, study.transit_weight, seed=study.seed
        )
    return real_run_costs(reference, study.w_xy, study.w_theta)


def case_threshold(
    reference: ReferenceSelection, study: Study, spec: CaseSpec | None = None
) -> float:
    """The acceptance threshold of one case alone (dimensionless; NaN without real-run costs):
    the `THRESHOLD_LEVEL` quantile (the next value up) of `case_null_costs`, and for the
    ensemble cost at least the largest cost of a single real run against the others (module
    docstring)."""
    costs = case_null_costs(reference, study, spec)
    if not len(costs):
        return math.nan
    q = float(np.quantile(costs, THRESHOLD_LEVEL, method="higher"))
    if study.cost_kind == "ensemble":
        single = ensemble_real_costs(reference, study.w_xy, study.w_theta, study.transit_weight)
        q = max(q, float(np.max(single)))
    return q


def threshold(references: Mapping[str, ReferenceSelection], study: Study) -> tuple[float, str]:
    """The acceptance threshold epsilon of the identifiability analysis, sum_k w_k q_k over the
    fitted cases of nonzero weight (module docstring), and how it was made."""
    cases = [s for s in study.cases if s.weight > 0]
    parts = [(s, case_threshold(references[s.label], study, s)) for s in cases]
    total = sum(s.weight * q for s, q in parts)
    level = f"{100 * THRESHOLD_LEVEL:g} % quantile"
    if study.cost_kind == "ensemble":

        def sets(s: CaseSpec) -> str:
            n = len(references[s.label].run_ids)
            k = effective_set_size(n, len(placement_seeds(study, s)))
            return f"{k} of {n}"

        what = (
            "of the ensemble cost of sets of real runs against the other real runs, at least "
            "the largest of one real run"
        )
        words = " + ".join(
            f"{s.weight:g} x {q:.3g} ({s.label}: sets of {sets(s)})" for s, q in parts
        )
    else:
        what = "of equation (3) of each real run against the reference run"
        words = " + ".join(f"{s.weight:g} x {q:.3g} ({s.label})" for s, q in parts)
    return total, f"{level} {what}, per case: {words}"


# -- advice: which test case would help most ---------------------------------------------------


def response_change(
    a: SimResult, b: SimResult, reference: ReferenceSelection, w_xy: float, w_theta: float
) -> float | None:
    """Delta between two runs of one case (module docstring; None if either has no run)."""
    if a.run is None or b.run is None or not (a.ok and b.ok):
        return None
    comp = reference.comparison
    pa, pb = comp.prepare(a.run.trajectory), comp.prepare(b.run.trajectory)
    sx = reference.max_xy if reference.max_xy > 0 else 1.0
    st = reference.max_theta if reference.max_theta > 0 else 1.0
    out = (
        w_xy * dtw_distance(pa.xy, pb.xy, comp.window) ** 2 / sx
        + w_theta * dtw_distance(pa.theta, pb.theta, comp.window) ** 2 / st
    )
    real = [t for t in reference.transit_times if t is not None]
    if a.run.transit_time is not None and b.run.transit_time is not None and len(real) >= 2:
        var = float(np.var(real, ddof=1))
        if var > 0:
            out += (a.run.transit_time - b.run.transit_time) ** 2 / var
    return float(out)


def advise(
    params: Mapping[str, float],
    intervals: Mapping[str, tuple[float, float]],
    candidates: Sequence[CaseSpec],
    references: Mapping[str, ReferenceSelection],
    simulate: Callable[[list[Task]], list[SimResult]],
    w_xy: float = 1.0,
    w_theta: float = 1.0,
) -> Advice:
    """The advice of the module docstring: ``params`` the full calibrated set (SI),
    ``intervals`` the undetermined parameters' intervals (SI), ``simulate`` runs a list of
    tasks and returns their results in order."""
    tasks = []
    for spec in candidates:
        for name, (lo, hi) in intervals.items():
            for end, value in (("lo", lo), ("hi", hi)):
                tasks.append(
                    Task({**params, name: value}, spec.case, f"advice-{spec.label}-{name}-{end}")
                )
    results = simulate(tasks) if tasks else []
    changes: dict[str, dict[str, float]] = {}
    k = 0
    for spec in candidates:
        per = {}
        for name in intervals:
            delta = response_change(
                results[k], results[k + 1], references[spec.label], w_xy, w_theta
            )
            k += 2
            if delta is not None:
                per[name] = delta
        changes[spec.label] = per
    scored = {c: sum(v.values()) for c, v in changes.items() if v}
    best = max(scored, key=lambda c: scored[c]) if scored else None
    return Advice(changes=changes, best=best, parameters=tuple(intervals))


__all__ = [
    "SPEED_DEVIATION",
    "THRESHOLD_LEVEL",
    "CaseRun",
    "advise",
    "case_cost",
    "case_null_costs",
    "case_threshold",
    "check_placements",
    "check_speed_deviation",
    "evaluation_outcome",
    "placement_seeds",
    "placements_for",
    "places_runs",
    "require_placements",
    "response_change",
    "simulate_items",
    "simulate_placed",
    "simulations_per_evaluation",
    "threshold",
    "varies_drives",
]
