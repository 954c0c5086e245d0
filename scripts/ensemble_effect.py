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
median and the sign test of how many placements went up.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from parcelfit.sim.ensemble import Member, ensemble_shift
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


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--low", nargs="+", type=Path, required=True)
    ap.add_argument("--high", nargs="+", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=0, help="seed of the bootstrap")
    args = ap.parse_args()
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
                f"mean paired change of {name}: {d.mean():.2f} (SE {se:.2f}, ratio "
                f"{abs(d.mean()) / se if se > 0 else math.inf:.1f}); median {np.median(d):.2f};"
                f" {up} of {n} up, {n - up} down (sign test p = {p_sign:.2g})"
            )
    n_spin = [sum(m.outcome == "spin" for m in e) for e in (a, b)]
    print(f"spins: {n_spin[0]} of {len(a)} (low), {n_spin[1]} of {len(b)} (high)")


if __name__ == "__main__":
    main()
