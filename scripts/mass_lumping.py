"""Where do the packaging's grams sit? Its moment of inertia with MuJoCo's equal shares and lumped.

    python scripts/mass_lumping.py [--types BW KPBW KP PB] [--dofs full auto]

For each consignment type and shell (``--dofs``: `SceneOptions.shell_dof`, "auto" being the
type's own), builds the E3 scene at rest and prints a Markdown table of the packaging's moment of
inertia about the vertical through its centre of mass [g cm^2] with the two
`SceneOptions.mass_lumping` choices: "equal" (every vertex or node the same share, MuJoCo's
own) and "area" (`parcelfit.sim.mujoco.lumped_mass`), beside a uniform flat sheet of the
packaging's mass over its outline (m (L^2 + W^2) / 12: the pillow's tapered rim and the seam add
a little to that), and the content's with either lumping (a rigid box is the same in both; a
soft content's grid of vertices differs) beside a uniform box of its mass and size. No
simulation is run; a second or two per row.
"""

from __future__ import annotations

import argparse
import sys

import mujoco
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator, SimOptions, load_consignment
from parcelfit.sim.mujoco.lumped_mass import mass_bodies
from parcelfit.sim.mujoco.options import SceneOptions

G_CM2 = 1e7  # kg m^2 -> g cm^2


def _bodies(model: mujoco.MjModel, name: str) -> np.ndarray:
    """The bodies that carry flex ``name``'s mass (none if the model has no such flex)."""
    f = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, name)
    return np.array([], dtype=int) if f < 0 else mass_bodies(model, f)


def yaw_inertia(model: mujoco.MjModel, bodies: np.ndarray) -> float:
    """Moment of inertia [kg m^2] of ``bodies`` about the vertical through their centre of mass
    (their own rotational inertia included), at the model's rest pose."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    m = model.body_mass[bodies]
    x = data.xipos[bodies]
    c = (m[:, None] * x).sum(axis=0) / m.sum()
    own = 0.0
    for b in bodies:
        rot = data.ximat[b].reshape(3, 3)
        own += float((rot @ np.diag(model.body_inertia[b]) @ rot.T)[2, 2])
    return float(np.sum(m * ((x[:, 0] - c[0]) ** 2 + (x[:, 1] - c[1]) ** 2))) + own


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--types", nargs="+", default=["BW", "KPBW", "KP", "PB"])
    ap.add_argument("--dofs", nargs="+", default=["full", "auto"])
    args = ap.parse_args(argv)
    print(
        "| type | shell | packaging [g] | I_z equal [g cm^2] | I_z area [g cm^2] | equal / area |"
        " flat sheet [g cm^2] | content I_z equal / area [g cm^2] | content box [g cm^2] |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    try:
        for name in args.types:
            cons = load_consignment(name)
            for dof in args.dofs:
                row = {}
                for lumping in ("equal", "area"):
                    options = SceneOptions(shell_dof=dof, mass_lumping=lumping)
                    sim = MujocoSimulator(SimOptions(scene=options), consignments={cons.name: cons})
                    model = sim.scene({}, TestCase("E3", cons.name, 1)).model()
                    pack = _bodies(model, "packaging")
                    content = _bodies(model, "content")
                    if not len(content):
                        content = np.array(
                            [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "content")]
                        )
                    row[lumping] = (
                        float(model.body_mass[pack].sum()),
                        yaw_inertia(model, pack),
                        yaw_inertia(model, content),
                    )
                mass, i_eq, c_eq = row["equal"]
                _, i_area, c_area = row["area"]
                L, W = cons.outer[0], cons.outer[1]
                sheet = mass * (L * L + W * W) / 12
                cL, cW, _ = cons.content
                box = (cons.mass - mass) * (cL * cL + cW * cW) / 12
                shell = (
                    dof
                    if dof != "auto"
                    else f"auto ({SceneOptions().shell_for(cons.soft, cons.shell)})"
                )
                print(
                    f"| {name} | {shell} | {mass * 1e3:.1f} | {i_eq * G_CM2:.0f} | {i_area * G_CM2:.0f} |"
                    f" {i_eq / i_area:.2f} | {sheet * G_CM2:.0f} | {c_eq * G_CM2:.0f} / {c_area * G_CM2:.0f} |"
                    f" {box * G_CM2:.0f} |"
                )
    except ParcelfitError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
