"""Can friction alone make a type spin? Ensembles over a grid of belt and plate friction.

    python scripts/friction_sweep.py --rig E3 --types BW
    python scripts/friction_sweep.py --types BW KP --placements 20 --belt 0.3 0.6 --metal 0.15 0.35

For each consignment type and each (mu_d_BePa, mu_d_MePa) pair (the other parameters at their
defaults) it simulates the placement seeds 0..N-1 at speed setting 1 and reports the median
absolute rotation, the spins (> 90 degrees), the share above 180 degrees, the median transit
time, Spearman's rho of rotation and transit time, and every run's rotation. Writes
``friction-sweep-<rig>.md`` into ``--out`` (default docs/research/) and prints the rows as they finish.
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from parcelfit.runs import TestCase
from parcelfit.sim.ensemble import simulate_ensemble, summarise
from parcelfit.sim.mujoco import MujocoSimulator, load_rig


class _Factory:
    """Picklable ``seed -> simulator`` on one rig file."""

    def __init__(self, rig_arg: str) -> None:
        self.rig_arg = rig_arg

    def __call__(self, seed: int) -> MujocoSimulator:
        rig = load_rig(self.rig_arg)
        return MujocoSimulator(rigs={rig.name: rig}).with_placement(seed)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rig", default="E3", help="bundled rig name or a rig YAML file")
    ap.add_argument("--types", nargs="+", default=["BW"])
    ap.add_argument("--placements", type=int, default=10)
    ap.add_argument("--belt", nargs="+", type=float, default=[0.3, 0.45, 0.6])
    ap.add_argument("--metal", nargs="+", type=float, default=[0.15, 0.35])
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", type=Path, default=Path("docs/research"))
    args = ap.parse_args(argv)

    rig = load_rig(args.rig)
    factory = _Factory(args.rig)
    seeds = list(range(args.placements))
    lines = [
        f"# Friction sweep on {rig.name} ({Path(args.rig).name})",
        "",
        f"Written by `python scripts/friction_sweep.py --rig {args.rig} --types "
        f"{' '.join(args.types)} --placements {args.placements} --belt "
        f"{' '.join(f'{b:g}' for b in args.belt)} --metal "
        f"{' '.join(f'{m:g}' for m in args.metal)}`: speed setting 1, placement seeds "
        f"0-{args.placements - 1}, all other parameters at their defaults. Rotation: net change "
        "of heading; spin: rotation above 90 degrees; rho: Spearman's rank correlation of "
        "rotation and transit time.",
        "",
        "| type | mu_d_BePa | mu_d_MePa | median rotation [deg] | spins | > 180 deg | "
        "median T [ms] | rho | rotations [deg] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    with ProcessPoolExecutor(args.workers) as pool:
        for cons in args.types:
            consignment = factory(0).consignment(cons)
            for belt, metal in itertools.product(args.belt, args.metal):
                params = consignment.parameter_values({"mu_d_BePa": belt, "mu_d_MePa": metal})
                members = simulate_ensemble(
                    factory, params, TestCase(rig.name, cons, 1), seeds, executor=pool
                )
                s = summarise(members)
                rotations = sorted(
                    round(math.degrees(m.rotation)) for m in members if m.rotation is not None
                )
                row = (
                    f"| {cons} | {belt:g} | {metal:g} | {math.degrees(s.rotation_median):.0f} | "
                    f"{s.spins}/{s.n} | {s.share_over_180:.0%} | {s.transit_median * 1e3:.0f} | "
                    f"{s.rank_correlation:.2f} | {', '.join(map(str, rotations))} |"
                )
                lines.append(row)
                print(row, flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    target = args.out / f"friction-sweep-{Path(args.rig).stem}.md"
    target.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"written: {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
