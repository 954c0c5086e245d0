"""Does the model's contact get the stiffness it asks for? The penalty mapping's inverse mass
against MuJoCo's own, on an interpolated shell.

    python scripts/contact_diagonal.py --consignment KP --material metal --k 100 611 1000

The penalty law (`parcelfit.sim.mujoco.contact.penalty_contact`) spreads the catalogue's
whole-face stiffness k [N/m] over the flat face's n_face contacts, K_c = k / n_face, and sets
each contact's solref from K_c and an inverse mass A, taken as that of a lone shell vertex,
1 / m_v. MuJoCo's regulariser takes its own diagonal approximation instead, which for a contact
on an interpolated flex is the vertex's interpolation weights times its node bodies' inverse
weights, A_v = sum_n W_vn body_invweight0[n] (`mj_diagApprox` in MuJoCo's
engine_core_constraint.c); the realised static stiffness per contact is then about
K_c (1 / m_v) / A_v. For each k this prints

* n_face and the requested K_c [N/m];
* the realised per-contact stiffness from the indentation test
  (`parcelfit.sim.mujoco.indentation`: the parcel on a still plate, its content pressed with two
  loads; d(force) over the summed d(penetration) of the plate contacts) and its ratio to K_c;
* how many plate contacts carried the load (MuJoCo keeps at most 50 per pair);
* 1 / m_v, the mean of A_v over the face's contact vertices, and their ratio.

SI units inside; k on the command line in N/mm as the catalogue.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

import mujoco
import numpy as np

from parcelfit.sim.mujoco import load_consignment
from parcelfit.sim.mujoco.indentation import indentation_test, plate_rig
from parcelfit.sim.mujoco.lumped_mass import element_vertex_masses, interpolation_weights
from parcelfit.sim.mujoco.options import SceneOptions
from parcelfit.sim.mujoco.scene import build_scene
from parcelfit.sim.params import parameter

_KEY = {"metal": "k_MePa", "belt": "k_BePa"}


def inverse_masses(consignment: str, material: str, stiffness: float) -> tuple[float, float]:
    """(1 / m_v, mean A_v) [1/kg] over the flat face's contact vertices of ``consignment``'s
    shell on a ``material`` plate, with the contact stiffness ``stiffness`` [N/m] (module
    docstring)."""
    cons = load_consignment(consignment)
    p = cons.parameter_values(si_values={_KEY[material]: stiffness})
    scene = build_scene(plate_rig(material), cons, p, 1, SceneOptions())
    shell = scene.shell
    masses = element_vertex_masses(shell.points, shell.triangles, p["m_Pa"])
    assumed = 1.0 / float(masses[shell.face_contact_vertices].mean())
    model = scene.model()
    flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
    nodes = model.flex_nodebodyid[
        model.flex_nodeadr[flex] : model.flex_nodeadr[flex] + model.flex_nodenum[flex]
    ]
    diagonal = interpolation_weights(model, flex) @ model.body_invweight0[nodes, 0]
    return assumed, float(np.mean(diagonal[shell.face_contact_vertices]))


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--consignment", default="KP", help="a type with a rigid content")
    ap.add_argument("--material", choices=sorted(_KEY), default="metal")
    ap.add_argument("--k", type=float, nargs="+", default=[100.0, 611.0, 1000.0], help="[N/mm]")
    ap.add_argument("--settle", type=float, default=0.3, help="time under each load [s]")
    args = ap.parse_args(argv)
    key = _KEY[args.material]
    if load_consignment(args.consignment).soft:
        ap.error(f"{args.consignment} has a soft content: the indentation presses a rigid one")
    print(
        f"{args.consignment} on a still {args.material} plate, content pressed with 10 then 20 N "
        f"({args.settle:g} s each)"
    )
    print(
        f"{key + ' [N/mm]':>14}{'n_face':>8}{'K_c asked':>11}{'K_c realised':>14}{'ratio':>7}"
        f"{'contacts':>10}{'1/m_v':>9}{'A_v':>9}{'ratio':>7}"
    )
    for k in args.k:
        stiffness = parameter(key).to_si(k)
        cons = load_consignment(args.consignment)
        result = indentation_test(
            cons, {key: stiffness}, material=args.material, settle=args.settle
        )
        asked = stiffness / result.n_face
        realised = result.plate / result.plate_contacts  # the face's stiffness per kept contact
        assumed, diagonal = inverse_masses(args.consignment, args.material, stiffness)
        print(
            f"{k:>14g}{result.n_face:>8d}{asked:>11.4g}{realised:>14.4g}{realised / asked:>7.2f}"
            f"{result.plate_contacts:>10d}{assumed:>9.0f}{diagonal:>9.0f}"
            f"{assumed / diagonal:>7.2f}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
