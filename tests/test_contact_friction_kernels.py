"""The per-contact friction law's compiled kernels (`parcelfit.sim.mujoco.friction`) do exactly
what its NumPy formulation did: the same contacts and keys, coefficients, forces by hand and the
record kept for the next step, to the last bit, step after step of a run that catches on E3's
plate (KP/BW, where contacts slide by hand and new contacts take their surface's mean)."""

import mujoco
import numpy as np
import pytest

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco.friction import _ELEM_BITS, NEGLIGIBLE_FRICTION

from .simhelpers import contact_law_scene


def _select(law, data):
    """The NumPy formulation of `ContactFriction._select`."""
    n = data.ncon
    con = data.contact
    g0, g1 = con.geom[:n, 0], con.geom[:n, 1]
    on0 = np.zeros(n, dtype=bool)
    on1 = np.zeros(n, dtype=bool)
    on0[g0 >= 0] = law.is_surface[g0[g0 >= 0]]
    on1[g1 >= 0] = law.is_surface[g1[g1 >= 0]]
    idx = np.flatnonzero((on0 | on1) & (con.efc_address[:n] >= 0))
    surface = np.where(on0[idx], g0[idx], g1[idx]).astype(np.int64)
    elem = con.elem[idx].max(axis=1).astype(np.int64)
    corner = np.zeros(idx.size, dtype=np.int64)
    if law.triangles is not None and idx.size:
        ok = (elem >= 0) & (elem < len(law.triangles))
        tri = law.triangles[elem[ok]]
        points = data.flexvert_xpos[law.vertex_offset + tri]
        gap = np.linalg.norm(points - con.pos[idx[ok], None, :], axis=2)
        corner[ok] = np.argmin(gap, axis=1)
    keys = (surface << (_ELEM_BITS + 2)) | ((elem + 1) << 2) | corner
    return idx, surface, keys


def _apply(law, model, data, selected):
    """The NumPy formulation of `ContactFriction.apply`: (friction of the selected contacts,
    generalised force by hand or None)."""
    idx, surface, keys = selected
    con = data.contact
    adr = con.efc_address[idx]
    v1, v2 = data.efc_vel[adr + 1], data.efc_vel[adr + 2]
    slip = np.hypot(v1, v2)
    mu_d = model.geom_friction[surface, 0]
    mu = mu_d + law.offset[surface] * law.stick_share(slip)
    normal = law._surface_normal[surface]
    inverse_mass = law._surface_inverse_mass[surface]
    if law._keys.size:
        pos = np.minimum(np.searchsorted(law._keys, keys), law._keys.size - 1)
        known = law._keys[pos] == keys
        normal[known] = law._normal[pos[known]]
        inverse_mass[known] = law._inverse_mass[pos[known]]
    by_hand = slip > law.v_d
    friction = np.where(by_hand, NEGLIGIBLE_FRICTION, mu)
    k = np.flatnonzero(by_hand & (normal > 0))
    if not k.size:
        return friction, None
    vec = np.zeros(data.nefc)
    force = np.minimum(mu_d[k] * normal[k], 0.5 * slip[k] / (law.h * inverse_mass[k]))
    scale = force / slip[k]
    vec[adr[k] + 1] = -scale * v1[k]
    vec[adr[k] + 2] = -scale * v2[k]
    qfrc = np.zeros(model.nv)
    mujoco.mj_mulJacTVec(model, data, qfrc, vec)
    return friction, qfrc


def _record(law, data, selected):
    """The NumPy formulation of `ContactFriction.record`: the arrays it keeps."""
    idx, surface, keys = selected
    adr = data.contact.efc_address[idx]
    normal = np.maximum(data.efc_force[adr], 0.0)
    inverse_mass = np.maximum(data.efc_diagA[adr + 1], 0.0)
    order = np.argsort(keys, kind="stable")
    count = np.bincount(surface, minlength=law.is_surface.size)
    seen = count > 0
    mean_normal = np.zeros(law.is_surface.size)
    mean_normal[seen] = (
        np.bincount(surface, weights=normal, minlength=law.is_surface.size)[seen] / count[seen]
    )
    mean_inverse_mass = np.full(law.is_surface.size, np.inf)
    mean_inverse_mass[seen] = (
        np.bincount(surface, weights=inverse_mass, minlength=law.is_surface.size)[seen]
        / count[seen]
    )
    return keys[order], normal[order], inverse_mass[order], mean_normal, mean_inverse_mass


@pytest.mark.slow
@pytest.mark.mujoco
def test_the_compiled_law_is_the_numpy_law_to_the_last_bit():
    with contact_law_scene(TestCase("E3", "KPBW", 2), placement=2) as (model, data, law):
        by_hand_steps = new_contacts = 0
        for step in range(round(0.9 / model.opt.timestep)):
            mujoco.mj_step1(model, data)
            if step % 7 == 0:  # every 7th step, checked against the NumPy formulation
                selected = _select(law, data)
                previous = law._keys.copy()
                friction, qfrc = _apply(law, model, data, selected)
                law.apply(model, data)
                for a, b in zip(selected, law._selected, strict=True):
                    assert np.array_equal(a, b)
                idx = selected[0]
                assert np.array_equal(data.contact.friction[idx, 0], friction)
                assert np.array_equal(data.contact.friction[idx, 1], friction)
                if qfrc is None:
                    assert not data.qfrc_applied.any()
                else:
                    assert np.array_equal(data.qfrc_applied, qfrc)
                    by_hand_steps += 1
                new_contacts += int(np.count_nonzero(~np.isin(selected[2], previous)))
                mujoco.mj_step2(model, data)
                expected = _record(law, data, selected)
                law.record(data)
                kept = (
                    law._keys,
                    law._normal,
                    law._inverse_mass,
                    law._surface_normal,
                    law._surface_inverse_mass,
                )
                for a, b in zip(expected, kept, strict=True):
                    assert np.array_equal(a, b)
            else:
                law.apply(model, data)
                mujoco.mj_step2(model, data)
                law.record(data)
    # the checks covered contacts sliding by hand and contacts new to their step
    assert by_hand_steps > 10 and new_contacts > 10
