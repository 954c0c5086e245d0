"""How far does one parameter change move an ensemble? From two `parcelfit simulate --repeat` tables.

    parcelfit simulate --rig E3 --consignment KPBW --setting 1 --set E_Pa=200 --repeat 20 --out low.csv
    parcelfit simulate --rig E3 --consignment KPBW --setting 1 --set E_Pa=1600 --repeat 20 --out high.csv
    python scripts/ensemble_effect.py low-ensemble.csv high-ensemble.csv

Each side may be several tables (e.g. placements 0-5 and 6-19 run apart: ``--low A.csv B.csv
--high C.csv D.csv``); placements are matched by seed. Prints the change high - low of the
ensemble statistics over the matched placements (`parcelfit.sim.ensemble.ensemble_shift`: the
median rotation, the median transit time and the share of spins, each with its paired bootstrap
standard error and the ratio), and the mean of the paired differences of rotation and transit
time with their standard errors (the placements' own scatter removed by the pairing), their
median and the sign test of how many placements went up; the same over the placements that
slide at both ends (a catch on the guide plate, a spin, is a branch; a slide's change is the
parameter's effect on the path).

With ``--dataset DIR --case RIG/TYPE/SETTING`` it also prints the change of the mean calibration
cost (method.md eq. 3) of the ensemble's runs against the case's reference run (chosen from the
dataset's runs as a study chooses it), and of its two DTW distances, with their paired bootstrap
standard errors: the ensemble statistic "mean DTW to the reference run". The runs are read from
the trajectory files `simulate --repeat` wrote beside each table (``OUT-s<seed>.csv``).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from parcelfit.metrics.cost import calibration_cost
from parcelfit.metrics.reference import select_reference
from parcelfit.runs.dataset import load_dataset
from parcelfit.runs.io import read_trajectory
from parcelfit.sim.ensemble import Member, ensemble_shift, paired_difference
from parcelfit.sim.protocol import SimStatus


def members(paths: list[Path]) -> list[Member]:
    """The ensemble members of ``simulate --repeat`` tables (seed, status, transit_time_s,
    rotation_deg), later tables overriding a seed."""
    by_seed: dict[int, Member] = {}
    for path in paths:
        for r in pd.read_csv(path).itertuples(index=False):
            ok = r.status == "ok"
            by_seed[int(r.seed)] = Member(
                seed=int(r.seed),
                status=SimStatus(r.status),
                transit_time=float(r.transit_time_s) if ok and pd.notna(r.transit_time_s) else None,
                rotation=math.radians(float(r.rotation_deg)) if ok else None,
                run=None,
                wall_time=float(r.wall_time_s),
            )
    return [by_seed[s] for s in sorted(by_seed)]


def reference_costs(paths: list[Path], dataset: Path, case: str) -> dict[int, np.ndarray]:
    """Per placement seed, (cost, DTW_xy [m], DTW_theta [rad]) of its run against the reference
    run of ``case`` in ``dataset`` (later tables overriding a seed); failed runs left out."""
    reference = select_reference(load_dataset(dataset)[case])
    out: dict[int, np.ndarray] = {}
    for path in paths:
        if not str(path).endswith("-ensemble.csv"):
            raise SystemExit(
                f"{path}: --dataset needs the table `simulate --repeat` wrote (OUT-ensemble.csv),"
                " with its runs OUT-s<seed>.csv beside it"
            )
        for r in pd.read_csv(path).itertuples(index=False):
            if r.status != "ok":
                continue
            run = Path(str(path).replace("-ensemble.csv", f"-s{int(r.seed)}.csv"))
            c = calibration_cost(read_trajectory(run), reference)
            out[int(r.seed)] = np.array([c.value, c.dtw_xy, c.dtw_theta])
    return out


def print_reference_shift(low: dict[int, np.ndarray], high: dict[int, np.ndarray], seed: int):
    """The change of the mean cost and DTW distances to the reference run, high - low, over the
    placements both ran, with paired bootstrap standard errors."""
    seeds = sorted(set(low) & set(high))
    a = np.array([low[s] for s in seeds])
    b = np.array([high[s] for s in seeds])
    print(f"against the reference run, {len(seeds)} matched placements:")
    for j, (name, scale) in enumerate(
        (
            ("mean cost (eq. 3) [-]", 1.0),
            ("mean DTW_xy [mm]", 1e3),
            ("mean DTW_theta [deg]", 180 / math.pi),
        )
    ):
        change, se = paired_difference(a[:, j] * scale, b[:, j] * scale, np.mean, seed)
        ratio = abs(change) / se if se > 0 else math.inf
        print(
            f"{name:<24}{change:>10.3f}{se:>9.3f}{ratio:>8.1f}   (low {a[:, j].mean() * scale:.3f},"
            f" SE of the low mean {a[:, j].std(ddof=1) * scale / math.sqrt(len(a)):.3f})"
        )


def print_paired_changes(pairs: list[tuple[Member, Member]], label: str) -> None:
    """The mean paired change high - low of rotation [deg] and transit time [ms] over
    ``pairs`` of placements, its standard error, median and sign test."""
    for name, attr, scale in (
        ("rotation [deg]", "rotation", math.degrees(1)),
        ("transit [ms]", "transit_time", 1e3),
    ):
        d = (
            np.array(
                [
                    getattr(y, attr) - getattr(x, attr)
                    for x, y in pairs
                    if getattr(x, attr) is not None and getattr(y, attr) is not None
                ]
            )
            * scale
        )
        if d.size >= 2:
            se = d.std(ddof=1) / math.sqrt(d.size)
            up, n = int(np.sum(d > 0)), int(np.sum(d != 0))
            p_sign = stats.binomtest(up, n).pvalue if n else math.nan
            print(
                f"mean paired change of {name}{label}: {d.mean():.2f} (SE {se:.2f}, ratio "
                f"{abs(d.mean()) / se if se > 0 else math.inf:.1f}); median {np.median(d):.2f};"
                f" {up} of {n} up, {n - up} down (sign test p = {p_sign:.2g})"
            )


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--low", nargs="+", type=Path, required=True)
    ap.add_argument("--high", nargs="+", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=0, help="seed of the bootstrap")
    ap.add_argument("--dataset", type=Path, help="dataset folder holding the reference run")
    ap.add_argument("--case", help="test case of the reference run, e.g. E3/KPBW/1")
    args = ap.parse_args()
    if (args.dataset is None) != (args.case is None):
        ap.error("--dataset and --case go together")
    a, b = members(args.low), members(args.high)
    shift = ensemble_shift(a, b, seed=args.seed)
    print(f"matched placements: {shift.n_pairs}")
    rows = [
        (
            "median rotation [deg]",
            math.degrees(shift.rotation_median),
            math.degrees(shift.rotation_median_se),
        ),
        ("median transit [ms]", 1e3 * shift.transit_median, 1e3 * shift.transit_median_se),
        ("share of spins [-]", shift.spin_share, shift.spin_share_se),
    ]
    print(f"{'statistic':<24}{'change':>10}{'SE':>9}{'ratio':>8}")
    for name, change, se in rows:
        ratio = abs(change) / se if se > 0 else math.inf if change else math.nan
        print(f"{name:<24}{change:>10.2f}{se:>9.2f}{ratio:>8.1f}")
    by_seed = {m.seed: m for m in b}
    pairs = [(m, by_seed[m.seed]) for m in a if m.seed in by_seed]
    slides = [(x, y) for x, y in pairs if x.outcome == "slide" and y.outcome == "slide"]
    for label, chosen in (("", pairs), (f" over the {len(slides)} slides at both ends", slides)):
        print_paired_changes(chosen, label)
    n_spin = [sum(m.outcome == "spin" for m in e) for e in (a, b)]
    print(f"spins: {n_spin[0]} of {len(a)} (low), {n_spin[1]} of {len(b)} (high)")
    if args.dataset is not None:
        print_reference_shift(
            reference_costs(args.low, args.dataset, args.case),
            reference_costs(args.high, args.dataset, args.case),
            args.seed,
        )


if __name__ == "__main__":
    main()
