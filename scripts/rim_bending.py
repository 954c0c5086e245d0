"""How much of a parcel's weight its rim carries in the rigid-box reference's ``rim-bending`` patch.

    python scripts/rim_bending.py
    python scripts/rim_bending.py --types KPBW KP --spacings 0.01 0.005 0.0025

For each consignment type with a rigid content and no bulge it prints the rim's bending length
lambda = (4 D / k_f)^(1/4) (`parcelfit.sim.rigidbox.geometry.rim_bending_length`) and the share of
the weight lying flat that rests outside the content's footprint, at the catalogue's defaults
and at the corners of the ranges of E_Pa, t_Pa and k_BePa (the sheet's stiffness against the
belt contact's), on the reference's default grid and finer ones (each node's load spread over its
cell), and at the finest spacing the share more than ``--beyond`` (5 mm) outside the footprint,
the margin `scripts/friction_budget.py` counts the model's rim load beyond; beside it the rim's
own weight and, measured the same way, the ``rim-weight`` patch (whose
nodes outside the footprint carry exactly the own weight; the footprint's edge nodes' cells reach
beyond it) and the ``outline`` patch.
"""

from __future__ import annotations

import argparse
import itertools

from parcelfit.sim.mujoco import load_consignment
from parcelfit.sim.params import parameter
from parcelfit.sim.rigidbox.geometry import parcel_body, rim_bending_length, rim_load_share


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--types", nargs="+", default=["KPBW", "KP"])
    ap.add_argument("--spacings", nargs="+", type=float, default=[0.01, 0.005, 0.0025])
    ap.add_argument(
        "--beyond",
        type=float,
        default=0.005,
        help="also the share more than this far beyond the footprint [m], at the last spacing "
        "(scripts/friction_budget.py's margin)",
    )
    args = ap.parse_args(argv)
    far = f"beyond {args.beyond * 1e3:g} mm"
    for name in args.types:
        cons = load_consignment(name)
        if cons.soft or cons.bulge is not None:
            print(f"{name}: skipped (a soft content or a bulge: no rim-bending patch by default)")
            continue
        L, W, _ = cons.outer
        p = cons.parameter_values()
        kind = cons.content_kind

        print(
            f"\n{name}: outer {L * 1e3:g} x {W * 1e3:g} mm, content "
            f"{cons.content[0] * 1e3:g} x {cons.content[1] * 1e3:g} mm, m_Pa "
            f"{p['m_Pa'] * 1e3:g} g of {cons.mass * 1e3:g} g"
        )
        rows = [("defaults", p["E_Pa"], p["t_Pa"], p["k_BePa"])]
        for E, t, K in itertools.product(
            parameter("E_Pa").si_range(kind),
            parameter("t_Pa").si_range(kind),
            parameter("k_BePa").si_range(kind),
        ):
            rows.append(("corner", E, t, K))
        for E in parameter("E_Pa").si_range(kind):
            rows.append(("E_Pa end", E, p["t_Pa"], p["k_BePa"]))
        head = "| E_Pa [N/mm^2] | t_Pa [mm] | k_BePa [N/mm] | lambda [mm] | "
        head += " | ".join(f"rim share at {s * 1e3:g} mm" for s in args.spacings)
        print(head + f" | {far} | row |")
        print("|" + "---|" * (6 + len(args.spacings)))
        for label, E, t, K in rows:
            lam = rim_bending_length(E, t, p["nu_Pa"], K, L * W)
            shares = []
            for s in args.spacings:
                body = parcel_body(cons, p["m_Pa"], s, "rim-bending", lam)
                shares.append(rim_load_share(cons, body))
            shares.append(rim_load_share(cons, body, args.beyond))
            cells = " | ".join(f"{x:.3f}" for x in shares)
            print(
                f"| {E / 1e6:g} | {t * 1e3:g} | {K / 1e3:g} | {lam * 1e3:.2f} | {cells} | {label} |"
            )
        cL, cW, _ = cons.content
        own = p["m_Pa"] * (1 - cL * cW / (L * W)) / cons.mass
        print(f"the rim's own weight: {own:.3f} of the weight")
        for patch in ("rim-weight", "outline"):
            shares = []
            for s in args.spacings:
                body = parcel_body(cons, p["m_Pa"], s, patch)
                shares.append(rim_load_share(cons, body))
            cells = ", ".join(f"{x:.3f}" for x in shares)
            print(
                f"{patch} patch, spread over cells: {cells}; {far}: "
                f"{rim_load_share(cons, body, args.beyond):.3f}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
