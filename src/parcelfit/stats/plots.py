"""Box plots of transit times per rig and speed setting, with significance brackets."""

from __future__ import annotations

import pandas as pd
from matplotlib.figure import Figure

from parcelfit.stats.transit import significance_stars


def transit_time_boxplots(
    times: pd.DataFrame, comparisons: pd.DataFrame, title: str = "Transit times"
) -> Figure:
    """One panel per rig and speed setting: transit times [s] per consignment type, brackets
    over the pairs whose Benjamini-Hochberg adjusted p-value is significant."""
    panels = sorted(
        {(r, int(s)) for r, s in zip(times["rig"], times["speed_setting"], strict=True)}
    )
    ncols = min(3, max(1, len(panels)))
    nrows = (len(panels) + ncols - 1) // ncols
    fig = Figure(figsize=(4.2 * ncols, 3.6 * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax, (rig, setting) in zip(axes, panels, strict=False):
        sub = times[(times["rig"] == rig) & (times["speed_setting"] == setting)]
        types = sorted(sub["consignment"].unique())
        data = [sub.loc[sub["consignment"] == t, "transit_time_s"].to_numpy() for t in types]
        ax.boxplot(data, tick_labels=types, widths=0.6)
        ax.set_title(f"{rig}, speed setting {setting}")
        ax.set_ylabel("transit time [s]")
        top = max(float(d.max()) for d in data)
        span = max(top - min(float(d.min()) for d in data), 1e-3)
        level = top + 0.08 * span
        comp = comparisons[(comparisons["rig"] == rig) & (comparisons["speed_setting"] == setting)]
        for _, row in comp[comp["significant"]].iterrows():
            i, j = types.index(row["type_a"]) + 1, types.index(row["type_b"]) + 1
            ax.plot(
                [i, i, j, j],
                [level, level + 0.03 * span, level + 0.03 * span, level],
                color="k",
                lw=0.8,
            )
            ax.text(
                (i + j) / 2,
                level + 0.035 * span,
                significance_stars(row["p_adjusted"]),
                ha="center",
                va="bottom",
            )
            level += 0.12 * span
        ax.set_ylim(top=level + 0.05 * span)
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    fig.suptitle(f"{title} (brackets: Mann-Whitney U, Benjamini-Hochberg adjusted)")
    return fig
