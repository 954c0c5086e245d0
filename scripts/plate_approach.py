"""How close does the model's rigid content come to E3's guide plate: does the packaging's rim
give way at the plate, or hold the content off it?

    python scripts/plate_approach.py
    python scripts/plate_approach.py --types KPBW KP --settings 1 2 --placements 20 --workers 2

For each type and speed setting it runs the MuJoCo model (its defaults; ``--set``: parameters in
catalogue units) at ``--placements`` seeded placements and records after every step the
content's closest approach to the face of a guide plate: the least distance [m] of the corners
of the content's footprint (its box cL x cW at its mid-height, `plate_gap`) from a plate's face,
among the corners within the plate's length. A rim as stiff as the content at the plate (the
rigid-box reference's ``wall_outline: outline``) would keep that gap at the rim's width beyond
the struck edge, less the small penetration of the contact (0.5-1.7 mm in the reference,
`scripts/plate_force.py`); a rim that gives way entirely (``wall_outline: content``) lets it
fall to about zero. Printed per placement: the least gap [mm] and the width of the rim that
faced the plate then (`facing_rim`: the edge whose normal lies nearer the plate's); per type and
setting: the gap's median and range, and the gap over that rim's width. The plates are the
scene's metal box geoms (the guide plate; lead-ins are cylinders and not counted).
"""

from __future__ import annotations

import argparse
import math
import statistics
from concurrent.futures import ProcessPoolExecutor

import mujoco
import numpy as np

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator, SimOptions, load_consignment
from parcelfit.sim.mujoco.friction import Stepper, observed_steps
from parcelfit.sim.params import parameter, parse_assignments


def plate_gap(
    centre: np.ndarray,
    rotation: np.ndarray,
    half: tuple[float, float],
    plate_centre: np.ndarray,
    plate_rotation: np.ndarray,
    plate_half: np.ndarray,
) -> float:
    """The least distance [m] from a plate's face (a box: centre, rotation with its local axes as
    columns, half extents [m]; its face normal along its thinnest axis) of the corners of a
    footprint (``half`` [m] along the body's x and y, at the body's ``centre`` [m] and
    ``rotation``) lying within the plate's extent along its other two axes, measured from the
    face on the footprint centre's side; negative: behind that face; inf: no corner within the
    plate's extent."""
    thin = int(np.argmin(plate_half))
    others = [k for k in range(3) if k != thin]
    hx, hy = half
    corners = np.array([[sx * hx, sy * hy, 0.0] for sx in (-1, 1) for sy in (-1, 1)])
    world = centre + corners @ rotation.T
    local = (world - plate_centre) @ plate_rotation
    within = np.all(np.abs(local[:, others]) <= plate_half[others], axis=1)
    if not within.any():
        return math.inf
    side = 1.0 if float((centre - plate_centre) @ plate_rotation[:, thin]) >= 0 else -1.0
    return float(np.min(side * local[within, thin] - plate_half[thin]))


def facing_rim(rotation: np.ndarray, plate_rotation: np.ndarray, plate_half: np.ndarray,
               outer: tuple[float, float], content: tuple[float, float]) -> float:  # fmt: skip
    """The width [m] of the rim beyond the content's edge that faces the plate: (L - cL) / 2 where
    the body's x axis lies nearer the plate's normal than its y axis, else (W - cW) / 2."""
    normal = plate_rotation[:, int(np.argmin(plate_half))]
    along_x = abs(float(rotation[:, 0] @ normal)) >= abs(float(rotation[:, 1] @ normal))
    return (outer[0] - content[0]) / 2 if along_x else (outer[1] - content[1]) / 2


def least_gap(
    consignment: str, setting: int, seed: int, params: dict[str, float]
) -> tuple[float, float]:
    """The content's least gap [m] to E3's guide plate over one run of the model (`plate_gap`),
    and the width [m] of the rim that faced the plate then (`facing_rim`; nan: no gap)."""
    cons = load_consignment(consignment)
    sim = MujocoSimulator(SimOptions()).with_placement(seed)
    case = TestCase("E3", cons.name, setting)
    scene = sim.scene(params, case)
    half = (cons.content[0] / 2, cons.content[1] / 2)
    found: list[tuple[int, list[int]]] = []
    least = [math.inf, math.nan]

    def look(stepper: Stepper) -> None:
        model, data = stepper.model, stepper.data
        if not found:
            content = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "content")
            plates = [
                g
                for g in (
                    mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in scene.metal_geoms
                )
                if g >= 0 and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX
            ]
            found.append((content, plates))
        content, plates = found[0]
        centre = data.xpos[content]
        rotation = data.xmat[content].reshape(3, 3)
        for g in plates:
            gap = plate_gap(
                centre,
                rotation,
                half,
                data.geom_xpos[g],
                data.geom_xmat[g].reshape(3, 3),
                model.geom_size[g],
            )
            if gap < least[0]:
                least[0] = gap
                least[1] = facing_rim(
                    rotation,
                    data.geom_xmat[g].reshape(3, 3),
                    model.geom_size[g],
                    cons.outer[:2],
                    cons.content[:2],
                )

    with observed_steps(look):
        sim.run(params, case)
    return least[0], least[1]


def _gap(job: tuple) -> tuple[float, float]:
    return least_gap(*job)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--types", nargs="+", default=["KPBW", "KP"])
    ap.add_argument("--settings", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--placements", type=int, default=20)
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE")
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args(argv)
    if args.placements < 1 or args.workers < 1:
        ap.error("--placements and --workers must be at least 1")
    user = {k: parameter(k).to_si(v) for k, v in parse_assignments(args.set).items()}
    line = f"python scripts/plate_approach.py --types {' '.join(args.types)} --settings "
    line += f"{' '.join(map(str, args.settings))} --placements {args.placements}"
    if args.set:
        line += f" --set {' '.join(args.set)}"
    print(f"Written by `{line}`.")
    with ProcessPoolExecutor(args.workers) as pool:
        for name in args.types:
            cons = load_consignment(name)
            if cons.soft:
                print(f"\n{name}: skipped (a soft content: no rigid footprint to measure from)")
                continue
            (L, W, _), (cL, cW, _) = cons.outer, cons.content
            print(
                f"\n{name}: rim {(W - cW) / 2 * 1e3:g} mm wide along the long edges, "
                f"{(L - cL) / 2 * 1e3:g} mm along the short ones"
            )
            for setting in args.settings:
                jobs = [(name, setting, s, user) for s in range(args.placements)]
                found = list(pool.map(_gap, jobs))
                print(f"setting {setting}, per placement (seed 0, 1, ...):")
                print(
                    "the content's least gap to the plate [mm]: "
                    + ", ".join(f"{g * 1e3:.1f}" for g, _ in found)
                )
                print(
                    "the facing rim's width then [mm]: "
                    + ", ".join(f"{r * 1e3:g}" for _, r in found)
                )
                met = [(g, r) for g, r in found if math.isfinite(g)]
                if not met:
                    print("no placement came within the plate's extent")
                    continue
                gaps = [g for g, _ in met]
                shares = [g / r for g, r in met]
                print(
                    f"median gap {statistics.median(gaps) * 1e3:.1f} mm (range "
                    f"{min(gaps) * 1e3:.1f}-{max(gaps) * 1e3:.1f}); the gap over the facing "
                    f"rim's width: median {statistics.median(shares):.2f}, range "
                    f"{min(shares):.2f}-{max(shares):.2f} over {len(met)} placements (1: the rim "
                    "held its width, 0: it gave way entirely)"
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
