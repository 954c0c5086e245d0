"""Simulations to validation of the E3 KP/BW calibration with each optimiser, from one run.

    python scripts/compare_optimizers.py [--study examples/e3-kpbw/study.yaml]
        [--samplers gp,published] [--seeds 1] [--out compare-optimizers] [--workers 2]

Runs the study once per optimiser (``optimizer: {sampler: ...}``) and seed into its own folder
under ``--out`` (an existing folder is resumed, not redone) and prints, per optimiser, the
fitting simulations until validation passed (or the budget), the iteration and the best cost.
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import yaml

from parcelfit.config import load_yaml
from parcelfit.study.calibration import Calibration
from parcelfit.study.studyfile import load_study


def run_one(study_file: Path, sampler: str, seed: int, out: Path, workers: int) -> tuple:
    """Calibrate with ``sampler`` and ``seed``; (evaluations, validated, last iteration, best cost)."""
    doc = load_yaml(study_file)
    doc["optimizer"] = {**(doc.get("optimizer") or {}), "sampler": sampler}
    doc["seed"] = seed
    doc["reference"]["dataset"] = str((study_file.parent / doc["reference"]["dataset"]).resolve())
    variant = study_file.parent / f".{study_file.stem}-{sampler}-{seed}.yaml"
    variant.write_text(yaml.safe_dump(doc, sort_keys=False))  # the study as written: the order
    # of its parameters sets the initial design
    try:
        result = Calibration(
            load_study(variant), out / f"{sampler}-seed{seed}", workers=workers
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
    print(f"{'optimizer':<11}{'seed':>5}{'simulations':>13}{'validated':>11}{'best cost':>11}")
    for sampler in args.samplers.split(","):
        counts = []
        for seed in range(1, args.seeds + 1):
            n, ok, _, cost = run_one(args.study, sampler, seed, args.out, args.workers)
            counts.append(n)
            print(f"{sampler:<11}{seed:>5}{n:>13}{ok!s:>11}{cost:>11.4f}", flush=True)
        if len(counts) > 1:
            print(f"{sampler:<11}{'med':>5}{statistics.median(counts):>13g}")


if __name__ == "__main__":
    main()
