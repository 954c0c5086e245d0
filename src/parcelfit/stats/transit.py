"""Transit-time comparisons between consignment types (method.md section 9).

For each rig and speed setting, every pair of consignment types is compared with a two-sided
Mann-Whitney U test (SciPy). Without ties the exact null distribution of U is used (cheap for
the ten runs per test case of the method, and exact where the normal approximation is rough);
with ties SciPy's exact routine would ignore them, so the tie-corrected normal approximation with
continuity correction is used instead. The table's ``method`` column says which. The p-values of one rig and
speed setting form one family and are adjusted by Benjamini-Hochberg (statsmodels
``multipletests(method="fdr_bh")``) at a false discovery rate ``alpha`` (default 5 %); pass
``family="all"`` to adjust all comparisons of the dataset together instead.
"""

from __future__ import annotations

import math
from itertools import combinations

import numpy as np
import pandas as pd
from scipy.stats import mannwhitneyu
from statsmodels.stats.multitest import multipletests

from parcelfit.errors import ParcelfitError
from parcelfit.runs import Dataset

COLUMNS = (
    "rig",
    "speed_setting",
    "type_a",
    "type_b",
    "n_a",
    "n_b",
    "median_a_s",
    "median_b_s",
    "u_statistic",
    "method",
    "p_value",
    "p_adjusted",
    "significant",
)


def transit_time_table(dataset: Dataset) -> pd.DataFrame:
    """One row per run with a transit time: rig, consignment, speed_setting, run_id, transit_time_s."""
    rows = [
        {
            "rig": r.case.rig,
            "consignment": r.case.consignment,
            "speed_setting": r.case.speed_setting,
            "run_id": r.id,
            "transit_time_s": r.transit_time,
        }
        for r in dataset.runs()
        if r.transit_time is not None
    ]
    return pd.DataFrame(
        rows, columns=["rig", "consignment", "speed_setting", "run_id", "transit_time_s"]
    )


def smallest_p_value(n_a: int, n_b: int) -> float:
    """The smallest two-sided p-value the exact Mann-Whitney U test can give with ``n_a`` and
    ``n_b`` observations (complete separation, no ties): 2 / C(n_a + n_b, n_a), at most 1."""
    if n_a < 1 or n_b < 1:
        return 1.0
    return min(1.0, 2.0 / math.comb(n_a + n_b, n_a))


def compare_transit_times(
    dataset: Dataset, alpha: float = 0.05, family: str = "rig_setting"
) -> pd.DataFrame:
    """Pairwise Mann-Whitney U tests with Benjamini-Hochberg adjustment; a tidy table (times in s)."""
    if not 0 < alpha < 1:
        raise ParcelfitError(f"alpha must lie in (0, 1), got {alpha}")
    if family not in ("rig_setting", "all"):
        raise ParcelfitError(f"unknown family {family!r}", fix="use rig_setting or all")
    times = transit_time_table(dataset)
    rows = []
    for (rig, setting), group in times.groupby(["rig", "speed_setting"], sort=True):
        by_type = {
            c: g["transit_time_s"].to_numpy() for c, g in group.groupby("consignment", sort=True)
        }
        for a, b in combinations(sorted(by_type), 2):
            xa, xb = by_type[a], by_type[b]
            ties = len(np.unique(np.concatenate([xa, xb]))) < len(xa) + len(xb)
            method = "asymptotic" if ties else "exact"
            res = mannwhitneyu(xa, xb, alternative="two-sided", method=method)
            rows.append(
                {
                    "rig": rig,
                    "speed_setting": int(setting),
                    "type_a": a,
                    "type_b": b,
                    "n_a": len(xa),
                    "n_b": len(xb),
                    "median_a_s": float(np.median(xa)),
                    "median_b_s": float(np.median(xb)),
                    "u_statistic": float(res.statistic),
                    "method": method,
                    "p_value": float(res.pvalue),
                }
            )
    table = pd.DataFrame(rows, columns=COLUMNS[:-2])
    table["p_adjusted"] = np.nan
    table["significant"] = False
    if table.empty:
        return table
    groups = (
        [table.index]
        if family == "all"
        else [g.index for _, g in table.groupby(["rig", "speed_setting"], sort=False)]
    )
    for idx in groups:
        reject, p_adj, _, _ = multipletests(
            table.loc[idx, "p_value"].to_numpy(), alpha=alpha, method="fdr_bh"
        )
        table.loc[idx, "p_adjusted"] = p_adj
        table.loc[idx, "significant"] = reject
    table["significant"] = table["significant"].astype(bool)
    return table


def significance_stars(p: float) -> str:
    """'***' for p < 0.001, '**' for < 0.01, '*' for < 0.05, 'n.s.' otherwise."""
    return "***" if p < 0.001 else "**" if p < 0.01 else "*" if p < 0.05 else "n.s."
