"""The acceptance threshold of the identifiability analysis, checked against the cost it guards.

    python scripts/threshold_check.py STUDY.yaml [STUDY.yaml ...]

Run from the repository's root. For every fitted case of each study (its real runs, no
simulation): what sets of real runs as large as the case's placements score in the study's cost
against the case's other real runs (`parcelfit.study.joint.case_null_costs`), with the transit
term's variances pooled (today's cost) and with Welch's form (each side's own variance, the
cost until 2026-12-04, computed here for comparison only), beside the largest cost of a single
real run (the threshold's former basis); then the study's threshold now
(`parcelfit.study.joint.threshold`) and the former one (the weighted sum of the cases' largest
single-run costs). Seconds per study.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
from pathlib import Path

import numpy as np

from parcelfit.metrics.ensemble import ensemble_real_costs
from parcelfit.metrics.reference import ReferenceSelection
from parcelfit.study.joint import case_null_costs, placement_seeds, threshold
from parcelfit.study.objective import select_references
from parcelfit.study.studyfile import load_study


def welch_costs(ref: ReferenceSelection, k: int, w_xy: float, w_theta: float, w_t: float) -> list:
    """The former ensemble cost of every set of ``k`` real runs against the others: the transit
    term's SE^2 = s_set^2 / k + s_others^2 / (n - k) (s_set^2 = s_others^2 for one run)."""
    n = len(ref.run_ids)
    k = max(1, min(k, n - 2))
    sx = ref.max_xy if ref.max_xy > 0 else 1.0
    st = ref.max_theta if ref.max_theta > 0 else 1.0
    d = w_xy * ref.d_xy / sx + w_theta * ref.d_theta / st
    t = np.array([x if x is not None else math.nan for x in ref.transit_times], float)
    use_t = bool(np.all(np.isfinite(t))) and n - k >= 2 and w_t > 0
    out = []
    for chosen in itertools.combinations(range(n), k):
        others = [r for r in range(n) if r not in chosen]
        c = float(d[np.ix_(chosen, others)].mean())
        if use_t:
            v_o = float(t[others].var(ddof=1))
            v_s = float(t[list(chosen)].var(ddof=1)) if k >= 2 else v_o
            se2 = v_s / k + v_o / len(others)
            c += w_t * float((t[list(chosen)].mean() - t[others].mean()) ** 2 / se2)
        out.append(c)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("studies", nargs="+", type=Path)
    args = ap.parse_args(argv)
    for path in args.studies:
        study = load_study(path)
        refs = select_references(study)
        print(f"## {path} ({study.cost_kind} cost)\n")
        print(
            "| case | real runs | set size K | largest single-run cost | K-set costs, pooled: "
            "median / 95 % / largest | K-set costs, Welch: median / 95 % / largest |"
        )
        print("|---|---|---|---|---|---|")
        former = 0.0
        for spec in study.cases:
            ref = refs[spec.label]
            k = len(placement_seeds(study, spec))
            if study.cost_kind == "ensemble":
                single = ensemble_real_costs(ref, study.w_xy, study.w_theta, study.transit_weight)
                welch = welch_costs(ref, k, study.w_xy, study.w_theta, study.transit_weight)
            else:
                single = welch = case_null_costs(ref, study, spec)
            now = case_null_costs(ref, study, spec)
            former += spec.weight * float(np.max(single))

            def q(x: object) -> str:
                a = np.asarray(x, float)
                m, h = np.median(a), np.quantile(a, 0.95, method="higher")
                return f"{m:.3g} / {h:.3g} / {a.max():.3g}"

            print(
                f"| {spec.label} | {len(ref.run_ids)} | {k} | {float(np.max(single)):.3g} "
                f"| {q(now)} | {q(welch)} |"
            )
        eps, source = threshold(refs, study)
        print(f"\nthreshold now: {eps:.4g} ({source})")
        print(f"former threshold (sum of the largest single-run costs): {former:.4g}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
