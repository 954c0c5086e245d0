"""Coulomb friction between the packaging and conveying surfaces, applied outside MuJoCo's solver.

Why by hand: MuJoCo's convex contact model lifts a contact that slides (it can only start slip
with some motion in the normal direction), so a parcel sliding on part of its bottom loads that
part several times more than its share, hops, and reaches a faster belt tens of milliseconds
early (docs/research/sliding-lift.md). MuJoCo has no friction law outside that solver. With
``SceneOptions.belt_friction = "coulomb"`` the belt, strip and roller contacts are frictionless
in MuJoCo (condim 1) and this module applies, before every step, at each contact point c of
the packaging with such a surface

    F_c = -mu N_c s_c / max(|s_c|, s_reg)

where N_c [N] is the contact's normal force from the step before, s_c [m/s] the slip of the
packaging's material point at c against the surface's own material velocity at c (a belt's top
velocity, or on a drum at a belt's end or a turning roller spin x arm), projected onto the contact's
tangent plane, mu the surface's current friction coefficient (mu_d plus any static offset the
simulator's friction switch has set) and s_reg = 5 mm/s the slip below which the force is
linear in the slip (a parcel at belt speed is held like a stiff viscous coupling instead of
chattering; explicit in time, it is stable for h mu N / (s_reg m) < 2 at every contact).

The packaging's material point at c is the barycentric combination w of its triangle's three
vertices, and each vertex moves with the shell's degrees of freedom q (an interpolated shell's
nodes, or a full shell's own vertices) through a constant linear map V (vertex = V q + const),
found once by moving each degree of freedom in turn. So the point's velocity is
J_c qdot with J_c = sum_a w_a V_a, and the force enters as the generalised force J_c^T F_c,
exactly as a contact force of MuJoCo's would.

Measured limits (the simulator README, "Sliding"): around rigid contents (an interpolated
shell) the forces are stable at 1/1200 s and finer. Around a soft content (PB's full shell,
whose film vertices weigh a fraction of a gram) they are not trustworthy: at 1/1200 s an E1 run
turned 42 degrees and stalled, and at 1/2400 s E1 placements turn 7-29 degrees with transit-time
spreads of 23-107 ms where MuJoCo's friction gives 0-3 degrees and 1-3 ms. A full shell with
Coulomb friction therefore logs a warning.
"""

from __future__ import annotations

import mujoco
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco.mjlog import LOGGER
from parcelfit.sim.mujoco.scene import Scene

SLIP_REG = 0.005  # [m/s]
_EPS = 1e-6  # finite-difference step of the constant vertex map [m]


class CoulombBelts:
    """Applies Coulomb belt friction as forces on the packaging (see the module docstring)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, scene: Scene) -> None:
        flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
        if flex < 0:
            raise ParcelfitError("Coulomb belt friction needs the packaging flex 'packaging'")
        self.flex = flex
        self.vadr = int(model.flex_vertadr[flex])
        self.nvert = int(model.flex_vertnum[flex])
        elem = model.flex_elem[model.flex_elemdataadr[flex] :]
        self.triangles = np.asarray(elem[: 3 * int(model.flex_elemnum[flex])]).reshape(-1, 3)
        self.surfaces = {model.geom(g.name).id: g for g in scene.driven if g.material != "metal"}
        if not self.surfaces:
            raise ParcelfitError("Coulomb belt friction: the scene has no belt, strip or roller")
        self.belt_ids = np.array(sorted(self.surfaces), dtype=int)
        self.dofs, self.vmap = self._vertex_map(model, data)
        if not model.flex_interp[flex]:
            LOGGER.warning(
                "Coulomb belt friction on a full shell (soft content) is not trustworthy: its "
                "explicit forces on the film's light vertices turn and delay the parcel "
                "(simulator README, Sliding); use belt_friction: mujoco for this consignment"
            )

    def _vertex_map(
        self, model: mujoco.MjModel, data: mujoco.MjData
    ) -> tuple[np.ndarray, np.ndarray]:
        """The shell's degrees of freedom and V [vertex, xyz, dof] with d(vertex) = V d(q)."""
        if model.flex_interp[self.flex]:
            adr, num = model.flex_nodeadr[self.flex], model.flex_nodenum[self.flex]
            bodies = model.flex_nodebodyid[adr : adr + num]
        else:
            bodies = model.flex_vertbodyid[self.vadr : self.vadr + self.nvert]
        dofs = np.array(
            [
                model.body_dofadr[b] + k
                for b in bodies
                if b >= 0
                for k in range(model.body_dofnum[b])
            ],
            dtype=int,
        )
        qadr = {int(model.jnt_dofadr[j]): int(model.jnt_qposadr[j]) for j in range(model.njnt)}
        scratch = mujoco.MjData(model)
        scratch.qpos[:] = data.qpos
        mujoco.mj_kinematics(model, scratch)
        mujoco.mj_flex(model, scratch)
        base = scratch.flexvert_xpos[self.vadr : self.vadr + self.nvert].copy()
        vmap = np.zeros((self.nvert, 3, dofs.size))
        for i, dof in enumerate(dofs):
            scratch.qpos[:] = data.qpos
            scratch.qpos[qadr[int(dof)]] += _EPS
            mujoco.mj_kinematics(model, scratch)
            mujoco.mj_flex(model, scratch)
            moved = scratch.flexvert_xpos[self.vadr : self.vadr + self.nvert]
            vmap[:, :, i] = (moved - base) / _EPS
        return dofs, vmap

    def apply(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Set ``data.qfrc_applied`` on the shell's degrees of freedom to the Coulomb friction
        [N, as generalised forces] of the last step's belt contacts; call before ``mj_step``."""
        data.qfrc_applied[self.dofs] = 0.0
        n = data.ncon
        if n == 0:
            return
        con = data.contact
        geom0 = con.geom[:n, 0]
        on_belt = np.isin(geom0, self.belt_ids) & (con.flex[:n, 1] == self.flex)
        on_belt &= con.efc_address[:n] >= 0
        idx = np.flatnonzero(on_belt)
        if idx.size == 0:
            return
        normal_force = np.maximum(data.efc_force[con.efc_address[idx]], 0.0)
        keep = normal_force > 0
        idx, normal_force = idx[keep], normal_force[keep]
        if idx.size == 0:
            return
        tri = self.triangles[con.elem[idx, 1]]  # (k, 3) vertex indices
        verts = data.flexvert_xpos[self.vadr : self.vadr + self.nvert]
        weights = _barycentric(con.pos[idx], verts[tri])  # (k, 3)
        jac = np.einsum("ka,kaxd->kxd", weights, self.vmap[tri])  # (k, 3, ndof)
        velocity = np.einsum("kxd,d->kx", jac, data.qvel[self.dofs])
        points = con.pos[idx]
        surface = np.empty_like(points)
        for g in np.unique(geom0[idx]):  # a drum or turning roller: spin x arm per point
            rows = geom0[idx] == g
            surface[rows] = self.surfaces[int(g)].velocity_at(points[rows])
        normal = con.frame[idx, :3]
        slip = velocity - surface
        slip -= np.sum(slip * normal, axis=1, keepdims=True) * normal
        mu = model.geom_friction[geom0[idx], 0]
        speed = np.maximum(np.linalg.norm(slip, axis=1), SLIP_REG)
        force = -(mu * normal_force / speed)[:, None] * slip
        data.qfrc_applied[self.dofs] += np.einsum("kxd,kx->d", jac, force)


def _barycentric(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Barycentric weights (k, 3) of points (k, 3) projected onto triangles (k, 3, 3), clipped
    to the triangle [m]."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    d00 = np.sum(v0 * v0, axis=1)
    d01 = np.sum(v0 * v1, axis=1)
    d11 = np.sum(v1 * v1, axis=1)
    d20 = np.sum(v2 * v0, axis=1)
    d21 = np.sum(v2 * v1, axis=1)
    denom = np.where(np.abs(d00 * d11 - d01 * d01) > 1e-30, d00 * d11 - d01 * d01, 1e-30)
    v = (d11 * d20 - d01 * d21) / denom
    w = (d00 * d21 - d01 * d20) / denom
    out = np.clip(np.stack([1.0 - v - w, v, w], axis=1), 0.0, 1.0)
    return out / np.sum(out, axis=1, keepdims=True)


__all__ = ["SLIP_REG", "CoulombBelts"]
