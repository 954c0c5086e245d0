"""The acceptance threshold of the identifiability analysis, checked against the cost it guards.

    python scripts/threshold_check.py STUDY.yaml [STUDY.yaml ...] [--folder STUDY_DIR]

Run from the repository's root. For every fitted case of each study (its real runs, no
simulation): the largest cost of a single real run against the others (the threshold's basis
until 2026-12-04) beside what sets of real runs as large as the case's placements score in the
study's cost against the case's other real runs (`parcelfit.study.joint.case_null_costs`: their
median, 95 % quantile (the next value up) and largest, and how many of the sets score above the
largest single-run cost); then the study's threshold now
(`parcelfit.study.joint.threshold`) and the former one (the weighted sum of the cases' largest
single-run costs). With ``--folder`` (one study file), the finished study in that folder is
analysed again with today's threshold (`parcelfit.study.finish.Finish.identifiability`, from
its stored evaluations: nothing is simulated), beside what its ``results.json`` holds; with
``--epsilon`` too, with that threshold instead (what the data would determine if the threshold
were that, e.g. the truth's own cost from scripts/threshold_truth.py). Seconds per study.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from parcelfit.metrics.ensemble import effective_set_size, ensemble_real_costs
from parcelfit.study.finish import Finish
from parcelfit.study.joint import case_null_costs, placement_seeds, threshold
from parcelfit.study.objective import select_references
from parcelfit.study.results import read_results
from parcelfit.study.store import STORE_FILE, Store
from parcelfit.study.studyfile import load_study


def reanalyse(study_path: Path, folder: Path, epsilon: float | None = None) -> None:
    """Print the stored and today's verdicts of the finished study in ``folder`` (today's with
    the threshold ``epsilon`` where given)."""
    study = load_study(study_path)
    store = Store(folder / STORE_FILE)
    finish = Finish(
        study, folder, store, None, select_references(study), lambda *_: None, lambda: None
    )  # type: ignore[arg-type]  # identifiability simulates nothing
    now = finish.identifiability(epsilon)
    stored = read_results(folder).identifiability
    print(f"## {folder}: what the data determine, stored and with today's threshold\n")
    for label, ident in (("stored", stored), ("today", now)):
        if ident is None:
            print(f"{label}: none")
            continue
        cells = "; ".join(
            f"{p.name} {p.verdict} [{p.interval[0]:.4g}, {p.interval[1]:.4g}]"
            for p in ident.parameters
        )
        print(f"{label} (threshold {ident.threshold:.4g}): {cells}")
    print()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("studies", nargs="+", type=Path)
    ap.add_argument("--folder", type=Path, help="a finished study of the (one) study file")
    ap.add_argument(
        "--epsilon",
        type=float,
        default=None,
        help="with --folder: analyse with this threshold instead of the study's (a what-if)",
    )
    args = ap.parse_args(argv)
    if args.epsilon is not None and (args.folder is None or not args.epsilon > 0):
        ap.error("--epsilon takes a positive threshold and --folder")
    if args.folder is not None:
        if len(args.studies) != 1:
            ap.error("--folder takes one study file")
        reanalyse(args.studies[0], args.folder, args.epsilon)
        return 0
    for path in args.studies:
        study = load_study(path)
        refs = select_references(study)
        print(f"## {path} ({study.cost_kind} cost)\n")
        print(
            "| case | real runs | set size | largest single-run cost | "
            "sets' costs: median / 95 % / largest | sets above the largest single-run cost |"
        )
        print("|---|---|---|---|---|---|")
        former = 0.0
        for spec in study.cases:
            ref = refs[spec.label]
            sets = case_null_costs(ref, study, spec)
            if study.cost_kind == "ensemble":
                single = ensemble_real_costs(ref, study.w_xy, study.w_theta, study.transit_weight)
                k = effective_set_size(len(ref.run_ids), len(placement_seeds(study, spec)))
            else:
                single, k = sets, 1
            former += spec.weight * float(np.max(single))
            q = np.quantile(sets, 0.95, method="higher")
            above = int(np.sum(sets > np.max(single)))
            print(
                f"| {spec.label} | {len(ref.run_ids)} | {k} | {float(np.max(single)):.3g} "
                f"| {np.median(sets):.3g} / {q:.3g} / {sets.max():.3g} | {above} of {len(sets)} |"
            )
        eps, source = threshold(refs, study)
        print(f"\nthreshold now: {eps:.4g} ({source})")
        print(
            f"former threshold (sum of the largest single-run costs, scored as today): {former:.4g}\n"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
