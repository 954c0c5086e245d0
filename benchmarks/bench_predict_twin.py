"""Calibrate, design and predict with MuJoCo on the bundled twin: the wall time of each stage,
and whether the prediction's 90 % band holds the twin runs of cases the calibration never saw.

    python benchmarks/bench_predict_twin.py [--study examples/e3-kpbw/study.yaml]
        [--unseen E1/KPBW/1,E1/KPBW/2,E1/KPBW/3] [--candidates E3/KPBW/2,E1/KPBW/1,...]
        [--sets 10] [--placements 4] [--design-sets 10] [--design-placements 3]
        [--workers 2] [--out bench-predict-twin]

Run from the repository's root. The three stages a user runs, as library calls, each into its
own folder under ``--out`` (a rerun resumes every stage and times only what was left):

1. the calibration of ``--study`` (default: the E3 KP/BW study of the examples, fitted on E3
   at speed setting 1 and validated at setting 2 against the bundled SYNTHETIC twin);
2. ``design`` over ``--candidates`` (``--design-sets`` x ``--design-placements`` each);
3. ``predict`` of every ``--unseen`` case (``--sets`` x ``--placements`` each): rig/type/setting
   cases of the twin dataset the calibration did not use (default: E1 with KP/BW at its three
   speed settings).

Then per unseen case and quantity (transit time, rotation, exit position, exit heading) the
5-95 % band of the model's runs and of a real run (with the real runs' own scatter,
``parcelfit.study.run_scatter``), and how many of the twin's runs of that case lie inside each;
the coverage over all; the wall time per stage and in all. One truth (the twin's), so the
coverage is of one calibration: a calibrated band holds about 90 % of the runs.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_predict_coverage import coverage_row, row_text
from machine_load import (
    Watch,
    installed,
    other_work_now,
    processor,
    report_machine,
    usable_cores,
)

QUANTITIES = ("transit_time", "rotation", "exit_y", "exit_heading")
DEFAULT_CANDIDATES = "E3/KPBW/2,E1/KPBW/1,E1/KPBW/3,E3/BW/1"


def _case(label: str) -> tuple[str, str, int]:
    """'RIG/TYPE/SETTING' -> (rig, type, setting); RIG may be a rig file's path."""
    rig, kind, setting = label.rsplit("/", 2)
    return rig, kind, int(setting)


def predict_cases(
    folder: Path,
    dataset_dir: Path,
    unseen: list[str],
    *,
    sets: int,
    placements: int,
    seed: int,
    out: Path,
    workers: int,
    numerical_runs: int | None = None,
) -> tuple[list[dict], dict[str, list[int]], float]:
    """``predict`` every ``unseen`` case (RIG/TYPE/SETTING, RIG a bundled name or a rig file)
    from the calibration in ``folder`` and count the runs of ``dataset_dir`` inside each band;
    prints a row per case and quantity. Returns the rows, per quantity [inside the model's
    band, inside the band of a real run, runs, inside that band without the model's numerical
    error], and the wall time [s]. ``numerical_runs``: the
    placements of predict's numerical error (None: predict's default; 0: none)."""
    from parcelfit.runs import load_dataset
    from parcelfit.study.numerical_error import NUMERICAL_RUNS
    from parcelfit.study.predict import predict, run_values, shown_value
    from parcelfit.study.run_scatter import real_run_band

    dataset = load_dataset(dataset_dir)
    rows = []
    inside = {q: [0, 0, 0, 0] for q in QUANTITIES}
    seconds = 0.0
    print(
        f"{'case':<12}{'quantity':<14}{'q05':>10}{'q95':>10}{'inside':>8}"
        f"{'run q05':>10}{'run q95':>10}{'inside':>8}{'parameters share':>18}"
    )
    for label in unseen:
        rig, kind, setting = _case(label)
        name = Path(rig).stem
        t = time.perf_counter()
        p = predict(
            folder,
            rig,
            kind,
            setting,
            sets=sets,
            placements=placements,
            seed=seed,
            out=out / f"predict-{name}-{kind}-{setting}",
            workers=workers,
            numerical_runs=NUMERICAL_RUNS if numerical_runs is None else numerical_runs,
        )
        seconds += time.perf_counter() - t
        err = p.numerical
        if err is not None and err.reason is None:
            shown = ", ".join(
                f"{q} {v * 100:.2g} %" if q == "transit_time" else f"{q} {shown_value(q, v, 2)}"
                for q, v in err.sd.items()
                if q in QUANTITIES
            )
            print(
                f"{label}: the model's numerical error (sd; refined {err.refinement} times, "
                f"{err.pairs} placements, {err.changed} changing outcome): {shown}",
                flush=True,
            )
        elif err is not None:
            print(f"{label}: no numerical error ({err.reason})", flush=True)
        print(f"{label}: {_simulation_time(out / f'predict-{name}-{kind}-{setting}')}", flush=True)
        real = [
            run_values(r)
            for c in dataset.cases.values()
            if (c.case.rig, c.case.consignment, c.case.speed_setting) == (name, kind, setting)
            for r in c.runs
        ]
        if not real:
            raise SystemExit(f"the twin dataset has no runs of {label}")
        for s in p.summaries:
            if s.quantity not in QUANTITIES:
                continue
            # the band of a real run, as predict reports it
            row = coverage_row(s, real, (s.run_q05, s.run_q95))
            # the same band without the model's numerical error (the same draws): what it adds
            values = [v for v in p.runs[s.quantity].tolist() if v == v]
            lo, hi = real_run_band(values, s.quantity, p.scatter, seed)
            row["inside_without_numerical"] = sum(
                lo <= v[s.quantity] <= hi for v in real if v[s.quantity] is not None
            )
            counts = inside[s.quantity]
            counts[0] += row["inside"]
            counts[1] += row["inside_run_band"]
            counts[2] += row["runs"]
            counts[3] += row["inside_without_numerical"]
            rows.append({"case": f"{name}/{kind}/{setting}", **row})
            print(f"{name + '/' + kind + '/' + str(setting):<12}{row_text(row)}", flush=True)
    return rows, inside, seconds


def _simulation_time(folder: Path) -> str:
    """From a prediction's store: the simulation time [s] summed by kind (the prediction's
    own runs, the real runs' scatter's, the numerical error's on the model and refined, each
    simulated here), the runs taken from other predictions, the
    numerical error's share, and a refined run's mean time over a model run's."""
    from parcelfit.study.predict import MODEL_ITERATION, PREDICT_STORE, REFINED_ITERATION
    from parcelfit.study.shared_runs import reused_ids
    from parcelfit.study.store import Store

    store = Store(folder / PREDICT_STORE, readonly=True)
    try:
        taken = reused_ids(store)  # runs another prediction simulated: no time here
        rows = [
            e for e in store.evaluations("screen") if e.wall_time is not None and e.id not in taken
        ]
    finally:
        store.close()

    def total(keep) -> tuple[float, int]:
        mine = [e.wall_time for e in rows if keep(e.iteration)]
        return float(sum(mine)), len(mine)

    own, scatter = total(lambda i: i == 0), total(lambda i: i > 0)
    model, refined = total(lambda i: i == MODEL_ITERATION), total(lambda i: i == REFINED_ITERATION)
    everything = own[0] + scatter[0] + model[0] + refined[0]
    ratio = (refined[0] / refined[1]) / (model[0] / model[1]) if model[1] and refined[1] else 0.0
    return (
        f"simulation time {own[0]:.0f} s for {own[1]} runs of the prediction, {scatter[0]:.0f} s "
        f"for {scatter[1]} of the scatter, {model[0]:.0f} s and {refined[0]:.0f} s for "
        f"{model[1]} and {refined[1]} of the numerical error on the model and refined: the "
        f"numerical error {(model[0] + refined[0]) / max(everything, 1e-9):.0%} of it, a refined "
        f"run {ratio:.2f} times a model run; {len(taken)} more runs taken from other predictions"
    )


def print_coverage(inside: dict[str, list[int]]) -> None:
    """The coverage per quantity and over all (the model's band, the band of a real run, and
    that band without the model's numerical error)."""
    print(
        "\ncoverage of the 90 % bands (the model's band, the band of a real run, the band of a "
        "real run without the model's numerical error):"
    )
    totals = [sum(c[i] for c in inside.values()) for i in range(4)]

    def line(name: str, n_in: int, n_run: int, n: int, n_without: int) -> str:
        return (
            f"  {name:<14}{n_in}/{n} = {n_in / max(n, 1):.0%}   {n_run}/{n} = "
            f"{n_run / max(n, 1):.0%}   {n_without}/{n} = {n_without / max(n, 1):.0%}"
        )

    for q, counts in inside.items():
        print(line(q, *counts))
    print(line("all", *totals))


def main() -> None:
    """Run the three stages and print the coverage table and the timing."""
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--study", type=Path, default=Path("examples/e3-kpbw/study.yaml"))
    ap.add_argument("--unseen", default="E1/KPBW/1,E1/KPBW/2,E1/KPBW/3")
    ap.add_argument("--candidates", default=DEFAULT_CANDIDATES)
    ap.add_argument("--sets", type=int, default=10)
    ap.add_argument("--placements", type=int, default=4)
    ap.add_argument("--design-sets", type=int, default=10)
    ap.add_argument("--design-placements", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--numerical-runs",
        type=int,
        default=None,
        help="predict's placements for the model's numerical error (default: predict's; 0: none)",
    )
    ap.add_argument("--out", type=Path, default=Path("bench-predict-twin"))
    args = ap.parse_args()

    from parcelfit.study.calibration import Calibration
    from parcelfit.study.design import rank_experiments
    from parcelfit.study.studyfile import load_study

    args.out.mkdir(parents=True, exist_ok=True)
    other = other_work_now()
    print(
        f"processor: {processor()}, {usable_cores()} usable cores; other work just before the "
        + ("start: not measured" if other is None else f"start: {other:.2f} cores busy"),
        flush=True,
    )
    print(f"installed: {installed(('mujoco', 'numba', 'numpy', 'scipy', 'scikit-learn'))}")
    watch = Watch()
    study = load_study(args.study)
    folder = args.out / "calibration"
    seconds: dict[str, float] = {}

    t = time.perf_counter()
    result = Calibration(study, folder, workers=args.workers).run()
    seconds["calibrate"] = time.perf_counter() - t
    print(
        f"calibrate: {result.evaluations} evaluations, validated {result.validated}, "
        f"{seconds['calibrate'] / 60:.1f} min",
        flush=True,
    )

    t = time.perf_counter()
    ranking = rank_experiments(
        folder,
        candidates=args.candidates.split(","),
        sets=args.design_sets,
        placements=args.design_placements,
        seed=args.seed,
        out=args.out / "design",
        workers=args.workers,
    )
    seconds["design"] = time.perf_counter() - t
    order = [label for label, _ in ranking.sequence]
    print(
        f"design: open {ranking.parameters or 'none'}; ranking {order or 'none'}; "
        f"{seconds['design'] / 60:.1f} min",
        flush=True,
    )

    rows, inside, seconds["predict"] = predict_cases(
        folder,
        study.dataset,
        args.unseen.split(","),
        sets=args.sets,
        placements=args.placements,
        seed=args.seed,
        out=args.out,
        workers=args.workers,
        numerical_runs=args.numerical_runs,
    )
    total = sum(seconds.values())
    (args.out / "results.json").write_text(
        json.dumps({"rows": rows, "seconds": seconds, "design_order": order}, indent=1)
    )
    print_coverage(inside)
    print(
        "wall time: "
        + ", ".join(f"{k} {v / 60:.1f} min" for k, v in seconds.items())
        + f"; in all {total / 60:.1f} min on {args.workers} processes"
    )
    # the workers have ended by now, so their CPU time is this process's children's; they
    # leave the cores beyond their number free
    free = max(usable_cores() - args.workers, 0)
    print(report_machine("while it ran", None, watch.cores(), free))


if __name__ == "__main__":
    main()
