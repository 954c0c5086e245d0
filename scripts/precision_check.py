"""Which parameters can a study's test cases determine, given the real runs' scatter?

    python scripts/precision_check.py STUDY.yaml [--placements 10] [--candidates E2a/KPBW/2 ...]
                                      [--at NAME=VALUE ...] [--workers 2] [--out precision-check]

Before spending a calibration's compute: for every parameter of the study, the study's fitted
test cases (and, as candidates, its validation and transfer cases and any named with
``--candidates``, real runs from the first case's dataset) are simulated with the parameter at
the low and the high end of its range, every other parameter at the centre of its range (or at
``--at`` values, catalogue units, e.g. a twin's hidden truth), over ``--placements`` seeded
placements (seeds 1..K, the same at both ends). `parcelfit.study.precision` turns the change of
the mean statistics (transit time, rotation, lateral drift) and the real runs' scatter into the
95 % half-width each parameter could be determined to, as a share of its range: the fitted cases
jointly, each alone, and the fitted cases plus each candidate. A half-width above 10 % says
that no calibration on these cases can be expected to recover the parameter within 10 % of its
range. Writes ``precision-check.md`` and prints it. The simulations are
cases x parameters x 2 x K.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from parcelfit.atomic import write_text_atomic
from parcelfit.errors import ParcelfitError
from parcelfit.metrics.comparison import Comparison
from parcelfit.runs import TestCase, load_dataset
from parcelfit.sim.executors import Task, make_executor
from parcelfit.sim.factory import make_simulator
from parcelfit.sim.params import parse_assignments
from parcelfit.study.joint import simulate_items
from parcelfit.study.precision import (
    STATISTICS,
    CaseSensitivity,
    precision,
    run_statistics,
    sensitivity,
)
from parcelfit.study.studyfile import CaseSpec, fixed_to_si, load_study


def _fmt(h: float) -> str:
    return f"{100 * h:.0f} %" + (" *" if h <= 0.10 else "")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("study", type=Path)
    ap.add_argument("--placements", type=int, default=10)
    ap.add_argument("--candidates", nargs="*", default=[], metavar="RIG/TYPE/SETTING")
    ap.add_argument("--at", nargs="*", default=[], metavar="NAME=VALUE")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", type=Path, default=Path("precision-check"))
    args = ap.parse_args(argv)
    if args.placements < 2:
        ap.error("--placements must be at least 2 (the sensitivity's standard error needs two)")

    study = load_study(args.study)
    names = study.space.names
    dims = {d.name: d for d in study.space.dims}
    centre = {n: 0.5 * (dims[n].low + dims[n].high) for n in names}
    at = fixed_to_si(parse_assignments(args.at), study.simulator.backend, args.study)
    unknown = sorted(set(at) - set(names))
    if unknown:
        raise ParcelfitError(
            f"--at names {', '.join(unknown)}, not a parameter of the study",
            fix=f"use one of {', '.join(names)}",
        )
    point = {**study.fixed, **centre, **at}
    fitted = list(study.cases)
    default_dataset = fitted[0].dataset
    candidates = [*study.validation_cases, *study.transfer]
    for label in args.candidates:
        spec = CaseSpec(TestCase.parse(label), default_dataset)
        if all(spec.case != c.case for c in (*fitted, *candidates)):
            candidates.append(spec)

    datasets = {}
    comparisons: dict[str, Comparison] = {}
    real: dict[str, list[np.ndarray | None]] = {}
    for spec in (*fitted, *candidates):
        if spec.dataset not in datasets:
            datasets[spec.dataset] = load_dataset(spec.dataset)
        data = datasets[spec.dataset][spec.case]
        comparisons[spec.label] = Comparison.for_case(data)
        real[spec.label] = [run_statistics(r, comparisons[spec.label]) for r in data.runs]

    # every run's statistics are kept in the output folder as they arrive, so a killed check
    # resumes and a rerun with more candidates simulates only the new cases
    args.out.mkdir(parents=True, exist_ok=True)
    cache_file = args.out / "statistics.json"
    setup = {"point": point, "simulator": repr(study.simulator)}
    cache: dict[str, list[float] | None] = {}
    if cache_file.exists():
        saved = json.loads(cache_file.read_text())
        if saved.get("setup") == json.loads(json.dumps(setup)):
            cache = saved["runs"]
        else:
            print(f"{cache_file} is from another point or simulator: not used", file=sys.stderr)

    seeds = list(range(1, args.placements + 1))
    items = []
    ids = []
    keys = []
    for spec in (*fitted, *candidates):
        for name in names:
            for end, value in (("low", dims[name].low), ("high", dims[name].high)):
                for seed in seeds:
                    run_id = f"precision-{spec.label}-{name}-{end}-{seed}"
                    keys.append((spec.label, name, end, run_id))
                    if run_id not in cache:
                        items.append((Task({**point, name: value}, spec.case, run_id), seed))
                        ids.append((spec.label, run_id))
    simulator = make_simulator(study.simulator)
    out_of = len(items)
    print(
        f"{out_of} simulations on {args.workers} process(es) ({len(keys) - out_of} kept)",
        file=sys.stderr,
    )
    start = time.perf_counter()

    def save() -> None:
        write_text_atomic(cache_file, json.dumps({"setup": setup, "runs": cache}))

    if items:
        with make_executor("local", workers=args.workers) as executor:
            for done, (i, result) in enumerate(simulate_items(executor, simulator, items), 1):
                label, run_id = ids[i]
                ok = result.ok and result.run is not None
                s = run_statistics(result.run, comparisons[label]) if ok else None
                cache[run_id] = None if s is None else [float(v) for v in s]
                if done % 20 == 0 or done == out_of:
                    save()
                    print(
                        f"  {done}/{out_of} ({time.perf_counter() - start:.0f} s)", file=sys.stderr
                    )
    stats: dict[tuple[str, str, str], list[np.ndarray | None]] = {}
    for label, name, end, run_id in keys:
        v = cache[run_id]
        stats.setdefault((label, name, end), []).append(None if v is None else np.array(v))
    wall = time.perf_counter() - start

    sens: dict[str, CaseSensitivity] = {}
    for spec in (*fitted, *candidates):
        low = {n: stats[(spec.label, n, "low")] for n in names}
        high = {n: stats[(spec.label, n, "high")] for n in names}
        sens[spec.label] = sensitivity(spec.label, names, low, high, real[spec.label])

    lines = [
        "# Precision check: what the test cases can determine",
        "",
        f"Written by `python scripts/precision_check.py {args.study.as_posix()} --placements "
        f"{args.placements}"
        + (f" --candidates {' '.join(args.candidates)}" if args.candidates else "")
        + (f" --at {' '.join(args.at)}" if args.at else "")
        + f"`: {len(keys)} simulations ({out_of} in this run, {wall:.0f} s on {args.workers} "
        "process(es)). "
        "Every other parameter at "
        + ("the given values" if args.at else "the centre of its range")
        + " (`parcelfit.study.precision`: linear, Gaussian estimate from the change of the mean "
        "transit time, rotation and lateral drift over each parameter's range and the real runs' "
        "scatter).",
        "",
        "95 % half-width each parameter could be determined to, as a share of its range (* where "
        "<= 10 %; 57 % means no information). Joint: the other parameters free; alone: the others "
        "known.",
        "",
    ]
    fitted_labels = [s.label for s in fitted]
    rows = [(" + ".join(fitted_labels) + " (fitted)", [sens[s] for s in fitted_labels])]
    rows += [(label, [sens[label]]) for label in fitted_labels if len(fitted_labels) > 1]
    rows += [
        (f"fitted + {s.label}", [*(sens[f] for f in fitted_labels), sens[s.label]])
        for s in candidates
    ]
    if len(candidates) > 1:
        rows.append(("fitted + every candidate", list(sens.values())))
    head = "| cases | " + " | ".join(f"{n} joint | {n} alone" for n in names) + " |"
    lines += [head, "|" + "---|" * (1 + 2 * len(names))]
    for title, group in rows:
        p = precision(group)
        cells = " | ".join(f"{_fmt(j)} | {_fmt(a)}" for j, a in zip(p.joint, p.alone, strict=True))
        lines.append(f"| {title} | {cells} |")
    lines += [
        "",
        "Sensitivity per case: change of the mean statistic over the parameter's whole range "
        "(standard error over the placements; - where not resolved, below twice it), and the real "
        "runs' standard deviation.",
        "",
    ]
    head = "| case | statistic | real sd | " + " | ".join(names) + " |"
    lines += [head, "|" + "---|" * (3 + len(names))]
    for label, s in sens.items():
        sd = s.real.std(axis=0, ddof=1) if len(s.real) > 1 else np.full(len(STATISTICS), np.nan)
        for k, stat in enumerate(STATISTICS):
            cells = " | ".join(
                f"{s.jacobian[k, j]:+.4g} ({s.jacobian_se[k, j]:.2g})"
                + ("" if s.resolved[k, j] else " -")
                for j in range(len(names))
            )
            lines.append(f"| {label} ({len(s.real)} real) | {stat} | {sd[k]:.3g} | {cells} |")
    text = "\n".join(lines) + "\n"
    write_text_atomic(args.out / "precision-check.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except ParcelfitError as exc:  # a bad study, dataset or --at: say what and how to fix it
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
