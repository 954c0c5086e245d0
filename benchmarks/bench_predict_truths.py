"""Does `parcelfit predict`'s 90 % band hold the MuJoCo twin runs of unseen cases, over several
hidden truths?

    python benchmarks/bench_predict_truths.py [--truths 3] [--seed 0]
        [--unseen E1/KPBW/1,E2b/KPBW/1,examples/own-rig/D1.yaml/KPBW/2]
        [--sets 6] [--placements 6] [--workers 2] [--out bench-predict-truths]

Run from the repository's root. For each of ``--truths`` hidden truths of the KP/BW mailer
(mu_d_BePa, mu_d_MePa, E_Pa and k_MePa at seeded fractions 0.1-0.9 of the ranges of the E3
KP/BW example study; every other parameter at its default, as in the bundled twin) it

1. makes a SYNTHETIC twin dataset with `parcelfit.synth` (the bundled twin's settings from
   ``src/parcelfit/data/examples/twin-spec.yaml``: 10 runs per case, each its own specimen,
   placement, drive speeds and tracking noise, at half the model's time step and a finer
   mesh) of E3/KPBW at speed settings 1 and 2 and of every ``--unseen`` case;
2. calibrates the E3 KP/BW example study (``examples/e3-kpbw/study.yaml``: fitted on E3 at
   setting 1, validated at setting 2, the published cost) against it;
3. predicts every unseen case (a bundled rig or a rig file, here the guide's own rig D1, which
   no calibration has seen) with ``--sets`` x ``--placements`` simulations, and counts the
   twin's runs inside the model's band and inside the band of a real run.

Prints per truth the table of `bench_predict_twin` and the recovered parameters (share of the
range off the truth, and whether the reported interval holds it), then the coverage over all
truths; writes ``<out>/results.json``. Every stage resumes from its folder under ``--out``.
The issue's target: the 90 % band holds 80-97 % of the unseen runs.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_predict_twin import QUANTITIES, predict_cases, print_coverage

STUDY = Path("examples/e3-kpbw/study.yaml")
SPEC = Path("src/parcelfit/data/examples/twin-spec.yaml")
FITTED = ("E3/KPBW/1", "E3/KPBW/2")


def truth_for(k: int, seed: int, ranges: dict[str, list[float]]) -> dict[str, float]:
    """Truth ``k``: each parameter at a seeded fraction 0.1-0.9 of its range (catalogue
    units), rounded to 3 significant digits."""
    rng = np.random.default_rng([seed, k, 0x7B])
    out = {}
    for name, (lo, hi) in ranges.items():
        v = lo + float(rng.uniform(0.1, 0.9)) * (hi - lo)
        out[name] = float(f"{v:.3g}")
    return out


def make_twin(folder: Path, truth: dict[str, float], cases: list[str], seed: int, workers: int):
    """The twin dataset of ``cases`` at ``truth`` in ``folder`` (resumes); its dataset folder."""
    from parcelfit.synth import load_twin_spec

    base = yaml.safe_load(SPEC.read_text(encoding="utf-8"))
    rigs, labels = [], []
    for c in cases:
        rig, kind, setting = c.rsplit("/", 2)
        if rig.endswith((".yaml", ".yml")):
            rigs.append(str(Path(rig).resolve()))
            rig = Path(rig).stem
        labels.append(f"{rig}/{kind}/{setting}")
    spec = {
        "name": folder.name,
        "seed": seed,
        "cases": labels,
        "truth": {"KPBW": truth},
        "rigs": rigs,
        "settings": base["settings"],
    }
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "twin-spec.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False), encoding="utf-8")
    tw = load_twin_spec(path)
    data = folder / "data"
    if not (data / "dataset.yaml").is_file():
        tw.make(data, workers=workers)
    return data


def study_file(folder: Path, data: Path, seed: int) -> Path:
    """The E3 KP/BW example study pointed at ``data`` (written into ``folder``)."""
    doc = yaml.safe_load(STUDY.read_text(encoding="utf-8"))
    doc["reference"]["dataset"] = str(data.resolve())
    doc["seed"] = seed
    doc["name"] = f"e3-kpbw-{folder.name}"
    path = folder / "study.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def recovery(folder: Path, truth: dict[str, float], ranges: dict[str, list[float]]) -> list[dict]:
    """Per parameter: the recommended value and interval (catalogue units), the error as a
    share of the range and whether the interval holds the truth."""
    from parcelfit.sim.params import CATALOGUE
    from parcelfit.study.store import STORE_FILE, Store

    doc = json.loads((folder / "results.json").read_text(encoding="utf-8"))
    ident = {p["name"]: p for p in doc["identifiability"]["parameters"]}
    factor = {p.name: p.si_factor for p in CATALOGUE}
    store = Store(folder / STORE_FILE, readonly=True)
    try:
        recommended = store.read_recommended()
    finally:
        store.close()
    chosen = {} if recommended is None else dict(recommended.params)
    rows = []
    for name, true in truth.items():
        f = factor.get(name, 1.0)
        p = ident[name]
        lo, hi = (v / f for v in p["interval"])
        value = chosen.get(name, p["median"]) / f
        span = ranges[name][1] - ranges[name][0]
        rows.append(
            {
                "parameter": name,
                "truth": true,
                "value": value,
                "error_share": abs(value - true) / span,
                "interval": [lo, hi],
                "holds": lo <= true <= hi,
                "verdict": p["verdict"],
            }
        )
    return rows


def main() -> None:
    """Make, calibrate and predict every truth; print the tables and the coverage."""
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--truths", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--unseen", default="E1/KPBW/1,E2b/KPBW/1,examples/own-rig/D1.yaml/KPBW/2")
    ap.add_argument("--sets", type=int, default=6)
    ap.add_argument("--placements", type=int, default=6)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("bench-predict-truths"))
    args = ap.parse_args()

    from parcelfit.study.calibration import Calibration
    from parcelfit.study.studyfile import load_study

    ranges = yaml.safe_load(STUDY.read_text(encoding="utf-8"))["parameters"]
    unseen = args.unseen.split(",")
    total = {q: [0, 0, 0, 0] for q in QUANTITIES}
    report = []
    for k in range(args.truths):
        folder = args.out / f"truth-{k}"
        truth = truth_for(k, args.seed, ranges)
        print(f"\n== truth {k}: {truth}", flush=True)
        seconds = {}
        t = time.perf_counter()
        data = make_twin(folder / "twin", truth, [*FITTED, *unseen], 100 + k, args.workers)
        seconds["twin"] = time.perf_counter() - t
        study = load_study(study_file(folder, data, args.seed + k))
        t = time.perf_counter()
        result = Calibration(study, folder / "calibration", workers=args.workers).run()
        seconds["calibrate"] = time.perf_counter() - t
        print(
            f"calibrate: {result.evaluations} evaluations, validated {result.validated}",
            flush=True,
        )
        rec = recovery(folder / "calibration", truth, ranges)
        for r in rec:
            print(
                f"  {r['parameter']:<10} truth {r['truth']:<8g} value {r['value']:<9.4g} "
                f"off {r['error_share']:.0%} of range; interval {r['interval'][0]:.4g}-"
                f"{r['interval'][1]:.4g} ({r['verdict']}) holds it: {r['holds']}",
                flush=True,
            )
        rows, inside, seconds["predict"] = predict_cases(
            folder / "calibration",
            data,
            unseen,
            sets=args.sets,
            placements=args.placements,
            seed=args.seed,
            out=folder,
            workers=args.workers,
        )
        print_coverage(inside)
        for q, counts in inside.items():
            total[q] = [a + b for a, b in zip(total[q], counts, strict=True)]
        print(
            "wall time: " + ", ".join(f"{n} {v / 60:.1f} min" for n, v in seconds.items()),
            flush=True,
        )
        report.append(
            {"truth": truth, "recovery": rec, "rows": rows, "inside": inside, "seconds": seconds}
        )
    (args.out / "results.json").write_text(
        json.dumps({"truths": report, "inside": total}, indent=1, default=float)
    )
    print(f"\n== over {args.truths} truths")
    print_coverage(total)


if __name__ == "__main__":
    main()
