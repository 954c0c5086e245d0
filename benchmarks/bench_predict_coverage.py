"""Does `parcelfit predict`'s 90 % band hold the runs of a case the calibration never saw?

    python benchmarks/bench_predict_coverage.py [--truths 3] [--sets 20] [--placements 10]
        [--budget 24] [--out bench-predict-coverage]

Run from the repository's root. The simulator is the analytic test simulator of the test suite
(``tests/fake_sim.py``): on rig R the drift follows mu_d_BePa and the turn mu_d_MePa, E_Pa
hardly acts; on rig Q (a rig file under that name) the turn follows E_Pa too. For each of
``--truths`` hidden truths (seeded fractions of the ranges) it writes a twin dataset of rigs R
and Q at speed settings 1 and 2 (8 runs per case with specimen, placement and tracking
scatter; every rig's runs, R's too, scatter as the calibration's ensemble placements do; before
2026-12-06 R's runs started at the nominal placement, which ``--r-nominal`` repeats),
calibrates on rig R only (both settings jointly, ensemble cost over 2 placements), so
that E_Pa stays undetermined, and predicts the unseen cases Q/1 and Q/2 (``--sets`` parameter
sets from the plausible set times ``--placements`` seeded placements). It prints, per truth,
case and quantity (transit time, rotation, exit heading), the 5-95 % predictive band, the twin
runs inside it and the share of the spread due to the parameters; then the coverage over all:
the share of twin runs inside their band. A calibrated prediction covers about 90 %; far more
means bands wider than needed, far less bands that are too narrow (overconfident).

On MuJoCo the same question needs the twin data of a rig the calibration did not use and hours
of simulation; this benchmark checks the prediction's logic (sampling the plausible set,
placements, the band) where a run costs nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # tests.fake_sim

import bench_twin

PARAMETERS = {"mu_d_BePa": [0.3, 0.55], "mu_d_MePa": [0.15, 0.35], "E_Pa": [200.0, 1600.0]}
QUANTITIES = ("transit_time", "rotation", "exit_heading")


def coverage_row(summary, real: list[dict], band: tuple[float, float]) -> dict[str, object]:
    """One quantity's coverage: how many of the ``real`` runs' values lie inside the model's
    5-95 % band (``summary``, a `QuantitySummary`) and inside ``band`` (a real run's)."""
    q = summary.quantity
    values = [v[q] for v in real if v[q] is not None]
    lo, hi = band
    return {
        "quantity": q,
        "q05": summary.q05,
        "q95": summary.q95,
        "inside": sum(summary.q05 <= v <= summary.q95 for v in values),
        "run_q05": lo,
        "run_q95": hi,
        "inside_run_band": sum(lo <= v <= hi for v in values),
        "runs": len(values),
        "parameter_share": summary.decomposition.parameter_share,
    }


def row_text(row: dict[str, object]) -> str:
    """The columns of a coverage row after its case (quantity, bands, counts, share)."""
    n = row["runs"]
    inside, inside_run = f"{row['inside']}/{n}", f"{row['inside_run_band']}/{n}"
    return (
        f"{row['quantity']:<14}{row['q05']:>10.4g}{row['q95']:>10.4g}"
        f"{inside:>8}{row['run_q05']:>10.4g}{row['run_q95']:>10.4g}"
        f"{inside_run:>8}{row['parameter_share']:>18.2f}"
    )


def truth_for(k: int) -> dict[str, float]:
    """Truth ``k``: catalogue values at seeded fractions 0.2-0.8 of the ranges."""
    fractions = np.random.default_rng([k, 53]).uniform(0.2, 0.8, len(PARAMETERS))
    return bench_twin.truth_values([float(f) for f in fractions], PARAMETERS)


def calibrate(
    k: int, budget: int, out: Path, nominal_rigs: tuple[str, ...] = ()
) -> tuple[Path, Path]:
    """Truth ``k``'s twin dataset (the runs on ``nominal_rigs`` at the nominal placement) and
    its calibration on rig R (folders)."""
    from tests.fake_sim import write_reference_dataset

    from parcelfit.sim.params import CATALOGUE
    from parcelfit.study.calibration import Calibration
    from parcelfit.study.studyfile import load_study

    specs = {p.name: p for p in CATALOGUE}
    truth_si = {n: specs[n].to_si(v) for n, v in truth_for(k).items()}
    data = out / f"truth{k + 1}" / "data"
    if not (data / "dataset.yaml").is_file():
        write_reference_dataset(
            data, rigs=("R", "Q"), truth=truth_si, seed=500 + k, nominal_rigs=nominal_rigs
        )
    setup = bench_twin.Setup(
        "fit-R",
        {
            "cases": [
                {"dataset": "{dataset}", "rig": "R", "speed_setting": 1},
                {"rig": "R", "speed_setting": 2},
            ],
            "cost": {"kind": "ensemble", "placements": 2},
        },
    )
    path = bench_twin.write_study_file(
        out / f"truth{k + 1}",
        setup,
        {"backend": "python", "factory": "tests.fake_sim:make", "consignment": "P"},
        PARAMETERS,
        data,
        seed=k,
        extra={"initial": 8, "batch_size": 4, "budget": budget, "executor": "serial"},
    )
    folder = out / f"truth{k + 1}" / setup.name
    Calibration(load_study(path), folder, figures=False, key_frames=False).run()
    return data, folder


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--truths", type=int, default=3)
    ap.add_argument("--sets", type=int, default=20)
    ap.add_argument("--placements", type=int, default=10)
    ap.add_argument("--budget", type=int, default=24, help="evaluations per calibration")
    ap.add_argument("--out", type=Path, default=Path("bench-predict-coverage"))
    bench_twin.add_analytic_arguments(ap, mirrored=False)
    args = ap.parse_args()

    from tests.predict_helpers import write_rig_q

    from parcelfit.runs import load_dataset
    from parcelfit.study.predict import load_inputs, predict, run_values
    from parcelfit.study.run_scatter import estimate_run_scatter, real_run_band

    nominal = bench_twin.analytic_nominal_rigs(args.out, args.r_nominal)
    rig_q = write_rig_q(args.out)
    inside = {q: 0 for q in QUANTITIES}
    inside_real = {q: 0 for q in QUANTITIES}
    total = {q: 0 for q in QUANTITIES}
    rows = []
    t0 = time.perf_counter()
    print(
        f"{'truth':<7}{'case':<6}{'quantity':<14}{'q05':>10}{'q95':>10}{'inside':>8}"
        f"{'run q05':>10}{'run q95':>10}{'inside':>8}{'parameters share':>18}"
    )
    for k in range(args.truths):
        data, folder = calibrate(k, args.budget, args.out, nominal)
        dataset = load_dataset(data)
        inputs = load_inputs(folder)
        scatter = estimate_run_scatter(inputs.folder, inputs.study)
        for setting in (1, 2):
            p = predict(
                folder,
                str(rig_q),
                "KPBW",  # a type predict accepts; the analytic simulator ignores it
                setting,
                sets=args.sets,
                placements=args.placements,
                seed=k,
                out=args.out / f"truth{k + 1}" / f"predict-Q{setting}",
                executor="serial",
            )
            real = [
                run_values(r)
                for c in dataset.cases.values()
                if (c.case.rig, c.case.speed_setting) == ("Q", setting)
                for r in c.runs
            ]
            for s in p.summaries:
                if s.quantity not in QUANTITIES:
                    continue
                band = real_run_band(p.runs[s.quantity].tolist(), s.quantity, scatter, k)
                row = coverage_row(s, real, band)
                inside[s.quantity] += row["inside"]
                inside_real[s.quantity] += row["inside_run_band"]
                total[s.quantity] += row["runs"]
                rows.append({"truth": k + 1, "case": f"Q/{setting}", **row})
                print(f"{k + 1:<7}{'Q/' + str(setting):<6}{row_text(row)}", flush=True)
    (args.out / "results.json").write_text(json.dumps(rows, indent=1))
    all_in, all_n = sum(inside.values()), sum(total.values())
    real_in = sum(inside_real.values())
    print(
        f"\ncoverage of the 90 % bands over {args.truths} truths (unseen cases Q/1 and Q/2): "
        "the model's band, and the band of a real run (with the real runs' own scatter, "
        "parcelfit.study.run_scatter)"
    )
    for q in QUANTITIES:
        n = max(total[q], 1)
        print(
            f"  {q:<14}{inside[q]}/{total[q]} = {inside[q] / n:.0%}"
            f"   {inside_real[q]}/{total[q]} = {inside_real[q] / n:.0%}"
        )
    print(
        f"  {'all':<14}{all_in}/{all_n} = {all_in / max(all_n, 1):.0%}"
        f"   {real_in}/{all_n} = {real_in / max(all_n, 1):.0%}"
        f"   ({(time.perf_counter() - t0) / 60:.1f} min)"
    )


if __name__ == "__main__":
    main()
