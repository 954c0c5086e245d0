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

from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from typing import TYPE_CHECKING

import mujoco
import numba
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco.contact_cap import CapWeights
from parcelfit.sim.mujoco.coulomb import CoulombBelts
from parcelfit.sim.mujoco.lumped_mass import flex_elements
from parcelfit.sim.params import DYNAMIC_THRESHOLD, STATIC_THRESHOLD

if TYPE_CHECKING:
    from parcelfit.sim.mujoco.options import SceneOptions
    from parcelfit.sim.mujoco.scene import Scene

# the coefficient a contact sliding by hand keeps in MuJoCo's cone: an elliptic cone of exactly 0
# is degenerate (MuJoCo's solve then drops the contact's normal force as well)
NEGLIGIBLE_FRICTION = 1e-6
_ELEM_BITS = 30
_NO_FORCE = np.zeros(0)  # a step without surface contacts: no force by hand


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
        # the packaging shell's triangles (vertex ids within the flex); none without a 2-D shell
        self.triangles = np.zeros((0, 3), dtype=np.int32)
        self.vertex_offset = 0
        if flex >= 0 and model.flex_dim[flex] == 2:
            self.triangles = flex_elements(model, flex)
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
        # this step's forces by hand in constraint space (``data.efc_*`` rows; empty in a step
        # without surface contacts; diagnostics)
        self.hand_force = _NO_FORCE

    def _select(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The current contacts on surfaces: their indices, surface geom ids and keys. A key
        names the surface, the packaging's element and the element's corner nearest to the
        contact point: MuJoCo makes one contact per touching corner of a triangle, so the element
        alone does not tell a triangle's contacts apart."""
        con = data.contact
        return _select_contacts(
            con.geom,
            con.efc_address,
            con.elem,
            con.pos,
            self.is_surface,
            self.triangles,
            data.flexvert_xpos,
            self.vertex_offset,
        )

    def stick_share(self, slip: np.ndarray) -> np.ndarray:
        """S(v): the share of the static offset at slip speed ``slip`` [m/s]."""
        values = [_stick_share(float(v), self.v_s, self.v_d) for v in np.ravel(slip)]
        return np.reshape(values, np.shape(slip))

    def apply(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Set each surface contact's friction, and the Coulomb forces of the sliding ones as
        ``data.qfrc_applied`` [N]; call between ``mj_step1`` and ``mj_step2``."""
        data.qfrc_applied[:] = 0.0
        idx, surface, keys = self._selected = self._select(data)
        if idx.size == 0:
            self.hand_force = _NO_FORCE
            return
        # the normal force [N] and tangential inverse effective mass [1/kg] each contact had in
        # the step before's solve (matched by surface geom, shell element and vertex; a contact
        # new in this step has no force by hand yet); a contact the step before did not have
        # takes that step's mean over the contacts on the same surface: MuJoCo keeps at most 50
        # contacts of a shell with one geom, and on a large face the 50 change from step to step.
        # Every sliding contact leaves MuJoCo's cone; its force by hand is mu_d N, but never more
        # than changes its slip by half in one step (explicit in time: a larger force would
        # reverse the slip and chatter). `_contact_friction` sets the coefficients and fills
        # ``vec`` with the forces in constraint space.
        vec = self.hand_force = np.zeros(data.nefc)
        by_hand, clamped = _contact_friction(
            idx,
            surface,
            keys,
            data.contact.efc_address,
            data.efc_vel,
            model.geom_friction,
            self.offset,
            self.v_s,
            self.v_d,
            self._surface_normal,
            self._surface_inverse_mass,
            self._keys,
            self._normal,
            self._inverse_mass,
            data.contact.friction,
            self.h,
            NEGLIGIBLE_FRICTION,
            vec,
        )
        if by_hand:
            self.explicit_steps += 1
            self.clamped += clamped
            mujoco.mj_mulJacTVec(model, data, self._qfrc, vec)
            data.qfrc_applied[:] = self._qfrc

    def record(self, data: mujoco.MjData) -> None:
        """Keep this step's surface contacts' normal forces [N] and tangential inverse effective
        masses [1/kg] (MuJoCo's ``efc_diagA``) for the next step; call after ``mj_step2`` (the
        contacts `apply` selected in this step, else selected here)."""
        selected, self._selected = self._selected, None
        idx, surface, keys = selected if selected is not None else self._select(data)
        (
            self._keys,
            self._normal,
            self._inverse_mass,
            self._surface_normal,
            self._surface_inverse_mass,
        ) = _record_contacts(
            idx,
            surface,
            keys,
            data.contact.efc_address,
            data.efc_force,
            data.efc_diagA,
            self.is_surface.size,
        )


# The kernels below are the law's per-step work on the ~10-100 surface contacts, compiled
# with numba: as NumPy calls on such small arrays it cost more in call overhead than in
# arithmetic (a fifth of a BW run's time on E1, under a profiler). They do the arithmetic of those
# NumPy calls, in the same order, so a run is the same to the last bit.


@numba.njit(cache=True, inline="always")
def _stick_share(slip: float, v_s: float, v_d: float) -> float:
    """S(v) = 1 - u^2 (3 - 2 u), u = clip((v - v_s) / (v_d - v_s), 0, 1) at slip speed v [m/s]."""
    u = min(max((slip - v_s) / (v_d - v_s), 0.0), 1.0)
    return 1.0 - u * u * (3.0 - 2.0 * u)


@numba.njit(cache=True)
def _select_contacts(
    geom: np.ndarray,
    efc_address: np.ndarray,
    elem: np.ndarray,
    pos: np.ndarray,
    is_surface: np.ndarray,
    triangles: np.ndarray,
    vertices: np.ndarray,
    vertex_offset: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indices, surface geom ids and keys of the contacts on surfaces (see `_select`)."""
    n = geom.shape[0]
    idx = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        g0, g1 = geom[i, 0], geom[i, 1]
        on0 = g0 >= 0 and is_surface[g0]
        on1 = g1 >= 0 and is_surface[g1]
        if (on0 or on1) and efc_address[i] >= 0:
            idx[m] = i
            m += 1
    idx = idx[:m]
    surface = np.empty(m, dtype=np.int64)
    keys = np.empty(m, dtype=np.int64)
    n_tri = triangles.shape[0]
    for j in range(m):
        i = idx[j]
        g0 = geom[i, 0]
        surface[j] = g0 if (g0 >= 0 and is_surface[g0]) else geom[i, 1]
        e = np.int64(max(elem[i, 0], elem[i, 1]))
        corner = 0
        if 0 <= e < n_tri:
            best = 0.0
            for c in range(3):
                v = vertex_offset + triangles[e, c]
                dx = vertices[v, 0] - pos[i, 0]
                dy = vertices[v, 1] - pos[i, 1]
                dz = vertices[v, 2] - pos[i, 2]
                gap = np.sqrt((dx * dx + dy * dy) + dz * dz)  # NumPy's norm, summed alike
                # np.argmin: the first of equal gaps, and the first NaN wins over any number
                if best != best:
                    break
                if c == 0 or gap < best or gap != gap:
                    best = gap
                    corner = c
        keys[j] = (surface[j] << (_ELEM_BITS + 2)) | ((e + 1) << 2) | corner
    return idx, surface, keys


@numba.njit(cache=True, error_model="numpy")
def _contact_friction(
    idx: np.ndarray,
    surface: np.ndarray,
    keys: np.ndarray,
    efc_address: np.ndarray,
    efc_vel: np.ndarray,
    geom_friction: np.ndarray,
    offset: np.ndarray,
    v_s: float,
    v_d: float,
    surface_normal: np.ndarray,
    surface_inverse_mass: np.ndarray,
    prev_keys: np.ndarray,
    prev_normal: np.ndarray,
    prev_inverse_mass: np.ndarray,
    friction: np.ndarray,
    h: float,
    negligible: float,
    vec: np.ndarray,
) -> tuple[bool, int]:
    """Each surface contact's coefficient mu(v) into ``friction``, and the Coulomb force of
    each sliding one with a normal force into ``vec`` (constraint space); returns whether any
    contact slid by hand and how many forces the half-slip bound limited."""
    n_prev = prev_keys.size
    any_by_hand = False
    clamped = 0
    for j in range(idx.size):
        i = idx[j]
        s = surface[j]
        adr = efc_address[i]
        v1, v2 = efc_vel[adr + 1], efc_vel[adr + 2]
        slip = np.hypot(v1, v2)
        mu_d = geom_friction[s, 0]
        mu = mu_d + offset[s] * _stick_share(slip, v_s, v_d)
        normal = surface_normal[s]
        inverse_mass = surface_inverse_mass[s]
        if n_prev:
            k = min(np.searchsorted(prev_keys, keys[j]), n_prev - 1)
            if prev_keys[k] == keys[j]:
                normal = prev_normal[k]
                inverse_mass = prev_inverse_mass[k]
        by_hand = slip > v_d
        friction[i, 0] = negligible if by_hand else mu
        friction[i, 1] = friction[i, 0]
        if by_hand and normal > 0:
            any_by_hand = True
            coulomb = mu_d * normal
            bound = 0.5 * slip / (h * inverse_mass)
            # np.minimum: a NaN on either side gives NaN
            force = coulomb if (coulomb < bound or coulomb != coulomb) else bound
            if force < coulomb:
                clamped += 1
            scale = force / slip
            vec[adr + 1] = -scale * v1
            vec[adr + 2] = -scale * v2
    return any_by_hand, clamped


@numba.njit(cache=True)
def _record_contacts(
    idx: np.ndarray,
    surface: np.ndarray,
    keys: np.ndarray,
    efc_address: np.ndarray,
    efc_force: np.ndarray,
    efc_diag: np.ndarray,
    n_geom: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The contacts' keys in order with their normal forces [N] and tangential inverse
    effective masses [1/kg], and both's means by surface geom (0 and inf where none)."""
    m = idx.size
    normal = np.empty(m)
    inverse_mass = np.empty(m)
    for j in range(m):
        adr = efc_address[idx[j]]
        f, a = efc_force[adr], efc_diag[adr + 1]
        # np.maximum(x, 0.0): NaN kept, -0.0 and below give +0.0
        normal[j] = f if (f > 0.0 or f != f) else 0.0
        inverse_mass[j] = a if (a > 0.0 or a != a) else 0.0
    order = np.argsort(keys, kind="mergesort")  # stable
    count = np.zeros(n_geom, dtype=np.int64)
    normal_sum = np.zeros(n_geom)
    inverse_mass_sum = np.zeros(n_geom)
    for j in range(m):  # in the contacts' order, as np.bincount sums
        count[surface[j]] += 1
        normal_sum[surface[j]] += normal[j]
        inverse_mass_sum[surface[j]] += inverse_mass[j]
    surface_normal = np.zeros(n_geom)
    surface_inverse_mass = np.full(n_geom, np.inf)
    for g in range(n_geom):
        if count[g] > 0:
            surface_normal[g] = normal_sum[g] / count[g]
            surface_inverse_mass[g] = inverse_mass_sum[g] / count[g]
    return keys[order], normal[order], inverse_mass[order], surface_normal, surface_inverse_mass


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
    (the per-surface static switch is the simulator's, `simulator._FrictionSwitch`). With the
    "solver" contact mapping (`SceneOptions.contact_mapping`) the capped pairs' kept contacts
    are weighted after ``mj_step1`` (`CapWeights.apply`), before the friction law reads them."""

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        scene: Scene,
        params: Mapping[str, float],
        options: SceneOptions,
    ) -> None:
        self.model, self.data = model, data
        self.shell = scene.shell  # the packaging's mesh (diagnostics read it, `observed_steps`)
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
        self.cap = CapWeights(model, scene.shell) if options.contact_mapping == "solver" else None

    def step(self) -> None:
        """Advance the simulation by one time step."""
        model, data = self.model, self.data
        if self.coulomb is not None:
            self.coulomb.apply(model, data)
        if self.contact is None and self.cap is None:
            mujoco.mj_step(model, data)
            return
        mujoco.mj_step1(model, data)
        if self.cap is not None:
            self.cap.apply(model, data)
        if self.contact is not None:
            self.contact.apply(model, data)
        mujoco.mj_step2(model, data)
        if self.contact is not None:
            self.contact.record(data)

    def diagnostics(self) -> dict[str, float]:
        """How often the contact law slid contacts by hand: steps, and contact-steps whose force
        the half-slip bound limited; with the "solver" contact mapping, how often it weighted a
        capped pair (`CapWeights.diagnostics`)."""
        out: dict[str, float] = {}
        if self.contact is not None:
            out["hand_friction_steps"] = self.contact.explicit_steps
            out["hand_friction_clamped"] = self.contact.clamped
        if self.cap is not None:
            out.update(self.cap.diagnostics())
        return out


@contextmanager
def observed_steps(observe: Callable[[Stepper], None]) -> Iterator[None]:
    """While open, every `Stepper.step` in this process calls ``observe(stepper)`` after the
    step: for diagnostic scripts, which look at each step of exactly the simulator's own
    stepping loop without changing it (the loop is the simulator's; wrapping its stepper is the
    one way in)."""
    step = Stepper.step

    def observed(stepper: Stepper) -> None:
        step(stepper)
        observe(stepper)

    Stepper.step = observed  # type: ignore[method-assign]
    try:
        yield
    finally:
        Stepper.step = step  # type: ignore[method-assign]


__all__ = [
    "DYNAMIC_THRESHOLD",
    "STATIC_THRESHOLD",
    "ContactFriction",
    "Stepper",
    "observed_steps",
    "surface_offsets",
]
