"""Simulations to validation of the E3 KP/BW calibration with each optimiser, from one run.

    python scripts/compare_optimizers.py [--study examples/e3-kpbw/study.yaml]
        [--samplers gp,published] [--seeds 1] [--out compare-optimizers] [--workers 2]

Runs the study once per optimiser (``optimizer: {sampler: ...}``; ``gp:prior=none:amplitude=true``
gives the sampler ``gp`` with those study-file optimizer keys) and seed into its own folder
under ``--out`` (an existing folder is resumed, not redone) and prints, per optimiser, the
fitting simulations until validation passed (or the budget), the iteration, the best cost, the
band test (`parcelfit.study.verdict`) and, where the study's dataset holds the hidden truth of a
twin (``truth.yaml``), the error of each validated parameter as a share of its range, with the
median over seeds.
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import yaml

from parcelfit.config import load_yaml
from parcelfit.runs import TestCase, read_truth
from parcelfit.sim.params import parameter
from parcelfit.study.calibration import Calibration
from parcelfit.study.results import read_results
from parcelfit.study.status import folder_verdict
from parcelfit.study.studyfile import load_study


def truth_si(study_file: Path, consignment: str) -> dict[str, float]:
    """The twin's hidden truth (SI) of ``consignment``, from the study's dataset (empty for real
    data)."""
    doc = load_yaml(study_file)
    folder = (study_file.parent / doc["reference"]["dataset"]).resolve()
    return {n: parameter(n).to_si(v) for n, v in read_truth(folder, consignment).items()}


def errors(folder: Path, study_file: Path) -> dict[str, float]:
    """The shown validation's parameters against the twin's truth (SI) of its case's
    consignment type, each as a share of its range."""
    results = read_results(folder)
    shown = results.shown_validation() if results is not None else None
    if shown is None or results is None or results.identifiability is None:
        return {}
    values = truth_si(study_file, TestCase.parse(shown.case).consignment)
    return {
        p.name: abs(shown.params[p.name] - values[p.name]) / (p.high - p.low)
        for p in results.identifiability.parameters
        if p.name in values and p.name in shown.params
    }


def _folder(sampler: str) -> str:
    """A folder name for ``sampler`` (its keys joined by underscores)."""
    return sampler.replace(":", "_").replace("=", "-")


def run_one(study_file: Path, sampler: str, seed: int, out: Path, workers: int) -> tuple:
    """Calibrate with ``sampler`` and ``seed``; (evaluations, validated, last iteration, best cost)."""
    doc = load_yaml(study_file)
    name, *pairs = sampler.split(":")
    keys = {k: yaml.safe_load(v) for k, v in (pair.split("=", 1) for pair in pairs)}
    doc["optimizer"] = {**(doc.get("optimizer") or {}), "sampler": name, **keys}
    doc["seed"] = seed
    doc["reference"]["dataset"] = str((study_file.parent / doc["reference"]["dataset"]).resolve())
    variant = study_file.parent / f".{study_file.stem}-{_folder(sampler)}-{seed}.yaml"
    variant.write_text(yaml.safe_dump(doc, sort_keys=False))  # the study as written: the order
    # of its parameters sets the initial design
    try:
        result = Calibration(
            load_study(variant), out / f"{_folder(sampler)}-seed{seed}", workers=workers
        ).run()
    finally:
        variant.unlink()
    return result.evaluations, result.validated, result.last_iteration, result.best_cost


def main() -> None:
    """Run every optimiser on the study and print the table."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--study", type=Path, default=Path("examples/e3-kpbw/study.yaml"))
    ap.add_argument("--samplers", default="gp,published")
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path("compare-optimizers"))
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    print(
        f"{'optimizer':<11}{'seed':>5}{'simulations':>13}{'validated':>11}{'best cost':>11}"
        f"{'band test':>11}  errors [% of range]"
    )
    for sampler in args.samplers.split(","):
        counts, errs = [], []
        for seed in range(1, args.seeds + 1):
            n, ok, _, cost = run_one(args.study, sampler, seed, args.out, args.workers)
            folder = args.out / f"{_folder(sampler)}-seed{seed}"
            band = next(c.outcome for c in folder_verdict(folder).checks if c.name == "band test")
            err = errors(folder, args.study)
            counts.append(n)
            errs.append(err)
            shown = " / ".join(f"{name} {100 * e:.0f}" for name, e in err.items())
            print(
                f"{sampler:<11}{seed:>5}{n:>13}{ok!s:>11}{cost:>11.4f}{band:>11}  {shown}",
                flush=True,
            )
        if len(counts) > 1:
            med = " / ".join(
                f"{name} {100 * statistics.median(e[name] for e in errs if name in e):.0f}"
                for name in errs[0]
            )
            print(f"{sampler:<11}{'med':>5}{statistics.median(counts):>13g}{'':>33}  {med}")


if __name__ == "__main__":
    main()
