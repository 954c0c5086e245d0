"""Figures made for the report only (the others come from the stages' own modules), drawn from
the stored results (`parcelfit.study.results`), never from a new analysis.

* ``distance_heatmaps``: a test case's DTW distance matrices (section 4), the reference run
  outlined;
* ``validation_transit``: the real runs' transit times as a box plot, the simulated run marked,
  the published tolerance interval [min, max] dashed (section 8, criterion 1);
* ``validation_mean_dtw``: each real run's mean squared DTW distance to the other real runs as a
  box plot, the simulated run's mean to the real runs marked (criteria 2 and 3);
* ``validation_overlays``: lateral position y over x and heading theta over x of the real runs
  (grey) and the simulated run (colour) on the prepared trajectories the criteria use, with the
  stricter criterion's band shaded (like the published Figures 16-19);
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from parcelfit.metrics import Validation
from parcelfit.study.results import BandRecord, ReferenceRecord

SIM_COLOUR = "#d35400"
REAL_COLOUR = "#9aa0a6"


def _short(run_ids: Sequence[str]) -> list[str]:
    """Run ids without their common prefix (E3-KPBW-1-07 -> 07)."""
    prefix = ""
    if len(run_ids) > 1:
        first = run_ids[0]
        n = 0
        while n < len(first) and all(r[: n + 1] == first[: n + 1] for r in run_ids):
            n += 1
        prefix = first[:n]
    return [r[len(prefix) :] or r for r in run_ids]


def distance_heatmaps(sel: ReferenceRecord) -> Figure:
    """Heat maps of a test case's distance matrices; the reference run's row and column outlined."""
    panels: list[tuple[str, np.ndarray]] = [
        ("DTW$_{xy}$ [m$^2$]", sel.d_xy),
        (r"DTW$_\theta$ [rad$^2$]", sel.d_theta),
    ]
    if sel.uses_time:
        panels.append(("transit-time difference$^2$ [s$^2$]", sel.d_time))
    panels.append(("combined (normalised sum)", sel.d_combined))
    fig = Figure(figsize=(3.3 * len(panels), 3.3), layout="constrained")
    axes = fig.subplots(1, len(panels))
    labels = _short(list(sel.run_ids))
    n = len(labels)
    for ax, (title, m) in zip(axes, panels, strict=True):
        im = ax.imshow(m, cmap="viridis")
        ax.set_title(title, fontsize=9)
        ax.set_xticks(range(n), labels, fontsize=6, rotation=90)
        ax.set_yticks(range(n), labels, fontsize=6)
        i = sel.index
        for rect in ((i - 0.5, -0.5, 1, n), (-0.5, i - 0.5, n, 1)):
            ax.add_patch(
                Rectangle(rect[:2], rect[2], rect[3], fill=False, edgecolor="#e74c3c", lw=1.2)
            )
        fig.colorbar(im, ax=ax, shrink=0.75)
    fig.suptitle(
        f"{sel.case}: reference run {sel.reference_id} (red: its row and column)", fontsize=10
    )
    return fig


def validation_transit(
    transit_times: Sequence[float | None], verdict: Validation, label: str
) -> Figure:
    """Box plot of the real transit times [s] with the simulated one and the tolerance interval."""
    real = [t for t in transit_times if t is not None]
    fig = Figure(figsize=(3.2, 3.6), layout="constrained")
    ax = fig.subplots()
    ax.boxplot([real], tick_labels=["real runs"], widths=0.5)
    ax.scatter(np.ones(len(real)), real, s=10, color=REAL_COLOUR, zorder=3)
    tt = verdict.transit_time
    for v in (tt.low, tt.high):
        ax.axhline(v, color="k", ls="--", lw=0.8)
    if tt.simulated is not None:
        ax.scatter([1], [tt.simulated], marker="D", s=50, color=SIM_COLOUR, zorder=4, label=label)
        ax.legend(fontsize=7, loc="lower right")
    ax.set_ylabel("transit time [s]")
    ax.set_title(f"transit time: {'pass' if tt.passed else 'fail'}", fontsize=9)
    return fig


def validation_mean_dtw(verdict: Validation, label: str) -> Figure:
    """Box plots of the real runs' mean DTW distances with the simulated run's mean marked."""
    fig = Figure(figsize=(5.6, 3.6), layout="constrained")
    axes = fig.subplots(1, 2)
    for ax, check, unit in ((axes[0], verdict.xy, "m$^2$"), (axes[1], verdict.theta, "rad$^2$")):
        real = np.asarray(check.real_means)
        ax.boxplot([real], tick_labels=["real runs"], widths=0.5)
        ax.scatter(np.ones(len(real)), real, s=10, color=REAL_COLOUR, zorder=3)
        ax.axhline(check.largest_real_mean, color="k", ls="--", lw=0.8)
        ax.scatter(
            [1], [check.simulated_mean], marker="D", s=50, color=SIM_COLOUR, zorder=4, label=label
        )
        name = "xy" if check.quantity == "xy" else r"\theta"
        ax.set_ylabel(f"mean DTW$_{{{name}}}$ [{unit}]")
        ax.set_title(f"{check.quantity}: {'pass' if check.passed else 'fail'}", fontsize=9)
        ax.legend(fontsize=7, loc="lower right")
    return fig


def validation_overlays(
    sel: ReferenceRecord, sim_xy: np.ndarray, sim_theta: np.ndarray, band: BandRecord | None
) -> Figure:
    """y over x and heading over x: real runs grey, simulation coloured, the band shaded."""
    fig = Figure(figsize=(10, 3.8), layout="constrained")
    ax_y, ax_t = fig.subplots(1, 2)
    for k, (xy, th) in enumerate(zip(sel.xy_series, sel.theta_series, strict=True)):
        lab = "real runs" if k == 0 else None
        ax_y.plot(xy[:, 0], xy[:, 1] * 1e3, color=REAL_COLOUR, lw=0.9, label=lab)
        ax_t.plot(xy[:, 0], np.degrees(th), color=REAL_COLOUR, lw=0.9, label=lab)
    if band is not None:
        ax_y.fill_between(
            band.grid,
            band.y_low * 1e3,
            band.y_high * 1e3,
            color="#3498db",
            alpha=0.15,
            label="band (stricter criterion)",
        )
        ax_t.fill_between(
            band.grid,
            np.degrees(band.theta_low),
            np.degrees(band.theta_high),
            color="#3498db",
            alpha=0.15,
            label="band (stricter criterion)",
        )
    ax_y.plot(sim_xy[:, 0], sim_xy[:, 1] * 1e3, color=SIM_COLOUR, lw=1.8, label="simulation")
    ax_t.plot(sim_xy[:, 0], np.degrees(sim_theta), color=SIM_COLOUR, lw=1.8, label="simulation")
    ax_y.set_xlabel("x relative to the start [m]")
    ax_y.set_ylabel("y relative to the start [mm]")
    ax_t.set_xlabel("x relative to the start [m]")
    ax_t.set_ylabel("heading relative to the start [deg]")
    ax_y.set_title("path (lateral position over travel)", fontsize=9)
    ax_t.set_title("heading over travel", fontsize=9)
    ax_y.legend(fontsize=7)
    return fig
