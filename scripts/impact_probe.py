"""Is the step fine enough to tell a stiff packaging contact from a soft one?

A parcel is dropped flat at 0.5 m/s on a still plate of metal (k_MePa) or belt material (k_BePa),
with today's defaults (the penalty law). For each stiffness and time step the probe reports the
impact's peak force [N], how long the force exceeds twice the parcel's weight [ms], and omega h,
the contact's angular frequency times the step (`ContactParams.omega_dt` of the plate's contacts).
MuJoCo integrates the contact implicitly, so a large omega h stays stable but damps the impact:
if the peak force and duration at the default step (1/2400 s) differ between the soft and the
stiff contact by about what they do at a four times finer step, the default step tells the
stiffnesses apart. Run (seconds):

    python scripts/impact_probe.py --consignment KPBW --material metal
"""

from __future__ import annotations

import argparse

import mujoco
import numpy as np

from parcelfit.sim.mujoco import load_consignment
from parcelfit.sim.mujoco.indentation import plate_rig
from parcelfit.sim.mujoco.options import SceneOptions
from parcelfit.sim.mujoco.scene import build_scene
from parcelfit.sim.mujoco.simulator import add_rigid_velocity

G = 9.81


def impact(
    consignment: str, material: str, stiffness: float, timestep: float, speed: float = 0.5
) -> tuple[float, float, float]:
    """Peak plate force [N], time above twice the weight [s] and omega h of a flat drop at
    ``speed`` [m/s] with the plate contact's whole-face ``stiffness`` [N/m]."""
    cons = load_consignment(consignment)
    key = "k_MePa" if material == "metal" else "k_BePa"
    full = cons.parameter_values(si_values={key: stiffness})
    scene = build_scene(plate_rig(material), cons, full, 1, SceneOptions(timestep=timestep))
    model = scene.model()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    add_rigid_velocity(model, data, np.array([0.0, 0.0, -speed]))
    plate = model.geom("plate").id
    forces = []
    for _ in range(round(0.05 / timestep)):
        mujoco.mj_step(model, data)
        adr = data.contact.efc_address[: data.ncon]
        on = (data.contact.geom[: data.ncon] == plate).any(axis=1) & (adr >= 0)
        forces.append(float(data.efc_force[adr[on]].sum()))
    f = np.asarray(forces)
    omega_dt = scene.contacts[material].omega_dt
    return float(f.max()), float(np.count_nonzero(f > 2 * cons.mass * G) * timestep), omega_dt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--consignment", default="KPBW")
    ap.add_argument("--material", default="metal", choices=["metal", "belt"])
    ap.add_argument("--stiffness", type=float, nargs="+", default=[100.0, 1000.0], help="N/mm")
    ap.add_argument("--steps", type=float, nargs="+", default=[2400.0, 9600.0], help="1/s")
    args = ap.parse_args()
    print(
        f"`python scripts/impact_probe.py --consignment {args.consignment} --material "
        f"{args.material}`: a flat drop at 0.5 m/s\n"
    )
    print("| stiffness [N/mm] | step [s] | omega h | peak force [N] | above 2 m g [ms] |")
    print("|---|---|---|---|---|")
    for k in args.stiffness:
        for n in args.steps:
            peak, duration, omega_dt = impact(args.consignment, args.material, k * 1e3, 1 / n)
            print(f"| {k:g} | 1/{n:g} | {omega_dt:.2f} | {peak:.1f} | {duration * 1e3:.2f} |")


if __name__ == "__main__":
    main()
