"""The acceptance threshold of "what the data determine" against what the truth itself scores.

    python scripts/threshold_truth.py STUDY.yaml --set NAME=VALUE [--set ...] [--draws 20]
                                      [--executor local|serial]
                                      [--workers N]

Run from the repository's root, on a study whose dataset is a twin with a known truth (the
``--set`` values, in the catalogue's units, e.g. ``mu_d_BePa=0.45``; parameters not given keep
the study's fixed values and the defaults). The identifiability analysis excludes a parameter
set when it is 95 % sure that its cost exceeds epsilon (`parcelfit.study.joint.threshold`),
which stands for "what a simulation at the true parameters would score" and is estimated from
the real runs alone. Here the truth is simulated: at the study's own placement seeds (1..K, as
every evaluation) and at ``--draws - 1`` further disjoint sets of K seeds, each scored in the
study's cost against the real runs like any evaluation (`parcelfit.study.joint.evaluation_outcome`).
Printed: per case and in total, epsilon beside the truth's costs (at the study's seeds, the
median, the 95 % quantile (from 40 draws on; with fewer it would be the largest) and the largest
over the draws), and how many draws score above epsilon. Zero of 20 bounds the share of draws
above epsilon only below about 14 % (95 % confidence).
A threshold far above every draw of the truth's cost rules out less than the data could; a
draw above it would exclude the truth. With several cases, the rank correlation of their costs
over the draws (the placement seeds are shared across cases) is printed too. A study on the
analytic test simulator (``tests.fake_sim``) runs with ``PYTHONPATH=.``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from parcelfit.sim.executors import Task, make_executor
from parcelfit.sim.factory import make_simulator
from parcelfit.sim.params import parse_assignments
from parcelfit.study.joint import (
    CaseRun,
    case_threshold,
    check_placements,
    evaluation_outcome,
    placement_seeds,
    simulate_items,
    threshold,
)
from parcelfit.study.objective import select_references
from parcelfit.study.studyfile import fixed_to_si, load_study


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("study", type=Path)
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", required=True)
    ap.add_argument("--draws", type=int, default=20, help="sets of K placement seeds (>= 1)")
    ap.add_argument("--workers", type=int, default=None, help="worker processes (default: cores)")
    ap.add_argument("--executor", choices=("local", "serial"), default="local")
    args = ap.parse_args(argv)
    if args.draws < 1:
        ap.error("--draws must be at least 1")
    study = load_study(args.study)
    if study.cost_kind != "ensemble":
        ap.error("the study must use the ensemble cost (placements), not the published one")
    truth = fixed_to_si(parse_assignments(args.set), study.simulator.backend, None, "--set")
    missing = [d.name for d in study.space.dims if d.name not in truth]
    if missing:
        ap.error(f"--set gives no truth for the fitted {', '.join(missing)}")
    params = {**study.fixed, **truth}
    refs = select_references(study)
    simulator = make_simulator(study.simulator)
    check_placements(study, simulator)
    k_max = max(len(placement_seeds(study, s)) for s in study.cases)
    items: list[tuple[Task, int | None]] = []
    owner: list[tuple[int, int]] = []  # (draw, case index)
    for d in range(args.draws):
        for c, spec in enumerate(study.cases):
            for seed in placement_seeds(study, spec):
                # draw 0: the study's own seeds; a mirrored seed -s stays the mirror image of
                # its positive one, the nominal placement (None) stays nominal
                shifted = (
                    None if seed is None else (abs(seed) + d * k_max) * (1 if seed > 0 else -1)
                )
                items.append((Task(params, spec.case, f"truth-d{d}-c{c}-p{shifted}"), shifted))
                owner.append((d, c))
    runs: dict[int, list[tuple[int, CaseRun]]] = {}
    executor = make_executor(args.executor, workers=args.workers)
    try:
        for j, result in simulate_items(executor, simulator, items):
            d, c = owner[j]
            runs.setdefault(d, []).append((j, CaseRun(study.cases[c], items[j][1], result)))
    finally:
        executor.close()
    per_case = np.full((args.draws, len(study.cases)), np.nan)
    total = np.full(args.draws, np.nan)
    for d, got in runs.items():
        out = evaluation_outcome([r for _, r in sorted(got, key=lambda t: t[0])], refs, study)
        if out["status"] != "ok":
            print(f"draw {d}: {out['status']} ({out['details'].message})")
            continue
        total[d] = out["cost"]
        for c, part in enumerate(out["details"].cases):
            per_case[d, c] = part.cost
    eps, source = threshold(refs, study)
    print(f"## {args.study}: the truth's cost against epsilon ({args.draws} sets of placements)\n")
    print(
        "| case | epsilon | the truth's cost at the study's seeds | median / 95 % (from 40 "
        "draws) / largest over the draws | draws above epsilon |"
    )
    print("|---|---|---|---|---|")

    def row(label: str, e: float, costs: np.ndarray) -> None:
        ok = costs[np.isfinite(costs)]
        if not len(ok):
            print(f"| {label} | {e:.3g} | - | no draw ended ok | - |")
            return
        # the 95 % quantile only from 40 draws on: with fewer, `higher` gives the largest
        q = np.quantile(ok, 0.95, method="higher") if len(ok) >= 40 else math.nan
        above = "-" if math.isnan(e) else f"{int(np.sum(ok > e))} of {len(ok)}"
        print(
            f"| {label} | {e:.3g} | {costs[0]:.3g} | {np.median(ok):.3g} / {q:.3g} / {ok.max():.3g} "
            f"| {above} |"
        )

    for c, spec in enumerate(study.cases):
        row(spec.label, case_threshold(refs[spec.label], study, spec), per_case[:, c])
    row("all (weighted)", eps, total)
    print(f"\nepsilon: {source}")
    if len(study.cases) > 1 and args.draws >= 5:  # do the cases' costs at the truth move together?
        from scipy.stats import spearmanr

        pairs = [
            f"{a.label} ~ {b.label} {spearmanr(per_case[:, i], per_case[:, j], nan_policy='omit')[0]:+.2f}"
            for i, a in enumerate(study.cases)
            for j, b in enumerate(study.cases)
            if i < j
        ]
        print("rank correlation of the cases' costs over the draws: " + "; ".join(pairs))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
