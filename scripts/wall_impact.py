"""How does a parcel leave a guide plate it is carried into? The model against the reference.

    python scripts/wall_impact.py --consignment KP --wall 14 --speed 1.56 --angles -8 8 16 24
    python scripts/wall_impact.py --consignment KP --wall 90 --speed 0.4 --angles 0 20

A belt carries the parcel at ``--speed`` [m/s] into a metal wall at ``--wall`` degrees to the
belt (90: square across it; 14: glancing, as E3's guide plate lies to its main belt, which runs
at 1.56 m/s at setting 1), on a rig built here (`wall_rig`). The parcel starts with its long
side along the wall turned by each ``--angles`` value [deg]: positive, its front corner towards
the wall; negative, its rear corner; 0, the side meets the wall flat. Its nearest point lies
5 mm from the wall's face, and it moves at the belt's speed. Each start is simulated by the MuJoCo model
(`MujocoSimulator`: its defaults, then each ``--model`` variant of scene options, default half
the step) and by the rigid-box reference (`RigidBoxSimulator`: its defaults, each
``--reference`` variant, default half the point spacing, and half its step), both with the
consignment's default parameters but those ``--set`` (catalogue units), sampled at ``--rate``
[Hz]. From the centre's path and heading the script prints, per run:

* ``rebound``: the largest speed of the centre away from the wall within ``--window`` [s] of
  the strike, as a share of the speed it struck with (a coefficient of restitution; 0: the
  parcel stays at the wall). The strike is the first sample where the centre's speed towards
  the wall falls below 90 % of the belt's share towards it;
* ``spin``: the largest yaw rate [deg/s] within that window;
* ``indent``: how far the consignment's outer outline, a rigid rectangle at the centre's pose,
  reaches at most past the wall's face [mm] (negative: it stopped short of it): the
  reference's penetration (its box is that rectangle); for the model only an estimate within
  about 1-2 mm, as its contact vertices carry a 1 mm radius (contact begins about 1 mm before
  the outline reaches the face) and its rim may bend;
* ``overshoot``: how far the heading passes flush with the wall, away from the side it started
  on [deg] (a start at 0: the largest turn either way); a negative ``--angles`` value starts
  the parcel turned the other way, its rear corner towards the wall;
* ``final``: the heading at the end, relative to flush [deg] (negative: turned the way it
  started, its rear away from the wall), and ``end rate``: the yaw rate over the last 20 ms
  [deg/s] (about 0: settled; else still turning, so ``final`` is not where it ends).

Why (docs/research/e3-contact-law/wall-impact.md): on E3, with every type's right side in line,
the reference's KP pivots on its front corner along the plate where the model's lies flush and
slides. This rig isolates that strike from the strips, the step and the lead-in.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

from parcelfit.runs import TestCase, Trajectory
from parcelfit.sim.mujoco import MujocoSimulator, SimOptions, load_consignment
from parcelfit.sim.mujoco.options import scene_options
from parcelfit.sim.params import BOTTOM_PATCHES, WALL_CONTACTS, parameter, parse_assignments
from parcelfit.sim.rigidbox import RigidBoxOptions, RigidBoxSimulator

WALL_POINT = (0.2, 0.0)  # a point of the wall's line [m]
GAP = 0.005  # between the parcel's nearest point and the wall's face at the start [m]
WALL_THICKNESS = 0.003  # [m], as E3's guide plate
DURATION = 0.6  # simulated time [s]


def _axes(wall: float) -> tuple[np.ndarray, np.ndarray]:
    """The wall's direction d and its normal n towards the side the parcel comes from, for a
    wall at ``wall`` [deg] from the belt's direction (+x)."""
    w = math.radians(wall)
    return np.array([math.cos(w), math.sin(w)]), np.array([-math.sin(w), math.cos(w)])


def _reach(length: float, width: float, heading: float, n: np.ndarray) -> float:
    """Half the extent [m] along the unit vector ``n`` of a ``length`` x ``width`` box at
    ``heading`` [deg]."""
    h = math.radians(heading)
    u, v = np.array([math.cos(h), math.sin(h)]), np.array([-math.sin(h), math.cos(h)])
    return (length * abs(float(u @ n)) + width * abs(float(v @ n))) / 2


def wall_rig(length: float, width: float, angle: float, speed: float, wall: float) -> dict:
    """A rig file's content: a belt along +x at ``speed`` [m/s] (setting 1) into a metal wall at
    ``wall`` [deg] to the belt (90: square across it), the parcel (``length`` x ``width`` [m])
    starting with its long side along the wall turned by ``angle`` [deg] (its front corner
    towards the wall), its nearest point GAP from the wall's face."""
    d, n = _axes(wall)
    p0 = np.array(WALL_POINT)
    heading = wall - angle
    clearance = WALL_THICKNESS / 2 + GAP + _reach(length, width, heading, n)
    centre = p0 - 0.6 * abs(d[0]) * d + clearance * n
    ends = [p0 - 1.2 * d, p0 + 1.2 * d] if wall < 60 else [p0 - 0.6 * d, p0 + 0.6 * d]
    return {
        "name": "wall-impact",
        "description": "A belt carrying a parcel into a metal wall (scripts/wall_impact.py).",
        "speeds": {1: {"belt": speed}},
        "surfaces": [
            {
                "name": "belt",
                "type": "belt",
                "material": "belt",
                "centre": [0.0, 0.0],
                "length": 2.6,
                "width": 1.2,
                "heading": 0,
                "top": 0.0,
                "drive": "belt",
            }
        ],
        "walls": [
            {
                "name": "wall",
                "material": "metal",
                "from": [round(float(v), 6) for v in ends[0]],
                "to": [round(float(v), 6) for v in ends[1]],
                "height": 0.096,
                "base": 0.004,
                "thickness": WALL_THICKNESS,
            }
        ],
        "start": {
            "position": [round(float(v), 6) for v in centre],
            "heading": heading,
            "surface": "belt",
        },
        "light_barriers": [
            {"name": "LS1", "from": [-1.25, -0.6], "to": [-1.25, 0.6]},
            {"name": "LS2", "from": [1.25, -0.6], "to": [1.25, 0.6]},
        ],
        "regions": [{"x": [-1.25, 1.25]}],
        "margin": 0.02,
        "end": {"x": [-1.3, 1.3], "y": [-0.6, 0.6], "duration": DURATION},
    }


def measures(
    traj: Trajectory,
    size: tuple[float, float],
    angle: float,
    speed: float,
    wall: float,
    window: float,
) -> dict[str, float]:
    """rebound [share], spin [deg/s], indent [m], overshoot [deg] and final heading [deg] (0:
    flush) of a run on ``wall_rig`` (module docstring); NaN where the parcel never struck."""
    _, n = _axes(wall)
    t = np.asarray(traj.t)
    xy = np.column_stack([traj.x, traj.y])
    theta = np.degrees(np.unwrap(np.asarray(traj.theta)))
    turn = theta - wall  # -angle at the start, 0 with the long side on the wall
    approach = -np.gradient(xy @ n, t)  # the centre's speed towards the wall
    rate = np.gradient(turn, t)
    v_in = speed * math.sin(math.radians(wall))
    gap = xy @ n - float(np.array(WALL_POINT) @ n) - WALL_THICKNESS / 2
    indent = max(_reach(*size, h, n) - g for h, g in zip(theta, gap, strict=True))
    final = float(turn[-1])
    # the yaw rate over the last 20 ms: near 0 once the parcel has settled against the wall
    last = t >= t[-1] - 0.02
    settling = float(np.polyfit(t[last], turn[last], 1)[0]) if np.count_nonzero(last) > 1 else 0.0
    hit = np.flatnonzero(approach < 0.9 * v_in)  # the belt carried it at v_in towards the wall
    if len(hit) == 0:
        nan = math.nan
        return {
            "rebound": nan,
            "spin": nan,
            "indent": indent,
            "overshoot": nan,
            "final": final,
            "end rate": settling,
        }
    i0 = int(hit[0])
    after = (t >= t[i0]) & (t <= t[i0] + window)
    return {
        "rebound": max(0.0, float(-approach[after].min())) / v_in,
        "spin": float(np.abs(rate[after]).max()),
        "indent": indent,
        # past flush on the side away from the start (a start at 0: either side)
        "overshoot": max(0.0, float((np.sign(angle) * turn[i0:]).max()))
        if angle
        else float(np.abs(turn[i0:]).max()),
        "final": final,
        "end rate": settling,
    }


def _reference_options(text: str, base: RigidBoxOptions) -> RigidBoxOptions:
    """``base`` with the fields ``KEY=VALUE,...`` (numbers as floats) changed."""
    given: dict[str, object] = {}
    for item in filter(None, text.split(",")):
        key, value = item.split("=", 1)
        try:
            given[key] = float(value)
        except ValueError:
            given[key] = value
    return replace(base, **given)  # type: ignore[arg-type]


def _engines(
    model: SimOptions,
    reference: RigidBoxOptions,
    model_variants: Sequence[str],
    reference_variants: Sequence[str],
    params: Mapping[str, float],
    case: TestCase,
) -> list[tuple[str, MujocoSimulator | RigidBoxSimulator]]:
    """(label, simulator): the model with ``model`` and with each of ``model_variants``
    (``KEY=VALUE,...`` scene options), the reference with ``reference``, with each of
    ``reference_variants`` (`RigidBoxOptions` fields) and at half its step for ``case`` with
    ``params`` (SI)."""
    engines: list[tuple[str, MujocoSimulator | RigidBoxSimulator]] = [
        ("model", MujocoSimulator(model))
    ]
    for text in model_variants:
        engines.append(
            (f"model {text}", MujocoSimulator(replace(model, scene=scene_options(text.split(",")))))
        )
    engines.append(("reference", RigidBoxSimulator(reference)))
    for text in reference_variants:
        engines.append(
            (f"reference {text}", RigidBoxSimulator(_reference_options(text, reference)))
        )
    _, step = RigidBoxSimulator(reference).world(params, case)  # the reference's own step [s]
    half = replace(reference, timestep=step / 2)
    engines.append(("reference, half step", RigidBoxSimulator(half)))
    return engines


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--consignment", default="KP")
    ap.add_argument("--angles", type=float, nargs="+", default=[0.0, 10.0, 20.0, 30.0])
    ap.add_argument("--speed", type=float, default=0.4, help="belt speed [m/s]")
    ap.add_argument("--wall", type=float, default=90.0, help="wall to belt [deg]; 90: square")
    ap.add_argument("--rate", type=float, default=2400.0, help="sample rate [Hz]")
    ap.add_argument("--window", type=float, default=0.05, help="after the strike [s]")
    ap.add_argument(
        "--model",
        nargs="*",
        default=["timestep=0.000208333333"],
        help="model variants, each KEY=VALUE,... scene options (default: half the step)",
    )
    ap.add_argument(
        "--reference",
        nargs="*",
        default=["spacing=0.005"],
        help="reference variants, each KEY=VALUE,... (default: half the point spacing)",
    )
    ap.add_argument(
        "--bottom-patch",
        default="outline",
        choices=BOTTOM_PATCHES,
        help="the reference's bottom contact patch (outline, as the E3 reference runs)",
    )
    ap.add_argument(
        "--wall-contact",
        choices=WALL_CONTACTS,
        default="outline",
        help="how the reference's wall meets the box: its outline or its contact points",
    )
    ap.add_argument("--duration", type=float, default=DURATION, help="simulated time [s]")
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="catalogue units")
    args = ap.parse_args(argv)
    params = {k: parameter(k).to_si(v) for k, v in parse_assignments(args.set).items()}
    outer = load_consignment(args.consignment).outer
    print(
        f"{args.consignment} carried at {args.speed:g} m/s into a metal wall at {args.wall:g} "
        "degrees to the belt" + (f", {', '.join(args.set)}" if args.set else "")
    )
    print(
        f"{'angle':>6}  {'engine':<34}{'step [s]':>12}{'rebound':>9}{'spin [deg/s]':>14}"
        f"{'indent [mm]':>13}{'overshoot':>11}{'final':>8}{'end rate':>10}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for angle in args.angles:
            path = Path(tmp) / f"wall-impact-{angle:g}.yaml"
            path.write_text(
                yaml.safe_dump(wall_rig(outer[0], outer[1], angle, args.speed, args.wall))
            )
            case = TestCase(str(path), args.consignment, 1)
            engines = _engines(
                SimOptions(sample_rate=args.rate, duration=args.duration),
                RigidBoxOptions(
                    sample_rate=args.rate,
                    duration=args.duration,
                    bottom_patch=args.bottom_patch,
                    wall_contact=args.wall_contact,
                ),
                args.model,
                args.reference,
                params,
                case,
            )
            for name, sim in engines:
                result = sim.run(params, case)
                step = result.diagnostics.get("timestep")
                if step is None:  # the model reports its steps, not its step
                    step = 1 / round(
                        result.diagnostics["steps"] / result.diagnostics["simulated_time"]
                    )
                if result.run is None:
                    print(f"{angle:>6g}  {name:<34}{float(step):>12.3g}  {result.status}")
                    continue
                m = measures(
                    result.run.trajectory, outer[:2], angle, args.speed, args.wall, args.window
                )
                print(
                    f"{angle:>6g}  {name:<34}{float(step):>12.3g}{m['rebound']:>9.2f}"
                    f"{m['spin']:>14.0f}{m['indent'] * 1e3:>13.1f}{m['overshoot']:>11.1f}"
                    f"{m['final']:>8.1f}{m['end rate']:>10.1f}",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
