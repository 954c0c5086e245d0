"""Simulation speed: 2 s of E3 (induction) with the flexible parcels, one core.

    python benchmarks/bench_sim.py [--repeats 3] [--types KPBW PB] [--scene KEY=VALUE ...]
                                   [--peer KEY=VALUE ...] [--profile]

Simulates exactly 2 s (the end box is widened so the run does not stop at the rig's end) for
KPBW (flexible packaging, rigid content) and PB (polybag, soft content), or the ``--types``
given, at speed setting 1 and the default resolution, and prints the median wall time, steps
per second, and the ratio to the published cost of one such simulation (about 5 hours on a
16-core desktop with a commercial MFBD solver, method.md section 10). MuJoCo runs one
simulation on one core.

Beside the configuration measured (the defaults, or ``--scene``) it measures a peer in the same
run, alternating the two (``--peer``, default the contact and friction laws before 2026-12-01:
``contact_law=impedance friction=geom``), and prints the ratio of their wall times, so that a
change of the machine's state between runs moves both.

``--profile`` then steps each type's scene once more for the same 2 s with MuJoCo's own timers
and prints where a step's time goes: the constraint solver, positions and collisions, and the
rest (mostly the smooth dynamics' factorisation), with the mean Newton iterations, contacts,
constraint rows and degrees of freedom (nv).
"""

from __future__ import annotations

import argparse
import statistics
from dataclasses import replace

import mujoco
import numpy as np

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator, SceneOptions, SimOptions, load_rig
from parcelfit.sim.mujoco.friction import Stepper
from parcelfit.sim.mujoco.mjlog import CountedWarnings
from parcelfit.sim.mujoco.options import parse_scene_options
from parcelfit.sim.mujoco.simulator import _set_velocity

PUBLISHED_SECONDS = 5 * 3600.0
BUDGET = {"KPBW": 8.0, "PB": 30.0}  # s, the targets of the physics issue
FORMER_LAWS = ["contact_law=impedance", "friction=geom"]


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--types",
        nargs="+",
        default=["KPBW", "PB"],
        help="consignment types to time (e.g. KP with --scene shell_dof=quadratic as its peer)",
    )
    ap.add_argument(
        "--iterations",
        type=int,
        default=None,
        help="MuJoCo's iteration cap instead of the default (e.g. 50, the former default, as a peer)",
    )
    ap.add_argument(
        "--scene",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="scene options other than the defaults (e.g. belt_friction=coulomb)",
    )
    ap.add_argument(
        "--peer",
        nargs="*",
        default=FORMER_LAWS,
        metavar="KEY=VALUE",
        help="scene options of the peer measured alternately (default: the former laws)",
    )
    ap.add_argument(
        "--profile",
        action="store_true",
        help="also print where a step's time goes (MuJoCo's timers, Newton iterations, contacts)",
    )
    args = ap.parse_args()
    rig = load_rig("E3")
    rig = replace(rig, end=replace(rig.end, x=(-1.0, 3.9), duration=2.0, after_last_barrier=10.0))
    given = parse_scene_options(args.scene)
    if args.iterations is not None:
        given["iterations"] = args.iterations
    scene = SceneOptions(**given)  # type: ignore[arg-type]
    peer = SceneOptions(**{**given, **parse_scene_options(args.peer)})  # type: ignore[arg-type]
    sim = MujocoSimulator(SimOptions(scene=scene), rigs={"E3": rig})
    peer_sim = MujocoSimulator(SimOptions(scene=peer), rigs={"E3": rig})
    print(
        f"E3, speed setting 1, 2.0 s simulated, default resolution, one core, "
        f"iteration cap {scene.iterations}, contact law {scene.contact_law}, friction "
        f"{scene.friction}; peer: {' '.join(args.peer) or 'the same'}"
    )
    print(
        f"{'case':<10}{'wall [s]':>10}{'steps/s':>10}{'x faster than 5 h':>20}{'target [s]':>12}"
        f"{'peer [s]':>10}{'ratio':>7}"
    )
    for cons in args.types:
        walls, rates, peer_walls = [], [], []
        for _ in range(args.repeats):
            for which, out in ((sim, walls), (peer_sim, peer_walls)):
                res = which.run({}, TestCase("E3", cons, 1))
                assert res.ok and abs(res.diagnostics["simulated_time"] - 2.0) < 0.01, (
                    res.diagnostics
                )
                out.append(res.wall_time)
                if which is sim:
                    rates.append(res.diagnostics["steps_per_second"])
        wall, peer_wall = statistics.median(walls), statistics.median(peer_walls)
        print(
            f"{'E3/' + cons:<10}{wall:>10.2f}{statistics.median(rates):>10.0f}{PUBLISHED_SECONDS / wall:>20.0f}"
            + (f"{BUDGET[cons]:>12.0f}" if cons in BUDGET else f"{'-':>12}")
            + f"{peer_wall:>10.2f}{wall / peer_wall:>7.2f}"
        )
    if args.profile:
        print(
            f"\n{'case':<10}{'ms/step':>9}{'solver':>8}{'pos+col':>9}{'rest':>7}"
            f"{'Newton it':>11}{'contacts':>10}{'rows':>7}{'nv':>6}"
        )
        for cons in args.types:
            print(f"{'E3/' + cons:<10}" + _profile(sim, cons))


def _profile(sim: MujocoSimulator, cons: str) -> str:
    """One 2 s run of ``cons`` on E3 stepped here with MuJoCo's timers: per step [ms] in total,
    in the constraint solver, in positions and collisions, and the rest; mean Newton
    iterations, contacts and constraint rows per step; the degrees of freedom."""
    scene = sim.scene({}, TestCase("E3", cons, 1))
    iters = contacts = rows = 0
    with CountedWarnings():  # counted, not printed, as in the simulator's own runs
        model = scene.model()
        data = mujoco.MjData(model)
        _set_velocity(model, data, np.asarray(scene.start_velocity))
        stepper = Stepper(
            model, data, scene, sim.consignment(cons).parameter_values(), sim.options.scene
        )
        n = round(2.0 / model.opt.timestep)
        for _ in range(n):
            stepper.step()
            iters += int(data.solver_niter[0])
            contacts += data.ncon
            rows += data.nefc

    def per_step(timer: mujoco.mjtTimer) -> float:
        t = data.timer[timer]
        return 1e3 * t.duration / max(t.number, 1)

    total = per_step(mujoco.mjtTimer.mjTIMER_STEP)
    solver = per_step(mujoco.mjtTimer.mjTIMER_CONSTRAINT)
    position = per_step(mujoco.mjtTimer.mjTIMER_POSITION)
    return (
        f"{total:>9.2f}{solver:>8.2f}{position:>9.2f}{total - solver - position:>7.2f}"
        f"{iters / n:>11.2f}{contacts / n:>10.0f}{rows / n:>7.0f}{model.nv:>6d}"
    )


if __name__ == "__main__":
    main()
