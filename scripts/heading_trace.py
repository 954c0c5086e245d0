"""Where does a run turn? One placement in the model and in the independent reference, side by side.

    python scripts/heading_trace.py --rig examples/e3-variants/E3-right-sides.yaml --consignment KP --seed 2
    python scripts/heading_trace.py --consignment KP --seed 1 --set k_MePa=6110   # catalogue units

Simulates one seeded placement of a test case with the MuJoCo model (`MujocoSimulator`) and with
the rigid-box reference (`RigidBoxSimulator`, ``--bottom-patch``), both at their defaults, and
prints every ``--every`` seconds of each trajectory the centre x, y [m] and the heading [deg]
(unwrapped, as sampled), and at the end each run's net rotation [deg] and transit time [s] and
how deep each guide plate's lead-in reached into the consignment's outline at the run's poses
(`lead_in_reach`; sample with ``--rate`` well above 60 Hz for it, e.g. 1200).
``--set NAME=VALUE`` changes parameters in both (catalogue units). ``--step-check`` then runs
the reference again at a half and a quarter of its step and prints the three net rotations (is
the reference's answer converged in its step?).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from parcelfit.runs import TestCase, Trajectory
from parcelfit.sim.ensemble import rotation
from parcelfit.sim.mujoco import MujocoSimulator, SimOptions, load_consignment, load_rig
from parcelfit.sim.params import WALL_CONTACTS, parameter, parse_assignments
from parcelfit.sim.rigidbox import RigidBoxOptions, RigidBoxSimulator


def samples(traj: Trajectory, every: float) -> list[tuple[float, float, float, float]]:
    """(t [s], x [m], y [m], heading [deg]) of ``traj`` at its samples nearest to multiples of
    ``every`` [s]."""
    out = []
    for t in np.arange(0.0, float(traj.t[-1]) + 1e-9, every):
        i = int(np.argmin(np.abs(traj.t - t)))
        out.append(
            (float(traj.t[i]), float(traj.x[i]), float(traj.y[i]), math.degrees(traj.theta[i]))
        )
    return out


def lead_in_reach(
    traj: Trajectory, size: tuple[float, float], axis: tuple[float, float], radius: float
) -> tuple[float, float]:
    """The deepest reach [m] of a vertical lead-in (its ``axis`` [m], ``radius`` [m]) into a
    rigid ``size`` = (L, W) [m] rectangle at the run's sampled poses, and when [s]; negative:
    it never reached the rectangle. For the reference the rectangle is its box; for the model
    only an estimate within about 1-2 mm (its contact vertices carry a 1 mm radius, so contact
    begins about 1 mm outside the rectangle, and its rim may bend)."""
    best, when = -math.inf, math.nan
    for t, x, y, th in zip(traj.t, traj.x, traj.y, traj.theta, strict=True):
        dx, dy = axis[0] - x, axis[1] - y
        c, s = math.cos(th), math.sin(th)
        qx = abs(c * dx + s * dy) - size[0] / 2  # the axis in the body frame, past the sides
        qy = abs(-s * dx + c * dy) - size[1] / 2
        outside = math.hypot(max(qx, 0.0), max(qy, 0.0))
        depth = radius - outside if outside > 0 else radius - max(qx, qy)
        if depth > best:
            best, when = depth, float(t)
    return best, when


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--rig", default="E3", help="a bundled rig's name or a rig file")
    ap.add_argument("--consignment", default="KP")
    ap.add_argument("--setting", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0, help="placement seed")
    ap.add_argument("--every", type=float, default=0.1, help="print interval [s]")
    ap.add_argument("--duration", type=float, default=None, help="simulated time [s] (the rig's)")
    ap.add_argument(
        "--bottom-patch", choices=("consignment", "outline", "content"), default="outline"
    )
    ap.add_argument(
        "--wall-contact",
        choices=WALL_CONTACTS,
        default="outline",
        help="how the reference's walls meet the box: its outline or its contact points",
    )
    ap.add_argument(
        "--step-check", action="store_true", help="the reference also at 1/2 and 1/4 of its step"
    )
    ap.add_argument("--rate", type=float, default=60.0, help="sample rate [Hz] of both runs")
    ap.add_argument(
        "--set", nargs="*", default=[], metavar="NAME=VALUE", help="both engines; catalogue units"
    )
    args = ap.parse_args(argv)
    params = {k: parameter(k).to_si(v) for k, v in parse_assignments(args.set).items()}
    case = TestCase(args.rig, args.consignment, args.setting)
    rig = load_rig(args.rig)
    size = load_consignment(args.consignment).outer
    outer = (float(size[0]), float(size[1]))
    reference = RigidBoxOptions(
        bottom_patch=args.bottom_patch,
        wall_contact=args.wall_contact,
        placement_seed=args.seed,
        duration=args.duration,
        sample_rate=args.rate,
    )
    runs = {
        "model (MuJoCo)": MujocoSimulator(
            SimOptions(placement_seed=args.seed, duration=args.duration, sample_rate=args.rate)
        ).run(params, case),
        f"reference (rigid box, {args.bottom_patch} patch)": RigidBoxSimulator(reference).run(
            params, case
        ),
    }
    for name, result in runs.items():
        print(f"{name}, {case.label}, placement {args.seed}: {result.status.value}")
        if result.run is None:
            continue
        traj = result.run.trajectory
        for t, x, y, h in samples(traj, args.every):
            print(f"  t {t:5.2f} s   x {x:+.3f} m   y {y:+.3f} m   heading {h:7.1f} deg")
        for wall in rig.walls:
            if wall.lead_in > 0:
                depth, when = lead_in_reach(traj, outer, wall.start, wall.lead_in)
                print(
                    f"  {wall.name}'s lead-in reaches {depth * 1e3:.1f} mm into the outline at most"
                    f" (t {when:.3f} s)"
                )
        turned = math.degrees(rotation(traj))
        transit = result.run.transit_time
        print(
            f"  net rotation {turned:.1f} deg, transit "
            + ("none" if transit is None else f"{transit:.4f} s")
        )
    if args.step_check:
        first = list(runs.values())[1]
        step = float(first.diagnostics["timestep"])
        turns = []
        for factor in (1.0, 0.5, 0.25):
            result = RigidBoxSimulator(replace(reference, timestep=step * factor)).run(params, case)
            turns.append(
                math.degrees(rotation(result.run.trajectory)) if result.run else float("nan")
            )
        print(
            f"reference's net rotation at its step {step:.3g} s, 1/2 and 1/4 of it: "
            + ", ".join(f"{t:.1f}" for t in turns)
            + " deg"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
