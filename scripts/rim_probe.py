"""Does the packaging's Young's modulus E_Pa reach the rim of a mailer in the model?

A parcel lies flat on a still metal plate. Its rim beyond the content's end (the packaging between
the content and the seam) is lifted at the seam by an upward force F [N], spread over the bodies
that carry the seam's end (the flex vertices of a full shell, the end plane's nodes of an
interpolated one); the content stays on the plate. After settling, the seam end's mean height is
read at two forces, and the rim's compliance is

    c = (z(F2) - z(F1)) / (F2 - F1)        [m/N]

A rim that bends as a plate does has c proportional to 1 / E_Pa (a cantilever: c = a^3 / (3 D b),
D = E t^3 / (12 (1 - nu^2))), so c(E_Pa = 200) / c(E_Pa = 1600) would be 8; a rim that cannot bend
apart from its content (a coarse interpolation) gives a ratio near 1. The full shell (each vertex
its own degrees of freedom) is the reference the interpolated shells are judged by.

The shells: "full" (each vertex its own degrees of freedom, at 1/4800 s), "default" (the
consignment's own: trilinear over 4 x 4 x 1 cells for BW and KP, 5 x 5 x 1 for KP/BW since
2026-12-03), trilinear over 4 x 4 x 1 (KP/BW's former default), 5 x 5 x 1 (KP/BW's cell
boundaries then lie on its content's ends) and 8 x 8 x 1 cells,
quadratic over one cell, and trilinear over 5 x 5 x 1 cells with braces across its rim cells
(`parcelfit.sim.mujoco.rim_brace`: the ideal wedge, s = 1, and s = 0.067). Run (prints a
Markdown table; one to a few minutes per shell on one core):

    python scripts/rim_probe.py --consignment KPBW --shells full default trilinear-5x5x1
    python scripts/rim_probe.py --consignment KPBW --param k_CoPa --values 100 1000
    python scripts/rim_probe.py --consignment KPBW --shells braced-5x5x1 braced-5x5x1-s1

(``--param`` varies another parameter over ``--values``, in the catalogue's unit.)
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

from parcelfit.sim.mujoco import load_consignment
from parcelfit.sim.mujoco.indentation import plate_rig
from parcelfit.sim.mujoco.options import SceneOptions
from parcelfit.sim.mujoco.scene import build_scene
from parcelfit.sim.params import catalogue_unit, parameter

SHELLS = {
    "full": SceneOptions(shell_dof="full", timestep=1 / 4800),
    "default": SceneOptions(),
    "trilinear-4x4x1": SceneOptions(shell_dof="trilinear", shell_cells=(4, 4, 1)),
    "trilinear-5x5x1": SceneOptions(shell_dof="trilinear", shell_cells=(5, 5, 1)),
    "trilinear-8x8x1": SceneOptions(shell_dof="trilinear", shell_cells=(8, 8, 1)),
    "trilinear-4x4x2": SceneOptions(shell_dof="trilinear", shell_cells=(4, 4, 2)),
    "trilinear-5x5x2": SceneOptions(shell_dof="trilinear", shell_cells=(5, 5, 2)),
    "quadratic-1x1x1": SceneOptions(shell_dof="quadratic", shell_cells=(1, 1, 1)),
    # braces across the rim cells (sim/mujoco/rim_brace.py): the ideal wedge, and the share of
    # it that matches the full shell's rim
    "braced-5x5x1-s1": SceneOptions(shell_dof="trilinear", shell_cells=(5, 5, 1), rim_brace=1.0),
    "braced-5x5x1": SceneOptions(shell_dof="trilinear", shell_cells=(5, 5, 1), rim_brace=0.067),
}


def rim_compliance(
    consignment: str,
    name: str,
    value: float,
    options: SceneOptions,
    forces: tuple[float, float],
    settle: float,
) -> tuple[float, float]:
    """The rim's compliance [m/N] between the two lifting ``forces`` [N] and the seam end's lift
    [m] at the larger one, with parameter ``name`` at ``value`` (the catalogue's unit)."""
    cons = load_consignment(consignment)
    full = cons.parameter_values(si_values={name: parameter(name).to_si(value)})
    scene = build_scene(plate_rig("metal"), cons, full, 1, options)
    model = scene.model()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
    content = model.body("content").id
    rot = data.xmat[content].reshape(3, 3)
    centre = data.xpos[content].copy()
    v0, nv = int(model.flex_vertadr[flex]), int(model.flex_vertnum[flex])

    def local(points: np.ndarray) -> np.ndarray:
        return (points - centre) @ rot

    verts = local(data.flexvert_xpos[v0 : v0 + nv])
    tip = np.flatnonzero(verts[:, 0] > verts[:, 0].max() - 1e-4)  # the seam's end at +x
    n0, nn = int(model.flex_nodeadr[flex]), int(model.flex_nodenum[flex])
    if nn:  # interpolated: the nodes of the end plane carry the seam's end
        bodies = model.flex_nodebodyid[n0 : n0 + nn]
        x = local(data.xpos[bodies])[:, 0]
        bodies = bodies[x > x.max() - 1e-4]
    else:
        bodies = model.flex_vertbodyid[v0 + tip]
    steps = round(settle / model.opt.timestep)

    def settle_at(force: float) -> float:
        data.xfrc_applied[bodies, 2] = force / len(bodies)
        for _ in range(steps):
            mujoco.mj_step(model, data)
        return float(data.flexvert_xpos[v0 + tip, 2].mean())

    z0 = settle_at(0.0)
    z1 = settle_at(forces[0])
    z2 = settle_at(forces[1])
    return (z2 - z1) / (forces[1] - forces[0]), z2 - z0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--consignment", default="KPBW")
    ap.add_argument("--param", default="E_Pa", help="the parameter varied")
    ap.add_argument(
        "--values", type=float, nargs=2, default=(200.0, 1600.0), help="in the catalogue's unit"
    )
    ap.add_argument("--forces", type=float, nargs=2, default=(0.05, 0.15), help="N")
    ap.add_argument("--settle", type=float, default=0.6, help="s per load")
    ap.add_argument(
        "--shells", nargs="+", default=["full", "default", "quadratic-1x1x1"], choices=list(SHELLS)
    )
    args = ap.parse_args()
    lo, hi = args.values
    name, unit = args.param, catalogue_unit(args.param)
    print(
        f"Rim compliance of {args.consignment}, lifted at the seam by {args.forces[0]:g} -> "
        f"{args.forces[1]:g} N, {name} at {lo:g} and {hi:g} {unit}\n"
    )
    print(
        f"| shell | c at {name} {lo:g} [mm/N] | c at {name} {hi:g} [mm/N] | ratio (a plate "
        f"under E_Pa: {hi / lo:g}) | lift at {args.forces[1]:g} N, {lo:g} / {hi:g} [mm] | time [s] |"
    )
    print("|---|---|---|---|---|---|")
    for shell in args.shells:
        options = SHELLS[shell]
        t0 = time.perf_counter()
        c_lo, z_lo = rim_compliance(args.consignment, name, lo, options, args.forces, args.settle)
        c_hi, z_hi = rim_compliance(args.consignment, name, hi, options, args.forces, args.settle)
        print(
            f"| {shell} | {c_lo * 1e3:.3g} | {c_hi * 1e3:.3g} | {c_lo / c_hi:.2f} | "
            f"{z_lo * 1e3:.3g} / {z_hi * 1e3:.3g} | {time.perf_counter() - t0:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
