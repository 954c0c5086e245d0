"""The rigid-box reference (parcelfit.sim.rigidbox): its integrator, contact law and simulator
against analytic results, and a smoke run on E3."""

from __future__ import annotations

import math
import pickle
from dataclasses import replace

import numpy as np
import pytest

from parcelfit.errors import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim import SimStatus, Simulator
from parcelfit.sim.ensemble import rotation, simulate_ensemble
from parcelfit.sim.mujoco import load_consignment, load_rig
from parcelfit.sim.rigidbox import (
    Motion,
    Primitives,
    RigidBoxOptions,
    RigidBoxSimulator,
    World,
    parcel_body,
    rig_primitives,
)
from parcelfit.sim.rigidbox.contact import (
    KAPPA,
    disc_rectangle_overlap,
    friction_coefficient,
    law_array,
)
from parcelfit.sim.rigidbox.engine import yaw_quaternion
from parcelfit.sim.rigidbox.geometry import (
    BELT,
    BOX,
    CAPSULE,
    CYLINDER,
    LEAD_IN,
    METAL,
    SIDE,
    WALL,
    box_inertia,
    primitive,
    resolved_bottom_patch,
    rim_bending_length,
    rim_buckling_load,
    rim_load_share,
    rot_z,
    strip_profile,
)

G = 9.81
DT = 1e-5
K = 5e5  # N/m
MU_D, OFFSET = 0.45, 0.1


@pytest.fixture(scope="module")
def bw():
    """BW with a flat bottom (the bundled file's bulge removed): the analytic checks' box, on its
    whole outline (``bottom_patch="outline"``: every bottom point as stiff per unit area)."""
    return replace(load_consignment("BW"), bulge=None)


def _plane_world(bw, speed=0.0, spacing=0.01, gravity=G, stick=0.001, slip=0.0015, patch="outline"):
    """BW on a large flat belt (top at z = 0) moving at ``speed`` along x."""
    body = parcel_body(bw, 0.02, spacing, patch)
    belt = primitive("belt", BOX, (0, 0, -0.02), rot_z(0), (5, 1, 0.02), BELT, vel=(speed, 0, 0))
    law = law_array((K, K), (1, 1), (MU_D, MU_D), (OFFSET, OFFSET), bw.mass, body.bottom_area)
    return World(body, Primitives.of([belt]), law, stick, slip, gravity)


def _on_plane(world, **kw):
    return Motion(world, (0, 0, float(world.body.half[2])), (1, 0, 0, 0), **kw)


# -- the body and the contact law --------------------------------------------------------------


def test_the_box_has_the_consignment_s_mass_inertia_and_contact_areas(bw):
    body = parcel_body(bw, 0.02, bottom_patch="outline")
    L, W, H = bw.outer
    assert body.mass == bw.mass
    assert np.allclose(body.inertia, box_inertia(bw.mass, bw.outer, bw.content, 0.02))
    # the packaging's two sheets add (L^2 + W^2) / 12 per unit mass about z
    cL, cW, _ = bw.content
    assert body.inertia[2] == pytest.approx(0.06 * (cL**2 + cW**2) / 12 + 0.02 * (L**2 + W**2) / 12)
    faces = body.area[body.group != SIDE].sum()
    assert faces == pytest.approx(2 * L * W)
    assert body.area[body.group == SIDE].sum() == pytest.approx(2 * (L + W) * H)
    assert body.bottom_area == pytest.approx(L * W)
    # every tile is a contiguous range whose sphere holds its points
    for s, e, c, r in zip(
        body.tile_start, body.tile_end, body.tile_centre, body.tile_radius, strict=True
    ):
        assert np.all(np.linalg.norm(body.points[s:e] - c, axis=1) <= r + 1e-12)
    # a patch decides where the bottom's stiffness sits: its weights sum to the outline's area,
    # the area that divides the law's stiffness, so sides, top and walls are as stiff on any patch
    content = parcel_body(bw, 0.02, bottom_patch="content")
    bulged = parcel_body(load_consignment("BW"), 0.02)  # the default: the bundled BW's bulge
    for patched in (content, bulged):
        assert patched.bottom_area == pytest.approx(L * W)
        assert patched.area[patched.group == 0].sum() == pytest.approx(L * W)
        assert np.array_equal(patched.area[patched.group != 0], body.area[body.group != 0])
    assert parcel_body(load_consignment("BW"), 0.02, bottom_patch="outline").bottom_area == (
        pytest.approx(L * W)
    )
    bottom = content.points[content.group == 0]
    assert np.all(np.abs(bottom[:, 0]) <= cL / 2 + 1e-12)
    assert np.all(np.abs(bottom[:, 1]) <= cW / 2 + 1e-12)
    # the bulge's patch: half the outline's length and width
    bottom = bulged.points[bulged.group == 0]
    assert np.max(np.abs(bottom[:, 0])) == pytest.approx(0.25 * L)


@pytest.mark.parametrize("name", ["KPBW", "KP"])
def test_the_rim_weight_patch_lays_only_the_rims_own_weight_on_the_rim(name):
    # lying flat every bottom point is as deep, so each carries its weight's share of the load:
    # the rim (outside the content's footprint) its own mass, m_Pa over its share of the area
    cons = load_consignment(name)
    L, W, _ = cons.outer
    cL, cW, _ = cons.content
    m_pa = 0.02
    body = parcel_body(cons, m_pa, bottom_patch="rim-weight")
    outline = parcel_body(cons, m_pa, bottom_patch="outline")
    bottom = body.group == 0
    pts, w = body.points[bottom], body.area[bottom]
    rim = (np.abs(pts[:, 0]) > cL / 2 + 1e-9) | (np.abs(pts[:, 1]) > cW / 2 + 1e-9)
    assert rim.any() and (~rim).any()
    share = m_pa * (1 - cL * cW / (L * W)) / cons.mass
    assert w[rim].sum() / w.sum() == pytest.approx(share, rel=1e-12)
    # the same grid as the outline's; the rim's nodes lighter against the footprint's
    assert np.array_equal(pts, outline.points[outline.group == 0])
    w_out = outline.area[outline.group == 0]
    ratio = w / w_out
    assert np.allclose(ratio[~rim], ratio[~rim][0], rtol=1e-12)
    assert np.all(ratio[rim] < ratio[~rim][0])
    # the whole bottom as stiff as the outline's, and the sides, top and walls too
    assert w.sum() == pytest.approx(L * W, rel=1e-12)
    assert body.bottom_area == outline.bottom_area == pytest.approx(L * W)
    assert np.array_equal(body.area[~bottom], outline.area[outline.group != 0])
    # a heavier packaging lays more on its rim
    heavier = parcel_body(cons, 2 * m_pa, bottom_patch="rim-weight")
    hw = heavier.area[heavier.group == 0]
    assert hw[rim].sum() / hw.sum() == pytest.approx(2 * share, rel=1e-12)


def test_a_box_on_its_rim_weight_patch_rests_at_the_outlines_depth_with_its_rim_light():
    # dropped flat on a belt it settles as deep as on its outline (the bottom's stiffness is K);
    # the rim's contact points then carry its own weight, those under the content the rest
    cons = load_consignment("KPBW")
    world = _plane_world(cons, patch="rim-weight")
    m = Motion(world, (0, 0, float(world.body.half[2]) + 0.002), (1, 0, 0, 0))
    m.advance(DT, 30000)
    depth = float(world.body.half[2]) - m.x[2]
    assert depth == pytest.approx(cons.mass * G / K, rel=1e-3)
    body = world.body
    bottom = body.group == 0
    L, W, _ = cons.outer
    cL, cW, _ = cons.content
    pts = body.points[bottom]
    rim = (np.abs(pts[:, 0]) > cL / 2 + 1e-9) | (np.abs(pts[:, 1]) > cW / 2 + 1e-9)
    force = world.law[BELT, KAPPA] * body.area[bottom] * depth  # each point's spring at rest
    assert force.sum() == pytest.approx(cons.mass * G, rel=1e-3)
    share = 0.02 * (1 - cL * cW / (L * W)) / cons.mass
    assert force[rim].sum() / force.sum() == pytest.approx(share, rel=1e-9)
    # a content smaller than the grid's cells has no contact point to carry it: refused
    tiny = replace(cons, content=(0.02, 0.02, cons.content[2]))
    with pytest.raises(ParcelfitError, match="inside the content's footprint"):
        parcel_body(tiny, 0.02, spacing=0.1, bottom_patch="rim-weight")


def test_the_rims_bending_length_is_the_plate_on_its_contacts_foundation():
    # lambda = (4 D / k_f)^(1/4), D = E t^3 / (12 (1 - nu^2)), k_f = K / (L W)
    E, t, nu, K, area = 1e9, 5e-4, 0.3, 5e5, 0.055
    D = E * t**3 / (12 * (1 - nu**2))
    assert rim_bending_length(E, t, nu, K, area) == pytest.approx((4 * D * area / K) ** 0.25)
    assert rim_bending_length(E, t, nu, K, area) == pytest.approx(8.424e-3, rel=1e-3)
    # a sixteenth of the foundation's stiffness doubles it
    assert rim_bending_length(E, t, nu, K / 16, area) == pytest.approx(
        2 * rim_bending_length(E, t, nu, K, area)
    )
    for bad in ((0, t, nu, K, area), (E, -t, nu, K, area), (E, t, 0.5, K, area)):
        with pytest.raises(ParcelfitError, match="bending"):
            rim_bending_length(*bad)
    with pytest.raises(ParcelfitError, match="bending length"):
        parcel_body(load_consignment("KPBW"), 0.02, bottom_patch="rim-bending", bending_length=-1)


def test_the_strip_profile_solves_the_plate_on_its_foundation():
    # d4g/db4 + 4 g = 0, g(0) = 1, g'(0) = 0, free at the span: against SciPy's BVP solver
    from scipy.integrate import solve_bvp

    def rhs(_, y):
        return np.vstack([y[1], y[2], y[3], -4 * y[0]])

    def ends(ya, yb):
        return np.array([ya[0] - 1, ya[1], yb[2], yb[3]])

    for span in (0.5, 1.5, 4.0):
        x = np.linspace(0, span, 60)
        guess = np.zeros((4, x.size))
        guess[0] = 1
        sol = solve_bvp(rhs, ends, x, guess, tol=1e-6)
        assert sol.success
        b = np.linspace(0, span, 9)
        assert np.allclose(strip_profile(b, span), sol.sol(b)[0], atol=1e-6)
    # over a long span, the semi-infinite strip's e^-b (cos b + sin b)
    b = np.linspace(0, 6, 13)
    assert np.allclose(strip_profile(b, 200.0), np.exp(-b) * (np.cos(b) + np.sin(b)), atol=1e-12)
    for b, span in ((5.0, 1.0), (-0.1, 1.0), (0.0, -1.0)):
        with pytest.raises(ParcelfitError, match="0 <= b <= span"):
            strip_profile(b, span)


def test_the_rim_bending_patch_passes_a_strip_of_the_bending_length_to_the_rim():
    # beyond a long edge the content's pressure decays as e^-b (cos b + sin b), b = d / lambda,
    # whose integral is lambda: a strip lambda wide at the content's pressure per metre of edge,
    # and pi lambda^2 at the four corners together (2 pi lambda^2 times the integral of
    # b e^-b (cos b + sin b), 1 / 2); the rim's own weight rests on it besides. KP/BW's
    # overhangs are 4.7 and 6.9 lambda at lambda = 8 mm, long enough to count as infinite
    cons = load_consignment("KPBW")
    L, W, _ = cons.outer
    cL, cW, _ = cons.content
    m_pa, lam = 0.02, 0.008
    passed = lam * 2 * (cL + cW) + math.pi * lam**2  # [m^2] at the content's pressure
    a_in, a_out = cL * cW, L * W - cL * cW
    share = m_pa * a_out / (L * W) / cons.mass  # the rim's own weight
    # the own weight at pressure q_w over a_out, q_w a_out = share M g; the content's pressure
    # p_c over a_in and, less q_w, over the passed strip
    p_c = (1 - share * (a_out - passed) / a_out) / (a_in + passed)  # per unit M g
    expected = 1 - p_c * a_in
    body = parcel_body(cons, m_pa, 0.0025, "rim-bending", lam)
    assert rim_load_share(cons, body) == pytest.approx(expected, rel=0.01)
    assert 0.2 < expected < 0.3  # more than its own weight (8.9 %), less than the outline's
    # no bending: the rim-weight patch, node for node
    flexible = parcel_body(cons, m_pa, 0.01, "rim-bending", 0.0)
    weight = parcel_body(cons, m_pa, 0.01, "rim-weight")
    assert np.array_equal(flexible.area, weight.area)
    # a stiffer sheet passes more to the rim; the bottom always sums to the outline's area
    shares = [
        rim_load_share(cons, parcel_body(cons, m_pa, 0.005, "rim-bending", x))
        for x in (0.002, 0.005, 0.01, 0.02)
    ]
    assert shares == sorted(shares) and shares[0] > share
    body = parcel_body(cons, m_pa, 0.005, "rim-bending", 0.02)
    assert body.area[body.group == 0].sum() == pytest.approx(L * W)


def test_the_reference_rests_a_consignment_without_a_bulge_on_its_bending_rim():
    # the default patch: the bulge where the file has one (BW), else the rim's bending from
    # E_Pa, t_Pa, nu_Pa and k_BePa (KP/BW, KP)
    cons = load_consignment("KPBW")
    assert resolved_bottom_patch(cons, "consignment") == "rim-bending"
    assert resolved_bottom_patch(load_consignment("BW"), "consignment") == "bulge"
    assert resolved_bottom_patch(cons, "outline") == "outline"
    sim = RigidBoxSimulator()
    case = TestCase("E3", "KPBW", 1)
    L, W, _ = cons.outer
    for E_pa in (200e6, 1600e6):
        world, _ = sim.world({"E_Pa": E_pa}, case)
        p = cons.parameter_values(si_values={"E_Pa": E_pa})
        lam = rim_bending_length(E_pa, p["t_Pa"], p["nu_Pa"], p["k_BePa"], L * W)
        expected = parcel_body(cons, p["m_Pa"], 0.01, "rim-bending", lam)
        assert np.array_equal(world.body.area, expected.area)
    soft, _ = sim.world({"E_Pa": 200e6}, case)
    stiff, _ = sim.world({"E_Pa": 1600e6}, case)
    assert rim_load_share(cons, stiff.body) > rim_load_share(cons, soft.body) + 0.03


def test_a_soft_content_and_unknown_options_are_refused():
    with pytest.raises(ParcelfitError, match="rigid contents only"):
        parcel_body(load_consignment("PB"), 0.01)
    with pytest.raises(ParcelfitError, match="bottom_patch"):
        RigidBoxOptions(bottom_patch="rim")
    with pytest.raises(ParcelfitError, match="wall_contact"):
        RigidBoxOptions(wall_contact="edges")
    with pytest.raises(ParcelfitError, match="wall_damping"):
        RigidBoxOptions(wall_damping="none")
    with pytest.raises(ParcelfitError, match="wall_damping"):
        law_array((K, K), (1, 1), (0.3, 0.3), (0, 0), 0.08, 0.03, "none")
    with pytest.raises(ParcelfitError, match="stick_speed < slip_speed"):
        RigidBoxOptions(stick_speed=0.002, slip_speed=0.001)


def test_friction_rises_to_static_at_v_s_and_falls_to_dynamic_at_v_d():
    mu_s, v_s, v_d = 0.6, 0.001, 0.0015
    assert friction_coefficient(0.0, 0.45, mu_s, v_s, v_d) == 0.0
    assert friction_coefficient(0.0005, 0.45, mu_s, v_s, v_d) == pytest.approx(0.3)
    assert friction_coefficient(0.001, 0.45, mu_s, v_s, v_d) == pytest.approx(mu_s)
    assert friction_coefficient(0.00125, 0.45, mu_s, v_s, v_d) == pytest.approx(0.525)
    assert friction_coefficient(0.0015, 0.45, mu_s, v_s, v_d) == pytest.approx(0.45)
    assert friction_coefficient(3.0, 0.45, mu_s, v_s, v_d) == 0.45


def test_disc_rectangle_overlap_is_exact():
    r = 0.01
    assert disc_rectangle_overlap(0.0, 0.0, r, 0.1, 0.05) == pytest.approx(math.pi * r**2)
    assert disc_rectangle_overlap(0.1, 0.0, r, 0.1, 0.05) == pytest.approx(math.pi * r**2 / 2)
    assert disc_rectangle_overlap(0.1, 0.05, r, 0.1, 0.05) == pytest.approx(math.pi * r**2 / 4)
    assert disc_rectangle_overlap(0.2, 0.0, r, 0.1, 0.05) == 0.0
    g = np.linspace(-r, r, 2001)
    X, Y = np.meshgrid(g, g)
    inside = np.hypot(X, Y) <= r
    cell = (g[1] - g[0]) ** 2
    for ax, ay in [(0.095, 0.047), (0.104, -0.01), (-0.093, 0.052), (0.0, -0.056)]:
        box = (np.abs(X + ax) <= 0.1) & (np.abs(Y + ay) <= 0.05)
        numeric = np.sum(inside & box) * cell
        assert disc_rectangle_overlap(ax, ay, r, 0.1, 0.05) == pytest.approx(numeric, rel=5e-3)


def test_the_lead_in_contact_is_the_segment_law_whatever_the_point_spacing(bw):
    """A parcel's side pressed delta into a vertical lead-in mounted 4 mm above the belt: the
    force is (K / A_b) h A_seg(delta) over the shared height h, at 10 mm and at 5 mm spacing."""
    r, delta = 0.01, 0.002
    forces = []
    for spacing in (0.01, 0.005):
        body = parcel_body(bw, 0.02, spacing, "outline")
        L, _, H = bw.outer
        lead = primitive(
            "lead", LEAD_IN, (L / 2 + r - delta, 0.0, 0.054), np.eye(3), (r, 0.05, 0), 1
        )
        law = law_array((K, 6e5), (1, 1), (0.3, 0.3), (0, 0), bw.mass, body.bottom_area)
        m = Motion(
            World(body, Primitives.of([lead]), law, 0.001, 0.0015, 0.0), (0, 0, H / 2), (1, 0, 0, 0)
        )
        forces.append(m.F.copy())
        segment = r**2 * math.acos((r - delta) / r) - (r - delta) * math.sqrt(
            2 * r * delta - delta**2
        )
        expected = 6e5 / body.bottom_area * (H - 0.004) * segment
        assert m.F[0] == pytest.approx(-expected, rel=1e-9)
    assert np.allclose(forces[0], forces[1], rtol=1e-12, atol=1e-15)


def _pressed_into_a_wall(bw, kind, spacing, yaw_deg, delta):
    """The contact force [N] of BW (yawed by ``yaw_deg``) whose outline reaches ``delta`` past
    the face of a 3 mm metal wall along world y, mounted 4 mm above the belt."""
    body = parcel_body(bw, 0.02, spacing, "outline")
    a = math.radians(yaw_deg)
    hx, hy, hz = body.half
    reach = hx * math.cos(a) + hy * math.sin(a)  # the corner (hx, -hy) reaches farthest in x
    wall = primitive(
        "wall", kind, (reach - delta + 0.0015, 0.0, 0.054), rot_z(90), (0.5, 0.0015, 0.05), METAL
    )
    law = law_array((K, 6e5), (1, 1), (0.3, 0.3), (0, 0), bw.mass, body.bottom_area)
    world = World(body, Primitives.of([wall]), law, 0.001, 0.0015, 0.0)
    return Motion(world, (0, 0, hz), yaw_quaternion(yaw_deg)).F.copy(), body


@pytest.mark.parametrize("yaw_deg", [0.0, 8.0, 24.0])
def test_a_wall_meets_the_outline_whatever_the_point_spacing(bw, yaw_deg):
    """The outline law's force: flat, kappa h delta (W + delta); a corner at alpha,
    kappa h delta^2 (1 / sin alpha + 1 / cos alpha) / 2, at 10, 5 and 2.5 mm spacing alike."""
    delta = 0.002
    forces = []
    for spacing in (0.01, 0.005, 0.0025):
        F, body = _pressed_into_a_wall(bw, WALL, spacing, yaw_deg, delta)
        kappa, h = 6e5 / body.bottom_area, 2 * body.half[2] - 0.004
        if yaw_deg == 0.0:
            expected = kappa * h * delta * (2 * body.half[1] + delta)
        else:
            a = math.radians(yaw_deg)
            expected = kappa * h * delta**2 * (1 / math.sin(a) + 1 / math.cos(a)) / 2
        assert -F[0] == pytest.approx(expected, rel=1e-9)
        assert F[1] == pytest.approx(0.0, abs=1e-9 * expected)  # at rest: no friction
        forces.append(F)
    assert np.allclose(forces[0], forces[2], rtol=1e-12, atol=1e-12)


def test_a_wall_s_face_takes_only_the_outline_nearer_to_it_than_to_the_wall_s_end(bw):
    """A box straddling a wall's line, its front edge 5 mm past the wall's end: of the edge
    behind the face on the centre's side only the part less deep than its 5 mm to the end is
    the face's (kappa h d^2 / 2 with d = 5 mm, pushing the box to its side); the rest, up to
    W / 2 deep, is left to the end's contact (a lead-in)."""
    body = parcel_body(bw, 0.02, 0.01, "outline")
    hx, _, hz = body.half
    d, s1 = 0.005, 0.0015
    # a wall along world x whose start lies d inside the box's front edge, 1 mm to its left
    wall = primitive("wall", WALL, (hx - d + 0.5, 0.001, 0.054), rot_z(0), (0.5, s1, 0.05), METAL)
    law = law_array((K, 6e5), (1, 1), (0.3, 0.3), (0, 0), bw.mass, body.bottom_area)
    world = World(body, Primitives.of([wall]), law, 0.001, 0.0015, 0.0)
    force = Motion(world, (0, 0, hz), (1, 0, 0, 0)).F
    kappa, h = 6e5 / body.bottom_area, 2 * hz - 0.004
    assert force == pytest.approx((0.0, -kappa * h * d**2 / 2, 0.0), rel=1e-9, abs=1e-9)


def _strike_a_wall(bw, damping, speed=0.5):
    """BW (no gravity) moving at ``speed`` flat into a wall along world y: its rebound speed over
    ``speed``."""
    body = parcel_body(bw, 0.02, 0.01, "outline")
    hx, _, hz = body.half
    wall = primitive("wall", WALL, (hx + 0.002 + 0.0015, 0, 0.054), rot_z(90), (0.5, 0.0015, 0.05),
                     METAL)  # fmt: skip
    law = law_array((K, 6e5), (1, 1), (0.3, 0.3), (0, 0), bw.mass, body.bottom_area, damping)
    world = World(body, Primitives.of([wall]), law, 0.001, 0.0015, 0.0)
    m = Motion(world, (0, 0, hz), (1, 0, 0, 0), velocity=(speed, 0, 0))
    m.advance(DT, 5000)  # 50 ms: in, and out again
    return -m.v[0] / speed


def test_a_wall_s_damping_ratio_is_the_catalogue_s_for_its_own_contact(bw):
    """With ``ratio`` the whole contact's damper is 2 zeta sqrt(k_S M), k_S = kappa S its
    stiffness over the pressed strip S = h (W + 2 delta): at zeta = 1 a linear spring-damper that
    only pushes rebounds with exp(-2) of its speed; per unit area the same side is damped at
    zeta sqrt(S / A_b) and rebounds more."""
    delta, u = 0.002, 0.1
    body = parcel_body(bw, 0.02, 0.01, "outline")
    hx, hy, hz = body.half
    wall = primitive("wall", WALL, (hx - delta + 0.0015, 0, 0.054), rot_z(90), (0.5, 0.0015, 0.05),
                     METAL)  # fmt: skip
    forces = {}
    for damping in ("ratio", "area"):
        law = law_array((K, 6e5), (1, 1), (0.3, 0.3), (0, 0), bw.mass, body.bottom_area, damping)
        world = World(body, Primitives.of([wall]), law, 0.001, 0.0015, 0.0)
        at_rest = Motion(world, (0, 0, hz), (1, 0, 0, 0)).F[0]
        moving = Motion(world, (0, 0, hz), (1, 0, 0, 0), velocity=(u, 0, 0)).F[0]
        forces[damping] = (at_rest - moving) / u  # the damper [N s/m]
    kappa, h = 6e5 / body.bottom_area, 2 * hz - 0.004
    shared = h * (2 * hy + 2 * delta)
    assert forces["ratio"] == pytest.approx(2 * math.sqrt(kappa * shared * bw.mass), rel=1e-9)
    assert forces["area"] == pytest.approx(
        2 * math.sqrt(6e5 * bw.mass) / body.bottom_area * shared, rel=1e-9
    )
    assert _strike_a_wall(bw, "ratio") == pytest.approx(math.exp(-2), rel=0.02)
    assert _strike_a_wall(bw, "area") > 0.3


def test_walls_may_meet_the_content_s_outline_instead_of_the_packaging_s(bw):
    """``wall_outline: content``: a wall meets the content's cL x cW outline (a rim that gives
    way), so the packaging's outline pressed 2 mm past the face meets nothing, and the content's
    pressed delta takes kappa h delta (cW + delta); the sides' contact points stay on the
    outline; an unknown outline is refused."""
    body = parcel_body(bw, 0.02, 0.01, "outline", wall_outline="content")
    outline = parcel_body(bw, 0.02, 0.01, "outline")
    (L, W, H), (cL, cW, _) = bw.outer, bw.content
    assert body.wall_half == pytest.approx((cL / 2, cW / 2, H / 2))
    assert outline.wall_half == pytest.approx((L / 2, W / 2, H / 2))
    assert np.array_equal(body.points, outline.points) and np.array_equal(body.area, outline.area)
    law = law_array((K, 6e5), (1, 1), (0.3, 0.3), (0, 0), bw.mass, body.bottom_area)
    kappa, h = 6e5 / body.bottom_area, H - 0.004

    def force(reach, delta):
        wall = primitive("wall", WALL, (reach - delta + 0.0015, 0.0, 0.054), rot_z(90),
                         (0.5, 0.0015, 0.05), METAL)  # fmt: skip
        world = World(body, Primitives.of([wall]), law, 0.001, 0.0015, 0.0)
        return Motion(world, (0, 0, H / 2), (1, 0, 0, 0)).F.copy()

    assert force(L / 2, 0.002) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    delta = 0.002
    assert -force(cL / 2, delta)[0] == pytest.approx(kappa * h * delta * (cW + delta), rel=1e-9)
    with pytest.raises(ParcelfitError, match="wall_outline"):
        parcel_body(bw, 0.02, 0.01, "outline", wall_outline="rim")


def test_a_wall_inset_moves_the_outline_walls_meet_in_no_further_than_the_content(bw):
    """``wall_inset`` d: the packaging's outline inset by d on every side (a rim that gave way by
    d), clipped at the content's; a wall then meets the outline pressed delta past the inset
    face as the outline law does, kappa h delta (W - 2 d + delta); negative insets and insets
    with a content outline are refused."""
    (L, W, H), (cL, cW, _) = bw.outer, bw.content
    d = 0.004
    body = parcel_body(bw, 0.02, 0.01, "outline", wall_inset=d)
    assert body.wall_half == pytest.approx((L / 2 - d, W / 2 - d, H / 2))
    deep = parcel_body(bw, 0.02, 0.01, "outline", wall_inset=1.0)
    assert deep.wall_half == pytest.approx((cL / 2, cW / 2, H / 2))
    law = law_array((K, 6e5), (1, 1), (0.3, 0.3), (0, 0), bw.mass, body.bottom_area)
    delta = 0.002
    wall = primitive("wall", WALL, (L / 2 - d - delta + 0.0015, 0.0, 0.054), rot_z(90),
                     (0.5, 0.0015, 0.05), METAL)  # fmt: skip
    world = World(body, Primitives.of([wall]), law, 0.001, 0.0015, 0.0)
    force = Motion(world, (0, 0, H / 2), (1, 0, 0, 0)).F
    kappa, h = 6e5 / body.bottom_area, H - 0.004
    assert -force[0] == pytest.approx(kappa * h * delta * (W - 2 * d + delta), rel=1e-9)
    for bad in ({"wall_inset": -0.001}, {"wall_inset": math.nan}):
        with pytest.raises(ParcelfitError, match="wall_inset"):
            parcel_body(bw, 0.02, 0.01, "outline", **bad)
    with pytest.raises(ParcelfitError, match="wall_inset"):
        parcel_body(bw, 0.02, 0.01, "outline", wall_outline="content", wall_inset=d)
    with pytest.raises(ParcelfitError, match="wall_inset"):
        RigidBoxOptions(wall_inset=d, wall_contact="points")
    assert RigidBoxOptions(wall_inset=d).wall_inset == d


def test_a_content_wall_outline_needs_walls_met_by_the_outline():
    assert RigidBoxOptions(wall_outline="content").wall_outline == "content"
    with pytest.raises(ParcelfitError, match="wall_contact"):
        RigidBoxOptions(wall_outline="content", wall_contact="points")
    with pytest.raises(ParcelfitError, match="wall_outline"):
        RigidBoxOptions(wall_outline="rim")


def test_a_probe_world_of_the_walls_alone_gives_their_force(bw):
    """`Primitives.subset` and `Motion.take_state`: a world of a belt and a wall, and a probe
    world of its wall alone without gravity; at the first's state the probe's force is the
    wall's, the total less the belt's and gravity's."""
    body = parcel_body(bw, 0.02, 0.01, "outline")
    hx, _, hz = body.half
    belt = primitive("belt", BOX, (0, 0, -0.02), rot_z(0), (5, 1, 0.02), BELT)
    wall = primitive("wall", WALL, (hx - 0.002 + 0.0015, 0.0, 0.054), rot_z(90),
                     (0.5, 0.0015, 0.05), METAL)  # fmt: skip
    law = law_array((K, 6e5), (1, 1), (0.3, 0.3), (0, 0), bw.mass, body.bottom_area)
    prims = Primitives.of([belt, wall])
    both = Motion(World(body, prims, law, 0.001, 0.0015, G), (0, 0, hz - 1e-4), (1, 0, 0, 0))
    belt_only = Motion(
        World(body, Primitives.of([belt]), law, 0.001, 0.0015, G), (0, 0, hz - 1e-4), (1, 0, 0, 0)
    )
    walls = prims.subset((WALL, LEAD_IN))
    assert walls.names == ("wall",)
    probe = Motion(World(body, walls, law, 0.001, 0.0015, 0.0), (0, 0, 0), (1, 0, 0, 0))
    probe.take_state(both)
    assert np.allclose(probe.F, both.F - belt_only.F, rtol=1e-12, atol=1e-12)
    assert probe.F[0] < 0
    with pytest.raises(ParcelfitError, match="no primitive"):
        Primitives.of([belt]).subset((WALL,))
    other = Motion(
        World(parcel_body(bw, 0.02, 0.005, "outline"), walls, law, 0.001, 0.0015, 0.0),
        (0, 0, 0),
        (1, 0, 0, 0),
    )
    with pytest.raises(ParcelfitError, match="same body"):
        other.take_state(both)


def test_the_rim_s_buckling_load_is_the_cantilever_strips_euler_load():
    """Two plies, each pi^2 D / (4 b^2) per unit length: 40.2 N/m for KP/BW's 37.5 mm rim at the
    defaults (E 1000 N/mm^2, t 0.5 mm, nu 0.3); 1 / b^2 and t^3; bad input refused."""
    E, t, nu, b = 1e9, 5e-4, 0.3, 0.0375
    D = E * t**3 / (12 * (1 - nu**2))
    assert rim_buckling_load(E, t, nu, b) == pytest.approx(2 * math.pi**2 * D / (4 * b**2))
    assert rim_buckling_load(E, t, nu, b) == pytest.approx(40.2, abs=0.05)
    assert rim_buckling_load(E, t, nu, b / 2) == pytest.approx(4 * rim_buckling_load(E, t, nu, b))
    assert rim_buckling_load(E, 2 * t, nu, b) == pytest.approx(8 * rim_buckling_load(E, t, nu, b))
    for bad in ((E, t, nu, 0.0), (E, t, 0.5, b), (-E, t, nu, b), (E, math.nan, nu, b)):
        with pytest.raises(ParcelfitError):
            rim_buckling_load(*bad)


def test_a_wall_met_by_points_depends_on_their_spacing(bw):
    """The point contact the outline law replaces: a corner strike's force changes with the
    spacing (why walls default to the outline)."""
    F10, _ = _pressed_into_a_wall(bw, BOX, 0.01, 24.0, 0.004)
    F5, _ = _pressed_into_a_wall(bw, BOX, 0.005, 24.0, 0.004)
    assert abs(F10[0] - F5[0]) > 0.1 * abs(F5[0])


def test_rig_primitives_follow_the_mujoco_scene():
    e3 = rig_primitives(load_rig("E3"), 1)
    names = list(e3.names)
    assert names.count("guide") == 1 and "guide_lead_in" in names
    assert e3.kind[names.index("guide_lead_in")] == LEAD_IN
    assert e3.kind[names.index("guide")] == WALL
    points = rig_primitives(load_rig("E3"), 1, wall_contact="points")
    assert points.kind[names.index("guide")] == BOX
    assert e3.material[names.index("guide")] == METAL
    main = names.index("main")
    assert np.allclose(e3.vel[main], (1.56, 0, 0))
    assert e3.centre[main, 2] + e3.size[main, 2] == pytest.approx(0.0)  # top of the slab
    assert e3.size[main, 0] == pytest.approx(4.5 / 2 - 0.02)  # shortened by the drum radius
    tail, head = names.index("main_tail"), names.index("main_head")
    assert e3.kind[tail] == CYLINDER
    # the drum's surface: belt speed on top, up at the tail, down at the head
    top = e3.centre[tail] + (0, 0, 0.02)
    assert np.allclose(e3.velocity_at(tail, top), (1.56, 0, 0))
    assert np.allclose(e3.velocity_at(tail, e3.centre[tail] - (0.02, 0, 0)), (0, 0, 1.56))
    assert np.allclose(e3.velocity_at(head, e3.centre[head] + (0.02, 0, 0)), (0, 0, -1.56))
    strips = [n for n in names if n.startswith("strips_") and "_" not in n[len("strips_") :]]
    assert len(strips) == 7
    fast = rig_primitives(load_rig("E3"), 1, speed_factors={"main": 1.1})
    assert np.allclose(fast.vel[main], (1.716, 0, 0))
    e2a = rig_primitives(load_rig("E2a"), 1)
    assert np.sum(e2a.kind == CAPSULE) == 7 * 8


# -- the integrator ------------------------------------------------------------------------------


@pytest.mark.parametrize("duration, tolerance", [(0.1, 1e-6), (2.0, 1e-4)])
def test_a_spinning_box_in_free_flight_keeps_its_energy_and_angular_momentum(
    bw, duration, tolerance
):
    world = _plane_world(bw, gravity=0.0)
    # mostly about the intermediate axis: the box tumbles
    m = Motion(world, (0, 0, 1.0), (1, 0, 0, 0), (0.3, 0.2, 0), angular_velocity=(0.3, 15, 0.5))
    e0, l0 = m.kinetic_energy, m.angular_momentum.copy()
    m.advance(DT, round(duration / DT))
    assert abs(m.kinetic_energy - e0) / e0 < tolerance
    assert np.linalg.norm(m.angular_momentum - l0) / np.linalg.norm(l0) < tolerance
    assert np.allclose(m.x, (0.3 * duration, 0.2 * duration, 1.0))
    if duration > 1:  # it did tumble
        assert np.min(np.abs(m.angular_velocity)) < 14


def test_a_box_dropped_flat_on_a_belt_rests_at_the_static_penetration(bw):
    world = _plane_world(bw)
    m = Motion(world, (0, 0, float(world.body.half[2]) + 0.002), (1, 0, 0, 0))
    m.advance(DT, 30000)
    penetration = float(world.body.half[2]) - m.x[2]
    assert penetration == pytest.approx(bw.mass * G / K, rel=1e-3)
    assert np.linalg.norm(m.v) < 1e-9


def test_a_box_on_a_moving_belt_accelerates_at_mu_d_g_to_belt_speed(bw):
    speed = 1.5
    m = _on_plane(_plane_world(bw, speed=speed))
    t, v = [], []
    while m.steps * DT < 0.5:
        m.advance(DT, 500)
        t.append(m.steps * DT)
        v.append(m.v[0])
    t, v = np.array(t), np.array(v)
    sliding = (v > 0.1) & (v < 1.3)
    assert np.polyfit(t[sliding], v[sliding], 1)[0] == pytest.approx(MU_D * G, rel=1e-3)
    # within the friction's threshold speed of the belt at the analytic time
    t_belt = speed / (MU_D * G)
    assert np.interp(t_belt, t, v) == pytest.approx(speed, abs=0.002)
    assert v[-1] == pytest.approx(speed, abs=1e-6)
    assert np.linalg.norm(m.angular_velocity) < 1e-9


def test_a_box_sliding_on_a_still_plane_stops_after_v2_over_2_mu_g(bw):
    v0 = 1.0
    m = _on_plane(_plane_world(bw), velocity=(v0, 0, 0))
    m.advance(DT, 50000)
    assert m.x[0] == pytest.approx(v0**2 / (2 * MU_D * G), rel=1e-3)
    assert np.linalg.norm(m.v) < 1e-6


def test_a_box_spinning_on_a_still_plane_stops_its_spin(bw):
    """Uniform pressure: friction torque mu g (M / A) integral |r| dA, so the spin stops at
    t = I_zz w0 / torque."""
    w0 = 10.0
    world = _plane_world(bw)
    L, W, _ = bw.outer
    g = np.linspace(-0.5, 0.5, 801)[:-1] + 0.5 / 800
    X, Y = np.meshgrid(g * L, g * W)
    torque = MU_D * G * bw.mass * np.mean(np.hypot(X, Y))
    t_stop = world.body.inertia[2] * w0 / torque
    m = _on_plane(world, angular_velocity=(0, 0, w0))
    m.advance(DT, round(0.9 * t_stop / DT))
    assert 0 < m.angular_velocity[2] < 0.2 * w0
    m.advance(DT, round(0.2 * t_stop / DT))
    assert abs(m.angular_velocity[2]) < 1e-3
    assert np.hypot(*m.x[:2]) < 1e-6  # it spun on the spot


# -- the simulator on E3 -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def e3_runs():
    sim = RigidBoxSimulator()
    return {name: sim.run({}, TestCase("E3", name, 1)) for name in ("KPBW", "BW")}


@pytest.mark.slow
@pytest.mark.parametrize("name", ["KPBW", "BW"])
def test_e3_smoke(e3_runs, name):
    result = e3_runs[name]
    assert result.status is SimStatus.OK, result.diagnostics
    t1, t2 = result.diagnostics["barrier_times"]
    assert t1 is not None and t2 is not None
    assert 1.0 <= result.run.transit_time <= 2.5
    traj = result.run.trajectory
    assert np.allclose(np.diff(traj.t), 1 / 60)
    rig = load_rig("E3")
    assert (traj.x[0], traj.y[0]) == pytest.approx(
        rig.start_centre(*load_consignment(name).outer[:2])
    )
    assert traj.theta[0] == pytest.approx(math.radians(30))


def test_same_inputs_give_bit_identical_runs():
    """Through the strips, the drop to the main belt and the first impact on the lead-in."""
    sim = RigidBoxSimulator().with_options(duration=0.6).with_placement(4)
    a, b = (sim.run({}, TestCase("E3", "BW", 1)).run for _ in range(2))
    for col in ("t", "x", "y", "theta"):
        assert np.array_equal(getattr(a.trajectory, col), getattr(b.trajectory, col))
    assert a.trajectory.theta[-1] != a.trajectory.theta[0]


@pytest.mark.slow
def test_halving_the_step_changes_an_e3_rotation_by_less_than_2_degrees(e3_runs):
    base = e3_runs["BW"]
    half = RigidBoxSimulator().with_options(timestep=base.diagnostics["timestep"] / 2)
    fine = half.run({}, TestCase("E3", "BW", 1))
    assert fine.ok
    diff = rotation(fine.run.trajectory) - rotation(base.run.trajectory)
    assert abs(math.degrees(diff)) < 2


def test_the_simulator_is_picklable_and_seeds_its_placement():
    sim = RigidBoxSimulator().with_options(duration=0.05)
    assert isinstance(sim, Simulator)
    copy = pickle.loads(pickle.dumps(sim.with_placement(3)))
    assert copy.options.placement_seed == 3 and copy.options.duration == 0.05
    members = simulate_ensemble(copy.with_placement, {}, TestCase("E3", "KP", 1), [0, 1])
    rig = load_rig("E3")
    for m in members:
        dx, dy, dh = rig.placement(m.seed)
        traj = m.run.trajectory
        cx, cy = rig.start_centre(*load_consignment("KP").outer[:2])
        assert traj.x[0] == pytest.approx(cx + dx)
        assert traj.y[0] == pytest.approx(cy + dy)
        assert math.degrees(traj.theta[0]) == pytest.approx(rig.start.heading + dh)


def test_the_default_step_resolves_the_stiffest_contact():
    opt = RigidBoxOptions()
    dt = opt.step_for(1e6, 0.08)  # 1000 N/mm on BW: omega 3536 rad/s
    assert dt <= 1e-5 and math.sqrt(1e6 / 0.08) * dt <= 0.1
    assert (1 / 60) / dt == pytest.approx(round((1 / 60) / dt))
    assert opt.step_for(1e9, 0.08) < 1e-5  # a stiffer contact takes a finer step
    assert RigidBoxOptions(timestep=2e-5).step_for(1e9, 0.08) == 2e-5
    assert RigidBoxOptions(step_divisor=2).step_for(1e6, 0.08) == pytest.approx(dt / 2, rel=1e-12)
    with pytest.raises(ParcelfitError, match="step_divisor"):
        RigidBoxOptions(step_divisor=0)


def test_a_study_s_simulator_section_makes_a_rigidbox_simulator(tmp_path):
    from parcelfit.sim.factory import (
        SimulatorConfig,
        SimulatorSection,
        content_kind,
        make_simulator,
    )

    section = SimulatorSection(
        backend="rigidbox", rig="E3", consignment="KPBW", spacing=0.005, bottom_patch="content",
        stick_speed=0.002, wall_limit=60, wall_contact="points",
    )  # fmt: skip
    config = section.to_config(tmp_path)
    sim = make_simulator(config)
    assert isinstance(sim, RigidBoxSimulator)
    opt = sim.options
    assert (opt.spacing, opt.bottom_patch, opt.wall_limit) == (0.005, "content", 60)
    assert opt.wall_contact == "points"
    assert (opt.stick_speed, opt.slip_speed) == (0.002, pytest.approx(0.003))
    assert content_kind(config) == "rigid"
    assert (
        make_simulator(
            SimulatorSection(backend="rigidbox", rig="E3", consignment="BW").to_config(tmp_path)
        ).options
        == RigidBoxOptions()
    )
    with pytest.raises(ParcelfitError, match="does not take shell_dof"):
        SimulatorConfig("rigidbox", rig="E3", consignment="BW", shell_dof="full")
    with pytest.raises(ParcelfitError, match="bottom_patch is a setting of the rigidbox"):
        SimulatorConfig("mujoco", rig="E3", consignment="BW", bottom_patch="content")
    with pytest.raises(ParcelfitError, match="wall_contact is a setting of the rigidbox"):
        SimulatorConfig("mujoco", rig="E3", consignment="BW", wall_contact="points")
    with pytest.raises(Exception, match="wall_contact"):
        SimulatorSection(backend="rigidbox", rig="E3", consignment="BW", wall_contact="edges")
    content = SimulatorSection(
        backend="rigidbox", rig="E3", consignment="KPBW", wall_outline="content"
    ).to_config(tmp_path)
    assert make_simulator(content).options.wall_outline == "content"
    with pytest.raises(ParcelfitError, match="wall_outline is a setting of the rigidbox"):
        SimulatorConfig("mujoco", rig="E3", consignment="BW", wall_outline="content")
    with pytest.raises(Exception, match="wall outline"):
        SimulatorSection(backend="rigidbox", rig="E3", consignment="BW", wall_outline="rim")
    inset = SimulatorSection(
        backend="rigidbox", rig="E3", consignment="KPBW", wall_inset=0.008
    ).to_config(tmp_path)
    assert make_simulator(inset).options.wall_inset == 0.008
    with pytest.raises(ParcelfitError, match="wall_inset is a setting of the rigidbox"):
        SimulatorConfig("mujoco", rig="E3", consignment="BW", wall_inset=0.008)
    with pytest.raises(Exception, match="must exceed stick_speed"):  # the rigid box's 1 mm/s
        SimulatorSection(backend="rigidbox", rig="E3", consignment="BW", slip_speed=0.0008)
    pb = SimulatorSection(backend="rigidbox", rig="E3", consignment="PB").to_config(tmp_path)
    with pytest.raises(ParcelfitError, match="rigid contents only"):
        make_simulator(pb)


def test_the_reference_is_built_from_exactly_its_listed_parameters(monkeypatch):
    """`rigidbox.simulator.PARAMETERS` names what `parameter_effects.py --backend rigidbox`
    accepts: the world must read those and no others (E_Pa, k_CoPa... act on no rigid box)."""
    from parcelfit.sim.mujoco.consignment import Consignment
    from parcelfit.sim.rigidbox.simulator import PARAMETERS

    read: set[str] = set()

    class Recording(dict):
        def __getitem__(self, key):
            read.add(key)
            return super().__getitem__(key)

    original = Consignment.parameter_values
    monkeypatch.setattr(
        Consignment,
        "parameter_values",
        lambda self, *a, **k: Recording(original(self, *a, **k)),
    )
    RigidBoxSimulator().world({}, TestCase("E3", "KPBW", 1))
    assert read == set(PARAMETERS)
