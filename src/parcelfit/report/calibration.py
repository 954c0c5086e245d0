"""The report's calibration section: the history of the evaluations, the calibrated parameters
in catalogue units with their ranges (and, for synthetic data, the hidden truth), what the
evaluations determine about each (`parcelfit.study.identify`, as stored), the surrogate's
partial dependence and the parameter traces."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from parcelfit.report.page import NOT_STORED, Page, figure_html
from parcelfit.sim.params import catalogue_unit, to_catalogue_units
from parcelfit.study.identify import VERDICTS, Identifiability
from parcelfit.study.results import StudyResults
from parcelfit.study.status import study_status
from parcelfit.study.store import STORE_FILE, Store, StudyRecord

RECOVERY_TOLERANCE = 0.10  # of the range's width
BOUNDED = ("lower bound", "upper bound", "narrowed")


@dataclass(frozen=True)
class ParameterRow:
    """One calibrated parameter in catalogue units: its range, the optimiser's recommended
    value, the hidden truth (synthetic data) and what the evaluations determine about it
    (`parcelfit.study.identify`: the interval, the verdict and, for a determined parameter,
    the reported value; None where no analysis is stored)."""

    name: str
    unit: str
    low: float
    high: float
    best: float
    truth: float | None
    interval: tuple[float, float] | None = None
    verdict: str | None = None
    estimate: float | None = None  # the reported value: determined parameters only

    @property
    def determined(self) -> bool | None:
        """Do the data fix this parameter (None: no analysis stored)?"""
        return None if self.verdict is None else self.verdict == "determined"

    @property
    def error_share(self) -> float | None:
        """|calibrated - truth| as a share of the range's width."""
        if self.truth is None:
            return None
        return abs(self.best - self.truth) / (self.high - self.low)

    @property
    def recovered(self) -> bool | None:
        """Is the calibrated value within ``RECOVERY_TOLERANCE`` of the range from the truth?"""
        err = self.error_share
        return None if err is None else err <= RECOVERY_TOLERANCE

    @property
    def covers_truth(self) -> bool | None:
        """Does the interval contain the hidden truth (None without both)?"""
        if self.truth is None or self.interval is None:
            return None
        return self.interval[0] <= self.truth <= self.interval[1]

    @property
    def bound_text(self) -> str:
        """The verdict in words with its numbers, e.g. ``at least 0.41``."""
        if self.interval is None or self.verdict is None:
            return "-"
        a, b = self.interval
        if self.verdict == "determined":
            return f"{(a + b) / 2 if self.estimate is None else self.estimate:.4g} +- {(b - a) / 2:.2g}"
        return {
            "lower bound": f"at least {a:.4g}",
            "upper bound": f"at most {b:.4g}",
            "narrowed": f"between {a:.4g} and {b:.4g}",
            "undetermined": "no value: the data cannot tell",
        }.get(self.verdict, "-")


def parameter_rows(
    record: StudyRecord,
    best: dict[str, float],
    truth: dict[str, float],
    ident: Identifiability | None,
) -> list[ParameterRow]:
    """The calibrated parameters' table rows (catalogue units), with the stored identifiability
    analysis ``ident`` (None: not stored)."""
    by_name = {p.name: p for p in ident.parameters} if ident is not None else {}
    rows = []
    for name, (lo, hi) in zip(record.parameters, record.bounds, strict=True):
        p = by_name.get(name)

        def cat(v: float, name: str = name) -> float:
            return float(to_catalogue_units(name, v))

        rows.append(
            ParameterRow(
                name,
                catalogue_unit(name),
                cat(lo),
                cat(hi),
                cat(best[name]),
                truth.get(name),
                None if p is None else (cat(p.interval[0]), cat(p.interval[1])),
                None if p is None else p.verdict,
                None if p is None or p.estimate is None else cat(p.estimate),
            )
        )
    return rows


def _iteration_span(last: int) -> str:
    """Iterations 1 to ``last`` (0 is the initial design, numbered as everywhere else)."""
    return "iteration 1" if last == 1 else f"iterations 1-{last}"


def _surrogate_note(results: StudyResults | None) -> dict[str, Any]:
    """What the template says about the surrogate the identifiability test read."""
    if results is None:
        return {"missing": NOT_STORED}
    sur = results.surrogate
    if sur is None:
        return {"missing": "The stored results hold no surrogate (no study record)."}
    opt = sur.optimizer
    settings = ", ".join(
        f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
        for k, v in (opt.settings or {}).items()
    )
    return {
        "missing": None,
        "evaluations": sur.evaluations,
        "sampler": opt.sampler,
        "settings": settings,
        "note": opt.note,
        "fitted": sur.curves is not None,
    }


def _identifiability_view(
    results: StudyResults | None,
    rows: list[ParameterRow],
    truth: dict[str, float],
    synthetic: bool,
) -> dict[str, Any]:
    """What the template says about what the evaluations determine (`parcelfit.study.identify`),
    with the pairwise figure and the advice."""
    from parcelfit.study.plots import pairwise_figure

    ident = None if results is None else results.identifiability
    if results is None:
        return {"missing": NOT_STORED}
    if ident is None:
        return {
            "missing": "The stored results hold no identifiability analysis (fewer than three "
            "successful evaluations, or results written by an earlier parcelfit: rerun "
            "`parcelfit calibrate` on the study to write it without simulating again)."
        }
    by = {v: [r for r in rows if r.verdict == v] for v in VERDICTS}
    advice = results.advice
    return {
        "missing": None,
        "determined": ", ".join(r.name for r in by["determined"]),
        "bounded": [(r.name, r.bound_text) for r in rows if r.verdict in BOUNDED],
        "undetermined": ", ".join(r.name for r in by["undetermined"]),
        "evaluations": ident.evaluations,
        "threshold": ident.threshold,
        "threshold_source": ident.threshold_source,
        "noise_sd": ident.noise_sd,
        "level": f"{ident.level * 100:.0f}",
        "reached": ident.reached,
        "supported": ident.supported,
        "best_acceptance": ident.best_acceptance,
        "converged": ident.converged,
        "correlations": [(a, b, f"{r:+.2f}") for a, b, r in ident.strongest_correlations()],
        "missed": ", ".join(r.name for r in rows if synthetic and r.covers_truth is False),
        "figure": figure_html(
            pairwise_figure(ident, _truth_si(truth) if synthetic else None),
            "pairwise plot of the values not excluded",
        ),
        "advice": None
        if advice is None
        else {
            "best": advice.best,
            "rows": [
                (case, ", ".join(f"{p} {v:.3g}" for p, v in ch.items()) or "-", sum(ch.values()))
                for case, ch in advice.changes.items()
            ],
            "parameters": ", ".join(advice.parameters),
        },
    }


def _truth_si(truth: dict[str, float]) -> dict[str, float]:
    """The hidden truth (catalogue units, as truth.yaml holds it) in SI."""
    from parcelfit.sim.params import CATALOGUE

    units = {p.name: p for p in CATALOGUE}
    return {n: units[n].to_si(v) if n in units else v for n, v in truth.items()}


def calibration_section(
    page: Page,
    folder: Path,
    record: StudyRecord,
    results: StudyResults | None,
    truth: dict[str, float],
    synthetic: bool,
) -> tuple[dict[str, float] | None, list[ParameterRow]]:
    from parcelfit.study.plots import dependence_figure, history, traces

    title = page.start("Calibration")
    status = study_status(folder)
    store = Store(folder / STORE_FILE, readonly=True)
    try:
        fits, vals = store.evaluations("fit"), store.evaluations("validation")
    finally:
        store.close()
    done = [e for e in fits if e.finished_at is not None]
    last = status.last_iteration
    data: dict[str, Any] = {
        "evaluations": status.evaluations,
        "iterations": _iteration_span(last) if last else None,
        "batch_size": record.batch_size,
        "validations": len(vals),
        "span_min": (
            max(e.finished_at for e in done) - min(e.asked_at for e in fits)  # type: ignore[type-var]
            if done
            else 0.0
        )
        / 60,
        "sim_min": sum(e.wall_time or 0.0 for e in fits + vals) / 60,
        "stopped": status.stop_reason or "not finished",
        "history": figure_html(history(fits, vals), "cost history"),
        "best": None,
    }
    low, rec = status.lowest_cost, status.recommended
    if low is None:
        page.add("calibration", title, "calibration", data)
        return None, []
    best = low.to_json()
    if rec is not None:  # what the study validated
        best = {**rec.to_json(), "lowest_cost": low.cost}
    curves = None
    if results is not None and results.surrogate is not None:
        curves = results.surrogate.curves
    ident = None if results is None else results.identifiability
    rows = parameter_rows(record, best["params"], truth, ident)
    data.update(
        best=best,
        truth=bool(truth),
        rows=rows,
        surrogate=_surrogate_note(results),
        identifiability=_identifiability_view(results, rows, truth, synthetic),
        cases=[] if results is None else list(results.cases),
        parts=None if rec is None else rec.parts,
        dependence=None
        if not curves
        else figure_html(dependence_figure(list(curves)), "partial dependence"),
        traces=figure_html(traces(fits, list(record.parameters)), "parameter traces"),
    )
    page.add("calibration", title, "calibration", data)
    return best["params"], rows


__all__ = [
    "BOUNDED",
    "RECOVERY_TOLERANCE",
    "ParameterRow",
    "calibration_section",
    "parameter_rows",
]
