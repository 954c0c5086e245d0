"""Virtual indentation test: the realised whole-face contact stiffness of a parcel model [N/m].

The parcel lies flat on a static plate of the chosen material. The (rigid) content is pressed
down with a force F1 [N] and the parcel settles, then with F2 > F1 and it settles again (both
loads keep the whole face in contact; under gravity alone a few corner contacts at the face's
edge do not touch yet), stepped as the simulator steps (`parcelfit.sim.mujoco.friction.Stepper`,
so the contact mapping's weights act). Every contact between the plate and the packaging, and
between the content and the packaging's bottom sheet (below the content's centre: the face that
carries the load), reports its penetration. Where MuJoCo keeps every touching contact, the n
contacts at F2 carry the added load in parallel, each of stiffness (F2 - F1) / sum_i d(delta_i)
(contacts that appear or vanish between the loads sit at near zero penetration), so the
realised whole-face stiffness is

    K_face = n (F2 - F1) / sum_i d(delta_i)

Where MuJoCo keeps 50 of more (its cap per pair, `parcelfit.sim.mujoco.contact_cap`), it picks
them anew at each load, all carrying, and the face's displacement is their mean penetration:

    K_face = (F2 - F1) / (mean delta(F2) - mean delta(F1))

Both assume the whole face touches at both loads. Where the touching area grows with the load
(a light, stiff face), the quotient measures that growth too, and with the "solver" contact
mapping, whose weights follow the touching area, it can even come out negative.
`parcelfit.sim.mujoco.contact` promises K_face = k_BePa / k_MePa / k_CoPa where n is the flat
face's n_face (`ShellMesh.face_contacts`). (Until 2026-12-07 the test took n_face (F2 - F1) /
sum_i d(delta_i) throughout: the same where MuJoCo keeps all the face's contacts, as with the
full shell, and about n_face / 50 times too stiff where it keeps 50 of them, as with an
interpolated shell: docs/research/contact-cap.md.)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import mujoco
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco.consignment import Consignment
from parcelfit.sim.mujoco.friction import Stepper
from parcelfit.sim.mujoco.options import MAX_CONTACTS_PER_PAIR, SceneOptions
from parcelfit.sim.mujoco.rig import Rig, parse_rig
from parcelfit.sim.mujoco.scene import build_scene


@dataclass(frozen=True)
class Indentation:
    """Realised whole-face stiffnesses [N/m], the contacts that carried the load (at F2), and
    n_face (the flat face's contacts, `ShellMesh.face_contacts`)."""

    plate: float
    content: float
    plate_contacts: int
    content_contacts: int
    n_face: int


def plate_rig(material: str, tile: float | None = None) -> Rig:
    """A still 1 m x 1 m plate of ``material`` ("belt" or "metal") centred at the origin, as one
    surface named ``plate`` or, with ``tile`` [m], as n x n touching square tiles
    ``plate_<i>_<j>`` of side 1/n m, n = round(1 / tile): physically the same plate, but MuJoCo
    meets each tile as its own contact pair (at most 50 contacts each with an interpolated
    shell), so a model that depends on the split is not converged in it."""
    if tile is None:
        tiles = [("plate", 0.0, 0.0, 1.0)]
    else:
        if not 0.01 <= tile <= 1.0:
            raise ParcelfitError(
                f"plate tile must lie in [10, 1000] mm, got {tile * 1e3:g} mm",
                fix="give the tile side in metres, e.g. 0.05",
            )
        n = round(1.0 / tile)  # at least 1: tile <= 1 m
        side = 1.0 / n
        tiles = [
            (f"plate_{i}_{j}", (i - (n - 1) / 2) * side, (j - (n - 1) / 2) * side, side)
            for i in range(n)
            for j in range(n)
        ]
    return parse_rig(
        {
            "name": "plate",
            "speeds": {1: {"none": 0.0}},
            "surfaces": [
                {
                    "name": name,
                    "type": "belt",
                    "material": material,
                    "centre": [x, y],
                    "length": side,
                    "width": side,
                    "heading": 0,
                    "top": 0.0,
                    "drive": "none",
                }
                for name, x, y, side in tiles
            ],
            # the parcel starts at the origin, on the tile nearest to it (all lie at one height)
            "start": {
                "position": [0, 0],
                "heading": 0,
                "surface": min(tiles, key=lambda t: t[1] ** 2 + t[2] ** 2)[0],
            },
            "light_barriers": [
                {"name": "a", "from": [0.4, -1], "to": [0.4, 1]},
                {"name": "b", "from": [0.45, -1], "to": [0.45, 1]},
            ],
            "end": {"x": [-1, 1], "y": [-1, 1], "duration": 1.0},
        },
        "<indentation plate>",
    )


def plate_geoms(model: mujoco.MjModel) -> list[int]:
    """The geom ids of a `plate_rig` plate in a compiled scene: ``plate`` or its tiles."""
    return [g for g in range(model.ngeom) if model.geom(g).name.startswith("plate")]


def _penetrations(
    model: mujoco.MjModel, data: mujoco.MjData, plate: int, content: int
) -> tuple[np.ndarray, np.ndarray, bool, bool]:
    """The penetrations [m] of the plate's contacts and of the content's contacts below its
    centre (the packaging's bottom sheet under it), and whether MuJoCo capped each pair."""
    n = data.ncon
    geoms = np.asarray(data.contact.geom[:n])
    dist = np.asarray(data.contact.dist[:n])
    below = np.asarray(data.contact.pos[:n])[:, 2] < data.xpos[model.geom_bodyid[content], 2]
    on_plate = (geoms == plate).any(axis=1)
    on_content = (geoms == content).any(axis=1)
    return (
        -dist[on_plate],
        -dist[on_content & below],
        int(on_plate.sum()) == MAX_CONTACTS_PER_PAIR,
        int(on_content.sum()) == MAX_CONTACTS_PER_PAIR,
    )


def _face_stiffness(added: float, before: np.ndarray, after: np.ndarray, capped: bool) -> float:
    """The realised face stiffness [N/m] from the penetrations [m] before and after adding
    ``added`` [N] (module docstring)."""
    if capped:
        # MuJoCo re-picks the 50 it keeps at each load, all carrying: the face's displacement
        return added / float(np.mean(after) - np.mean(before))
    # every touching contact kept: those that appear or vanish carry (near) no force
    return len(after) * added / float(np.sum(after) - np.sum(before))


def indentation_test(
    consignment: Consignment,
    params: Mapping[str, float] | None = None,
    material: str = "belt",
    loads: tuple[float, float] = (10.0, 20.0),
    settle: float = 0.5,
    options: SceneOptions | None = None,
) -> Indentation:
    """Measure the realised stiffness [N/m] of the plate/packaging and content/packaging faces."""
    if consignment.soft:
        raise ParcelfitError(
            "the indentation test presses a rigid content", fix="use a rigid-content consignment"
        )
    if options is not None and options.content_tiles > 1:
        raise ParcelfitError(
            "the indentation test reads the contacts of one content box",
            fix="use content_tiles=1 (the default)",
        )
    options = options or SceneOptions()
    full = consignment.parameter_values(si_values=params or {})
    scene = build_scene(plate_rig(material), consignment, full, 1, options)
    model = scene.model()
    data = mujoco.MjData(model)
    stepper = Stepper(model, data, scene, full, options)
    plate = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "plate")
    content = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "content")
    body = model.geom_bodyid[content]
    steps = round(settle / model.opt.timestep)

    def settle_and_measure(force: float) -> tuple[np.ndarray, np.ndarray, bool, bool]:
        data.xfrc_applied[body, 2] = -force
        for _ in range(steps):
            stepper.step()
        return _penetrations(model, data, plate, content)

    p0, c0, p0_capped, c0_capped = settle_and_measure(loads[0])
    p1, c1, p1_capped, c1_capped = settle_and_measure(loads[1])
    added = loads[1] - loads[0]
    return Indentation(
        plate=_face_stiffness(added, p0, p1, p0_capped and p1_capped),
        content=_face_stiffness(added, c0, c1, c0_capped and c1_capped),
        plate_contacts=len(p1),
        content_contacts=len(c1),
        n_face=scene.shell.face_contacts,
    )
