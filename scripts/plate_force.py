"""The guide plate's peak force on a parcel in the rigid-box reference, against the load under
which the parcel's rim buckles.

    python scripts/plate_force.py
    python scripts/plate_force.py --types KPBW KP --settings 1 2 --placements 20 --workers 2

For each type and speed setting of the rig (E3) it runs the reference at its defaults, its walls
meeting the packaging's outline as if the rim were as stiff as the content (``--set``:
parameters in catalogue units), at ``--placements`` seeded placements, and records, every step
while a wall or a lead-in touches the parcel (every ``--chunk`` steps otherwise, so a contact's
first steps may be missed), the horizontal force they exert on it, the largest spring force per
unit length of outline a wall exerts (at the outline's deepest corner behind its face,
`wall_press`; damping left out) and how deep that corner reaches. It prints
each placement's peak force, line load and depth, and from the catalogue's E_Pa, t_Pa and
nu_Pa (the defaults and the ends of E_Pa's and t_Pa's ranges) an estimate of the load per unit
length under which each rim buckles (`parcelfit.sim.rigidbox.geometry.rim_buckling_load`,
neither bound: its docstring), against which it sets the median peak line load. Where the line
load is well above it, a rim as stiff as the content is not what the packaging can be; where it
is well below, the rim holds. The estimate is for a load spread evenly along an edge: a corner
or a lead-in presses a short length, which the rim beside it helps to carry, and the lead-ins'
loads are in the force but not in the line load.

``--engines model`` measures the MuJoCo model instead (``--engines reference model``: both): how
close its rigid content comes to the guide plate, after every step the least distance of the
corners of the content's footprint (its box cL x cW at its mid-height, `plate_gap`) from a
plate's face, among the corners within the plate's length and height, and the same for the
packaging's outline L x W set rigidly at the content's pose: negative, the rim gave way by that
much (whatever the angle of the strike), measured against the width of the rim that faced the
plate then (`facing_rim`: beyond the edge whose normal lies nearer the plate's). A rim as stiff
as the content gives way by the contact's penetration alone (in the reference 0.2-1.7 mm,
medians 0.5-1.2); a rim that gives way entirely by its width. The plates are the scene's metal
box geoms: lead-ins are cylinders and not counted, and the content itself does not collide with
the plate (the shell keeps it off).
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
from parcelfit.sim.rigidbox import RigidBoxOptions, RigidBoxSimulator
from parcelfit.sim.rigidbox import integrator as ig
from parcelfit.sim.rigidbox.engine import Motion, World
from parcelfit.sim.rigidbox.geometry import LEAD_IN, WALL, rim_buckling_load

ENGINES = ("reference", "model")


def _pressed(world: World, motion: Motion) -> list[tuple[float, float, float]]:
    """For each wall of ``world`` that the parcel of ``motion`` presses: kappa [N/m^3], the
    height h [m] the parcel (lying flat) and the wall share, and the depth [m] of the deepest
    corner of the outline walls meet (``wall_outline``) behind the wall's face."""
    prims, body = world.primitives, world.body
    hx, hy, hz = body.wall_half
    corners = np.array([[sx * hx, sy * hy, 0.0] for sx in (-1, 1) for sy in (-1, 1)])
    world_corners = motion.x + corners @ motion.R.T
    out = []
    for j in np.flatnonzero(prims.kind == WALL):
        rot, centre, (s0, s1, s2) = prims.rot[j], prims.centre[j], prims.size[j]
        local = (world_corners - centre) @ rot  # the corners in the wall's frame
        side = 1.0 if float((motion.x - centre) @ rot[:, 1]) >= 0 else -1.0
        depth = s1 - side * local[:, 1]
        inside = (np.abs(local[:, 0]) < s0) & (depth > 0)
        if not inside.any():
            continue
        z = float((motion.x - centre) @ rot[:, 2])
        shared = min(z + hz, s2) - max(z - hz, -s2)
        if shared <= 0:
            continue
        kappa = float(world.law[prims.material[j], 0])
        out.append((kappa, shared, float(depth[inside].max())))
    return out


def wall_press(world: World, motion: Motion) -> tuple[float, float]:
    """How a wall of ``world`` presses the parcel of ``motion``: the largest spring force per unit
    length of outline [N/m], kappa h delta at the outline's deepest corner behind a wall's face
    (kappa = K / A_b, h the height the parcel and the wall share, the parcel lying flat; damping
    left out), and how far [m] that outline reaches behind a wall's face at its deepest corner
    (0, 0: no wall pressed). The outline is the one walls meet (``wall_outline``)."""
    pressed = _pressed(world, motion)
    return (
        max((k * h * d for k, h, d in pressed), default=0.0),
        max((d for _, _, d in pressed), default=0.0),
    )


def peak_plate_force(
    rig: str,
    consignment: str,
    setting: int,
    seed: int,
    params: dict[str, float],
    chunk: int = 20,
) -> tuple[float, float, float, float]:
    """The peak horizontal force [N] of the walls and lead-ins of ``rig`` on ``consignment`` at
    placement ``seed`` of ``setting`` (SI ``params``) in the rigid-box reference, when [s]
    ((0, nan) if none touches it), the peak line load of a wall [N/m] and the deepest the outline
    reached behind a wall's face [m] (`wall_press`)."""
    sim = RigidBoxSimulator(RigidBoxOptions()).with_placement(seed)
    case = TestCase(rig, consignment, setting)
    world, dt = sim.world(params, case)
    the_rig = sim.rig(rig)
    motion = Motion(world, **sim.start(the_rig, case, float(world.body.half[2])))
    plates = World(
        world.body,
        world.primitives.subset((WALL, LEAD_IN)),
        world.law,
        world.stick_speed,
        world.slip_speed,
        gravity=0.0,
    )
    probe = Motion(plates, motion.x, motion.q)
    n_steps = round(the_rig.end.duration / dt)
    (x_lo, x_hi), (y_lo, y_hi) = the_rig.end.x, the_rig.end.y
    peak, when, touching, line, deepest = 0.0, math.nan, False, 0.0, 0.0
    while motion.steps < n_steps:
        code = motion.advance(dt, 1 if touching else chunk)
        if code in (ig.NOT_FINITE, ig.TOO_FAST):
            raise RuntimeError(f"{consignment} seed {seed}: the reference's run blew up")
        probe.take_state(motion)
        force = math.hypot(float(probe.F[0]), float(probe.F[1]))
        touching = force > 0.0
        if force > peak:
            peak, when = force, motion.steps * dt
        if touching:
            load, depth = wall_press(plates, motion)
            line, deepest = max(line, load), max(deepest, depth)
        c = motion.x
        if code == ig.STOPPED or not (x_lo <= c[0] <= x_hi and y_lo <= c[1] <= y_hi):
            break
    return peak, when, line, deepest


def _peak(job: tuple) -> tuple[float, float, float, float]:
    return peak_plate_force(*job)


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
    rig: str, consignment: str, setting: int, seed: int, params: dict[str, float]
) -> tuple[float, float, float]:
    """Over one run of the MuJoCo model on ``rig``: the content's least gap [m] to a guide plate
    (`plate_gap` of its footprint cL x cW), the least gap [m] of the packaging's outline L x W
    set rigidly at the content's pose (negative: the rim gave way by that much, whatever the
    angle of the strike) and the width [m] of the rim that faced the plate then (`facing_rim`;
    nan: no gap)."""
    cons = load_consignment(consignment)
    sim = MujocoSimulator(SimOptions()).with_placement(seed)
    case = TestCase(rig, cons.name, setting)
    scene = sim.scene(params, case)
    half = (cons.content[0] / 2, cons.content[1] / 2)
    outline = (cons.outer[0] / 2, cons.outer[1] / 2)
    found: list[tuple[int, list[int]]] = []
    least = [math.inf, math.inf, math.nan]

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
            plate = (data.geom_xpos[g], data.geom_xmat[g].reshape(3, 3), model.geom_size[g])
            least[0] = min(least[0], plate_gap(centre, rotation, half, *plate))
            gap = plate_gap(centre, rotation, outline, *plate)
            if gap < least[1]:
                least[1] = gap
                least[2] = facing_rim(
                    rotation, plate[1], plate[2], cons.outer[:2], cons.content[:2]
                )

    with observed_steps(look):
        sim.run(params, case)
    return least[0], least[1], least[2]


def _reference_lines(
    name: str, setting: int, peaks: list[tuple[float, float, float, float]], per_length: dict
) -> None:
    """Print the reference's peaks at one setting against the rims' buckling loads."""
    print(f"\n{name}, setting {setting}, the reference, per placement (seed 0, 1, ...):")
    print("peak force of the walls and lead-ins [N]: " + ", ".join(f"{f:.1f}" for f, *_ in peaks))
    print("deepest behind a wall's face [mm]: " + ", ".join(f"{d * 1e3:.1f}" for *_, d in peaks))
    depths = [d for *_, d in peaks if d > 0]
    if not depths:
        print("no placement touched a wall")
        return
    print(
        f"median deepest {statistics.median(depths) * 1e3:.2f} mm, most {max(depths) * 1e3:.2f} mm"
    )
    print("peak line load of a wall [N/m]: " + ", ".join(f"{q:.0f}" for _, _, q, _ in peaks))
    touched = [q for _, _, q, _ in peaks if q > 0]
    forces = [f for f, *_ in peaks if f > 0]
    median = statistics.median(touched)
    print(
        f"median peak force {statistics.median(forces):.1f} N; median peak line "
        f"load {median:.0f} N/m over the {len(touched)} placements that met a wall"
    )
    for label in ("defaults", "E_Pa end", "t_Pa end"):
        for pair in per_length[label]:
            parts = [
                f"{which} rim's {q:.1f} N/m: median {median / q:.1f} times it, "
                f"{sum(x > q for x in touched)} of {len(touched)} above it"
                for which, q in zip(("the weaker", "the stiffer"), pair, strict=True)
            ]
            print(f"  buckling load ({label}) of " + "; of ".join(parts))


def _model_lines(name: str, setting: int, found: list[tuple[float, float, float]]) -> None:
    """Print the model's least gaps of the content and of the outline to the plate at one
    setting, and how far the rim gave way."""
    print(f"\n{name}, setting {setting}, the model, per placement (seed 0, 1, ...):")
    print(
        "the content's least gap to the plate [mm]: "
        + ", ".join(f"{g * 1e3:.1f}" for g, _, _ in found)
    )
    print(
        "the outline's least gap, set at the content's pose [mm] (negative: the rim gave way): "
        + ", ".join(f"{o * 1e3:.1f}" for _, o, _ in found)
    )
    print("the facing rim's width then [mm]: " + ", ".join(f"{r * 1e3:g}" for *_, r in found))
    met = [(g, o, r) for g, o, r in found if math.isfinite(g) and math.isfinite(o)]
    if not met:
        print("no placement came within the plate's extent")
        return
    gaps = [g for g, _, _ in met]
    given = [max(0.0, -o) for _, o, _ in met]
    shares = [y / r for y, (_, _, r) in zip(given, met, strict=True)]
    print(
        f"the content's least gap: median {statistics.median(gaps) * 1e3:.1f} mm (range "
        f"{min(gaps) * 1e3:.1f}-{max(gaps) * 1e3:.1f}); the rim gave way by a median "
        f"{statistics.median(given) * 1e3:.1f} mm (range {min(given) * 1e3:.1f}-"
        f"{max(given) * 1e3:.1f}), {statistics.median(shares):.2f} of the facing rim's width "
        f"(range {min(shares):.2f}-{max(shares):.2f}; 0: it held, 1: it gave way entirely) "
        f"over {len(met)} placements"
    )


def _gap(job: tuple) -> tuple[float, float, float]:
    return least_gap(*job)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", default="E3")
    ap.add_argument("--types", nargs="+", default=["KPBW", "KP"])
    ap.add_argument("--settings", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--placements", type=int, default=20)
    ap.add_argument(
        "--engines",
        nargs="+",
        choices=ENGINES,
        default=["reference"],
        help="reference: the rigid-box reference's plate load; model: the MuJoCo model's gap",
    )
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE")
    ap.add_argument("--chunk", type=int, default=20, help="steps between looks, out of contact")
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args(argv)
    if args.placements < 1 or args.chunk < 1 or args.workers < 1:
        ap.error("--placements, --chunk and --workers must be at least 1")
    user = {k: parameter(k).to_si(v) for k, v in parse_assignments(args.set).items()}
    line = f"python scripts/plate_force.py --rig {args.rig} --types {' '.join(args.types)}"
    line += f" --settings {' '.join(map(str, args.settings))} --placements {args.placements}"
    if args.engines != ["reference"]:
        line += f" --engines {' '.join(args.engines)}"
    if args.set:
        line += f" --set {' '.join(args.set)}"
    print(f"Written by `{line}`.")
    with ProcessPoolExecutor(args.workers) as pool:
        for name in args.types:
            cons = load_consignment(name)
            if cons.soft:
                print(f"\n{name}: skipped (a soft content: no rigid content, no rim to measure)")
                continue
            (L, W, _), (cL, cW, _) = cons.outer, cons.content
            p = cons.parameter_values(si_values=user)
            kind = cons.content_kind
            print(
                f"\n{name}: outer {L * 1e3:g} x {W * 1e3:g} mm, content {cL * 1e3:g} x "
                f"{cW * 1e3:g} mm; rim {(W - cW) / 2 * 1e3:g} mm wide along the long edges, "
                f"{(L - cL) / 2 * 1e3:g} mm along the short ones"
            )
            per_length: dict[str, list[tuple[float, float]]] = {}
            if "reference" in args.engines:
                rows = [("defaults", p["E_Pa"], p["t_Pa"])]
                rows += [("E_Pa end", E, p["t_Pa"]) for E in parameter("E_Pa").si_range(kind)]
                rows += [("t_Pa end", p["E_Pa"], t) for t in parameter("t_Pa").si_range(kind)]
                print(
                    "| E_Pa [N/mm^2] | t_Pa [mm] | buckling load, long edges' rim [N/m] | "
                    "short edges' [N/m] | along a whole long edge [N] | short edge [N] | row |"
                )
                print("|---|---|---|---|---|---|---|")
                for label, E, t in rows:
                    q_long = rim_buckling_load(E, t, p["nu_Pa"], (W - cW) / 2)
                    q_short = rim_buckling_load(E, t, p["nu_Pa"], (L - cL) / 2)
                    per_length.setdefault(label, []).append(
                        (min(q_long, q_short), max(q_long, q_short))
                    )
                    print(
                        f"| {E * 1e-6:g} | {t * 1e3:g} | {q_long:.1f} | {q_short:.1f} | "
                        f"{q_long * L:.2f} | {q_short * W:.2f} | {label} |"
                    )
            for setting in args.settings:
                seeds = range(args.placements)
                if "reference" in args.engines:
                    jobs = [(args.rig, name, setting, s, user, args.chunk) for s in seeds]
                    _reference_lines(name, setting, list(pool.map(_peak, jobs)), per_length)
                if "model" in args.engines:
                    jobs = [(args.rig, name, setting, s, user) for s in seeds]
                    _model_lines(name, setting, list(pool.map(_gap, jobs)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
