"""The packaging's contacts as MuJoCo's solver meets them: its own inverse mass, and its cap of
50 contacts per pair (`SceneOptions.contact_mapping = "solver"`).

The penalty law (`parcelfit.sim.mujoco.contact`) spreads a catalogue stiffness K [N/m] (a whole
face's) over the face's n_face contacts, K_c = K / n_face, a stiffness per unit contact area, and
sets each contact's solref from K_c and the contact's inverse effective mass A:

    s = K_c A (1 - d),   b = c_c A (1 - d)          (static stiffness K_c, damping c_c)

MuJoCo realises s / ((1 - d) A_hat) = K_c A / A_hat, with A_hat its own diagonal estimate of
the contact's inverse mass. Two things part an interpolated shell's realised face from K:

1. **The inverse mass.** The "vertex" mapping takes A as a lone shell vertex's, 1 / m_v (plus
   the other side's: 0 for a surface, 1 / m_content for a rigid content). An interpolated
   shell's vertex has no body; MuJoCo's A_hat is its nodes' inverse weights through the
   interpolation (`mj_diagApprox`),

       A_v = sum_n W_vn / m_n      (W: the interpolation weights, m_n: the node masses)

   which is 0.42 of 1 / m_v on KP/BW's 30 mm mesh and 0.105 on 15 mm (a finer mesh has lighter
   vertices, its nodes are the same): each contact comes out 1 / 0.42 = 2.4 and 9.5 times as
   stiff as asked, a vertex of the rim by another factor than one of the face. The "solver"
   mapping scales each packaging pair's solref by (A_face + A_other) / (1 / m_v + A_other)
   after the model is compiled, A_face the flat face's contacts' harmonic mean of A_v (as the
   vertex mapping averages their masses; `solver_inverse_mass`, `map_to_solver`), and each
   contact in every step by
   (A_v + A_other) / (A_face + A_other) of its own vertex (the corner of its triangle nearest
   to the contact point; `CapWeights`), so that every contact realises K_c.
2. **The cap.** MuJoCo keeps at most 50 contacts of a flex with one geom (mjMAXCONPAIR), chosen
   by farthest-point sampling from the deepest (``filterFlexContacts`` in MuJoCo's
   engine_collision_driver.c): spread over the touching region, each standing for
   n_touch / 50 of it. A parcel flat on a belt touches it with n_face = 212 triangle corners on
   KP/BW's 30 mm mesh and 650 on 15 mm, so only 50 / n_face of the face's stiffness acts. The
   "solver" mapping weights each kept contact of a pair at the cap by w = n_touch / 50 (its
   solref times w, so stiffness and damping alike, between ``mj_step1`` and ``mj_step2``),
   where

       n_touch = sum over the shell's vertices within the flex's radius of the geom of the
                 number of triangles the vertex is a corner of

   (MuJoCo makes one contact per touching corner of a triangle; the count matches MuJoCo's own
   wherever a pair stays below the cap: `tests/test_contact_cap.py`). Only box geoms (belts,
   strips, plates, walls, a rigid content) are counted; a capped pair on another geom type
   keeps w = 1 and is counted in the run's diagnostics (``cap_unweighted``).

With both, each contact has K / n_face, the stiffness per unit area, wherever the packaging
touches (an edge on a guide plate too), and a face pressed flat realises K: a plate's face 0.96-1.01
of 100 N/mm on 30 and 15 mm meshes for KP/BW, KP and BW (the virtual indentation test,
`parcelfit.sim.mujoco.indentation`; docs/research/contact-cap.md, which has where it does not).
The weights assume that the kept contacts spread evenly over the touching region, as MuJoCo's
farthest-point sampling means them to; MuJoCo's issue #3297 (open) reports that its selection
can keep a contact other than the one it chose. A full shell (vertex bodies) is not capped by
MuJoCo 4.0.1, so its pairs are never weighted.
Why by hand: MuJoCo's cap is a compile-time constant, and its solver estimates the inverse
mass itself; neither is a setting.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import mujoco
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco.lumped_mass import (
    flex_elements,
    interpolation_weights,
    is_interpolated,
    mass_bodies,
)
from parcelfit.sim.mujoco.options import MAX_CONTACTS_PER_PAIR

if TYPE_CHECKING:
    from parcelfit.sim.mujoco.shell import ShellMesh

PACKAGING = "packaging"  # the packaging flex's name in every scene


def _packaging_flex(model: mujoco.MjModel) -> int:
    flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, PACKAGING)
    if flex < 0:
        raise ValueError("the model has no packaging flex")
    return int(flex)


def vertex_inverse_masses(model: mujoco.MjModel) -> np.ndarray:
    """MuJoCo's inverse mass A_v [1/kg] of a contact at each packaging vertex against a static
    geom (module docstring): through the interpolation for an interpolated shell, the vertex
    bodies' own for a full shell. A quadratic shell (a node fixed to its frame) is refused."""
    flex = _packaging_flex(model)
    inverse = np.asarray(model.body_invweight0[mass_bodies(model, flex), 0], dtype=float)
    if not is_interpolated(model, flex):
        return inverse
    try:
        weights = interpolation_weights(model, flex)
    except ValueError as exc:  # MuJoCo's quadratic shell: a node fixed to its frame
        raise ParcelfitError(
            f"contact_mapping 'solver' cannot read this shell's inverse masses ({exc})",
            fix="use shell_dof=trilinear or full with it, or contact_mapping=vertex",
        ) from exc
    return weights @ inverse


def face_inverse_mass(per_vertex: np.ndarray, shell: ShellMesh) -> float:
    """A_face [1/kg]: the harmonic mean of ``per_vertex`` over the flat face's contacts (a
    face's stiffness adds over its contacts as their masses do)."""
    return float(1.0 / np.mean(1.0 / per_vertex[shell.face_contact_vertices]))


def solver_inverse_mass(model: mujoco.MjModel, shell: ShellMesh) -> float:
    """A_face [1/kg] of ``model`` (`vertex_inverse_masses`, `face_inverse_mass`)."""
    return face_inverse_mass(vertex_inverse_masses(model), shell)


def packaging_geoms(model: mujoco.MjModel) -> list[int]:
    """The geoms that can touch the packaging flex (contype/conaffinity), in id order."""
    flex = _packaging_flex(model)
    ftype, faff = int(model.flex_contype[flex]), int(model.flex_conaffinity[flex])
    return [
        g
        for g in range(model.ngeom)
        if (int(model.geom_contype[g]) & faff) or (ftype & int(model.geom_conaffinity[g]))
    ]


def map_to_solver(model: mujoco.MjModel, shell: ShellMesh, vertex_inverse_mass: float) -> float:
    """Scale, in place, the solref of every geom the packaging can touch from the lone-vertex
    inverse mass ``vertex_inverse_mass`` [1/kg] the scene was written with to MuJoCo's own
    (`solver_inverse_mass`), each with its own body's inverse weight added (0 for the world, 1 /
    m for a rigid content); return A_v / (1 / m_v) [-]. Exact for the penalty law, whose solref
    is proportional to the inverse mass."""
    a_v = solver_inverse_mass(model, shell)
    for g in packaging_geoms(model):
        body = int(model.geom_bodyid[g])
        other = float(model.body_invweight0[body, 0]) if body != 0 else 0.0
        model.geom_solref[g] *= (a_v + other) / (vertex_inverse_mass + other)
    return a_v / vertex_inverse_mass


def packaging_contacts(data: mujoco.MjData, flex: int) -> tuple[np.ndarray, ...]:
    """This step's contacts of flex ``flex``'s elements with a geom: their indices in
    ``data.contact``, the geom each touches and the element."""
    n = data.ncon
    con = data.contact
    geom = np.asarray(con.geom[:n])
    flexes = np.asarray(con.flex[:n])
    elem = np.asarray(con.elem[:n])
    # the flex's side of each contact (0 or 1; -1: not the flex's); the other side must be a
    # geom (not a soft content's flex) and the flex's an element
    side = np.where(flexes[:, 1] == flex, 1, np.where(flexes[:, 0] == flex, 0, -1))
    rows = np.arange(n)
    own = np.maximum(side, 0)
    idx = np.flatnonzero((side >= 0) & (geom[rows, 1 - own] >= 0) & (elem[rows, own] >= 0))
    return idx, geom[idx, 1 - side[idx]], elem[idx, side[idx]]


class CapWeights:
    """The "solver" mapping's per-step part (module docstring): each packaging contact's solref
    scaled to its own vertex's inverse mass, and the kept contacts of a pair at the cap weighted
    for the dropped ones; `apply` between ``mj_step1`` and ``mj_step2``."""

    def __init__(self, model: mujoco.MjModel, shell: ShellMesh) -> None:
        flex = _packaging_flex(model)
        self.flex = flex
        self.vadr, self.vnum = int(model.flex_vertadr[flex]), int(model.flex_vertnum[flex])
        self.elements = flex_elements(model, flex)
        # contacts per touching vertex: one per element it is a corner of
        self.corners = np.bincount(self.elements.ravel(), minlength=self.vnum).astype(float)
        self.reach = float(model.flex_radius[flex]) + float(model.flex_margin[flex])
        self.is_box = np.asarray(model.geom_type) == mujoco.mjtGeom.mjGEOM_BOX
        # MuJoCo 4.0.1 caps an interpolated flex's pairs, not a full shell's (vertex bodies)
        self.capped = is_interpolated(model, flex)
        self.per_vertex = vertex_inverse_masses(model)
        self.face = face_inverse_mass(self.per_vertex, shell)
        body = np.asarray(model.geom_bodyid)
        # the other side's inverse mass by geom: 0 for the world, 1 / m for a rigid content
        self.other = np.where(body != 0, model.body_invweight0[body, 0], 0.0)
        self.weighted = 0  # pair-steps whose kept contacts were weighted
        self.unweighted = 0  # pair-steps at the cap on a geom that is not a box (w = 1)
        self.largest = 1.0  # the largest weight applied [-]

    def touching(self, model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> float:
        """n_touch: the contacts the packaging would make with box ``geom`` without the cap, the
        corners of its elements within the flex's reach of the box (module docstring)."""
        verts = data.flexvert_xpos[self.vadr : self.vadr + self.vnum]
        rot = data.geom_xmat[geom].reshape(3, 3)
        local = (verts - data.geom_xpos[geom]) @ rot
        q = np.abs(local) - model.geom_size[geom]
        # signed distance to the box: outside, the norm of the positive parts; inside, negative
        distance = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
        touch = distance < self.reach + float(model.geom_margin[geom])
        return float(self.corners[touch].sum())

    def apply(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Scale this step's packaging contacts (module docstring)."""
        idx, other, element = packaging_contacts(data, self.flex)
        if len(idx) == 0:
            return
        con = data.contact
        n = data.ncon
        # each contact's vertex: the corner of its element nearest to the contact point
        corners = self.elements[element]
        verts = data.flexvert_xpos[self.vadr : self.vadr + self.vnum]
        gaps = np.linalg.norm(verts[corners] - np.asarray(con.pos[:n])[idx, None, :], axis=2)
        vertex = corners[np.arange(len(idx)), np.argmin(gaps, axis=1)]
        a_other = self.other[other]
        factor = (self.per_vertex[vertex] + a_other) / (self.face + a_other)
        counts = np.bincount(other, minlength=model.ngeom)
        at_cap = np.flatnonzero(counts == MAX_CONTACTS_PER_PAIR) if self.capped else []
        for g in at_cap:
            if not self.is_box[g]:
                self.unweighted += 1
                continue
            w = self.touching(model, data, int(g)) / MAX_CONTACTS_PER_PAIR
            if w > 1.0:
                factor[other == g] *= w
                self.weighted += 1
                self.largest = max(self.largest, w)
        solref = con.solref
        # direct format (-s, -b): stiffness and damping alike
        solref[idx] = solref[idx] * factor[:, None]

    def diagnostics(self) -> dict[str, float]:
        """Pair-steps weighted and unweighted at the cap, and the largest weight [-]."""
        return {
            "cap_weighted": self.weighted,
            "cap_unweighted": self.unweighted,
            "cap_largest_weight": self.largest,
        }
