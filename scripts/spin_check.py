"""Does a parcel model keep and lose its spin as a body should? (`parcelfit.sim.mujoco.spin`)

    python scripts/spin_check.py [--types BW KPBW KP] [--dofs full quadratic]
                                 [--steps 600 1200 2400] [--w0 10] [--out docs]

For each rigid-content type, shell degrees of freedom (`SceneOptions.shell_dof`) and time step
(1/N s) the parcel, settled on a still belt-material plate, is kicked to w0 rad/s about the
vertical: in free flight (gravity off) the fraction of the spin its content keeps after 0.1 s
(1 for a faithful model), and on the plate the turn until friction stops it beside the rigid
Coulomb estimate from the model's own contact forces at rest. Writes ``spin-check.md``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from parcelfit.sim.mujoco import SceneOptions, load_consignment
from parcelfit.sim.mujoco.spin import spin_test


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--types", nargs="+", default=["BW", "KPBW", "KP"])
    ap.add_argument("--dofs", nargs="+", default=["full", "quadratic"])
    ap.add_argument("--steps", nargs="+", type=int, default=[600, 1200, 2400])
    ap.add_argument("--w0", type=float, default=10.0, help="[rad/s]")
    ap.add_argument("--out", type=Path, default=Path("docs"))
    args = ap.parse_args(argv)
    lines = [
        "# Spin check: does the parcel keep and lose its spin as a body should?",
        "",
        f"Written by `python scripts/spin_check.py --types {' '.join(args.types)} --dofs "
        f"{' '.join(args.dofs)} --steps {' '.join(map(str, args.steps))} --w0 {args.w0:g}` "
        "(`parcelfit.sim.mujoco.spin`, default parameters). Free flight: the fraction of the "
        f"kick ({args.w0:g} rad/s about the vertical) the content still has after 0.1 s with "
        "gravity off (1 for a faithful model). Spin-down: the turn on a still belt-material "
        "plate until friction stops it, beside the rigid Coulomb estimate I w0^2 / (2 mu sum f r) "
        "from the model's own contact forces at rest and its own masses.",
        "",
        "| type | shell dof | time step | free flight: spin kept | spin-down [deg] | "
        "Coulomb estimate [deg] | wall [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    t_all = time.perf_counter()
    for name in args.types:
        cons = load_consignment(name)
        for dof in args.dofs:
            for n in args.steps:
                t0 = time.perf_counter()
                opt = SceneOptions(shell_dof=dof, timestep=1.0 / n)
                free = spin_test(cons, w0=args.w0, free=True, options=opt)
                down = spin_test(cons, w0=args.w0, options=opt)
                est = "-" if down.coulomb_turn is None else f"{math.degrees(down.coulomb_turn):.1f}"
                row = (
                    f"| {name} | {dof} | 1/{n} s | {free.retained:.2f} | "
                    f"{math.degrees(down.turn):.1f} | {est} | {time.perf_counter() - t0:.1f} |"
                )
                print(row, flush=True)
                lines.append(row)
    lines += ["", f"Wall time {time.perf_counter() - t_all:.0f} s on one core."]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "spin-check.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
