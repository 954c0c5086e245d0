"""Where does a parcel catch? The packaging's contacts with the rig, surface by surface, over time.

    python scripts/contact_trace.py --rig E2a --consignment KPBW --setting 1 --seed 3
                                    --from 1.76 --to 1.9 [--every 0.01] [--scene KEY=VALUE ...]
                                    [--bulge FOOTPRINT [--bulge-depth D]] [--bottom] [--stop]

Runs one simulation as `parcelfit simulate` does and prints, at every ``--every`` seconds of the
window [``--from``, ``--to``] (simulated time, s): the packaging's centre [m] (the mean of its
vertices) and how far it has turned since the start [deg] (a line through two of its vertices),
and for the rig geoms that push it hardest about the vertical through its centre their yaw
torque [N m] and the world force they exert on the packaging [N]. A catch on an edge shows as a
large horizontal force against the direction of travel from one geom. Also printed: how many
contacts the packaging has with each body MuJoCo collides it with as one pair (the world with
all the rig's geoms, the content); MuJoCo keeps at most 50 per pair (``mjMAXCONPAIR``), so a
count of 50 means the cap was reached and others may have been dropped. ``--rig`` and
``--consignment`` take bundled names or files.

``--bulge`` gives the packaging a bottom that bulges below a rigid content (0: a flat one; footprint: the
patch's fraction of the outline; ``--bulge-depth`` [m], `parcelfit.sim.mujoco.shell`), and
``--bottom`` adds to each sample how the bottom sheet lies: the lowest and the mean height [mm]
of the vertices of its face (the flat patch under the content, or the bulge's patch) and of the
rest of the bottom sheet (the rim, seam excluded), both above the bottom sheet's lowest vertex,
and the content's height above that vertex [mm], its heading [deg] and its yaw rate [rad/s] (a
rigid content). A bulge that the weight presses flat shows as a rim as low as the face.

The run goes on to its end and the last line gives its rotation and transit time; ``--stop``
ends it at ``--to`` instead if the rig's run lasts that long (a look at an early moment then
costs only the simulated time up to it; the last line's rotation is up to there, and its
transit "none" unless the parcel crossed both light barriers before). ``--to`` is then at
least 0.05 s (a run needs three samples).
"""

from __future__ import annotations

import argparse
import collections
import math
import sys

import mujoco
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim.ensemble import outcome_line
from parcelfit.sim.mujoco import MujocoSimulator, SimOptions, load_consignment, load_rig
from parcelfit.sim.mujoco.consignment import BULGE_DEPTH, with_bulge
from parcelfit.sim.mujoco.friction import Stepper, observed_steps
from parcelfit.sim.mujoco.options import scene_options

CAP = 50  # MuJoCo's mjMAXCONPAIR: contacts kept per colliding pair (geom-flex, body-flex)


def _line_angle(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    """The direction [deg] of the line from the packaging's first vertex to its last."""
    flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
    first, last = model.flex_vertadr[flex], model.flex_vertadr[flex] + model.flex_vertnum[flex] - 1
    d = data.flexvert_xpos[last] - data.flexvert_xpos[first]
    return math.degrees(math.atan2(d[1], d[0]))


def _trace(model: mujoco.MjModel, data: mujoco.MjData, top: int, start_angle: float) -> str:
    flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
    adr, num = model.flex_vertadr[flex], model.flex_vertnum[flex]
    verts = data.flexvert_xpos[adr : adr + num]
    centre = verts.mean(axis=0)
    turn = (_line_angle(model, data) - start_angle + 180) % 360 - 180
    torque: dict[str, float] = collections.defaultdict(float)
    force: dict[str, np.ndarray] = collections.defaultdict(lambda: np.zeros(3))
    pairs: collections.Counter[str] = collections.Counter()
    f6 = np.zeros(6)
    for i in range(data.ncon):
        con = data.contact[i]
        if flex not in (con.flex[0], con.flex[1]):
            continue
        geom = con.geom[0] if con.geom[0] >= 0 else con.geom[1]
        if geom < 0:  # packaging and a soft content (flex against flex)
            pairs["content"] += 1
            continue
        body = int(model.geom_bodyid[geom])
        pairs["world" if body == 0 else model.body(body).name] += 1
        if body != 0:
            continue
        mujoco.mj_contactForce(model, data, i, f6)
        # the frame's normal points from object 1 to object 2: the force on object 2
        on_second = con.frame.reshape(3, 3).T @ f6[:3]
        f = on_second if con.geom[0] == geom else -on_second
        arm = con.pos - centre
        name = model.geom(geom).name
        torque[name] += arm[0] * f[1] - arm[1] * f[0]
        force[name] += f
    hardest = sorted(torque, key=lambda k: -abs(torque[k]))[:top]
    parts = [
        f"{k} {torque[k]:+.4f} N m (F {force[k][0]:+.2f} {force[k][1]:+.2f} {force[k][2]:+.2f} N)"
        for k in hardest
    ]
    counts = " ".join(f"{k}={n}{'(cap)' if n >= CAP else ''}" for k, n in sorted(pairs.items()))
    return (
        f"t {data.time:.3f} s  x {centre[0]:+.3f} y {centre[1]:+.4f} m  turned {turn:+.2f} deg"
        f"  yaw torque {sum(torque.values()):+.4f} N m | contacts {counts}\n    "
        + ("; ".join(parts) if parts else "no rig contact")
    )


def _bottom(model: mujoco.MjModel, data: mujoco.MjData, face: np.ndarray, rim: np.ndarray) -> str:
    """How the bottom sheet lies: face and rim heights [mm] above its lowest vertex, the content."""
    flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
    verts = data.flexvert_xpos[
        model.flex_vertadr[flex] : model.flex_vertadr[flex] + model.flex_vertnum[flex]
    ]
    sheet = verts[np.concatenate([face, rim])]
    top = sheet[:, 2].min()
    zf, zr = (verts[face, 2] - top) * 1e3, (sheet[len(face) :, 2] - top) * 1e3
    if not len(zr):  # a sheet without a rim: its face stands for both
        zr = zf
    text = (
        f"    bottom: face min {zf.min():.2f} mean {zf.mean():.2f} mm,"
        f" rim min {zr.min():.2f} mean {zr.mean():.2f} mm"
    )
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "content")
    if body >= 0:
        xmat = data.xmat[body].reshape(3, 3)
        yaw = math.degrees(math.atan2(xmat[1, 0], xmat[0, 0]))
        dof = model.jnt_dofadr[model.body_jntadr[body]]
        text += (
            f"; content at {(data.xpos[body][2] - top) * 1e3:.2f} mm, heading {yaw:+.1f} deg,"
            f" yaw rate {data.qvel[dof + 5]:+.2f} rad/s"
        )
    return text


STOP_MIN = 0.05  # [s] the shortest run --stop makes: a run needs three samples


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", required=True)
    ap.add_argument("--consignment", required=True)
    ap.add_argument("--setting", type=int, default=1)
    ap.add_argument("--seed", type=int, default=None, help="placement seed (default: nominal)")
    ap.add_argument("--from", dest="t0", type=float, default=0.0, help="[s]")
    ap.add_argument("--to", dest="t1", type=float, default=math.inf, help="[s]")
    ap.add_argument("--every", type=float, default=0.01, help="[s]")
    ap.add_argument("--top", type=int, default=4, help="geoms listed per sample")
    ap.add_argument("--scene", nargs="*", default=[], metavar="KEY=VALUE")
    ap.add_argument("--bulge", type=float, default=None, metavar="FOOTPRINT")
    ap.add_argument("--bulge-depth", type=float, default=BULGE_DEPTH, help="[m]")
    ap.add_argument("--bottom", action="store_true", help="print how the bottom sheet lies")
    ap.add_argument("--stop", action="store_true", help="end the run at --to")
    args = ap.parse_args(argv)
    if not (args.every > 0 and args.t1 > args.t0 and args.top > 0):
        ap.error("--every and --top must be positive and --to after --from")
    if args.stop and not (math.isfinite(args.t1) and args.t1 >= STOP_MIN):
        ap.error(f"--stop needs --to of at least {STOP_MIN} s")
    try:
        rig = load_rig(args.rig)  # --bulge 0: a flat bottom, whatever the consignment file says
        cons = with_bulge(load_consignment(args.consignment), args.bulge, args.bulge_depth)
        stop = min(args.t1, rig.end.duration) if args.stop else None  # never longer
        options = SimOptions(scene=scene_options(args.scene), duration=stop)
        sim = MujocoSimulator(options, {rig.name: rig}, {cons.name: cons}).with_placement(args.seed)
        case = TestCase(rig.name, cons.name, args.setting)
        shell = sim.scene({}, case).shell
    except ParcelfitError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    face = np.asarray(shell.bottom_face)
    sheet = set(shell.triangles[shell.bottom_triangles].ravel()) - set(shell.seam) - set(face)
    rim = np.array(sorted(sheet), dtype=int)
    state = {"next": args.t0}

    def traced_step(stepper: Stepper) -> None:
        model, data = stepper.model, stepper.data
        if "start" not in state:
            state["start"] = _line_angle(model, data)
        if args.t0 <= data.time <= args.t1 and data.time >= state["next"] - 1e-9:
            state["next"] = data.time + args.every
            print(_trace(model, data, args.top, state["start"]), flush=True)
            if args.bottom:
                print(_bottom(model, data, face, rim), flush=True)

    with observed_steps(traced_step):
        result = sim.run({}, case)
    print(outcome_line(result))
    return 0 if result.run is not None else 1


if __name__ == "__main__":
    raise SystemExit(main())
