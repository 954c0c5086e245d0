"""The real runs' own scatter: what a band for a real run adds to the model's band.

A prediction's runs differ by parameter set and placement (`parcelfit.study.predict`). Real runs
of one test case differ further: each is its own specimen (its friction and stiffness scatter
about its type's values) and tracking and light barriers measure with noise. Neither is a
parameter the calibration sets nor a placement the rig file describes, so where the data
determine the parameters the model's band is narrower than the spread of real runs
(docs/research/predict-coverage.md: 77-83 % of unseen twin transit times inside a 90 % band).

**Estimate** from the calibration's cases with real runs, per quantity q of a run (transit
time T [s], rotation [rad], exit x and y [m], exit heading [rad];
`parcelfit.study.predict.run_values`) and case c:

    V_real(c)  = robust variance of q over the case's real runs: (1.4826 MAD)^2, MAD the median
                 absolute deviation from the median (scipy.stats.median_abs_deviation, scale
                 "normal": the variance itself for normal scatter)
    V_model(c) = robust variance of q over the model's runs of c at the recommended parameters:
                 `parcelfit predict` simulates them at 10 seeded placements per fitted and
                 validation case, each with its drives off their mean speeds as the
                 prediction's own runs; without them (`estimate_run_scatter` not given the
                 model's runs) the simulations of c in the recommended evaluation, 0 with one
    D(c)       = V_real(c) - V_model(c)
    s_q^2      = max(0, mean of D(c) over the cases with at least two real runs)

The differences are averaged before the cut at 0: cut case by case (max(0, D(c)), then the
mean), cases whose real runs scatter exactly like the model's would still add a positive
excess, about a third of their variance from ten noisy robust variances.

The transit time is taken relative to each case's mean real transit time (V divided by its
square), as a specimen's friction and the timing noise move it in proportion. With one
simulation per case (a simulator without placements) the placements' scatter is in E(c) as
well as in the prediction's own placements: the band is then wider than needed, and for the
rotation, an absolute angle, it can miss calm runs entirely when the fitted rig's runs spun or
slid and the predicted rig's do not; the prediction then says so (`scatter_note`).

**Why robust.** Where a case's runs split between outcomes (on E3 a parcel spins or slides on
the guide plate), the sample variance is the split's: a model whose share of spins differs
from the real runs' then shows a large "excess" that is a misfit of the outcome, not a run's
own scatter, and carried to a calm rig it made the bands absurd (on the twin data of another
truth, E1's rotation band 0.02-0.63 rad for runs of 0.01-0.05 rad). The MAD's variance is the
scatter within the outcome most runs share, which is what a specimen and the measurement add
(docs/research/predict-coverage.md).

**Band for a real run.** Each predicted run value v_i is joined by D seeded draws
v_i + s z_ik (transit time: v_i (1 + s z_ik)), z ~ N(0, 1), and the 5th and 95th
percentiles are taken over all draws; for the rotation, an absolute angle, |v_i + s z_ik|.
s = s_q, or sqrt(s_q^2 + s_num^2) where the model's numerical error at the design s_num is
known (`parcelfit.study.numerical_error`): the two are independent.
Hand-written because it is a few lines of NumPy over the stored runs, not a model a library
fits.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.stats import median_abs_deviation

from parcelfit.runs import Run, TestCase, Trajectory, load_dataset, read_trajectory
from parcelfit.sim.ensemble import rotation
from parcelfit.study.store import STORE_FILE, Evaluation, Store
from parcelfit.study.studyfile import Study

QUANTITIES = ("transit_time", "rotation", "exit_x", "exit_y", "exit_heading")
RELATIVE = frozenset({"transit_time"})  # scatter as a share of the value
DRAWS = 200  # draws per predicted run for the band of a real run


@dataclass(frozen=True)
class RunScatter:
    """The real runs' scatter beyond the model's, per quantity: ``sd`` (SI, or a share of the
    value for the transit time; 0 when the model's placements already hold the real spread,
    absent when no fitted case has two real runs with the quantity), the cases it was estimated
    from and the simulations per case of the recommended evaluation."""

    sd: Mapping[str, float]
    cases: tuple[str, ...]
    simulations: int

    def to_json(self) -> dict[str, object]:
        """The stored form (prediction.json)."""
        return {"sd": dict(self.sd), "cases": list(self.cases), "simulations": self.simulations}


def quantities(tr: Trajectory, transit_time: float | None) -> dict[str, float | None]:
    """The quantities of one run (SI): transit time [s], rotation [rad], exit x, y [m] and
    heading [rad] (the unwrapped heading at the run's last sample)."""
    theta = np.unwrap(np.asarray(tr.theta, float))
    return {
        "transit_time": None if transit_time is None else float(transit_time),
        "rotation": rotation(tr),
        "exit_x": float(np.asarray(tr.x, float)[-1]),
        "exit_y": float(np.asarray(tr.y, float)[-1]),
        "exit_heading": float(theta[-1]),
    }


def robust_variance(values: np.ndarray) -> float:
    """(1.4826 MAD)^2 of ``values`` (their unit squared): the variance for normal scatter, the
    majority's own where the values split between outcomes."""
    return float(median_abs_deviation(values, scale="normal")) ** 2


def variance_difference(
    real: Sequence[float], model: Sequence[float], relative: bool = False
) -> float | None:
    """D = V_real - V_model (module docstring: robust variances) of one quantity of one case,
    negative where the model scatters more; relative: both divided by the square of the real
    runs' mean. None with fewer than two real values."""
    r = np.asarray([v for v in real if v is not None and math.isfinite(v)], float)
    m = np.asarray([v for v in model if v is not None and math.isfinite(v)], float)
    if r.size < 2:
        return None
    v_real = robust_variance(r)
    v_model = robust_variance(m) if m.size >= 2 else 0.0
    difference = v_real - v_model
    if relative:
        mean = float(r.mean())
        return difference / mean**2 if mean != 0 else None
    return difference


def recommended_evaluation(store: Store) -> Evaluation | None:
    """The fit evaluation of the recommended parameters (the lowest-cost ok one without a
    recommendation, or when none matches)."""
    fits = [e for e in store.evaluations("fit") if e.status == "ok" and e.cost is not None]
    if not fits:
        return None
    rec = store.read_recommended()
    if rec is not None:
        for e in fits:
            if all(
                k in e.params and math.isclose(e.params[k], v, rel_tol=1e-9, abs_tol=1e-12)
                for k, v in rec.params.items()
            ):
                return e
    return min(fits, key=lambda e: e.cost)  # type: ignore[arg-type, return-value]


def stored_recommendation(folder: Path) -> Evaluation | None:
    """`recommended_evaluation` of the study store in ``folder`` (opened read-only)."""
    store = Store(folder / STORE_FILE, readonly=True)
    try:
        return recommended_evaluation(store)
    finally:
        store.close()


def _model_values(folder: Path, evaluation: Evaluation, case: TestCase) -> list[dict]:
    """The quantities of each simulation of ``case`` in ``evaluation`` (read from its run
    files in the study folder)."""
    out = []
    parts = evaluation.details.cases
    if parts:
        for part in parts:
            if part.case != case.label:
                continue
            for f, t in zip(part.run_files, part.transit_times, strict=False):
                if f and (folder / f).is_file():
                    out.append(quantities(read_trajectory(folder / f), t))
    elif evaluation.run_file and (folder / evaluation.run_file).is_file():
        out.append(
            quantities(read_trajectory(folder / evaluation.run_file), evaluation.transit_time)
        )
    return out


def estimate_run_scatter(
    folder: Path,
    study: Study,
    model: Mapping[str, Sequence[Mapping[str, float | None]]] | None = None,
) -> RunScatter | None:
    """The real runs' scatter beyond the model's (module docstring) from the finished
    calibration in ``folder`` and its ``study``: against ``model`` (case label -> the
    quantities of the model's runs of that case at the recommended parameters) where given,
    else against the recommended evaluation's own simulations of the fitted cases; None when
    the store has no ok fit."""
    evaluation = stored_recommendation(folder)
    if evaluation is None:
        return None
    datasets: dict[Path, object] = {}
    pooled: dict[str, list[float]] = {q: [] for q in QUANTITIES}
    used: list[str] = []
    sims = 0
    specs = study.cases
    if model is not None:
        specs = tuple({s.label: s for s in (*study.cases, *study.validation_cases)}.values())
        specs = tuple(s for s in specs if s.label in model)
    for spec in specs:
        if spec.dataset not in datasets:
            datasets[spec.dataset] = load_dataset(spec.dataset)
        runs: Sequence[Run] = datasets[spec.dataset][spec.case].runs  # type: ignore[index]
        real = [quantities(r.trajectory, r.transit_time) for r in runs]
        if model is None:
            values: Sequence[Mapping[str, float | None]] = _model_values(
                folder, evaluation, spec.case
            )
        else:
            values = model[spec.label]
        sims = max(sims, len(values))
        any_used = False
        for q in QUANTITIES:
            e = variance_difference(
                [v[q] for v in real], [v.get(q) for v in values], relative=q in RELATIVE
            )
            if e is not None:
                pooled[q].append(e)
                any_used = True
        if any_used:
            used.append(spec.label)
    sd = {q: math.sqrt(max(0.0, float(np.mean(v)))) for q, v in pooled.items() if v}
    return RunScatter(sd, tuple(used), sims)


def scatter_note(scatter: RunScatter | None) -> str | None:
    """A warning for the prediction's notes when ``scatter`` came from one simulation per case
    (module docstring): it then holds the fitted cases' placement scatter too."""
    if scatter is None or scatter.simulations >= 2 or not scatter.sd:
        return None
    return (
        "the band of a real run takes the real runs' scatter against one simulation per "
        "fitted case (the simulator takes no placements), so it holds the fitted cases' "
        "placement scatter too; on another rig that can be far wider than the rig's own (on "
        "the twin data, E3's spins and slides made the bands of calm E1 runs hold 100 % of "
        "transit times but the rotation's band miss them: docs/research/predict-coverage.md)"
    )


def real_run_band(
    values: Sequence[float],
    quantity: str,
    scatter: RunScatter | None,
    seed: int,
    numerical: Mapping[str, float] | None = None,
) -> tuple[float, float]:
    """The 5-95 % band of a real run (module docstring) around the predicted run values of
    ``quantity`` (SI); with ``numerical`` (the model's numerical error per quantity,
    `parcelfit.study.numerical_error`) the two sd combine as s^2 = s_q^2 + s_num^2; the model's
    own band when neither is known for it."""
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], float)
    if v.size == 0:
        return math.nan, math.nan
    s_q = None if scatter is None else scatter.sd.get(quantity)
    s_num = None if numerical is None else numerical.get(quantity)
    s = math.sqrt((s_q or 0.0) ** 2 + (s_num or 0.0) ** 2)
    if not s:
        return float(np.percentile(v, 5)), float(np.percentile(v, 95))
    z = np.random.default_rng([seed, 0x5C, QUANTITIES.index(quantity)]).standard_normal(
        (v.size, DRAWS)
    )
    draws = v[:, None] * (1 + s * z) if quantity in RELATIVE else v[:, None] + s * z
    if quantity == "rotation":
        draws = np.abs(draws)
    return float(np.percentile(draws, 5)), float(np.percentile(draws, 95))
