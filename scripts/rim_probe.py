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

``--probe content`` presses the content instead, down into its packaging lying on a still belt
plate (a downward force on the content's body, ``--forces`` default 10 and 20 N), and reads
the content's sink between the two forces, c = (z(F1) - z(F2)) / (F2 - F1) [m/N]: the
stiffness the content meets in its packaging, k_CoPa's in series with the shell's and the
bottom's contact on the plate. ``--spacing`` [m] sets the shell's mesh spacing around the rigid
content (the type's default otherwise). On 15 mm and finer the loaded content of KP/BW does not
come to rest (it jitters by some 0.01-0.03 mm from step to step), so ``--average`` [s] reads
each height as its mean over the end of the load:

    python scripts/rim_probe.py --probe content --param k_CoPa --values 100 1000 \
        --shells default full --spacing 0.015 --settle 1.0 --average 0.4
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from typing import NamedTuple

import mujoco
import numpy as np

from parcelfit.sim.mujoco import load_consignment
from parcelfit.sim.mujoco.indentation import plate_rig
from parcelfit.sim.mujoco.options import SceneOptions
from parcelfit.sim.mujoco.scene import build_scene, content_contacts
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


class Reading(NamedTuple):
    """One probe: the ``compliance`` [m/N] between the two forces, the ``travel`` [m] from no
    force to the larger one, the height's ``jitter`` (its range [m] over the averaged time at
    the larger force) and the content's ``contacts`` at the end."""

    compliance: float
    travel: float
    jitter: float
    contacts: int


def compliance(
    probe: str,
    consignment: str,
    name: str,
    value: float,
    options: SceneOptions,
    forces: tuple[float, float],
    settle: float,
    average: float = 0.0,
) -> Reading:
    """With parameter ``name`` at ``value`` (the catalogue's unit): for ``probe`` "rim" the rim's
    compliance [m/N] between the two lifting ``forces`` [N] and the seam end's lift [m] at the
    larger one (the parcel on a still metal plate); for "content" the content's compliance in
    its packaging between the two downward ``forces`` on the content and its sink [m] from no
    force to the larger one (on a still belt plate). Each height is read after ``settle`` [s]
    at its load, as the mean over the last ``average`` [s] of it (0: the last step's)."""
    cons = load_consignment(consignment)
    full = cons.parameter_values(si_values={name: parameter(name).to_si(value)})
    material = "belt" if probe == "content" else "metal"
    model = build_scene(plate_rig(material), cons, full, 1, options).model()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    content = model.body("content").id
    steps = round(settle / model.opt.timestep)
    if probe == "content":
        bodies, sign = np.array([content]), -1.0  # pushed down: the sink is the height lost

        def height() -> float:
            return float(data.xpos[content, 2])

    else:
        flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
        v0, nv = int(model.flex_vertadr[flex]), int(model.flex_vertnum[flex])
        tip = v0 + _seam_tip(data, content, v0, nv)
        bodies, sign = _seam_end(model, data, content, flex, tip), 1.0

        def height() -> float:
            return float(data.flexvert_xpos[tip, 2].mean())

    window = min(steps, max(1, round(average / model.opt.timestep)))

    def settle_at(force: float) -> float:
        data.xfrc_applied[bodies, 2] = sign * force / len(bodies)
        heights.clear()
        for i in range(steps):
            mujoco.mj_step(model, data)
            if i >= steps - window:
                heights.append(height())
        return float(np.mean(heights))

    heights: list[float] = []
    z0 = settle_at(0.0)
    z1 = settle_at(forces[0])
    z2 = settle_at(forces[1])
    return Reading(
        sign * (z2 - z1) / (forces[1] - forces[0]),
        sign * (z2 - z0),
        max(heights) - min(heights),
        content_contacts(model, data),
    )


def _local(data: mujoco.MjData, content: int, points: np.ndarray) -> np.ndarray:
    """``points`` [m] in the content's frame (the parcel's, at the start)."""
    return (points - data.xpos[content]) @ data.xmat[content].reshape(3, 3)


def _seam_tip(data: mujoco.MjData, content: int, v0: int, nv: int) -> np.ndarray:
    """The packaging's vertices (offsets from ``v0``) at the seam's end, at +x."""
    verts = _local(data, content, data.flexvert_xpos[v0 : v0 + nv])
    return np.flatnonzero(verts[:, 0] > verts[:, 0].max() - 1e-4)


def _seam_end(
    model: mujoco.MjModel, data: mujoco.MjData, content: int, flex: int, tip: np.ndarray
) -> np.ndarray:
    """The bodies that carry the seam's end (vertices ``tip``): the flex vertices of a full
    shell, the end plane's nodes of an interpolated one."""
    n0, nn = int(model.flex_nodeadr[flex]), int(model.flex_nodenum[flex])
    if nn:  # interpolated: the nodes of the end plane carry the seam's end
        bodies = model.flex_nodebodyid[n0 : n0 + nn]
        x = _local(data, content, data.xpos[bodies])[:, 0]
        return bodies[x > x.max() - 1e-4]
    return model.flex_vertbodyid[tip]


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__.splitlines()[0] + " (--probe content: and the content's stiffness?)"
    )
    ap.add_argument("--consignment", default="KPBW")
    ap.add_argument("--param", default="E_Pa", help="the parameter varied")
    ap.add_argument(
        "--values", type=float, nargs=2, default=(200.0, 1600.0), help="in the catalogue's unit"
    )
    ap.add_argument(
        "--probe",
        choices=("rim", "content"),
        default="rim",
        help="lift the rim at its seam, or press the content down into its packaging",
    )
    ap.add_argument(
        "--forces", type=float, nargs=2, help="N (default 0.05 0.15 for the rim, 10 20 the content)"
    )
    ap.add_argument("--settle", type=float, default=0.6, help="s per load")
    ap.add_argument(
        "--average",
        type=float,
        default=0.0,
        help="s at the end of each load over which the height is averaged (0: the last step)",
    )
    ap.add_argument(
        "--shells", nargs="+", default=["full", "default", "quadratic-1x1x1"], choices=list(SHELLS)
    )
    ap.add_argument("--spacing", type=float, help="shell mesh spacing around the rigid content [m]")
    ap.add_argument(
        "--content-tiles",
        type=int,
        default=1,
        help="the rigid content as N x N box tiles (SceneOptions.content_tiles)",
    )
    ap.add_argument(
        "--content-kept",
        type=int,
        help="with --content-tiles: the contacts the tiles keep, as counted by a run before; "
        "the stiffness is shared so that they are as stiff as one box's (SceneOptions.content_kept)",
    )
    args = ap.parse_args()
    if args.content_tiles > 1 and "full" in args.shells:
        ap.error("--content-tiles works on interpolated shells: give --shells without full")
    lo, hi = args.values
    name, unit = args.param, catalogue_unit(args.param)
    content = args.probe == "content"
    forces = args.forces or ((10.0, 20.0) if content else (0.05, 0.15))
    mesh = "" if args.spacing is None else f", shell mesh {args.spacing * 1e3:g} mm"
    if args.content_tiles > 1:
        mesh += f", the content as {args.content_tiles} x {args.content_tiles} tiles"
        if args.content_kept is not None:
            mesh += f" sharing its stiffness over {args.content_kept} kept contacts"
    what, moved = (
        ("Content compliance", "pressed down by")
        if content
        else ("Rim compliance", "lifted at the seam by")
    )
    print(
        f"{what} of {args.consignment}, {moved} {forces[0]:g} -> {forces[1]:g} N, {name} at "
        f"{lo:g} and {hi:g} {unit}{mesh}; {args.settle:g} s per load"
        + (f", each height the mean of its last {args.average:g} s" if args.average > 0 else "")
        + "\n"
    )
    ideal = "a plate under E_Pa" if name == "E_Pa" and not content else f"{name} alone"
    averaged = args.average > 0
    print(
        f"| shell | c at {name} {lo:g} [mm/N] | c at {name} {hi:g} [mm/N] | ratio ({ideal}: "
        f"{hi / lo:g}) | {'sink' if content else 'lift'} at {forces[1]:g} N, "
        f"{lo:g} / {hi:g} [mm] | "
        + (f"range over the last {args.average:g} s, {lo:g} / {hi:g} [mm] | " if averaged else "")
        + (f"content's contacts at {forces[1]:g} N | " if content else "")
        + "time [s] |"
    )
    print("|---" * (6 + averaged + content) + "|")
    for shell in args.shells:
        options = SHELLS[shell]
        if args.spacing is not None:
            options = replace(options, spacing=args.spacing)
        options = replace(options, content_tiles=args.content_tiles, content_kept=args.content_kept)
        t0 = time.perf_counter()
        a, b = (
            compliance(
                args.probe, args.consignment, name, v, options, forces, args.settle, args.average
            )
            for v in (lo, hi)
        )
        print(
            f"| {shell} | {a.compliance * 1e3:.3g} | {b.compliance * 1e3:.3g} | "
            f"{a.compliance / b.compliance:.2f} | {a.travel * 1e3:.3g} / {b.travel * 1e3:.3g} | "
            + (f"{a.jitter * 1e3:.2g} / {b.jitter * 1e3:.2g} | " if averaged else "")
            + (f"{a.contacts} / {b.contacts} | " if content else "")
            + f"{time.perf_counter() - t0:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
