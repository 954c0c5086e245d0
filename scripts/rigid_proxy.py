"""A rigid-box proxy of a rig: which mechanisms can make small parcels rotate most?

    python scripts/rigid_proxy.py                                   # bundled E3, 10 placements
    python scripts/rigid_proxy.py --rigs examples/e3-variants/E3-far-plate-20.yaml \
        --footprint BW=0.3 KPBW=0.45 KP=1.0 --plate-damping 0.1

NOT the parcelfit model. Each consignment is one rigid box of its outer size and mass (no shell,
no content), on the rig's belts, strips and guide plates (read from the rig file, lead-ins
included), started at the rig's seeded hand placements (``Rig.placement``), at speed setting 1.
A run takes milliseconds instead of seconds, so layouts and contact mechanisms can be screened
before the (slow) shell model is changed. Two mechanism switches:

* ``--footprint TYPE=f``: the box touches the belt only through a centred box of f times its
  length and width (a pillow-shaped mailer whose bottom bulges under the content), which lowers
  the belt's friction torque on a spinning parcel by about f; 1 is a flat bottom;
* ``--plate-damping z``: damping ratio of the plate contacts (1: a dead impact, about 0.1: a
  springy bubble-wrap edge that bounces off the plate).

It prints, per rig and option set, the median absolute rotation, the share of placements above
90 and 180 degrees, and the section-11 checks of ``scripts/ensemble_check.py``. Rotation is the
net change of the unwrapped heading while the parcel is on the rig; a placement whose box falls
off a surface edge is reported as fallen, not counted as a rotation.
Measured results and what they mean: docs/research/e3-geometry.md, "A rigid-box proxy".
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Mapping

import mujoco
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco import load_rig
from parcelfit.sim.mujoco.consignment import load_consignment
from parcelfit.sim.mujoco.rig import Rig
from parcelfit.sim.params import parse_assignments

TYPES = ("BW", "KPBW", "KP")
SLAB = 0.02  # half-thickness of belt boxes [m]
TIMESTEP = 1.0 / 1200.0  # [s]
CONTACT_TIMECONST = 0.004  # MuJoCo solref time constant of every contact [s]
SAMPLE_EVERY = 20  # steps between heading samples (60 Hz at 1/1200 s)


def _quat(yaw_deg: float) -> str:
    a = math.radians(yaw_deg) / 2
    return f"{math.cos(a):.9g} 0 0 {math.sin(a):.9g}"


def proxy_xml(
    rig: Rig,
    consignment: str,
    offset: tuple[float, float, float],
    mu_belt: float,
    mu_metal: float,
    footprint: float,
    plate_damping: float,
) -> tuple[str, tuple[float, float]]:
    """MJCF of the rigid-box proxy and the parcel's start velocity [m/s] (speed setting 1)."""
    cons = load_consignment(consignment)
    L, W, H = cons.outer
    speeds = rig.drive_speeds(1)
    belt_ref = f"{CONTACT_TIMECONST} 1"
    plate_ref = f"{CONTACT_TIMECONST} {plate_damping}"
    # belts and strips touch the parcel's footprint geom (bit 1), plates its outline (bit 2)
    geoms = []
    for s in rig.surfaces:
        u = s.unit()
        n = np.array([-u[1], u[0]])
        if s.type == "strips":
            k = int(s.extra["count"])
            parts = [
                (
                    np.array(s.centre) + (i - (k - 1) / 2) * s.extra["pitch"] * n,
                    s.extra["strip_width"],
                )
                for i in range(k)
            ]
        else:  # belts (roller matrices are beyond this proxy: treated as a belt)
            parts = [(np.array(s.centre), s.width)]
        v = speeds[s.drive]
        for c, width in parts:
            geoms.append(
                f'<geom type="box" size="{s.length / 2} {width / 2} {SLAB}" '
                f'pos="{c[0]} {c[1]} {s.top - SLAB}" quat="{_quat(s.heading)}" '
                f'surfacevel="{v} 0 0 0 0 0" friction="{mu_belt} 0.005 0.0001" '
                f'solref="{belt_ref}" contype="1" conaffinity="1"/>'
            )
    for w in rig.walls:
        a, b = np.array(w.start), np.array(w.end)
        c, length = (a + b) / 2, float(np.linalg.norm(b - a))
        yaw = math.degrees(math.atan2(b[1] - a[1], b[0] - a[0]))
        common = (
            f'friction="{mu_metal} 0.005 0.0001" solref="{plate_ref}" contype="2" conaffinity="2"'
        )
        geoms.append(
            f'<geom type="box" size="{length / 2} {w.thickness / 2} {w.height / 2}" '
            f'pos="{c[0]} {c[1]} {w.base + w.height / 2}" quat="{_quat(yaw)}" {common}/>'
        )
        if w.lead_in > 0:
            geoms.append(
                f'<geom type="cylinder" size="{w.lead_in} {w.height / 2}" '
                f'pos="{a[0]} {a[1]} {w.base + w.height / 2}" {common}/>'
            )
    start = rig.surface(rig.start.surface)
    cx, cy = rig.start_centre(L, W)
    x0, y0 = cx + offset[0], cy + offset[1]
    heading = rig.start.heading + offset[2]
    u0 = start.unit()
    v0 = speeds[start.drive]
    # friction 0 on the parcel's geoms: MuJoCo takes the larger of two geoms' coefficients, so
    # each contact gets the belt's or the plate's
    xml = f"""<mujoco><option timestep="{TIMESTEP}" cone="elliptic" integrator="implicitfast"/>
<worldbody>{"".join(geoms)}
<body name="parcel" pos="{x0} {y0} {start.top + H / 2 + 0.0005}" quat="{_quat(heading)}">
<freejoint/>
<geom type="box" size="{L / 2} {W / 2} {H / 2}" mass="{cons.mass}" friction="0 0.005 0.0001"
      solref="{belt_ref}" contype="2" conaffinity="2"/>
<geom type="box" size="{footprint * L / 2} {footprint * W / 2} {H / 2}" mass="1e-6"
      friction="0 0.005 0.0001" solref="{belt_ref}" contype="1" conaffinity="1"/>
</body></worldbody></mujoco>"""
    return xml, (v0 * u0[0], v0 * u0[1])


def rotation(
    rig: Rig,
    consignment: str,
    seed: int,
    duration: float,
    mu_belt: float,
    mu_metal: float,
    footprint: float,
    plate_damping: float,
) -> float:
    """Net rotation [deg] of one placement, NaN if the box fell off a surface edge."""
    xml, v0 = proxy_xml(
        rig, consignment, rig.placement(seed), mu_belt, mu_metal, footprint, plate_damping
    )
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qvel[0:2] = v0
    headings = []
    for k in range(int(duration / TIMESTEP)):
        mujoco.mj_step(model, data)
        if data.qpos[2] < 0.0:
            return math.nan
        if k % SAMPLE_EVERY == 0:
            w, x, y, z = data.qpos[3:7]
            headings.append(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
    unwrapped = np.unwrap(headings)
    return math.degrees(float(unwrapped[-1] - unwrapped[0]))


def _per_type(items: list[str]) -> Mapping[str, float]:
    """TYPE=VALUE options (parsed as parcelfit simulate's --set) keyed by the bundled type name."""
    return {k.upper().replace("/", ""): v for k, v in parse_assignments(items).items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--rigs", nargs="+", default=["E3"])
    ap.add_argument("--types", nargs="+", default=list(TYPES))
    ap.add_argument("--placements", type=int, default=10)
    ap.add_argument("--duration", type=float, default=1.4, help="simulated time [s]")
    ap.add_argument("--footprint", nargs="*", default=[], help="TYPE=f (default 1: flat)")
    ap.add_argument("--plate-damping", type=float, default=1.0)
    ap.add_argument("--mu-belt", type=float, default=0.45)
    ap.add_argument("--mu-metal", type=float, default=0.25)
    args = ap.parse_args()
    try:
        footprints = _per_type(args.footprint)
    except ParcelfitError as exc:
        raise SystemExit(f"--footprint: {exc}") from exc
    t0 = time.perf_counter()
    for rig_name in args.rigs:
        rig = load_rig(rig_name)
        print(
            f"## {rig.name}: footprint {dict(footprints) or 'flat'}, plate damping "
            f"{args.plate_damping}, mu belt {args.mu_belt}, mu metal {args.mu_metal}"
        )
        print("| type | median rotation [deg] | > 90 deg | > 180 deg | fell | rotations [deg] |")
        print("|---|---|---|---|---|---|")
        medians = {}
        for cons in args.types:
            rot = np.array(
                [
                    rotation(
                        rig,
                        cons,
                        seed,
                        args.duration,
                        args.mu_belt,
                        args.mu_metal,
                        footprints.get(cons, 1.0),
                        args.plate_damping,
                    )
                    for seed in range(args.placements)
                ]
            )
            ok = np.abs(rot[~np.isnan(rot)])
            medians[cons] = float(np.median(ok)) if ok.size else math.nan
            print(
                f"| {cons} | {medians[cons]:.0f} | {np.mean(ok > 90):.0%} | {np.mean(ok > 180):.0%} "
                f"| {int(np.isnan(rot).sum())} | {', '.join(f'{v:.0f}' for v in rot)} |"
            )
        if all(t in medians for t in TYPES):
            order = medians["BW"] > medians["KPBW"] > medians["KP"]
            print(
                f"\nmedian rotation BW > KP/BW > KP: {'met' if order else 'NOT met'}; "
                f"KP median < 30 deg: {'met' if medians['KP'] < 30 else 'NOT met'}\n"
            )
    print(f"wall time {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
