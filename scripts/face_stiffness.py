"""Does a whole face get the catalogue's stiffness? Both contact mappings on several meshes.

    python scripts/face_stiffness.py [--consignments KPBW KP BW] [--spacings 0.03 0.015]
                                     [--k 100 1000] [--mappings vertex solver] [--settle 0.4]

For each rigid-content type, mesh spacing [m], contact mapping (`SceneOptions.contact_mapping`)
and stiffness k [N/mm] (k_BePa and k_CoPa alike: the parcel on a still belt plate), the virtual
indentation test (`parcelfit.sim.mujoco.indentation`: the content pressed with 10 then 20 N, the
face's stiffness from the mean penetration of the contacts MuJoCo keeps) prints the realised
whole-face stiffness of the plate/packaging and content/packaging contacts as a share of k, the
contacts MuJoCo kept (at most 50 per pair) against the flat face's n_face, and, for the
interpolated shells, MuJoCo's own inverse mass of a face contact against a lone vertex's
(`parcelfit.sim.mujoco.contact_cap`; a property of the mesh). The type's own bottom (BW's bulge) is flattened: the
catalogue's stiffness is a flat face's. docs/research/contact-cap.md holds the output.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import replace

from parcelfit.sim.mujoco import SceneOptions, load_consignment
from parcelfit.sim.mujoco.contact_cap import solver_inverse_mass
from parcelfit.sim.mujoco.indentation import indentation_test, plate_rig
from parcelfit.sim.mujoco.mjlog import CountedWarnings
from parcelfit.sim.mujoco.scene import build_scene
from parcelfit.sim.params import CONTACT_MAPPINGS, parameter


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--consignments", nargs="+", default=["KPBW", "KP", "BW"])
    ap.add_argument("--spacings", nargs="+", type=float, default=[0.03, 0.015], help="[m]")
    ap.add_argument("--k", nargs="+", type=float, default=[100.0, 1000.0], help="[N/mm]")
    ap.add_argument("--mappings", nargs="+", choices=CONTACT_MAPPINGS, default=CONTACT_MAPPINGS)
    ap.add_argument("--settle", type=float, default=0.4, help="time under each load [s]")
    args = ap.parse_args(argv)
    for name in args.consignments:
        if load_consignment(name).soft:
            ap.error(f"{name} has a soft content: the indentation presses a rigid one")
    t0 = time.perf_counter()
    print(
        f"{'type':<6}{'mesh [mm]':>10}{'mapping':>9}{'k [N/mm]':>10}{'plate':>8}{'content':>9}"
        f"{'kept':>6}{'n_face':>8}{'A_v m_v':>9}"
    )
    for name in args.consignments:
        cons = replace(load_consignment(name), bulge=None)
        for spacing in args.spacings:
            with CountedWarnings():
                scene = build_scene(
                    plate_rig("belt"),
                    cons,
                    cons.parameter_values(),
                    1,
                    SceneOptions(spacing=spacing),
                )
                ratio = solver_inverse_mass(scene.model(), scene.shell) / scene.vertex_inverse_mass
            for mapping in args.mappings:
                options = SceneOptions(spacing=spacing, contact_mapping=mapping)
                for k in args.k:
                    stiffness = parameter("k_BePa").to_si(k)
                    params = {"k_BePa": stiffness, "k_CoPa": parameter("k_CoPa").to_si(k)}
                    with CountedWarnings():
                        result = indentation_test(
                            cons, params, "belt", settle=args.settle, options=options
                        )
                    print(
                        f"{name:<6}{spacing * 1e3:>10g}{mapping:>9}{k:>10g}"
                        f"{result.plate / stiffness:>8.3f}{result.content / stiffness:>9.3f}"
                        f"{result.plate_contacts:>6d}{result.n_face:>8d}{ratio:>9.3f}",
                        flush=True,
                    )
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
