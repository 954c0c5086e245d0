"""Does a parcel model keep and lose its spin as a body should? (`parcelfit.sim.mujoco.spin`)

    python scripts/spin_check.py [--types BW KPBW KP] [--dofs full quadratic]
                                 [--steps 600 1200 2400] [--w0 10] [--plates one 0.05]
                                 [--scene KEY=VALUE ...] [--out docs]

For each rigid-content type, shell degrees of freedom (`SceneOptions.shell_dof`) and time step
(1/N s) the parcel, settled on a still belt-material plate, is kicked to w0 rad/s about the
vertical: in free flight (gravity off) the fraction of the spin its content keeps after 0.1 s
(1 for a faithful model), and on the plate the turn until friction stops it beside the rigid
Coulomb estimate from the model's own contact forces at rest, with their lever (the mean
distance of the plate's contacts from the centre, weighted by their forces) and the load between
packaging and content at rest beside the content's weight. ``--plates``: the
plate as one surface ("one") and/or as square tiles of the given side [m], physically the same
plate; a model whose turn depends on the split is not converged in it. A type may be a
consignment file (e.g. a variant with another content size); ``--scene`` sets other scene
options (e.g. ``spacing=0.06``). Writes ``spin-check.md``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco import load_consignment
from parcelfit.sim.mujoco.options import scene_options
from parcelfit.sim.mujoco.spin import spin_test


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--types", nargs="+", default=["BW", "KPBW", "KP"])
    ap.add_argument("--dofs", nargs="+", default=["full", "quadratic"])
    ap.add_argument("--steps", nargs="+", type=int, default=[600, 1200, 2400])
    ap.add_argument("--w0", type=float, default=10.0, help="[rad/s]")
    ap.add_argument(
        "--plates",
        nargs="+",
        default=["one"],
        help="'one' (a single plate) and/or tile sides [m] of a plate split into square tiles",
    )
    ap.add_argument(
        "--scene",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="scene options other than the defaults (e.g. spacing=0.06)",
    )
    ap.add_argument("--out", type=Path, default=Path("docs/research"))
    args = ap.parse_args(argv)
    try:
        plates = [None if p == "one" else float(p) for p in args.plates]
    except ValueError:
        ap.error(f"--plates: give 'one' or tile sides in metres, got {' '.join(args.plates)}")
    if any(item.partition("=")[0].strip() in ("shell_dof", "timestep") for item in args.scene):
        ap.error("--scene: give the shell and the step with --dofs and --steps")
    try:
        base = scene_options(args.scene)
    except ParcelfitError as exc:
        ap.error(f"--scene: {exc}")
    lines = [
        "# Spin check: does the parcel keep and lose its spin as a body should?",
        "",
        f"Written by `python scripts/spin_check.py --types {' '.join(args.types)} --dofs "
        f"{' '.join(args.dofs)} --steps {' '.join(map(str, args.steps))} --w0 {args.w0:g} "
        f"--plates {' '.join(args.plates)}"
        + (f" --scene {' '.join(args.scene)}" if args.scene else "")
        + "` "
        "(`parcelfit.sim.mujoco.spin`, default parameters). Free flight: the fraction of the "
        f"kick ({args.w0:g} rad/s about the vertical) the content still has after 0.1 s with "
        "gravity off (1 for a faithful model). Spin-down: the turn on a still belt-material "
        "plate until friction stops it, beside the rigid Coulomb estimate I w0^2 / (2 mu sum f r) "
        "from the model's own contact forces at rest and its own masses; lever: the plate's "
        "contacts' mean distance from the centre at rest, weighted by their normal forces "
        "(sum f r / sum f); content load: the normal forces between packaging and content at "
        "rest, beside the content's weight (more where the shell clamps it). Plate: one "
        "surface, or square tiles of the given side (physically the same plate; MuJoCo meets "
        "each tile as its own contact pair).",
        "",
        "| type | shell dof | time step | plate | free flight: spin kept | spin-down [deg] | "
        "Coulomb estimate [deg] | lever at rest [mm] | plate contacts | "
        "content load at rest / weight [N] | wall [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    t_all = time.perf_counter()
    for name in args.types:
        cons = load_consignment(name)
        for dof in args.dofs:
            for n in args.steps:
                for tile in plates:
                    t0 = time.perf_counter()
                    opt = replace(base, shell_dof=dof, timestep=1.0 / n)
                    free = spin_test(cons, w0=args.w0, free=True, options=opt, plate_tile=tile)
                    down = spin_test(cons, w0=args.w0, options=opt, plate_tile=tile)
                    est = (
                        "-"
                        if down.coulomb_turn is None
                        else f"{math.degrees(down.coulomb_turn):.1f}"
                    )
                    lever = "-" if down.lever is None else f"{down.lever * 1e3:.1f}"
                    plate = "one" if tile is None else f"tiles {tile * 1e3:g} mm"
                    held = (
                        "-"
                        if down.content_load is None or down.content_weight is None
                        else f"{down.content_load:.2f} / {down.content_weight:.2f}"
                    )
                    row = (
                        f"| {name} | {dof} | 1/{n} s | {plate} | {free.retained:.2f} | "
                        f"{math.degrees(down.turn):.1f} | {est} | {lever} | "
                        f"{down.plate_contacts} | {held} | {time.perf_counter() - t0:.1f} |"
                    )
                    print(row, flush=True)
                    lines.append(row)
    lines += ["", f"Wall time {time.perf_counter() - t_all:.0f} s on one core."]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "spin-check.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
