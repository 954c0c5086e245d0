"""How much friction do the rig's surfaces exert per unit of normal force over one run?

    python scripts/friction_budget.py --rig E3 --consignment KPBW --setting 1 --seed 0
                                      [--set k_MePa=1000 ...] [--scene KEY=VALUE ...]
                                      [--bulge FOOTPRINT [--bulge-depth D]]

Runs one simulation as `parcelfit simulate` does (the default friction law, ``contact``,
`parcelfit.sim.mujoco.friction`) and sums over every step, for the packaging's contacts with
the guide plates and lead-ins (``metal``) and with the belts, strips and rollers (``belt``):

    normal impulse      I_n = sum_steps sum_contacts N h           [N s]
    friction impulse    I_t = sum_steps sum_contacts |F_t| h       [N s]

with N the contact's normal force and F_t its friction force in that step: MuJoCo's own (a
contact that sticks or slips slowly, inside its cone) and the Coulomb force applied by hand (a
contact that slides faster than the dynamic threshold, `ContactFriction`). Their ratio
I_t / I_n is the friction the surfaces exerted per unit of normal force, to compare with the
coefficients set (mu_d and mu_s = mu_d + offset): a sliding contact should give mu_d. Also
printed per material: the contact-steps, the share of them sliding by hand, the share of
those whose force by hand was less than mu_d N of its own step (the half-slip bound, or a
normal force that rose since the step before, whose force the hand law uses), the ratio of
the force by hand to mu_d N, the yaw impulse sum tau_z h [N m s] of the contacts' forces
about the packaging's centre (the mean of its vertices), the turn impulse
sum tau_z (T - t) h [N m s^2] (T the run's end: the double time integral of the torque, the
material's share of I_z times the net turn; a slide starts and ends without spin, so the yaw
impulses of all materials sum to about zero whatever the turn, the turn impulses do not), the
normal-force-weighted mean horizontal distance of the contacts from that centre [mm] (where on
the parcel the surface pushes), and the share of the normal impulse from contacts beyond the
footprint of a rigid content by more than 5 mm (in its frame: how much of the load a mailer's
rim carries; the shell has rows of vertices right below the content's edges).

Why by hand: MuJoCo reports its constraint forces (``mj_contactForce``) but not the forces the
contact law applies as ``qfrc_applied``; the law keeps this step's (`ContactFriction.hand_force`),
read after every step of the simulator's own loop (`friction.observed_steps`).
"""

from __future__ import annotations

import argparse
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
from parcelfit.sim.params import parameter, parse_assignments

MATERIALS = ("metal", "belt")
# a contact within this distance [m] of a rigid content's footprint counts as under it: the
# shell's mesh has rows of vertices right below the content's edges, which deformation moves by
# fractions of a millimetre to either side
EDGE_MARGIN = 0.005


def force_on_packaging(frame: np.ndarray, forces: np.ndarray, surface_first: bool) -> np.ndarray:
    """A contact's force [N] on the packaging in world axes: ``frame`` MuJoCo's contact frame
    (9 values, its rows the normal from geom 0 to geom 1 and the two tangents), ``forces`` the
    force along them (normal, tangent 1, tangent 2) as MuJoCo's constraint rows give it, the
    force on object 2; ``surface_first`` when the surface is geom 0 (the packaging object 2)."""
    f = np.asarray(frame, dtype=float).reshape(3, 3).T @ np.asarray(forces, dtype=float)
    return f if surface_first else -f


def beyond_footprint(
    pos: np.ndarray,
    content_pos: np.ndarray,
    content_xmat: np.ndarray,
    half: np.ndarray,
    margin: float = EDGE_MARGIN,
) -> bool:
    """Whether the world point ``pos`` [m] lies beyond a rigid content's footprint (half
    lengths ``half`` [m] in its frame, at ``content_pos`` with rotation ``content_xmat``) by
    more than ``margin`` [m]."""
    local = np.asarray(content_xmat, dtype=float).reshape(3, 3).T @ (
        np.asarray(pos, dtype=float) - np.asarray(content_pos, dtype=float)
    )
    return bool(abs(local[0]) > half[0] + margin or abs(local[1]) > half[1] + margin)


class Budget:
    """Impulses [N s] and counts per material, summed step by step (module docstring)."""

    def __init__(self, rigid_content: bool = True) -> None:
        self.rigid_content = rigid_content
        self.normal = dict.fromkeys(MATERIALS, 0.0)
        self.friction = dict.fromkeys(MATERIALS, 0.0)
        self.coulomb = dict.fromkeys(MATERIALS, 0.0)  # sum mu_d N h of the contacts by hand
        self.hand = dict.fromkeys(MATERIALS, 0.0)  # sum |F_hand| h
        self.steps = dict.fromkeys(MATERIALS, 0)
        self.by_hand = dict.fromkeys(MATERIALS, 0)
        self.short = dict.fromkeys(MATERIALS, 0)
        self.torque = dict.fromkeys(MATERIALS, 0.0)  # sum tau_z h about the packaging's centre
        self.torque_time = dict.fromkeys(MATERIALS, 0.0)  # sum tau_z t h
        self.arm = dict.fromkeys(MATERIALS, 0.0)  # sum N r h: r the horizontal distance from it
        self.outside = dict.fromkeys(MATERIALS, 0.0)  # sum N h beyond the content's footprint
        self.end = 0.0  # the last step's time [s]

    def add(
        self,
        material: str,
        normal: float,
        mujoco_t: float,
        hand: float,
        mu_d: float,
        h: float,
        yaw_torque: float,
        arm: float,
        outside: bool = False,
        t: float = 0.0,
    ) -> None:
        """One contact in one step: its normal force, MuJoCo's and the hand law's friction
        force [N], its dynamic coefficient [-], the step [s], the yaw torque [N m] of its
        whole force about the packaging's centre, its horizontal distance from it [m], whether
        it lies beyond the content's footprint, and the step's time [s]."""
        self.torque[material] += yaw_torque * h
        self.torque_time[material] += yaw_torque * t * h
        self.end = max(self.end, t)
        self.arm[material] += normal * arm * h
        if outside:
            self.outside[material] += normal * h
        self.normal[material] += normal * h
        self.friction[material] += (mujoco_t + hand) * h
        self.steps[material] += 1
        if hand > 0:
            self.by_hand[material] += 1
            self.hand[material] += hand * h
            self.coulomb[material] += mu_d * normal * h
            if hand < 0.999 * mu_d * normal:
                self.short[material] += 1

    def turn_impulse(self, material: str, end: float | None = None) -> float:
        """sum tau_z (T - t) h [N m s^2] up to T (``end``, default the last step's time): the
        double time integral of the material's yaw torque, the share of I_z times the net
        turn its torques drove (a torque early in the run turns the parcel for longer)."""
        end = self.end if end is None else end
        return end * self.torque[material] - self.torque_time[material]

    def lines(self) -> list[str]:
        """The table, one row per material that had contacts."""
        out = [
            "| surfaces | contact-steps | normal impulse [N s] | friction impulse [N s] | "
            "friction / normal | by hand | by hand below mu_d N | by hand: impulse / (mu_d N) | "
            "yaw impulse [N m s] | turn impulse [N m s^2] | mean distance from the centre [mm] | "
            f"normal impulse beyond the content's footprint (by > {EDGE_MARGIN * 1e3:g} mm) |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for m in MATERIALS:
            n = self.steps[m]
            if not n:
                continue
            ratio = self.friction[m] / self.normal[m] if self.normal[m] > 0 else math.nan
            hand_ratio = self.hand[m] / self.coulomb[m] if self.coulomb[m] > 0 else math.nan
            share = (
                f"{self.outside[m] / self.normal[m]:.1%}"
                if self.rigid_content and self.normal[m] > 0
                else "n/a"
            )
            out.append(
                f"| {m} | {n} | {self.normal[m]:.5g} | {self.friction[m]:.5g} | {ratio:.4f} | "
                f"{self.by_hand[m] / n:.1%} | {self.short[m] / max(1, self.by_hand[m]):.1%} | "
                f"{hand_ratio:.4f} | {self.torque[m]:+.5g} | {self.turn_impulse(m):+.5g} | "
                f"{self.arm[m] / self.normal[m] * 1e3 if self.normal[m] > 0 else math.nan:.1f} | "
                f"{share} |"
            )
        return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", required=True)
    ap.add_argument("--consignment", required=True)
    ap.add_argument("--setting", type=int, default=1)
    ap.add_argument("--seed", type=int, default=None, help="placement seed (default: nominal)")
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="catalogue units")
    ap.add_argument("--scene", nargs="*", default=[], metavar="KEY=VALUE")
    ap.add_argument(
        "--bulge",
        type=float,
        default=None,
        metavar="FOOTPRINT",
        help="a bottom bulging below the rigid content over this share of the outline (0: flat)",
    )
    ap.add_argument("--bulge-depth", type=float, default=BULGE_DEPTH, help="[m]")
    args = ap.parse_args(argv)
    try:
        rig = load_rig(args.rig)  # --bulge 0: a flat bottom, whatever the consignment file says
        cons = with_bulge(load_consignment(args.consignment), args.bulge, args.bulge_depth)
        scene_opts = scene_options(args.scene)
        if scene_opts.friction != "contact":
            raise ParcelfitError(
                "the budget reads the per-contact friction law's forces",
                fix="leave friction at its default (contact)",
            )
        params = {k: parameter(k).to_si(v) for k, v in parse_assignments(args.set).items()}
        cons.parameter_values(si_values=params)  # checks names and ranges
        sim = MujocoSimulator(
            SimOptions(scene=scene_opts), {rig.name: rig}, {cons.name: cons}
        ).with_placement(args.seed)
        case = TestCase(rig.name, cons.name, args.setting)
        scene = sim.scene(params, case)
    except ParcelfitError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    budget = Budget(rigid_content=not cons.soft)
    metal_names = [*scene.metal_geoms, *(g.name for g in scene.driven if g.material == "metal")]
    half = np.asarray(cons.content[:2]) / 2
    looked_up: list[tuple[set[int], slice, int]] = []  # the model's ids, looked up once

    def counted_step(stepper: Stepper) -> None:
        model, data, law = stepper.model, stepper.data, stepper.contact
        if law is None:
            return
        if not looked_up:
            flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
            adr = int(model.flex_vertadr[flex])
            looked_up.append(
                (
                    {mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, g) for g in metal_names},
                    slice(adr, adr + int(model.flex_vertnum[flex])),
                    -1
                    if cons.soft
                    else mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "content"),
                )
            )
        metal, verts, content = looked_up[0]
        h = float(model.opt.timestep)
        hand = law.hand_force
        centre = data.flexvert_xpos[verts].mean(axis=0)
        for i in range(data.ncon):
            con = data.contact[i]
            adr = con.efc_address
            surface = (
                con.geom[0] if con.geom[0] >= 0 and law.is_surface[con.geom[0]] else con.geom[1]
            )
            if adr < 0 or surface < 0 or not law.is_surface[surface]:
                continue
            material = "metal" if surface in metal else "belt"
            normal = float(data.efc_force[adr])
            mujoco_t = float(np.hypot(data.efc_force[adr + 1], data.efc_force[adr + 2]))
            by_hand = float(np.hypot(hand[adr + 1], hand[adr + 2])) if hand.size > adr + 2 else 0.0
            rows = data.efc_force[adr : adr + 3].copy()
            if hand.size > adr + 2:  # the hand law's forces lie along the same tangents
                rows[1:] += hand[adr + 1 : adr + 3]
            f = force_on_packaging(con.frame, rows, con.geom[0] == surface)
            arm = con.pos - centre
            budget.add(
                material,
                normal,
                mujoco_t,
                by_hand,
                float(model.geom_friction[surface, 0]),
                h,
                float(arm[0] * f[1] - arm[1] * f[0]),
                float(np.hypot(arm[0], arm[1])),
                content >= 0
                and beyond_footprint(con.pos, data.xpos[content], data.xmat[content], half),
                float(data.time),
            )

    with observed_steps(counted_step):
        result = sim.run(params, case)
    shown = " ".join(sys.argv[1:] if argv is None else argv)
    print(
        f"# Friction budget: {case.label}, placement seed {args.seed}"
        + (f", {' '.join(args.set)}" if args.set else "")
        + (f", scene {' '.join(args.scene)}" if args.scene else "")
        + (f", bulge {args.bulge:g} ({args.bulge_depth:g} m)" if args.bulge is not None else "")
    )
    print()
    print(f"Written by `python scripts/friction_budget.py {shown}`")
    print()
    print(
        "Coefficients set: "
        + ", ".join(
            f"{k} {v:g}"
            for k, v in cons.parameter_values(si_values=params).items()
            if k.startswith("mu_")
        )
    )
    print()
    print("\n".join(budget.lines()))
    print()
    print(outcome_line(result))
    return 0 if result.run is not None else 1


if __name__ == "__main__":
    raise SystemExit(main())
