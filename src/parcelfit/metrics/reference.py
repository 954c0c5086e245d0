"""Choosing the reference run of a test case (method.md section 4).

For the n runs of a test case, with transit times T_i, prepared centre trajectories X_i [m] and
headings theta_i [rad] (see `parcelfit.metrics.comparison`):

    D_time(i, j)  = (T_i - T_j)^2                      [s^2]
    D_xy(i, j)    = DTW(X_i, X_j)^2                    [m^2]
    D_theta(i, j) = DTW(theta_i, theta_j)^2            [rad^2]
    D_combined    = D_time / max D_time + D_xy / max D_xy + D_theta / max D_theta
    i*            = argmin_i sum_j D_combined(i, j)

A matrix whose largest entry is zero (all runs alike) contributes zero. If any run lacks a
transit time, D_time is left out (and ``uses_time`` is False). The largest entries are kept:
they normalise the calibration cost (equation 3).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.metrics.comparison import Comparison
from parcelfit.metrics.dtw import pairwise_dtw
from parcelfit.metrics.transit_adjustment import TransitAdjustment, fit_transit_adjustment
from parcelfit.runs import CaseData, Run, TestCase


def normalise(matrix: np.ndarray) -> tuple[np.ndarray, float]:
    """Divide a non-negative matrix by its largest entry; returns (normalised, largest)."""
    largest = float(np.max(matrix)) if matrix.size else 0.0
    if largest <= 0:
        return np.zeros_like(matrix, dtype=float), largest
    return matrix / largest, largest


@dataclass(frozen=True, eq=False)
class ReferenceSelection:
    """The reference run of a test case, the matrices behind the choice and their scales."""

    case: TestCase
    run_ids: tuple[str, ...]
    index: int
    d_time: np.ndarray
    d_xy: np.ndarray
    d_theta: np.ndarray
    d_combined: np.ndarray
    row_sums: np.ndarray
    max_time: float
    max_xy: float
    max_theta: float
    uses_time: bool
    comparison: Comparison
    transit_times: tuple[float | None, ...]
    xy_series: list[np.ndarray] = field(repr=False)
    theta_series: list[np.ndarray] = field(repr=False)
    # set when ``transit_times`` are adjusted for the belt speeds each run rode at
    # (`adjusted_reference`): simulated runs compared with them are adjusted alike
    transit_adjustment: TransitAdjustment | None = None

    @property
    def reference_id(self) -> str:
        """Id of the chosen reference run."""
        return self.run_ids[self.index]

    def to_dict(self) -> dict[str, object]:
        """Machine-readable summary (matrices as nested lists; units s^2, m^2, rad^2)."""
        return {
            "test_case": self.case.label,
            "reference_run": self.reference_id,
            "run_ids": list(self.run_ids),
            "row_sums": self.row_sums.tolist(),
            "max_d_time_s2": self.max_time,
            "max_d_xy_m2": self.max_xy,
            "max_d_theta_rad2": self.max_theta,
            "uses_transit_time": self.uses_time,
            "d_time_s2": self.d_time.tolist(),
            "d_xy_m2": self.d_xy.tolist(),
            "d_theta_rad2": self.d_theta.tolist(),
        }


def select_reference(
    case_data: CaseData, comparison: Comparison | None = None
) -> ReferenceSelection:
    """Choose the reference run of a test case by the row sums of D_combined (section 4)."""
    runs: tuple[Run, ...] = case_data.runs
    if not runs:
        raise ParcelfitError(f"test case {case_data.case.label} has no runs")
    comparison = comparison or Comparison.for_case(case_data)
    prepared = []
    for r in runs:  # one by one: an error names the case and the run
        try:
            prepared.append(comparison.prepare(r.trajectory))
        except ParcelfitError as exc:
            raise ParcelfitError(
                f"test case {case_data.case.label}, run {r.id}: {exc.message}", fix=exc.fix
            ) from None
    xy, theta = [p.xy for p in prepared], [p.theta for p in prepared]
    d_xy = pairwise_dtw(xy, comparison.window) ** 2
    d_theta = pairwise_dtw(theta, comparison.window) ** 2
    times = [r.transit_time for r in runs]
    uses_time = all(t is not None for t in times)
    if uses_time:
        tt = np.asarray(times, dtype=float)
        d_time = (tt[:, None] - tt[None, :]) ** 2
    else:
        d_time = np.zeros_like(d_xy)
    n_time, max_time = normalise(d_time)
    n_xy, max_xy = normalise(d_xy)
    n_theta, max_theta = normalise(d_theta)
    combined = n_time + n_xy + n_theta
    row_sums = combined.sum(axis=1)
    return ReferenceSelection(
        case=case_data.case,
        run_ids=tuple(r.id for r in runs),
        index=int(np.argmin(row_sums)),
        d_time=d_time,
        d_xy=d_xy,
        d_theta=d_theta,
        d_combined=combined,
        row_sums=row_sums,
        max_time=max_time,
        max_xy=max_xy,
        max_theta=max_theta,
        uses_time=uses_time,
        comparison=comparison,
        transit_times=tuple(times),
        xy_series=xy,
        theta_series=theta,
    )


def adjusted_reference(reference: ReferenceSelection, runs: Sequence[Run]) -> ReferenceSelection:
    """``reference`` with its transit times [s] adjusted by an adjustment fitted on ``runs``
    (the case's real runs, the ones the reference was chosen from), which it keeps in
    ``transit_adjustment`` so that simulated runs are adjusted alike. The choice of the
    reference run and its matrices stay as they were."""
    by_id = {r.id: r for r in runs}
    missing = [i for i in reference.run_ids if i not in by_id]
    if missing:
        raise ParcelfitError(
            f"runs {', '.join(missing)} of test case {reference.case.label} are not given",
            fix="adjust with the runs the reference was chosen from",
        )
    adjustment = fit_transit_adjustment([by_id[i] for i in reference.run_ids])
    times = tuple(adjustment.adjust_run(by_id[i]) for i in reference.run_ids)
    return replace(reference, transit_times=times, transit_adjustment=adjustment)
