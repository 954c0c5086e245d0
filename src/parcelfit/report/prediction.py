"""The HTML page of a prediction (`parcelfit.study.predict`): ``prediction.html`` in its output
folder, one self-contained file like the study report (`parcelfit.report.html`: the same
Jinja2 environment with autoescaping, style sheet and Content-Security-Policy; the figure
embedded as PNG data).

It shows the design and the study, the predictive distribution of each quantity (median, 5-95 %
band, histogram of the runs), the share of the spread due to the parameters versus the
placements, how far each parameter moves each prediction, and the sentences naming what the
undetermined parameters move. It renders the prediction it is given and computes nothing of
its own.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from markupsafe import Markup
from matplotlib.figure import Figure
from rich.markup import escape
from rich.table import Table

from parcelfit import __version__
from parcelfit.report.page import CONTENT_SECURITY_POLICY, CSS, TEMPLATES, write_page
from parcelfit.report.page import figure_html as _figure_html
from parcelfit.study.design import DesignResult
from parcelfit.study.numerical_error import NumericalError
from parcelfit.study.predict import (
    QUANTITIES,
    Prediction,
    quantity_words,
    shown_value,
)
from parcelfit.study.run_scatter import RELATIVE

PAGE_FILE = "prediction.html"


def _share(value: float) -> str:
    return "-" if not math.isfinite(value) else f"{value * 100:.0f} %"


def _histograms(prediction: Prediction) -> Figure:
    """One histogram per quantity over the runs, with the median and the 5-95 % band."""
    fig = Figure(figsize=(10, 6), layout="constrained")
    axes = fig.subplots(2, 2).ravel()
    by = {s.quantity: s for s in prediction.summaries}
    for ax, q in zip(axes, QUANTITIES, strict=True):
        values = prediction.runs[q].to_numpy(float)
        values = values[np.isfinite(values)]
        s = by[q]
        ax.set_title(quantity_words(q))
        if not values.size:
            ax.text(0.5, 0.5, "no run has this quantity", ha="center", transform=ax.transAxes)
            continue
        factor = {"transit_time": 1e3, "exit_y": 1e3}.get(q, 180 / math.pi)
        unit = {"transit_time": "ms", "exit_y": "mm"}.get(q, "deg")
        ax.hist(values * factor, bins=min(40, max(5, values.size // 5)), color="tab:blue")
        for v, style in ((s.median, "-"), (s.q05, "--"), (s.q95, "--")):
            ax.axvline(v * factor, color="k", linestyle=style, linewidth=1)
        for v in (s.run_q05, s.run_q95):  # the band of a real run
            if math.isfinite(v):
                ax.axvline(v * factor, color="tab:red", linestyle=":", linewidth=1)
        ax.set_xlabel(f"{quantity_words(q)} [{unit}]")
        ax.set_ylabel("runs")
    return fig


def prediction_view(prediction: Prediction) -> dict[str, Any]:
    """The values the page shows (text, escaped by the template)."""
    rows = []
    numerical = prediction.numerical
    for s in prediction.summaries:
        d = s.decomposition
        sd = None if numerical is None else numerical.sd.get(s.quantity)
        if sd is not None and s.quantity in RELATIVE:  # a share of the value: in its unit here
            sd = sd * abs(s.median) if math.isfinite(s.median) else None
        rows.append(
            {
                "quantity": quantity_words(s.quantity),
                "runs": s.runs,
                "median": shown_value(s.quantity, s.median),
                "band": f"{shown_value(s.quantity, s.q05)} to {shown_value(s.quantity, s.q95)}",
                "run_band": "-"
                if not math.isfinite(s.run_q05)
                else f"{shown_value(s.quantity, s.run_q05)} to {shown_value(s.quantity, s.run_q95)}",
                "parameters": _share(d.parameter_share),
                "placements": _share(d.placement_share),
                "numerical": "-" if sd is None else shown_value(s.quantity, sd, 2),
            }
        )
    effects = []
    for e in prediction.effects:
        effects.append(
            {
                "parameter": e.parameter,
                "verdict": e.verdict,
                "quantity": quantity_words(e.quantity),
                "effect": "-"
                if not math.isfinite(e.effect)
                else f"{shown_value(e.quantity, e.effect)} +- {shown_value(e.quantity, e.se, 2)}",
                "resolved": e.resolved,
                "threshold": "-" if not math.isfinite(e.threshold) else f"{e.threshold:.1f}",
            }
        )
    scatter = prediction.scatter
    return {
        "summary": rows,
        "effects": effects,
        "scatter": "not estimated, the calibration holding no fitted run to estimate it from"
        if scatter is None or not scatter.sd
        else f"estimated from the real runs of {', '.join(scatter.cases)} beyond the spread of "
        f"{scatter.simulations} simulation(s) per case at the recommended parameters",
        "numerical": _numerical_words(numerical),
    }


def _numerical_words(numerical: NumericalError | None) -> str:
    """How the model's numerical error was estimated, or why it was not (one clause)."""
    if numerical is None or numerical.reason is not None:
        why = "" if numerical is None else f" ({numerical.reason})"
        return f"not estimated{why}: the band of a real run holds no error of the mesh or step"
    at = "recommended parameters" if numerical.at == "recommended" else "plausible set's medians"
    return (
        f"estimated from {numerical.pairs} placement(s) of the {at} on this design, simulated "
        f"by the model and by the model refined {numerical.refinement} times over (every mesh "
        f"spacing and the time step divided), the differences times {numerical.refinement} / "
        f"{numerical.refinement - 1}: the model's whole error if it is of first order"
    )


def terminal_table(prediction: Prediction) -> Table:
    """The terminal summary of a prediction (Rich): one row per quantity."""
    view = prediction_view(prediction)
    d = prediction.design
    table = Table(
        title=f"{d.label}: {len(prediction.sets)} plausible parameter "
        f"set{'s' if len(prediction.sets) != 1 else ''} x {len(prediction.seeds)} "
        f"placement{'s' if len(prediction.seeds) != 1 else ''}",
        title_justify="left",
    )
    for col in (
        "quantity",
        "runs",
        "median",
        "5-95 % band",
        "band of a real run",
        "numerical error (sd)",
        "from parameters",
        "from placements",
    ):
        # narrow terminals and logs fold a header or cell, they never cut it off
        table.add_column(
            escape(col), justify="left" if col == "quantity" else "right", overflow="fold"
        )
    for r in view["summary"]:
        table.add_row(
            r["quantity"],
            str(r["runs"]),
            r["median"],
            r["band"],
            r["run_band"],
            r["numerical"],
            r["parameters"],
            r["placements"],
        )
    return table


def design_tables(result: DesignResult, top: int = 5) -> list[Table]:
    """The terminal summary of an experiment design (Rich): per open parameter its ``top``
    candidates, then the overall ranking's ``top``."""
    tables = []
    cands = result.candidates_table()
    for p in result.parameters:
        mine = cands[cands["parameter"] == p].head(top)
        if not len(mine):
            continue
        first = mine.iloc[0]
        t = Table(
            title=f"{p} ({first['verdict']}): the experiments that narrow it most after "
            f"{result.runs} real runs",
            title_justify="left",
        )
        for col in ("rank", "candidate", "signal/noise", "via", "interval left", "runs needed"):
            # a candidate's name ends in its speed setting: never cut it off
            t.add_column(
                escape(col),
                justify="left" if col in ("candidate", "via") else "right",
                no_wrap=col == "candidate",
                overflow="fold",
            )
        for r in mine.itertuples(index=False):
            t.add_row(
                str(r.rank),
                r.candidate,
                f"{r.snr:.1f}",
                "-" if pd.isna(r.quantity) else quantity_words(r.quantity),
                f"{r.expected_share * 100:.0f} %",
                "-" if pd.isna(r.runs_needed) else str(int(r.runs_needed)),
            )
        tables.append(t)
    ranking = result.ranking_table().head(top)
    t = Table(
        title="Overall: mean interval left over the open parameters; each candidate chosen "
        "given the ones above",
        title_justify="left",
    )
    cols = ("rank", "candidate", "interval left", "with the ones above", "narrows most")
    for col in (*cols, "determines"):
        t.add_column(
            escape(col),
            justify="right" if col in ("rank", "interval left", "with the ones above") else "left",
            no_wrap=col == "candidate",
        )
    for r in ranking.itertuples(index=False):
        t.add_row(
            str(r.rank),
            r.candidate,
            f"{r.mean_share * 100:.0f} %",
            f"{r.with_above * 100:.0f} %",
            "-" if pd.isna(r.narrows_most) else str(r.narrows_most),
            str(r.determines) or "-",
        )
    tables.append(t)
    return tables


def write_prediction_page(prediction: Prediction, path: str | Path) -> Path:
    """Write the prediction's HTML page to ``path``; returns it."""
    target = Path(path)
    fig = _histograms(prediction)
    d = prediction.design
    doc = TEMPLATES.get_template("prediction.html.j2").render(
        csp=CONTENT_SECURITY_POLICY,
        css=Markup(CSS),
        title=f"parcelfit prediction: {d.label}",
        version=__version__,
        generated=time.strftime("%Y-%m-%d %H:%M"),
        study=prediction.study,
        design=d.label,
        sets=len(prediction.sets),
        placements=len(prediction.seeds),
        runs=len(prediction.runs),
        view=prediction_view(prediction),
        sentences=prediction.sentences,
        notes=prediction.notes,
        figure=_figure_html(fig, "predictive distributions"),
    )
    write_page(target, doc)
    return target


__all__ = [
    "PAGE_FILE",
    "design_tables",
    "prediction_view",
    "terminal_table",
    "write_prediction_page",
]
