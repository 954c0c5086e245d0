"""The per-contact friction law's compiled kernels (`parcelfit.sim.mujoco.friction`) do exactly
what its NumPy formulation did, bit for bit (signed zeros included): on synthetic contacts with
the edge cases (NaN positions and forces, negative zeros, infinite and zero inverse masses, the
half-slip bound binding, no contacts, no shell triangles), and step after step of a KP/BW run
along E3's guide plate (contacts sliding by hand, contacts new to their step)."""

import mujoco
import numpy as np
import pytest

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco.friction import (
    _ELEM_BITS,
    NEGLIGIBLE_FRICTION,
    _contact_friction,
    _record_contacts,
    _select_contacts,
)

from .simhelpers import contact_law_scene

# -- the former NumPy formulation, on arrays ---------------------------------------------------


def np_select(geom, efc_address, elem, pos, is_surface, triangles, vertices, vertex_offset):
    n = geom.shape[0]
    g0, g1 = geom[:n, 0], geom[:n, 1]
    on0 = np.zeros(n, dtype=bool)
    on1 = np.zeros(n, dtype=bool)
    on0[g0 >= 0] = is_surface[g0[g0 >= 0]]
    on1[g1 >= 0] = is_surface[g1[g1 >= 0]]
    idx = np.flatnonzero((on0 | on1) & (efc_address[:n] >= 0))
    surface = np.where(on0[idx], g0[idx], g1[idx]).astype(np.int64)
    e = elem[idx].max(axis=1).astype(np.int64)
    corner = np.zeros(idx.size, dtype=np.int64)
    if len(triangles) and idx.size:
        ok = (e >= 0) & (e < len(triangles))
        tri = triangles[e[ok]]
        points = vertices[vertex_offset + tri]
        gap = np.linalg.norm(points - pos[idx[ok], None, :], axis=2)
        corner[ok] = np.argmin(gap, axis=1)
    keys = (surface << (_ELEM_BITS + 2)) | ((e + 1) << 2) | corner
    return idx, surface, keys


def np_friction(
    idx, surface, keys, efc_address, efc_vel, geom_friction, offset, v_s, v_d, kept, h, nefc
):
    """(friction of the selected contacts, forces by hand in constraint space or None, the
    number the half-slip bound limited)."""
    prev_keys, prev_normal, prev_inverse_mass, surface_normal, surface_inverse_mass = kept
    adr = efc_address[idx]
    v1, v2 = efc_vel[adr + 1], efc_vel[adr + 2]
    slip = np.hypot(v1, v2)
    mu_d = geom_friction[surface, 0]
    u = np.clip((slip - v_s) / (v_d - v_s), 0.0, 1.0)
    mu = mu_d + offset[surface] * (1.0 - u * u * (3.0 - 2.0 * u))
    normal = surface_normal[surface]
    inverse_mass = surface_inverse_mass[surface]
    if prev_keys.size:
        pos = np.minimum(np.searchsorted(prev_keys, keys), prev_keys.size - 1)
        known = prev_keys[pos] == keys
        normal[known] = prev_normal[pos[known]]
        inverse_mass[known] = prev_inverse_mass[pos[known]]
    by_hand = slip > v_d
    friction = np.where(by_hand, NEGLIGIBLE_FRICTION, mu)
    k = np.flatnonzero(by_hand & (normal > 0))
    if not k.size:
        return friction, None, 0
    vec = np.zeros(nefc)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        force = np.minimum(mu_d[k] * normal[k], 0.5 * slip[k] / (h * inverse_mass[k]))
        clamped = int(np.count_nonzero(force < mu_d[k] * normal[k]))
        scale = force / slip[k]
        vec[adr[k] + 1] = -scale * v1[k]
        vec[adr[k] + 2] = -scale * v2[k]
    return friction, vec, clamped


def np_record(idx, surface, keys, efc_address, efc_force, efc_diag, n_geom):
    adr = efc_address[idx]
    normal = np.maximum(efc_force[adr], 0.0)
    inverse_mass = np.maximum(efc_diag[adr + 1], 0.0)
    order = np.argsort(keys, kind="stable")
    count = np.bincount(surface, minlength=n_geom)
    seen = count > 0
    mean_normal = np.zeros(n_geom)
    mean_normal[seen] = np.bincount(surface, weights=normal, minlength=n_geom)[seen] / count[seen]
    mean_inverse_mass = np.full(n_geom, np.inf)
    mean_inverse_mass[seen] = (
        np.bincount(surface, weights=inverse_mass, minlength=n_geom)[seen] / count[seen]
    )
    return keys[order], normal[order], inverse_mass[order], mean_normal, mean_inverse_mass


def same_bits(a, b) -> bool:
    """Equal to the bit: -0.0 is not 0.0, NaN equals NaN of the same pattern."""
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind == "f":
        return a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))
    return np.array_equal(a, b)


def kernel_friction(selected, efc_address, efc_vel, geom_friction, offset, v_s, v_d, kept, h, nefc):
    idx, surface, keys = selected
    prev_keys, prev_normal, prev_inverse_mass, surface_normal, surface_inverse_mass = kept
    friction = np.full((max(efc_address.size, 1), 5), -1.0)
    vec = np.zeros(nefc)
    by_hand, clamped = _contact_friction(
        idx,
        surface,
        keys,
        efc_address,
        efc_vel,
        geom_friction,
        offset,
        v_s,
        v_d,
        surface_normal,
        surface_inverse_mass,
        prev_keys,
        prev_normal,
        prev_inverse_mass,
        friction,
        h,
        NEGLIGIBLE_FRICTION,
        vec,
    )
    assert np.array_equal(friction[idx, 0], friction[idx, 1])
    return friction[idx, 0], (vec if by_hand else None), clamped


# -- synthetic contacts ----------------------------------------------------------------------


def _synthetic(rng: np.random.Generator, n: int):
    """n contacts between 4 geoms (2 and 3 are surfaces) and a shell of 6 triangles."""
    geom = rng.integers(-1, 4, size=(n, 2)).astype(np.int32)
    efc_address = np.where(rng.random(n) < 0.8, 3 * np.arange(n), -1).astype(np.int32)
    elem = rng.integers(-1, 8, size=(n, 2)).astype(np.int32)  # 6 and 7 lie beyond the shell
    vertices = rng.normal(size=(12, 3))
    pos = vertices[rng.integers(2, 12, size=n)] + rng.normal(scale=1e-3, size=(n, 3))
    pos[: n // 4] = vertices[3]  # equidistant ties are broken alike
    triangles = rng.integers(0, 10, size=(6, 3)).astype(np.int32)
    is_surface = np.array([False, False, True, True])
    return geom, efc_address, elem, pos, is_surface, triangles, vertices


@pytest.mark.parametrize("seed", range(6))
def test_the_kernels_are_the_numpy_law_on_synthetic_contacts_with_edge_cases(seed):
    rng = np.random.default_rng(seed)
    n = 40
    geom, efc_address, elem, pos, is_surface, triangles, vertices = _synthetic(rng, n)
    if seed == 1:
        vertices[[2, 5]] = np.nan  # a blown-up shell: the first NaN gap wins, as argmin has it
    if seed == 2:
        triangles = np.zeros((0, 3), dtype=np.int32)  # no 2-D shell: every corner 0
    args = (geom, efc_address, elem, pos, is_surface, triangles, vertices, 2)
    selected = _select_contacts(*args)
    for a, b in zip(np_select(*args), selected, strict=True):
        assert same_bits(a, b)
    idx, surface, keys = selected
    assert idx.size > 5

    nefc = 3 * n
    efc_vel = rng.normal(scale=0.01, size=nefc)
    efc_vel[1:nefc:9] = 0.0  # sticking contacts
    efc_force = rng.normal(size=nefc)
    efc_force[::7] = -0.0
    efc_force[5] = np.nan
    efc_diag = rng.uniform(0.0, 50.0, size=nefc)
    efc_diag[1::5] = -0.0  # an inverse mass of -0.0 is kept as +0.0
    efc_diag[4::11] = np.nan
    kept = _record_contacts(idx, surface, keys, efc_address, efc_force, efc_diag, 4)
    expected = np_record(idx, surface, keys, efc_address, efc_force, efc_diag, 4)
    for a, b in zip(expected, kept, strict=True):
        assert same_bits(a, b)

    geom_friction = np.array([[0.4, 0.005, 1e-4]] * 4)
    offset = np.array([0.0, 0.0, 0.1, 0.15])
    # a next step: half the contacts as recorded, the others new; slow and fast slips; a step
    # long enough that the half-slip bound binds for some
    efc_vel2 = efc_vel * rng.choice([0.01, 0.1, 1.0, 10.0], size=nefc)
    for h in (1 / 2400, 0.05):
        got = kernel_friction(
            selected, efc_address, efc_vel2, geom_friction, offset, 0.001, 0.0015, kept, h, nefc
        )
        want = np_friction(
            *selected, efc_address, efc_vel2, geom_friction, offset, 0.001, 0.0015, kept, h, nefc
        )
        assert same_bits(want[0], got[0])
        assert (want[1] is None) == (got[1] is None)
        if want[1] is not None:
            assert same_bits(want[1], got[1])
        assert want[2] == got[2]
    assert got[2] > 0  # at the long step the bound binds


def test_no_contacts_select_nothing_and_record_empty_tables():
    empty2 = np.zeros((0, 2), dtype=np.int32)
    args = (empty2, np.zeros(0, np.int32), empty2, np.zeros((0, 3)), np.array([False, True]),
            np.zeros((0, 3), np.int32), np.zeros((0, 3)), 0)  # fmt: skip
    idx, surface, keys = _select_contacts(*args)
    assert idx.size == surface.size == keys.size == 0
    kept = _record_contacts(idx, surface, keys, np.zeros(0, np.int32), np.zeros(0), np.zeros(0), 2)
    assert [k.size for k in kept[:3]] == [0, 0, 0]
    assert same_bits(kept[3], np.zeros(2)) and same_bits(kept[4], np.full(2, np.inf))


# -- a run -------------------------------------------------------------------------------------


def _kept(law):
    """What the law keeps for the next step: sorted keys, normal forces, inverse masses, and
    their means by surface."""
    return (
        law._keys,
        law._normal,
        law._inverse_mass,
        law._surface_normal,
        law._surface_inverse_mass,
    )


@pytest.mark.slow
@pytest.mark.mujoco
def test_the_compiled_law_is_the_numpy_law_step_after_step_of_a_run():
    with contact_law_scene(TestCase("E3", "KPBW", 2), placement=2) as (model, data, law):
        by_hand_steps = new_contacts = 0
        for step in range(round(0.9 / model.opt.timestep)):
            mujoco.mj_step1(model, data)
            if step % 7 == 0:  # every 7th step, checked against the NumPy formulation
                con = data.contact
                selected = np_select(
                    con.geom,
                    con.efc_address,
                    con.elem,
                    con.pos,
                    law.is_surface,
                    law.triangles,
                    data.flexvert_xpos,
                    law.vertex_offset,
                )
                previous = law._keys.copy()
                kept = _kept(law)
                friction, vec, clamped = np_friction(
                    *selected,
                    con.efc_address,
                    data.efc_vel,
                    model.geom_friction,
                    law.offset,
                    law.v_s,
                    law.v_d,
                    kept,
                    law.h,
                    data.nefc,
                )
                steps_before, clamped_before = law.explicit_steps, law.clamped
                law.apply(model, data)
                for a, b in zip(selected, law._selected, strict=True):
                    assert same_bits(a, b)
                idx = selected[0]
                assert same_bits(data.contact.friction[idx, 0], friction)
                assert same_bits(data.contact.friction[idx, 1], friction)
                if vec is None:
                    assert not data.qfrc_applied.any() and law.explicit_steps == steps_before
                    assert not law.hand_force.any()  # the forces by hand kept: none
                else:
                    assert same_bits(law.hand_force, vec)  # kept for diagnostics, as applied
                    qfrc = np.zeros(model.nv)
                    mujoco.mj_mulJacTVec(model, data, qfrc, vec)
                    assert same_bits(data.qfrc_applied, qfrc)
                    assert law.explicit_steps == steps_before + 1
                    by_hand_steps += 1
                assert law.clamped == clamped_before + clamped
                new_contacts += int(np.count_nonzero(~np.isin(selected[2], previous)))
                mujoco.mj_step2(model, data)
                expected = np_record(
                    *selected,
                    data.contact.efc_address,
                    data.efc_force,
                    data.efc_diagA,
                    law.is_surface.size,
                )
                law.record(data)
                kept = _kept(law)
                for a, b in zip(expected, kept, strict=True):
                    assert same_bits(a, b)
            else:
                law.apply(model, data)
                mujoco.mj_step2(model, data)
                law.record(data)
    # the checks covered contacts sliding by hand and contacts new to their step
    assert by_hand_steps > 10 and new_contacts > 10


def test_observed_steps_sees_every_step_and_restores_the_stepper(monkeypatch):
    from parcelfit.sim.mujoco.friction import Stepper, observed_steps

    calls: list[str] = []
    monkeypatch.setattr(Stepper, "step", lambda self: calls.append("step"))
    plain = Stepper.step
    stepper = object.__new__(Stepper)
    with observed_steps(lambda s: calls.append("seen" if s is stepper else "other")):
        stepper.step()
        stepper.step()
    stepper.step()
    assert calls == ["step", "seen", "step", "seen", "step"]
    with pytest.raises(RuntimeError), observed_steps(lambda s: None):
        raise RuntimeError
    assert Stepper.step is plain  # restored after an error too
