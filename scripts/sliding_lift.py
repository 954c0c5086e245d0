"""Does a contact that slides carry more load than its share? (E1's transfer, step by step)

    python scripts/sliding_lift.py [--steps 1200 2400 4800] [--zetas 0.3 1 3] [--out docs]

Three measurements, written to ``sliding-lift.md``:

**Slide test** (`parcelfit.sim.mujoco.spin.slide_test`): each rigid-content type kicked to 1 m/s
on a still belt-material plate, for each law of belt friction (MuJoCo's contacts, or
``belt_friction: coulomb``, Coulomb forces at the contact points), time step and belt contact
damping ratio zeta_BePa: its slide beside the Coulomb slide v0^2 / (2 mu g), and the share of
sliding steps in which the shell touches the plate nowhere (a parcel that hops).

**Transfer load share.** A parcel crossing from a slow belt onto a fast one has its front sliding on the fast belt while
its back still rides the slow one. For a flat, stiff bottom the normal load splits between the
two belts by the share of the footprint over each. This script measures that split in two
models and writes ``sliding-lift.md``:

1. **Rigid box** (plain MuJoCo, no parcelfit shell): a box of KP/BW's outer size and mass at
   15 degrees, resting on a grid of 12 x 9 sphere contacts, carried by belt 1 (0.62 m/s) over a
   10 mm gap onto belt 2 at 1.57 m/s (E1 setting 3) or at 0.62 m/s (no slip), with the contact
   parameters of the bundled E1 scene. Footprint share: the share of its sphere contacts over
   belt 2.
2. **parcelfit model** (E1, KP/BW, nominal placement, default parameters): the same, with the
   footprint share counted over the shell's flat bottom vertices, with MuJoCo's belt friction
   and with ``belt_friction: coulomb``.

For each 50 ms window of the transfer: the footprint share over belt 2 and belt 2's share of
the normal contact impulse, at each time step; the arrival of the parcel's centre at
x = 0.6 m and the share of steps with no contact at all (hopping).

**E1 transit step error against the contact damping**: E1 setting 3, KP/BW and BW, nominal
placement and seed 1, transit time at each step against the finest, for each zeta_BePa.
"""

from __future__ import annotations

import argparse
import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import (
    MujocoSimulator,
    SceneOptions,
    SimOptions,
    load_consignment,
    load_rig,
)
from parcelfit.sim.mujoco.coulomb import CoulombBelts
from parcelfit.sim.mujoco.mjlog import CountedWarnings
from parcelfit.sim.mujoco.scene import build_scene
from parcelfit.sim.mujoco.simulator import add_rigid_velocity
from parcelfit.sim.mujoco.spin import slide_test

WINDOW = 0.05  # [s]
T_FROM, T_TO = 0.80, 1.15  # the transfer's windows reported [s]
BELT2_START = 0.01  # x of belt 2's upstream edge in the bundled E1 [m]
ARRIVAL_X = 0.6  # [m]
MU = 0.45  # the rigid box's belt friction coefficient, the catalogue's default mu_d_BePa
# Every model here runs at the catalogue's friction (belt 0.45, metal 0.25), not at a type's own
# defaults (its consignment file's ``parameters``), so that the rigid box and the shell model
# compare at the same friction and the page's figures stay what they were measured as.
FRICTION = {"mu_d_BePa": MU, "mu_d_MePa": 0.25}
SLIP_REG = 0.02  # slip speed below which the explicit Coulomb friction is linear [m/s]


@dataclass(frozen=True)
class Transfer:
    """Per window (end time [s]): footprint share over belt 2, belt 2's load share; the
    arrival time at ARRIVAL_X [s] (None if not reached) and the share of steps without contact."""

    windows: list[tuple[float, float, float]]
    arrival: float | None
    no_contact: float


READING = [
    "## Reading",
    "",
    "What the tables show (the numbers quoted in the README and the simulator README are "
    "this run's):",
    "",
    "- **With MuJoCo's friction a parcel sliding as a whole is right on average but hops**: the "
    "slide ends within a few per cent of the Coulomb slide at every step and damping ratio, but "
    "in a share of the steps the parcel touches the plate nowhere. That share grows with the "
    "contact damping ratio zeta_BePa and hardly with the step: a property of the contact model, "
    "not a step error. MuJoCo documents the cause: its convex contact model can only start slip "
    'by some motion in the normal direction, so a sliding contact lifts ("Computation" chapter, '
    "soft contact model).",
    "- **A parcel that slides on part of its bottom loads that part too much**: crossing onto "
    "a faster belt, belt 2 carries up to several times its footprint's share of the load while "
    "the parcel slides on it, in parcelfit's model and in a plain rigid box on point contacts "
    "alike; with both belts at the same speed the load follows the footprint.",
    "- **It is MuJoCo's friction, and Coulomb forces remove it**: with MuJoCo's belt contacts "
    "frictionless and Coulomb friction applied as forces at the contact points (the rigid box by "
    "hand; parcelfit's model with `belt_friction: coulomb`, `parcelfit.sim.mujoco.coulomb`), "
    "the slide is the Coulomb slide at every step and damping ratio with no step without "
    "contact, belt 2 carries the load it carries without slip (the model: 0.12 / 0.24 / 0.38 at "
    "2 / 12 / 28 % footprint, at every step), and the arrival no longer follows the step "
    "(the model: within 4 ms over 1/1200-1/4800 s, against 18 ms with MuJoCo's friction, whose "
    "runs arrive 8-28 ms earlier).",
    "- **Contact damping is no remedy**: a lower zeta_BePa hops less but leaves the step error "
    "of E1 setting 3's transit time; a higher one halves it for KP/BW and worsens it for BW.",
    "",
    "Coulomb belt friction is a scene option (`belt_friction: coulomb` in a study's simulator "
    "section, `parcelfit simulate --belt-friction coulomb`), not yet the default: its E3 "
    "ensemble, transit convergence, parameter effects and twin benchmark are in docs/research/coulomb/.",
]


def _normal_impulses(
    model: mujoco.MjModel, data: mujoco.MjData, belt1: set[int], belt2: set[int]
) -> tuple[float, float]:
    """Normal contact forces [N] on belt 1 and belt 2 in this step."""
    n = data.ncon
    if n == 0:
        return 0.0, 0.0
    geoms = data.contact.geom[:n]
    adr = data.contact.efc_address[:n]
    force = np.where(adr >= 0, data.efc_force[np.maximum(adr, 0)], 0.0)
    on1 = np.isin(geoms, list(belt1)).any(axis=1)
    on2 = np.isin(geoms, list(belt2)).any(axis=1)
    return float(force[on1].sum()), float(force[on2].sum())


def _follow(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    footprint: Callable[[], float],
    centre_x: Callable[[], float],
    t_end: float = 1.5,
    before_step: Callable[[], None] | None = None,
) -> Transfer:
    """Step to ``t_end`` [s] (calling ``before_step`` before each step) and collect the
    transfer's windows."""
    names = [model.geom(g).name for g in range(model.ngeom)]
    belt1 = {g for g, s in enumerate(names) if s.startswith("belt1")}
    belt2 = {g for g, s in enumerate(names) if s.startswith("belt2")}
    dt = model.opt.timestep
    windows: list[tuple[float, float, float]] = []
    f1 = f2 = 0.0
    shares: list[float] = []
    arrival = None
    empty = steps = 0
    while data.time < t_end:
        if before_step is not None:
            before_step()
        mujoco.mj_step(model, data)
        if arrival is None and centre_x() > ARRIVAL_X:
            arrival = float(data.time)
        if data.time < T_FROM - WINDOW:
            continue
        a, b = _normal_impulses(model, data, belt1, belt2)
        if data.time <= T_TO:
            steps += 1
            empty += a + b == 0.0
        f1, f2 = f1 + a, f2 + b
        shares.append(footprint())
        if len(shares) * dt >= WINDOW - 1e-9:
            if data.time <= T_TO + 1e-9:
                windows.append((float(data.time), float(np.mean(shares)), f2 / max(f1 + f2, 1e-12)))
            f1 = f2 = 0.0
            shares = []
    return Transfer(windows, arrival, empty / max(steps, 1))


def rigid_box(step: float, belt2_speed: float, explicit: bool = False) -> Transfer:
    """The rigid box with a 12 x 9 grid of sphere contacts across E1's transfer (see above).

    ``explicit``: the contacts are frictionless in MuJoCo (condim 1) and Coulomb friction
    -mu N s / max(|s|, 20 mm/s) acts as an external force at each contact point instead, from
    the step before's normal force N and the point's slip s against the belt (MuJoCo has no
    friction law outside its convex contact solver, hence by hand)."""
    cons = load_consignment("KPBW")
    params = cons.parameter_values(FRICTION)
    scene = build_scene(load_rig("E1"), cons, params, 3, SceneOptions(timestep=step))
    cp = scene.contacts["belt"]
    length, width, height = cons.outer[0], cons.outer[1], 0.02
    r, nx, ny = 0.001, 12, 9
    condim = 1 if explicit else 3
    spheres = "".join(
        f'<geom type="sphere" size="{r}" pos="{(i / (nx - 1) - 0.5) * length:.6f} '
        f'{(j / (ny - 1) - 0.5) * width:.6f} {-height / 2}" mass="0" condim="{condim}"/>'
        for i in range(nx)
        for j in range(ny)
    )
    q = f"{math.cos(math.radians(7.5)):.9f} 0 0 {math.sin(math.radians(7.5)):.9f}"
    surface = (
        f'friction="{MU} 0.005 0.0001" condim="{condim}" priority="2" solref="{cp.solref}" '
        f'solimp="{cp.solimp}"'
    )
    xml = f"""<mujoco><option timestep="{step}" cone="elliptic" solver="Newton"/><worldbody>
<geom name="belt1" type="box" size="0.75 0.3 0.02" pos="-0.75 0 -0.02" surfacevel="0.62 0 0 0 0 0" {surface}/>
<geom name="belt2" type="box" size="1.0 0.3 0.02" pos="1.01 0 -0.02" surfacevel="{belt2_speed} 0 0 0 0 0" {surface}/>
<body name="box" pos="-0.6 0 {height / 2 + r}" quat="{q}"><freejoint/>
<geom type="box" size="{length / 2} {width / 2} {height / 2}" mass="{cons.mass}" contype="0" conaffinity="0"/>
{spheres}</body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    add_rigid_velocity(model, data, np.array([0.62, 0.0, 0.0]))
    box = model.body("box").id
    first = model.body_geomadr[box] + 1
    grid = slice(first, first + nx * ny)
    belts = {
        model.geom("belt1").id: np.array([0.62, 0.0, 0.0]),
        model.geom("belt2").id: np.array([belt2_speed, 0.0, 0.0]),
    }
    return _follow(
        model,
        data,
        lambda: float(np.mean(data.geom_xpos[grid, 0] > BELT2_START)),
        lambda: float(data.xpos[box][0]),
        before_step=(lambda: _coulomb_forces(model, data, box, belts)) if explicit else None,
    )


def _coulomb_forces(
    model: mujoco.MjModel, data: mujoco.MjData, body: int, belts: dict[int, np.ndarray]
) -> None:
    """Coulomb friction [N] of the last step's contacts on ``body`` as applied forces."""
    data.qfrc_applied[:] = 0.0
    v6 = np.zeros(6)
    mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body, v6, 0)
    for i in range(data.ncon):
        con = data.contact[i]
        belt = con.geom[0] if con.geom[0] in belts else con.geom[1]
        normal = data.efc_force[con.efc_address]
        if belt not in belts or normal <= 0:
            continue
        slip = v6[3:] + np.cross(v6[:3], con.pos - data.xpos[body]) - belts[belt]
        slip[2] = 0.0
        force = -MU * normal * slip / max(float(np.hypot(slip[0], slip[1])), SLIP_REG)
        mujoco.mj_applyFT(model, data, force, np.zeros(3), con.pos, body, data.qfrc_applied)


def shell_model(step: float, equal_speeds: bool, belt_friction: str = "mujoco") -> Transfer:
    """parcelfit's E1 KP/BW scene at setting 3 (or belt 2 at belt 1's speed), nominal start,
    with the given law of belt friction (`SceneOptions.belt_friction`)."""
    cons = load_consignment("KPBW")
    options = SceneOptions(
        timestep=step,
        speed_factors={"belt2": 0.62 / 1.57} if equal_speeds else {},
        belt_friction=belt_friction,
    )
    scene = build_scene(load_rig("E1"), cons, cons.parameter_values(FRICTION), 3, options)
    model = scene.model()
    data = mujoco.MjData(model)
    flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
    adr, num = model.flex_vertadr[flex], model.flex_vertnum[flex]
    z = scene.shell.points[:, 2]
    bottom = z < z.min() + 1e-9
    verts = lambda: data.flexvert_xpos[adr : adr + num]  # noqa: E731
    with CountedWarnings():  # MuJoCo's per-step notes on interpolated shells, counted
        mujoco.mj_forward(model, data)
        add_rigid_velocity(model, data, np.asarray(scene.start_velocity))
        coulomb = CoulombBelts(model, data, scene) if belt_friction == "coulomb" else None
        return _follow(
            model,
            data,
            lambda: float(np.mean(verts()[bottom, 0] > BELT2_START)),
            lambda: float(verts()[:, 0].mean()),
            before_step=None if coulomb is None else (lambda: coulomb.apply(model, data)),
        )


def slide_rows(steps: list[int], zetas: list[float]) -> list[str]:
    """The slide-test table: belt friction law x type x step x zeta_BePa."""
    lines = [
        "## Slide test: a parcel kicked to 1 m/s on a still belt-material plate",
        "",
        "| belt friction | type | time step | zeta_BePa | slide [mm] | Coulomb slide [mm] "
        "| steps without contact |",
        "|---|---|---|---|---|---|---|",
    ]
    for law, name, n, zeta in itertools.product(
        ("mujoco", "coulomb"), ("BW", "KPBW", "KP"), steps, zetas
    ):
        res = slide_test(
            load_consignment(name),
            params={**FRICTION, "zeta_BePa": zeta},  # dimensionless: SI = catalogue units
            options=SceneOptions(timestep=1.0 / n, belt_friction=law),
        )
        lines.append(
            f"| {law} | {name} | 1/{n} s | {zeta:g} | {1e3 * res.slide:.1f} | "
            f"{1e3 * res.coulomb_slide:.1f} | {100 * res.no_contact:.0f} % |"
        )
    return [*lines, ""]


def transit_rows(steps: list[int], zetas: list[float]) -> list[str]:
    """E1 setting 3 transit time at each step against the finest, per zeta_BePa."""
    finest = max(steps)
    coarse = [n for n in steps if n != finest]
    lines = [
        "## E1 setting 3: transit time against the finest step, by belt contact damping",
        "",
        f"| case | placement | zeta_BePa | transit at 1/{finest} s [s] | "
        + " | ".join(f"1/{n} - 1/{finest} [ms]" for n in coarse)
        + " |",
        "|---" * (4 + len(coarse)) + "|",
    ]
    for case, seed, zeta in itertools.product(("E1/KPBW/3", "E1/BW/3"), (-1, 1), zetas):
        times = {}
        for n in steps:
            sim = MujocoSimulator(SimOptions(scene=SceneOptions(timestep=1.0 / n)))
            if seed >= 0:
                sim = sim.with_placement(seed)
            test_case = TestCase.parse(case)
            cons = sim.consignment(test_case.consignment)
            res = sim.run(cons.parameter_values(FRICTION, {"zeta_BePa": zeta}), test_case)
            times[n] = res.run.transit_time if res.ok and res.run is not None else None
        ref = times[finest]
        cells = [
            f"{1e3 * (times[n] - ref):+.1f}" if ref is not None and times[n] is not None else "-"
            for n in coarse
        ]
        ref_text = f"{ref:.4f}" if ref is not None else "-"
        where = "nominal" if seed < 0 else f"seed {seed}"
        lines.append(f"| {case} | {where} | {zeta:g} | {ref_text} | " + " | ".join(cells) + " |")
    return [*lines, ""]


def _arrivals(runs: dict[int, Transfer]) -> str:
    """The arrival times and no-contact shares of a model's runs, as a sentence."""
    return (
        "Arrival at x = 0.6 m: "
        + ", ".join(
            f"1/{n} s {r.arrival:.4f} s" if r.arrival else f"1/{n} s not reached"
            for n, r in runs.items()
        )
        + "; steps without any contact during the transfer: "
        + ", ".join(f"1/{n} s {100 * r.no_contact:.0f} %" for n, r in runs.items())
        + "."
    )


def _table(title: str, runs: dict[int, Transfer]) -> list[str]:
    steps = list(runs)
    head = "| window end [s] | " + " | ".join(f"1/{n} s: footprint / load on belt 2" for n in steps)
    lines = [f"### {title}", "", head + " |", "|---" * (len(steps) + 1) + "|"]
    for k, w in enumerate(runs[steps[0]].windows):
        cells = []
        for n in steps:
            _, area, load = runs[n].windows[k]
            cells.append(f"{area:.2f} / **{load:.2f}**")
        lines.append(f"| {w[0]:.2f} | " + " | ".join(cells) + " |")
    return [*lines, ""]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", nargs="+", type=int, default=[1200, 2400, 4800], help="1/N s")
    ap.add_argument("--zetas", nargs="+", type=float, default=[0.3, 1.0, 3.0])
    ap.add_argument("--out", type=Path, default=Path("docs/research"))
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    lines = [
        "# Does a sliding contact carry more load than its share?",
        "",
        f"Written by `python scripts/sliding_lift.py --steps {' '.join(map(str, args.steps))} "
        f"--zetas {' '.join(f'{z:g}' for z in args.zetas)}` (default parameters unless a row "
        "says otherwise).",
        "",
    ]
    lines += slide_rows(args.steps, args.zetas)
    lines += [
        "## Transfer load share: E1, belt 1 at 0.62 m/s onto belt 2",
        "",
        "Footprint = share of the parcel's bottom over belt 2, load = belt 2's share of the "
        "normal contact impulse, per 50 ms. For a flat, stiff bottom the two agree.",
        "",
    ]
    box = {n: rigid_box(1.0 / n, 1.57) for n in args.steps}
    box_coulomb = {n: rigid_box(1.0 / n, 1.57, explicit=True) for n in args.steps}
    box_still = {n: rigid_box(1.0 / n, 0.62) for n in args.steps}
    lines += _table("Rigid box on 108 sphere contacts, belt 2 at 1.57 m/s (sliding)", box)
    lines += [_arrivals(box), ""]
    lines += _table(
        "Rigid box, belt 2 at 1.57 m/s, Coulomb friction as explicit forces (MuJoCo's "
        "contacts frictionless)",
        box_coulomb,
    )
    lines += [_arrivals(box_coulomb), ""]
    lines += _table("Rigid box, belt 2 at 0.62 m/s (no slip)", box_still)
    shell = {n: shell_model(1.0 / n, False) for n in args.steps}
    lines += _table("parcelfit model, E1 KP/BW setting 3 (sliding)", shell)
    lines += [_arrivals(shell), ""]
    shell_coulomb = {n: shell_model(1.0 / n, False, "coulomb") for n in args.steps}
    lines += _table(
        "parcelfit model, E1 KP/BW setting 3 (sliding), Coulomb belt friction "
        "(`belt_friction: coulomb`)",
        shell_coulomb,
    )
    lines += [_arrivals(shell_coulomb), ""]
    lines += _table(
        "parcelfit model, belt 2 at 0.62 m/s (no slip)",
        {n: shell_model(1.0 / n, True) for n in args.steps},
    )
    lines += transit_rows(args.steps, args.zetas)
    lines.append(f"Wall time {time.perf_counter() - t0:.0f} s on one core.")
    lines += ["", *READING]
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "sliding-lift.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
