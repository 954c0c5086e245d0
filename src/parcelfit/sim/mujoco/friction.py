"""Friction between the packaging and the rig's surfaces, decided per contact from its own slip.

The law (the velocity-dependent friction coefficient of multibody solvers' contacts, as the
published solver's manual describes it): a contact whose slip speed v [m/s] (the packaging's
material point against the surface's own material velocity there, rotation included) is below
the static threshold v_s sticks with mu_s = mu_d + offset; above the dynamic threshold v_d it
slides with mu_d; in between the coefficient falls as a cubic step,

    mu(v) = mu_d + offset * S(v),   S = 1 - u^2 (3 - 2 u),   u = clip((v - v_s) / (v_d - v_s), 0, 1)

with the catalogue's offsets mu_s_BePa (belts, strips, drums, rollers) and mu_s_MePa (guide
plates and their lead-ins), and v_s = 1 mm/s, v_d = 1.5 mm/s by default (the published solver's
defaults, `SceneOptions.static_threshold`, `dynamic_threshold`).

How MuJoCo is made to follow it, each step (`ContactFriction.apply`, between ``mj_step1``, which
finds the contacts and their velocities, and ``mj_step2``, which solves and integrates):

* **Per contact, not per surface or per parcel.** MuJoCo has one friction coefficient per contact,
  which it takes from the geoms; here each contact's coefficient is set from its own slip,
  read from its tangential constraint velocities (``efc_vel``; MuJoCo includes a surface's
  ``surfacevel`` in them, so a parcel carried at belt speed has zero slip). A parcel that spins
  while its centre moves with the belt therefore slides at every contact point, instead of
  sticking over its whole footprint as the former per-surface switch (`simulator._FrictionSwitch`,
  which compared the centre's speed) had it.
* **Sticking and slow contacts stay in MuJoCo's solver** with mu(v): its friction is implicit in
  velocity, so a contact can stick without chattering at any step.
* **Sliding contacts are taken out of MuJoCo's friction cone** (their coefficient set to 0) and
  get the Coulomb force F = -mu_d N s / |s| instead, applied as a generalised force J_t^T F
  through the contact's own tangential Jacobian rows (``mj_mulJacTVec``). Why by hand: MuJoCo's
  convex soft contacts lift a contact that slides (its solution needs a separating normal
  velocity to slip), so a parcel sliding over a belt hops and loses contact in most steps
  (measured: BW on E3 during the plate catch, 63-77 % of steps without a main-belt contact;
  docs/research/contact-law.md). N is the contact's normal force in the step before's solve
  (matched by surface geom, shell element and the element's corner; a contact that step did not
  have takes its mean on the same surface, as MuJoCo keeps at most 50 contacts of a shell with
  one geom and on a large face picks other ones from step to step). The force is explicit, so it
  is limited to what changes the contact's slip by half in one step, F <= v / (2 h A_t) (A_t: the
  contact's tangential inverse effective mass in that solve, MuJoCo's ``efc_diagA``; how often
  the bound binds is reported as ``hand_friction_clamped``).

Contacts between the content and its packaging keep MuJoCo's own friction (mu_CoPa, no static
offset).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco.coulomb import CoulombBelts
from parcelfit.sim.params import DYNAMIC_THRESHOLD, STATIC_THRESHOLD

if TYPE_CHECKING:
    from parcelfit.sim.mujoco.options import SceneOptions
    from parcelfit.sim.mujoco.scene import Scene

# the coefficient a contact sliding by hand keeps in MuJoCo's cone: an elliptic cone of exactly 0
# is degenerate (MuJoCo's solve then drops the contact's normal force as well)
NEGLIGIBLE_FRICTION = 1e-6
_ELEM_BITS = 30


class ContactFriction:
    """Per-contact friction of the packaging on the rig's surfaces (see the module docstring).

    ``offsets`` maps a surface geom's id to its static friction offset (mu_s - mu_d) [-]; the
    dynamic coefficient is the geom's own MuJoCo friction."""

    def __init__(
        self,
        model: mujoco.MjModel,
        offsets: Mapping[int, float],
        static_threshold: float = STATIC_THRESHOLD,
        dynamic_threshold: float = DYNAMIC_THRESHOLD,
    ) -> None:
        if not 0 < static_threshold < dynamic_threshold:
            raise ParcelfitError(
                "friction thresholds must satisfy 0 < static < dynamic [m/s], got "
                f"{static_threshold} and {dynamic_threshold}"
            )
        self.v_s, self.v_d = static_threshold, dynamic_threshold
        self.is_surface = np.zeros(model.ngeom, dtype=bool)
        self.offset = np.zeros(model.ngeom)
        for gid, off in offsets.items():
            self.is_surface[gid] = True
            self.offset[gid] = off
        self.h = float(model.opt.timestep)
        flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
        self.triangles: np.ndarray | None = None
        self.vertex_offset = 0
        if flex >= 0 and model.flex_dim[flex] == 2:
            elems = model.flex_elem[model.flex_elemdataadr[flex] :]
            self.triangles = np.asarray(elems[: 3 * int(model.flex_elemnum[flex])]).reshape(-1, 3)
            self.vertex_offset = int(model.flex_vertadr[flex])
        self._qfrc = np.zeros(model.nv)
        # the step before's contacts on surfaces: sorted keys, normal forces, inverse masses
        self._keys = np.zeros(0, dtype=np.int64)
        self._normal = np.zeros(0)
        self._inverse_mass = np.zeros(0)
        self._surface_normal = np.zeros(model.ngeom)  # mean normal force [N] by surface geom
        self._surface_inverse_mass = np.full(model.ngeom, np.inf)
        # this step's selection, made in `apply` and read again in `record`: mj_step2 neither
        # finds contacts nor moves the flex's vertex positions, so both see the same contacts
        self._selected: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.explicit_steps = 0  # steps in which some contact slid by hand (diagnostics)
        self.clamped = 0  # contact-steps whose force by hand was limited by the half-slip bound

    def _select(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The current contacts on surfaces: their indices, surface geom ids and keys. A key
        names the surface, the packaging's element and the element's corner nearest to the
        contact point: MuJoCo makes one contact per touching corner of a triangle, so the element
        alone does not tell a triangle's contacts apart."""
        n = data.ncon
        con = data.contact
        g0, g1 = con.geom[:n, 0], con.geom[:n, 1]
        on0 = np.zeros(n, dtype=bool)
        on1 = np.zeros(n, dtype=bool)
        on0[g0 >= 0] = self.is_surface[g0[g0 >= 0]]
        on1[g1 >= 0] = self.is_surface[g1[g1 >= 0]]
        idx = np.flatnonzero((on0 | on1) & (con.efc_address[:n] >= 0))
        surface = np.where(on0[idx], g0[idx], g1[idx]).astype(np.int64)
        elem = con.elem[idx].max(axis=1).astype(np.int64)
        corner = np.zeros(idx.size, dtype=np.int64)
        if self.triangles is not None and idx.size:
            ok = (elem >= 0) & (elem < len(self.triangles))
            tri = self.triangles[elem[ok]]  # (k, 3) vertex ids within the flex
            points = data.flexvert_xpos[self.vertex_offset + tri]  # (k, 3, 3)
            gap = np.linalg.norm(points - con.pos[idx[ok], None, :], axis=2)
            corner[ok] = np.argmin(gap, axis=1)
        keys = (surface << (_ELEM_BITS + 2)) | ((elem + 1) << 2) | corner
        return idx, surface, keys

    def stick_share(self, slip: np.ndarray) -> np.ndarray:
        """S(v): the share of the static offset at slip speed ``slip`` [m/s]."""
        u = np.clip((slip - self.v_s) / (self.v_d - self.v_s), 0.0, 1.0)
        return 1.0 - u * u * (3.0 - 2.0 * u)

    def apply(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Set each surface contact's friction, and the Coulomb forces of the sliding ones as
        ``data.qfrc_applied`` [N]; call between ``mj_step1`` and ``mj_step2``."""
        data.qfrc_applied[:] = 0.0
        idx, surface, keys = self._selected = self._select(data)
        if idx.size == 0:
            return
        con = data.contact
        adr = con.efc_address[idx]
        v1, v2 = data.efc_vel[adr + 1], data.efc_vel[adr + 2]
        slip = np.hypot(v1, v2)
        mu_d = model.geom_friction[surface, 0]
        mu = mu_d + self.offset[surface] * self.stick_share(slip)
        # the normal force [N] and tangential inverse effective mass [1/kg] each contact had in
        # the step before's solve (matched by surface geom, shell element and vertex; a contact
        # new in this step has no force by hand yet)
        # a contact the step before did not have takes that step's mean over the contacts on
        # the same surface: MuJoCo keeps at most 50 contacts of a shell with one geom, and on a
        # large face the 50 change from step to step
        normal = self._surface_normal[surface]
        inverse_mass = self._surface_inverse_mass[surface]
        if self._keys.size:
            pos = np.minimum(np.searchsorted(self._keys, keys), self._keys.size - 1)
            known = self._keys[pos] == keys
            normal[known] = self._normal[pos[known]]
            inverse_mass[known] = self._inverse_mass[pos[known]]
        # every sliding contact leaves MuJoCo's cone; its force by hand is mu_d N, but never more
        # than changes its slip by half in one step (explicit in time: a larger force would
        # reverse the slip and chatter)
        by_hand = slip > self.v_d
        con.friction[idx, 0] = np.where(by_hand, NEGLIGIBLE_FRICTION, mu)
        con.friction[idx, 1] = con.friction[idx, 0]
        k = np.flatnonzero(by_hand & (normal > 0))
        if k.size:
            self.explicit_steps += 1
            vec = np.zeros(data.nefc)
            force = np.minimum(mu_d[k] * normal[k], 0.5 * slip[k] / (self.h * inverse_mass[k]))
            self.clamped += int(np.count_nonzero(force < mu_d[k] * normal[k]))
            scale = force / slip[k]
            vec[adr[k] + 1] = -scale * v1[k]
            vec[adr[k] + 2] = -scale * v2[k]
            mujoco.mj_mulJacTVec(model, data, self._qfrc, vec)
            data.qfrc_applied[:] = self._qfrc

    def record(self, data: mujoco.MjData) -> None:
        """Keep this step's surface contacts' normal forces [N] and tangential inverse effective
        masses [1/kg] (MuJoCo's ``efc_diagA``) for the next step; call after ``mj_step2`` (the
        contacts `apply` selected in this step, else selected here)."""
        selected, self._selected = self._selected, None
        idx, surface, keys = selected if selected is not None else self._select(data)
        adr = data.contact.efc_address[idx]
        normal = np.maximum(data.efc_force[adr], 0.0)
        inverse_mass = np.maximum(data.efc_diagA[adr + 1], 0.0)
        order = np.argsort(keys, kind="stable")
        self._keys = keys[order]
        self._normal = normal[order]
        self._inverse_mass = inverse_mass[order]
        count = np.bincount(surface, minlength=self.is_surface.size)
        seen = count > 0
        self._surface_normal = np.zeros(self.is_surface.size)
        self._surface_normal[seen] = (
            np.bincount(surface, weights=normal, minlength=self.is_surface.size)[seen] / count[seen]
        )
        self._surface_inverse_mass = np.full(self.is_surface.size, np.inf)
        self._surface_inverse_mass[seen] = (
            np.bincount(surface, weights=inverse_mass, minlength=self.is_surface.size)[seen]
            / count[seen]
        )


def surface_offsets(
    model: mujoco.MjModel,
    belt_geoms: Iterable[str],
    metal_geoms: Iterable[str],
    belt_offset: float,
    metal_offset: float,
) -> dict[int, float]:
    """The static friction offset [-] of each surface geom, by id: ``belt_offset`` for belts,
    strips, drums and rollers, ``metal_offset`` for plates and lead-ins."""
    out = {model.geom(name).id: belt_offset for name in belt_geoms}
    out.update({model.geom(name).id: metal_offset for name in metal_geoms})
    return out


class Stepper:
    """One MuJoCo step of a scene under its friction law (`SceneOptions.friction`): with
    "contact", ``mj_step1``, `ContactFriction.apply`, ``mj_step2`` and `ContactFriction.record`;
    with "geom", ``mj_step`` after the Coulomb belt forces where ``belt_friction`` asks for them
    (the per-surface static switch is the simulator's, `simulator._FrictionSwitch`)."""

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        scene: Scene,
        params: Mapping[str, float],
        options: SceneOptions,
    ) -> None:
        self.model, self.data = model, data
        self.contact: ContactFriction | None = None
        self.coulomb: CoulombBelts | None = None
        if options.friction == "contact":
            self.contact = ContactFriction(
                model,
                surface_offsets(
                    model,
                    [g.name for g in scene.driven if g.material != "metal"],
                    [*scene.metal_geoms, *(g.name for g in scene.driven if g.material == "metal")],
                    params["mu_s_BePa"],
                    params["mu_s_MePa"],
                ),
                options.static_threshold,
                options.dynamic_threshold,
            )
        elif options.belt_friction == "coulomb":
            self.coulomb = CoulombBelts(model, data, scene)

    def step(self) -> None:
        """Advance the simulation by one time step."""
        model, data = self.model, self.data
        if self.contact is not None:
            mujoco.mj_step1(model, data)
            self.contact.apply(model, data)
            mujoco.mj_step2(model, data)
            self.contact.record(data)
            return
        if self.coulomb is not None:
            self.coulomb.apply(model, data)
        mujoco.mj_step(model, data)

    def diagnostics(self) -> dict[str, int]:
        """How often the contact law slid contacts by hand: steps, and contact-steps whose force
        the half-slip bound limited."""
        if self.contact is None:
            return {}
        return {
            "hand_friction_steps": self.contact.explicit_steps,
            "hand_friction_clamped": self.contact.clamped,
        }


__all__ = [
    "DYNAMIC_THRESHOLD",
    "STATIC_THRESHOLD",
    "ContactFriction",
    "Stepper",
    "surface_offsets",
]
