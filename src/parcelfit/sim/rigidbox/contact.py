"""The rigid-box reference's contact law: penalty normal force plus velocity-dependent friction
per contact point, and an analytic contact of the parcel's outline with a wall's lead-in.

**Per point** (contact point i of area weight A_i, `geometry`): its penetration delta into each
primitive and the primitive's outward unit normal n there:

* box: the point's local coordinates q = R^T (p - c); inside when |q_k| < h_k on every axis;
  delta = h_k - |q_k| and n = sign(q_k) R e_k on the axis of least penetration, chosen when the
  point enters and kept while it stays inside (a point that went deeper than half a thin wall's
  thickness is still pushed back out of the face it came in through, not through the far face);
* cylinder (radius r, half-length l, axis local z): radial delta = r - rho, n radial, or through
  an end cap, delta = l - |q_z|, whichever is less;
* capsule: delta = r - |q - q_axis| from the nearest point of its segment, n along that line.

A side point stands for its band of the side's height (`geometry`: h = H / n_z along the body's
z). Against a box its band is clipped to the box's extent along the box's local z (vertical for
every box of a rig: walls and slabs): the point is moved within its band to the middle of the
part inside, and its area weight scaled by that part's share of the band. A guide plate mounted
a few millimetres above the belt then meets the exact share of a parcel's side whatever the
number of rows.

Normal force (RecurDyn's standard contact with linear exponents, one spring-damper per point):

    f_n = max(0, k_i delta + c_i d(delta)/dt),   d(delta)/dt = -(v_i - v_s(p_i)) . n
    k_i = (K / A_b) A_i,   c_i = 2 zeta sqrt(k_i m_i),   m_i = M A_i / A_b

K the catalogue's whole-face stiffness of the primitive's material (k_BePa belt and rollers,
k_MePa metal) [N/m], zeta its damping ratio (zeta_BePa, zeta_MePa), A_b the outline's area
L W, which the bottom contact patch's weights sum to whatever the patch (`geometry`), M the
parcel's mass: lying flat on its bottom patch the parcel has the stiffness K and the damping
ratio zeta; the same stiffness per unit area applies at its sides and top on every patch.
v_i = v + w x (p_i - x) is the point's velocity, v_s the primitive's surface velocity there.

Friction per point from its own slip: u = v_i - v_s(p_i) minus its normal part, v = |u|,

    f_t = -mu(v) f_n u / v,
    mu(v) = mu_s v / v_s                               for v < v_s
          = mu_s + (mu_d - mu_s)(3 s^2 - 2 s^3),  s = (v - v_s) / (v_d - v_s),   v_s <= v < v_d
          = mu_d                                        for v >= v_d

with mu_s = mu_d + offset (mu_s_BePa, mu_s_MePa): RecurDyn's velocity-dependent coefficient,
zero at rest, the static value at the static threshold speed v_s, the dynamic one beyond the
dynamic threshold v_d. Below v_s it acts as a viscous friction mu_s f_n / v_s.

**Lead-in** (a vertical cylinder of radius r at a wall's upstream end): met by the parcel's box
outline analytically, so that a catch does not depend on the contact points' spacing. The
parcel's height is cut into the side rows' bands (`geometry`); of each band, the part whose
crossing with the cylinder's axis lies within the cylinder's height is kept (its length h_j along
the body's z and its middle zeta_j: for a parcel lying flat their sum is exactly the height the
parcel and the lead-in share, whatever the number of rows); the axis meets the plane
z_body = zeta_j at a point a of the body frame (skipped when the parcel stands more than 60
degrees tilted); within that plane the lead-in's section is taken as the circle of radius r
around a, the parcel's as its rectangle |x| <= L/2, |y| <= W/2. Then

    f_n = max(0, (K / A_b) h_j A_o + c_a h_j l_o d(delta)/dt),   c_a = 2 zeta sqrt(K M) / A_b

with A_o the exact area of the circle inside the rectangle (the area integral of the point law's
penetration: for a flat side at depth delta it is the circle's segment, (4/3) sqrt(2 r)
delta^(3/2) to leading order, what the point contacts give as their spacing goes to zero) and l_o
the length of the rectangle's outline inside the circle. The force acts at the outline point
nearest to a, pushing the parcel from a towards it (a inside the rectangle: away from the nearest
side, so that the lead-in leaves through it), with the friction law above on that point's slip.
(c_a per unit area is ``wall_damping: area``'s; by default the damper follows the contact's own
stiffness, below.)

**Wall** (``WALL``, the default ``wall_contact: outline``; a thin vertical box of half extents
s_x along the wall, s_y across it, s_z up): met by the parcel's outline, not by its contact
points, so that a corner pressed into a guide plate does not depend on the points' spacing. The
face met is the one on the parcel centre's side (sign sigma of the centre's local y), with the
outward normal n = sigma e_y; a point q (wall frame) lies at the depth delta = s_y - sigma q_y
(growing on through the wall: no tunnelling). At each side row's level zeta_j (band height h_j)
the outline is the rectangle |x| <= L/2, |y| <= W/2 of the body frame; on each of its four edges
the part where 0 < delta < s_x - |q_x| (behind the face, and nearer to it than to the wall's
ends: nearer an end, the end's contact acts, the lead-in's or none, as a contact point is pushed
out through the face it entered by) is an interval of the edge (the bounds are linear along it),
integrated with the point law per unit length,

    f_n = max(0, kappa h_j delta(s) + c h_j d(delta)/dt (s)),   kappa = K / A_b, c = 2 zeta sqrt(K M) / A_b

by 4-point Gauss-Legendre quadrature on that interval (the band clipped to the wall's height as
a side point's): the limit of the side points' law as their spacing goes to zero. For a flat side
pressed delta into a wall over the height h the force is kappa h delta (W + delta) (the two
neighbouring sides' penetrated ends included); for a corner at angle alpha to the wall,
kappa h delta^2 (1 / sin alpha + 1 / cos alpha) / 2. Quadrature is exact for the normal force and
its torque (delta is linear along an edge); friction takes each node's own slip. The top and
bottom faces' points do not meet a wall. ``wall_contact: points`` restores the point contact (a
``BOX``), whose answer at a corner strike depends on the spacing. The rectangle walls and
lead-ins meet is the body's ``wall_half`` (``wall_outline``: the packaging's L x W, inset by
``wall_inset`` on every side, or the content's cL x cW).

**Damping of walls and lead-ins** (``wall_damping: ratio``, the default): the catalogue's zeta is
a damping ratio, and a wall's or a lead-in's contact is damped at that ratio of its own
stiffness. Its stiffness is kappa S, with S the pressed strip's measure: for a wall
S = sum of h_j times the edges' intervals' lengths (the quadrature's weights), for a lead-in
S = sum of h_j l_o (d A_o / d delta = l_o, so kappa S is the tangent stiffness). Its damper is
2 zeta sqrt(kappa S M), spread over S: per unit area 2 zeta sqrt(kappa M / S) in place of c,
which gives a contact the ratio zeta only when S = A_b. Per unit area (``wall_damping: area``,
as the contact points keep) a side pressed into a plate, S = h W much smaller than A_b, is
damped at zeta sqrt(S / A_b) (about 0.3 of zeta for BW's side, 0.07 at a lead-in) and rebounds:
KP bounced off E3's lead-in. At zeta = 1 a flat side's strike
rebounds with exp(-2) = 0.135 of its speed (a linear spring-damper that only pushes).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from parcelfit.errors import ParcelfitError
from parcelfit.sim.params import WALL_DAMPINGS
from parcelfit.sim.rigidbox.geometry import BOX, CAPSULE, CYLINDER, LEAD_IN, WALL

# law columns per material: stiffness per unit area K / A_b [N/m^3], damping per unit area
# 2 zeta sqrt(K M) / A_b [N s/m^3], mu_d, mu_s, and 2 zeta sqrt(M) [sqrt(kg)] where a wall's and a
# lead-in's contact is damped at the ratio zeta of its own stiffness (0: per unit area)
KAPPA, CDENS, MU_D, MU_S, ZDAMP = 0, 1, 2, 3, 4
MIN_LEAD_IN_COS = 0.5  # the lead-in's analytic contact needs the parcel less than 60 deg tilted
# Gauss-Legendre nodes and weights on [0, 1] for a wall's outline contact: exact for the normal
# force and its torque (penetration linear along an edge), the friction's smooth slip to high order
_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)
WALL_NODES = 0.5 * (_GL_X + 1.0)
WALL_WEIGHTS = 0.5 * _GL_W


@njit(cache=True, inline="always")
def friction_coefficient(v: float, mu_d: float, mu_s: float, v_s: float, v_d: float) -> float:
    """RecurDyn's velocity-dependent friction coefficient at slip speed ``v`` [m/s]."""
    if v < v_s:
        return mu_s * v / v_s
    if v < v_d:
        s = (v - v_s) / (v_d - v_s)
        return mu_s + (mu_d - mu_s) * s * s * (3.0 - 2.0 * s)
    return mu_d


@njit(cache=True)
def _primitive_of(x, y, z, j, centre, rot):
    """World point (x, y, z) in the local frame of primitive j."""
    dx, dy, dz = x - centre[j, 0], y - centre[j, 1], z - centre[j, 2]
    return (
        rot[j, 0, 0] * dx + rot[j, 1, 0] * dy + rot[j, 2, 0] * dz,
        rot[j, 0, 1] * dx + rot[j, 1, 1] * dy + rot[j, 2, 1] * dz,
        rot[j, 0, 2] * dx + rot[j, 1, 2] * dy + rot[j, 2, 2] * dz,
    )


@njit(cache=True)
def _outside_by(qx, qy, qz, j, reach):
    """How far [m] a local point lies outside primitive j's search box."""
    ex = max(abs(qx) - reach[j, 0], 0.0)
    ey = max(abs(qy) - reach[j, 1], 0.0)
    ez = max(abs(qz) - reach[j, 2], 0.0)
    return math.sqrt(ex * ex + ey * ey + ez * ez)


@njit(cache=True)
def _apply(F, T, px, py, pz, x, fx, fy, fz):
    F[0] += fx
    F[1] += fy
    F[2] += fz
    rx, ry, rz = px - x[0], py - x[1], pz - x[2]
    T[0] += ry * fz - rz * fy
    T[1] += rz * fx - rx * fz
    T[2] += rx * fy - ry * fx


@njit(cache=True)
def _spring_friction(
    F, T, x, px, py, pz, vx, vy, vz, nx, ny, nz, delta, k, c, mu_d, mu_s, v_s, v_d
) -> float:
    """Add one contact's normal and friction force (relative velocity v, normal n) at point p;
    returns the normal force [N]."""
    vn = vx * nx + vy * ny + vz * nz
    fn = k * delta - c * vn
    if fn <= 0.0:
        return 0.0
    tx, ty, tz = vx - vn * nx, vy - vn * ny, vz - vn * nz
    slip = math.sqrt(tx * tx + ty * ty + tz * tz)
    fx, fy, fz = fn * nx, fn * ny, fn * nz
    if slip > 1e-15:
        ft = friction_coefficient(slip, mu_d, mu_s, v_s, v_d) * fn / slip
        fx -= ft * tx
        fy -= ft * ty
        fz -= ft * tz
    _apply(F, T, px, py, pz, x, fx, fy, fz)
    return fn


@njit(cache=True)
def _surface_contact(F, T, x, v, w, rx, ry, rz, j, centre, vel, spin, nx, ny, nz, delta, k, c,
                     mu_d, mu_s, v_s, v_d):  # fmt: skip
    """One contact of the body point at x + r with primitive j's surface (normal n, depth
    delta): its relative velocity, the point's minus the surface's (vel + spin x (p - c)),
    into the spring, damper and friction of `_spring_friction`."""
    px, py, pz = x[0] + rx, x[1] + ry, x[2] + rz
    ax_, ay_, az_ = px - centre[j, 0], py - centre[j, 1], pz - centre[j, 2]
    sx = vel[j, 0] + spin[j, 1] * az_ - spin[j, 2] * ay_
    sy = vel[j, 1] + spin[j, 2] * ax_ - spin[j, 0] * az_
    sz = vel[j, 2] + spin[j, 0] * ay_ - spin[j, 1] * ax_
    vx = v[0] + w[1] * rz - w[2] * ry - sx
    vy = v[1] + w[2] * rx - w[0] * rz - sy
    vz = v[2] + w[0] * ry - w[1] * rx - sz
    _spring_friction(F, T, x, px, py, pz, vx, vy, vz, nx, ny, nz, delta, k, c, mu_d, mu_s, v_s,
                     v_d)  # fmt: skip


@njit(cache=True)
def _half_chord_integral(t, r):
    """The integral of sqrt(r^2 - X^2) dX from 0 to t (t clipped to [-r, r])."""
    t = min(max(t, -r), r)
    return 0.5 * (t * math.sqrt(max(r * r - t * t, 0.0)) + r * r * math.asin(t / r))


@njit(cache=True)
def _quadrant_area(x, y, r):
    """Area of the disc of radius r (centre 0) within X <= x, Y <= y."""
    if y <= -r or x <= -r:
        return 0.0
    xm = min(x, r)
    if y >= r:
        return 2.0 * (_half_chord_integral(xm, r) - _half_chord_integral(-r, r))
    c = math.sqrt(r * r - y * y)
    area = 0.0
    if y >= 0.0:
        area += 2.0 * (_half_chord_integral(min(xm, -c), r) - _half_chord_integral(-r, r))
        if xm > -c:
            hi = min(xm, c)
            area += y * (hi + c) + _half_chord_integral(hi, r) - _half_chord_integral(-c, r)
        if xm > c:
            area += 2.0 * (_half_chord_integral(xm, r) - _half_chord_integral(c, r))
    elif xm > -c:
        hi = min(xm, c)
        area += y * (hi + c) + _half_chord_integral(hi, r) - _half_chord_integral(-c, r)
    return area


@njit(cache=True)
def disc_rectangle_overlap(ax, ay, r, hx, hy):
    """Area of the disc of radius r around (ax, ay) inside the rectangle |x| <= hx, |y| <= hy."""
    x0, x1, y0, y1 = -hx - ax, hx - ax, -hy - ay, hy - ay
    return (
        _quadrant_area(x1, y1, r)
        - _quadrant_area(x0, y1, r)
        - _quadrant_area(x1, y0, r)
        + _quadrant_area(x0, y0, r)
    )


@njit(cache=True)
def _outline_inside(ax, ay, r, hx, hy):
    """Length of the rectangle's outline |x| <= hx, |y| <= hy inside the disc (ax, ay, r)."""
    total = 0.0
    for side in range(4):
        if side < 2:  # x = +-hx, y from -hy to hy
            d = (hx if side == 0 else -hx) - ax
            mid, lim = ay, hy
        else:
            d = (hy if side == 2 else -hy) - ay
            mid, lim = ax, hx
        if abs(d) >= r:
            continue
        h = math.sqrt(r * r - d * d)
        lo, hi = max(mid - h, -lim), min(mid + h, lim)
        if hi > lo:
            total += hi - lo
    return total


@njit(cache=True)
def _lead_in_band(x, R, row_z, row_h, i, j, centre, size, base):
    """Band i's section with lead-in j: (h, zeta, ax, ay) of the module docstring, h = 0: none."""
    cz = centre[j, 2]
    hh = size[j, 1]
    za = x[2] + (row_z[i] - 0.5 * row_h[i] - base) / R[2, 2]
    zb = x[2] + (row_z[i] + 0.5 * row_h[i] - base) / R[2, 2]
    lo, hi = max(min(za, zb), cz - hh), min(max(za, zb), cz + hh)
    if hi <= lo:
        return 0.0, 0.0, 0.0, 0.0
    zeta_lo, zeta_hi = R[2, 2] * (lo - x[2]) + base, R[2, 2] * (hi - x[2]) + base
    zeta = 0.5 * (zeta_lo + zeta_hi)
    h = abs(zeta_hi - zeta_lo)
    dz = (zeta - base) / R[2, 2]
    dx0, dy0 = centre[j, 0] - x[0], centre[j, 1] - x[1]
    ax = R[0, 0] * dx0 + R[1, 0] * dy0 + R[2, 0] * dz
    ay = R[0, 1] * dx0 + R[1, 1] * dy0 + R[2, 1] * dz
    return h, zeta, ax, ay


@njit(cache=True)
def _lead_in(F, T, x, R, v, w, half, row_z, row_h, j, centre, size, law_m, v_s, v_d, radius):
    """The analytic contact of the parcel's outline with lead-in j (module docstring)."""
    cx, cy = centre[j, 0], centre[j, 1]
    r = size[j, 0]
    dx0, dy0 = cx - x[0], cy - x[1]
    if dx0 * dx0 + dy0 * dy0 > (radius + r) ** 2:
        return
    if abs(R[2, 2]) < MIN_LEAD_IN_COS:
        return
    kappa, cdens, mu_d, mu_s, zdamp = law_m[0], law_m[1], law_m[2], law_m[3], law_m[4]
    hx, hy = half[0], half[1]
    base = R[0, 2] * dx0 + R[1, 2] * dy0  # the axis point at body height zeta lies at world
    # z = x_z + (zeta - base) / R_zz
    if zdamp > 0.0:  # damped at the ratio zeta of the whole contact's stiffness kappa S
        shared = 0.0  # S = sum of h l_o over the bands [m^2]
        for i in range(row_z.shape[0]):
            h, _, ax, ay = _lead_in_band(x, R, row_z, row_h, i, j, centre, size, base)
            if h > 0.0 and abs(ax) < hx + r and abs(ay) < hy + r:
                shared += h * _outline_inside(ax, ay, r, hx, hy)
        if shared > 0.0:  # (0: the lead-in wholly inside the outline; per unit area then)
            cdens = zdamp * math.sqrt(kappa / shared)  # c = 2 zeta sqrt(kappa S M) over S
    for i in range(row_z.shape[0]):
        # the part of the row's band whose axis point lies within the lead-in's height: its
        # length h along the body's z, its middle zeta, the axis point (ax, ay) of the body
        h, zeta, ax, ay = _lead_in_band(x, R, row_z, row_h, i, j, centre, size, base)
        if h <= 0.0:
            continue
        if abs(ax) >= hx + r or abs(ay) >= hy + r:
            continue
        inside = abs(ax) <= hx and abs(ay) <= hy  # closed: outside, the nearest point differs
        if inside:
            ex, ey = hx - abs(ax), hy - abs(ay)
            if ex < ey:
                sx = 1.0 if ax >= 0.0 else -1.0
                qx, qy, nbx, nby = sx * hx, ay, -sx, 0.0
            else:
                sy = 1.0 if ay >= 0.0 else -1.0
                qx, qy, nbx, nby = ax, sy * hy, 0.0, -sy
        else:
            qx, qy = min(max(ax, -hx), hx), min(max(ay, -hy), hy)
            ddx, ddy = qx - ax, qy - ay
            dist = math.sqrt(ddx * ddx + ddy * ddy)
            if dist >= r:
                continue
            nbx, nby = ddx / dist, ddy / dist
        area = disc_rectangle_overlap(ax, ay, r, hx, hy)
        if area <= 0.0:
            continue
        length = _outline_inside(ax, ay, r, hx, hy)
        # contact point and push direction in the world (the push made horizontal)
        px = x[0] + R[0, 0] * qx + R[0, 1] * qy + R[0, 2] * zeta
        py = x[1] + R[1, 0] * qx + R[1, 1] * qy + R[1, 2] * zeta
        pz = x[2] + R[2, 0] * qx + R[2, 1] * qy + R[2, 2] * zeta
        nx = R[0, 0] * nbx + R[0, 1] * nby
        ny = R[1, 0] * nbx + R[1, 1] * nby
        nn = math.sqrt(nx * nx + ny * ny)
        if nn < 1e-12:
            continue
        nx, ny = nx / nn, ny / nn
        rx, ry, rz = px - x[0], py - x[1], pz - x[2]
        vx = v[0] + w[1] * rz - w[2] * ry
        vy = v[1] + w[2] * rx - w[0] * rz
        vz = v[2] + w[0] * ry - w[1] * rx
        # the spring's "k delta" is kappa h A_o, its damper c_a h l_o (as k = 1, c = c_a h l_o)
        _spring_friction(
            F, T, x, px, py, pz, vx, vy, vz, nx, ny, 0.0,
            kappa * h * area, 1.0, cdens * h * length, mu_d, mu_s, v_s, v_d,
        )  # fmt: skip


@njit(cache=True)
def _edge_inside(a0, a1, lo, hi):
    """The part [t0, t1] of t in [0, 1] where a0 + t (a1 - a0) lies in (lo, hi) (t0 >= t1:
    none)."""
    t0, t1 = 0.0, 1.0
    d = a1 - a0
    if abs(d) < 1e-300:
        if a0 <= lo or a0 >= hi:
            return 1.0, 0.0
        return t0, t1
    ta, tb = (lo - a0) / d, (hi - a0) / d
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@njit(cache=True)
def _wall_pass(apply, F, T, x, R, v, w, half, row_z, row_h, j, centre, rot, size, vel, spin,
               kappa, cdens, mu_d, mu_s, v_s, v_d, nodes, weights):  # fmt: skip
    """One pass over the outline's nodes behind wall j's face: with ``apply`` add their forces
    (damping ``cdens`` per unit area); returns the nodes' summed area weights S [m^2]."""
    cx, cy, cz = _primitive_of(x[0], x[1], x[2], j, centre, rot)
    s0, s1, s2 = size[j, 0], size[j, 1], size[j, 2]
    shared = 0.0
    sigma = 1.0 if cy >= 0.0 else -1.0  # the face on the parcel centre's side
    nx, ny, nz = sigma * rot[j, 0, 1], sigma * rot[j, 1, 1], sigma * rot[j, 2, 1]
    # the body's z axis in the wall's frame (the bands' direction)
    ex, ey, ez = _primitive_of(x[0] + R[0, 2], x[1] + R[1, 2], x[2] + R[2, 2], j, centre, rot)
    ex, ey, ez = ex - cx, ey - cy, ez - cz
    hx, hy = half[0], half[1]
    for i in range(row_z.shape[0]):
        zeta, hb = row_z[i], row_h[i]
        reach_z = 0.5 * hb * abs(ez)
        for e in range(4):  # the outline's edges at body height zeta, corner to corner
            if e == 0:
                bx0, by0, bx1, by1 = hx, -hy, hx, hy
            elif e == 1:
                bx0, by0, bx1, by1 = -hx, hy, -hx, -hy
            elif e == 2:
                bx0, by0, bx1, by1 = hx, hy, -hx, hy
            else:
                bx0, by0, bx1, by1 = -hx, -hy, hx, -hy
            length = 2.0 * (hy if e < 2 else hx)
            p0x = x[0] + R[0, 0] * bx0 + R[0, 1] * by0 + R[0, 2] * zeta
            p0y = x[1] + R[1, 0] * bx0 + R[1, 1] * by0 + R[1, 2] * zeta
            p0z = x[2] + R[2, 0] * bx0 + R[2, 1] * by0 + R[2, 2] * zeta
            p1x = x[0] + R[0, 0] * bx1 + R[0, 1] * by1 + R[0, 2] * zeta
            p1y = x[1] + R[1, 0] * bx1 + R[1, 1] * by1 + R[1, 2] * zeta
            p1z = x[2] + R[2, 0] * bx1 + R[2, 1] * by1 + R[2, 2] * zeta
            q0x, q0y, q0z = _primitive_of(p0x, p0y, p0z, j, centre, rot)
            q1x, q1y, q1z = _primitive_of(p1x, p1y, p1z, j, centre, rot)
            # where the edge lies behind the near face (depth s1 - sigma q_y > 0) and nearer
            # to it than to either end of the wall (s1 - sigma q_y < s0 -+ q_x; nearer an end,
            # the end's contact acts: the lead-in's, or none), as a point entering the wall is
            # pushed out through the face it is nearest to
            ta, tb = _edge_inside(sigma * q0y, sigma * q1y, -1e300, s1)
            if tb <= ta:
                continue
            ua, ub = _edge_inside(q0x - sigma * q0y, q1x - sigma * q1y, -1e300, s0 - s1)
            va, vb = _edge_inside(-q0x - sigma * q0y, -q1x - sigma * q1y, -1e300, s0 - s1)
            ta, tb = max(ta, ua, va), min(tb, ub, vb)
            if tb <= ta:
                continue
            for g in range(nodes.shape[0]):
                t = ta + (tb - ta) * nodes[g]
                qx = q0x + t * (q1x - q0x)
                qy = q0y + t * (q1y - q0y)
                qz = q0z + t * (q1z - q0z)
                a = (tb - ta) * length * weights[g] * hb
                tau = 0.0
                if reach_z > 1e-12:  # the band against the wall's height, as a point's
                    lo, hi = max(qz - reach_z, -s2), min(qz + reach_z, s2)
                    if hi <= lo:
                        continue
                    a *= (hi - lo) / (2.0 * reach_z)
                    tau = (0.5 * (lo + hi) - qz) / ez
                    qx, qy, qz = qx + tau * ex, qy + tau * ey, 0.5 * (lo + hi)
                elif abs(qz) >= s2:
                    continue
                delta = s1 - sigma * qy
                if delta <= 0.0:
                    continue
                shared += a
                if not apply:
                    continue
                bx = bx0 + t * (bx1 - bx0)
                by = by0 + t * (by1 - by0)
                bz = zeta + tau
                rx = R[0, 0] * bx + R[0, 1] * by + R[0, 2] * bz
                ry = R[1, 0] * bx + R[1, 1] * by + R[1, 2] * bz
                rz = R[2, 0] * bx + R[2, 1] * by + R[2, 2] * bz
                _surface_contact(F, T, x, v, w, rx, ry, rz, j, centre, vel, spin, nx, ny, nz,
                                 delta, kappa * a, cdens * a, mu_d, mu_s, v_s, v_d)  # fmt: skip
    return shared


@njit(cache=True)
def _wall(F, T, x, R, v, w, half, row_z, row_h, j, centre, rot, size, vel, spin, law_m, v_s,
          v_d, radius, nodes, weights):  # fmt: skip
    """The outline contact of the parcel with wall j (module docstring)."""
    cx, cy, cz = _primitive_of(x[0], x[1], x[2], j, centre, rot)
    if (
        abs(cx) > size[j, 0] + radius
        or abs(cy) > size[j, 1] + radius
        or abs(cz) > size[j, 2] + radius
    ):
        return
    kappa, cdens, mu_d, mu_s, zdamp = law_m[0], law_m[1], law_m[2], law_m[3], law_m[4]
    if zdamp > 0.0:  # damped at the ratio zeta of the whole contact's stiffness kappa S
        shared = _wall_pass(False, F, T, x, R, v, w, half, row_z, row_h, j, centre, rot, size,
                            vel, spin, kappa, cdens, mu_d, mu_s, v_s, v_d, nodes,
                            weights)  # fmt: skip
        if shared <= 0.0:
            return
        cdens = zdamp * math.sqrt(kappa / shared)  # c = 2 zeta sqrt(kappa S M) over S
    _wall_pass(True, F, T, x, R, v, w, half, row_z, row_h, j, centre, rot, size, vel, spin,
               kappa, cdens, mu_d, mu_s, v_s, v_d, nodes, weights)  # fmt: skip


@njit(cache=True)
def contact_forces(
    x, R, v, w,
    points, area, band, tile_start, tile_end, tile_centre, tile_radius, half, row_z, row_h,
    radius,
    kind, centre, rot, size, material, vel, spin, reach,
    law, v_s, v_d, mem_face, mem_step, count, F, T,
):  # fmt: skip
    """Add the contact forces and torques (about the centre x) of every primitive on the parcel
    (position x, rotation R, velocity v, angular velocity w, all world) to F and T; ``count`` is
    this evaluation's number (the entry-face memory of box contacts holds the face a point
    entered through and the evaluation it was last inside)."""
    n_prim = kind.shape[0]
    for j in range(n_prim):
        kj = kind[j]
        m = material[j]
        if kj == LEAD_IN:
            _lead_in(F, T, x, R, v, w, half, row_z, row_h, j, centre, size, law[m], v_s, v_d,
                     radius)  # fmt: skip
            continue
        if kj == WALL:
            _wall(F, T, x, R, v, w, half, row_z, row_h, j, centre, rot, size, vel, spin, law[m],
                  v_s, v_d, radius, WALL_NODES, WALL_WEIGHTS)  # fmt: skip
            continue
        cx, cy, cz = _primitive_of(x[0], x[1], x[2], j, centre, rot)
        if _outside_by(cx, cy, cz, j, reach) > radius:
            continue
        kappa, cdens, mu_d, mu_s = law[m, 0], law[m, 1], law[m, 2], law[m, 3]
        s0, s1, s2 = size[j, 0], size[j, 1], size[j, 2]
        # the body's z axis in the primitive's frame (side points' bands)
        ex, ey, ez = _primitive_of(x[0] + R[0, 2], x[1] + R[1, 2], x[2] + R[2, 2], j, centre, rot)
        ex, ey, ez = ex - cx, ey - cy, ez - cz
        for t in range(tile_start.shape[0]):
            tc = tile_centre[t]
            wx = x[0] + R[0, 0] * tc[0] + R[0, 1] * tc[1] + R[0, 2] * tc[2]
            wy = x[1] + R[1, 0] * tc[0] + R[1, 1] * tc[1] + R[1, 2] * tc[2]
            wz = x[2] + R[2, 0] * tc[0] + R[2, 1] * tc[1] + R[2, 2] * tc[2]
            lx, ly, lz = _primitive_of(wx, wy, wz, j, centre, rot)
            if _outside_by(lx, ly, lz, j, reach) > tile_radius[t]:
                continue
            for i in range(tile_start[t], tile_end[t]):
                b0, b1, b2 = points[i, 0], points[i, 1], points[i, 2]
                rx = R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2
                ry = R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2
                rz = R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2
                px, py, pz = x[0] + rx, x[1] + ry, x[2] + rz
                qx, qy, qz = _primitive_of(px, py, pz, j, centre, rot)
                a = area[i]
                if kj == BOX:
                    hb = band[i]
                    if hb > 0.0:  # a side point's band against the box's z extent
                        reach_z = 0.5 * hb * abs(ez)
                        if reach_z > 1e-12:
                            lo, hi = max(qz - reach_z, -s2), min(qz + reach_z, s2)
                            if hi <= lo:
                                continue
                            a *= (hi - lo) / (2.0 * reach_z)
                            tau = (0.5 * (lo + hi) - qz) / ez  # along the body's z, |tau| <= hb/2
                            qx, qy, qz = qx + tau * ex, qy + tau * ey, 0.5 * (lo + hi)
                            rx, ry, rz = rx + tau * R[0, 2], ry + tau * R[1, 2], rz + tau * R[2, 2]
                            px, py, pz = x[0] + rx, x[1] + ry, x[2] + rz
                    if abs(qx) >= s0 or abs(qy) >= s1 or abs(qz) >= s2:
                        continue
                    if mem_step[i, j] == count - 1:
                        face = mem_face[i, j]
                    else:  # entering: the face of least penetration
                        face, best = 0, s0 - abs(qx)
                        if s1 - abs(qy) < best:
                            face, best = 2, s1 - abs(qy)
                        if s2 - abs(qz) < best:
                            face = 4
                        q = qx if face == 0 else (qy if face == 2 else qz)
                        if q > 0.0:
                            face += 1
                    mem_face[i, j] = face
                    mem_step[i, j] = count
                    axis = face // 2
                    sign = 1.0 if face % 2 == 1 else -1.0
                    q = qx if axis == 0 else (qy if axis == 1 else qz)
                    delta = size[j, axis] - sign * q
                    nx, ny, nz = (
                        sign * rot[j, 0, axis],
                        sign * rot[j, 1, axis],
                        sign * rot[j, 2, axis],
                    )
                elif kj == CYLINDER:
                    rho = math.sqrt(qx * qx + qy * qy)
                    if rho >= s0 or abs(qz) >= s1:
                        continue
                    d_r, d_a = s0 - rho, s1 - abs(qz)
                    if d_r <= d_a and rho > 1e-12:
                        delta = d_r
                        ux, uy = qx / rho, qy / rho
                        nx = rot[j, 0, 0] * ux + rot[j, 0, 1] * uy
                        ny = rot[j, 1, 0] * ux + rot[j, 1, 1] * uy
                        nz = rot[j, 2, 0] * ux + rot[j, 2, 1] * uy
                    else:
                        delta = d_a
                        sign = 1.0 if qz >= 0.0 else -1.0
                        nx, ny, nz = sign * rot[j, 0, 2], sign * rot[j, 1, 2], sign * rot[j, 2, 2]
                elif kj == CAPSULE:
                    zc = min(max(qz, -s1), s1)
                    ex, ey, ez = qx, qy, qz - zc
                    dist = math.sqrt(ex * ex + ey * ey + ez * ez)
                    if dist >= s0 or dist < 1e-12:
                        continue
                    delta = s0 - dist
                    ex, ey, ez = ex / dist, ey / dist, ez / dist
                    nx = rot[j, 0, 0] * ex + rot[j, 0, 1] * ey + rot[j, 0, 2] * ez
                    ny = rot[j, 1, 0] * ex + rot[j, 1, 1] * ey + rot[j, 1, 2] * ez
                    nz = rot[j, 2, 0] * ex + rot[j, 2, 1] * ey + rot[j, 2, 2] * ez
                else:
                    continue
                _surface_contact(F, T, x, v, w, rx, ry, rz, j, centre, vel, spin, nx, ny, nz,
                                 delta, kappa * a, cdens * a, mu_d, mu_s, v_s, v_d)  # fmt: skip


def law_array(
    stiffness: tuple[float, float],
    damping: tuple[float, float],
    mu_d: tuple[float, float],
    mu_s_offset: tuple[float, float],
    mass: float,
    bottom_area: float,
    wall_damping: str = "ratio",
) -> np.ndarray:
    """The law's per-material columns (belt, metal): K / A_b, 2 zeta sqrt(K M) / A_b, mu_d,
    mu_d + offset, and 2 zeta sqrt(M) with ``wall_damping`` ``ratio`` (walls and lead-ins
    damped at the ratio zeta of their contact's own stiffness), 0 with ``area`` (per unit area,
    as the points; module docstring)."""
    if wall_damping not in WALL_DAMPINGS:  # any other word would silently mean "area"
        raise ParcelfitError(
            f"unknown wall_damping {wall_damping!r}", fix=f"use one of {list(WALL_DAMPINGS)}"
        )
    law = np.empty((2, 5))
    for m in range(2):
        law[m, KAPPA] = stiffness[m] / bottom_area
        law[m, CDENS] = 2.0 * damping[m] * math.sqrt(stiffness[m] * mass) / bottom_area
        law[m, MU_D] = mu_d[m]
        law[m, MU_S] = mu_d[m] + mu_s_offset[m]
        law[m, ZDAMP] = 2.0 * damping[m] * math.sqrt(mass) if wall_damping == "ratio" else 0.0
    return law
