"""Newton-Euler integration of the rigid box: velocity Verlet for the translation, the
Dullweber-Leimkuhler-McLachlan (DLM) splitting for the rotation, contacts and gravity as kicks.

State: the centre x [m] and velocity v [m/s] (world), the orientation as a unit quaternion q
(body to world, R(q)), the angular momentum in the body frame pi = I omega_body [kg m^2/s] with the
principal inertia I (diagonal). One step of length h:

1. kick:  v += (h/2) F / M,  pi += (h/2) R^T T   (F, T: force and torque about x, world)
2. drift: x += h v; the torque-free rotation over h as five exact rotations about body axes,
   Strang-split from the kinetic energy sum_k pi_k^2 / (2 I_k):
   R_x(h/2) R_y(h/2) R_z(h) R_y(h/2) R_x(h/2), each R_k(s): angle phi = s pi_k / I_k about body
   axis k, q <- q (cos phi/2, sin phi/2 e_k), pi <- R_k(phi)^T pi
3. forces at the new pose (gravity M g and the contacts, `contact.contact_forces`, with the
   velocities v and omega = R (pi / I) of step 2: the velocity-dependent parts lag half a step)
4. kick:  v += (h/2) F / M,  pi += (h/2) R^T T.

In torque-free flight each sub-rotation keeps the world angular momentum R pi exactly and |pi|
exactly (up to rounding), and the scheme is symplectic: the kinetic energy error stays bounded,
O(h^2), instead of drifting. q is renormalised every step.

**Time step.** The stiffest contact is the parcel lying flat on its bottom patch against the
stiffer material: omega_max = sqrt(K_max / M) (K_max = max(k_BePa, k_MePa) if the rig has
metal, else k_BePa) [rad/s]. The default step satisfies omega_max h <= 0.1 and divides the
camera's 1/60 s: h = 1 / (60 n), n the least whole number with that property and h <= 1e-5 s
(the velocity-dependent friction below its static threshold, mu_s f_n / v_s, is a damper whose
rate mu_s g / v_s stays below 0.1 / h at v_s >= 1 mm/s with this bound).

**Light barriers.** Every step, the beam's margin over the parcel's eight box corners projected
onto the plane (min(max_i s_i, -min_i s_i) of their signed distances to the beam's line, over the
corners whose projection lies on the beam's segment: >= 0 when they straddle it) is interpolated
linearly within the step where it turns non-negative (as the MuJoCo simulator times its shell's
vertices).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from parcelfit.sim.rigidbox.contact import contact_forces

RUNNING, STOPPED, NOT_FINITE, TOO_FAST = 0, 1, 2, 3
MAX_SPEED = 20.0  # m/s


@njit(cache=True)
def quat_matrix(q, R):
    """Write the rotation matrix of unit quaternion q = (w, x, y, z) into R."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    R[0, 0] = 1 - 2 * (y * y + z * z)
    R[0, 1] = 2 * (x * y - w * z)
    R[0, 2] = 2 * (x * z + w * y)
    R[1, 0] = 2 * (x * y + w * z)
    R[1, 1] = 1 - 2 * (x * x + z * z)
    R[1, 2] = 2 * (y * z - w * x)
    R[2, 0] = 2 * (x * z - w * y)
    R[2, 1] = 2 * (y * z + w * x)
    R[2, 2] = 1 - 2 * (x * x + y * y)


@njit(cache=True)
def _rotate(q, pi, axis, phi):
    """Turn the body by phi about its own axis ``axis``: q <- q (cos phi/2, sin phi/2 e_axis),
    pi <- R_axis(phi)^T pi."""
    c2, s2 = math.cos(0.5 * phi), math.sin(0.5 * phi)
    w, x, y, z = q[0], q[1], q[2], q[3]
    c, s = math.cos(phi), math.sin(phi)
    if axis == 0:
        q[0], q[1], q[2], q[3] = w * c2 - x * s2, x * c2 + w * s2, y * c2 + z * s2, z * c2 - y * s2
        p1, p2 = pi[1], pi[2]
        pi[1], pi[2] = c * p1 + s * p2, -s * p1 + c * p2
    elif axis == 1:
        q[0], q[1], q[2], q[3] = w * c2 - y * s2, x * c2 - z * s2, y * c2 + w * s2, z * c2 + x * s2
        p0, p2 = pi[0], pi[2]
        pi[0], pi[2] = c * p0 - s * p2, s * p0 + c * p2
    else:
        q[0], q[1], q[2], q[3] = w * c2 - z * s2, x * c2 + y * s2, y * c2 - x * s2, z * c2 + w * s2
        p0, p1 = pi[0], pi[1]
        pi[0], pi[1] = c * p0 + s * p1, -s * p0 + c * p1


@njit(cache=True)
def free_rotation(q, pi, inertia, h):
    """The torque-free rotation over ``h`` [s] (DLM: x, y, z, y, x sub-rotations)."""
    _rotate(q, pi, 0, 0.5 * h * pi[0] / inertia[0])
    _rotate(q, pi, 1, 0.5 * h * pi[1] / inertia[1])
    _rotate(q, pi, 2, h * pi[2] / inertia[2])
    _rotate(q, pi, 1, 0.5 * h * pi[1] / inertia[1])
    _rotate(q, pi, 0, 0.5 * h * pi[0] / inertia[0])
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for k in range(4):
        q[k] /= n


@njit(cache=True)
def evaluate(
    x, q, v, pi, R, w, F, T, mass, inertia, gravity,
    points, area, band, tile_start, tile_end, tile_centre, tile_radius, half, row_z, row_h,
    radius,
    kind, centre, rot, size, material, vel, spin, reach,
    law, v_s, v_d, mem_face, mem_step, count,
):  # fmt: skip
    """Forces F and torques T (world, about x) at the state (x, q, v, pi); also sets R and the
    world angular velocity w."""
    quat_matrix(q, R)
    w0, w1, w2 = pi[0] / inertia[0], pi[1] / inertia[1], pi[2] / inertia[2]
    for k in range(3):
        w[k] = R[k, 0] * w0 + R[k, 1] * w1 + R[k, 2] * w2
        F[k] = 0.0
        T[k] = 0.0
    F[2] = -mass * gravity
    contact_forces(
        x, R, v, w,
        points, area, band, tile_start, tile_end, tile_centre, tile_radius, half, row_z, row_h,
    radius,
        kind, centre, rot, size, material, vel, spin, reach,
        law, v_s, v_d, mem_face, mem_step, count, F, T,
    )  # fmt: skip


@njit(cache=True)
def _kick(v, pi, R, F, T, mass, h):
    for k in range(3):
        v[k] += h * F[k] / mass
    for k in range(3):
        pi[k] += h * (R[0, k] * T[0] + R[1, k] * T[1] + R[2, k] * T[2])


@njit(cache=True)
def _beam_margin(x, R, corners, a, d, d2, nrm):
    """The beam's margin over the box corners (module docstring); -inf when none lies over the
    segment."""
    smax, smin = -np.inf, np.inf
    found = False
    for c in range(corners.shape[0]):
        b = corners[c]
        px = x[0] + R[0, 0] * b[0] + R[0, 1] * b[1] + R[0, 2] * b[2] - a[0]
        py = x[1] + R[1, 0] * b[0] + R[1, 1] * b[1] + R[1, 2] * b[2] - a[1]
        along = (px * d[0] + py * d[1]) / d2
        if along < 0.0 or along > 1.0:
            continue
        found = True
        s = px * nrm[0] + py * nrm[1]
        smax = max(smax, s)
        smin = min(smin, s)
    if not found:
        return -np.inf
    return min(smax, -smin)


@njit(cache=True)
def advance(
    x, q, v, pi, R, w, F, T, mass, inertia, gravity, dt, n_steps, counters,
    points, area, band, tile_start, tile_end, tile_centre, tile_radius, half, row_z, row_h,
    radius,
    kind, centre, rot, size, material, vel, spin, reach,
    law, v_s, v_d, mem_face, mem_step,
    corners, beam_a, beam_d, beam_d2, beam_n, crossed, clear_t, clear_g, after_steps,
):  # fmt: skip
    """Integrate up to ``n_steps`` steps of ``dt`` [s] from the state (x, q, v, pi; its forces F,
    T already evaluated). ``counters``: [step, force evaluation, stop_at]; the run stops early at
    step stop_at (set ``after_steps`` after both beams broke). Beams: ``crossed`` (NaN
    until broken: the time [s]; inf where broken at the first step, before the run),
    ``clear_t``, ``clear_g``: the last uninterrupted time and margin (NaN: none). Returns
    RUNNING, STOPPED, NOT_FINITE or TOO_FAST."""
    half_dt = 0.5 * dt
    for _ in range(n_steps):
        _kick(v, pi, R, F, T, mass, half_dt)
        for k in range(3):
            x[k] += dt * v[k]
        free_rotation(q, pi, inertia, dt)
        counters[1] += 1
        evaluate(
            x, q, v, pi, R, w, F, T, mass, inertia, gravity,
            points, area, band, tile_start, tile_end, tile_centre, tile_radius, half, row_z,
            row_h, radius, kind, centre, rot, size, material, vel, spin, reach,
            law, v_s, v_d, mem_face, mem_step, counters[1],
        )  # fmt: skip
        _kick(v, pi, R, F, T, mass, half_dt)
        counters[0] += 1
        step = counters[0]
        t = step * dt
        for k in range(3):
            if not (math.isfinite(x[k]) and math.isfinite(v[k]) and math.isfinite(pi[k])):
                return NOT_FINITE
        if v[0] * v[0] + v[1] * v[1] + v[2] * v[2] > MAX_SPEED * MAX_SPEED:
            return TOO_FAST
        for b in range(2):
            if not math.isnan(crossed[b]):  # each beam on its own: the order is checked after
                continue
            g = _beam_margin(x, R, corners, beam_a[b], beam_d[b], beam_d2[b], beam_n[b])
            if g == -np.inf:
                clear_t[b] = np.nan
                clear_g[b] = np.nan
            elif g < 0.0:
                clear_t[b] = t
                clear_g[b] = g
            elif step == 1:
                # broken at the first position checked: crossed before the run (inf: no time),
                # as tracking leaves out a beam broken in the first frame
                crossed[b] = np.inf
            else:
                if math.isnan(clear_t[b]) or not (clear_g[b] < 0.0 <= g):
                    crossed[b] = t
                else:
                    crossed[b] = clear_t[b] + (t - clear_t[b]) * clear_g[b] / (clear_g[b] - g)
                if not (math.isnan(crossed[0]) or math.isnan(crossed[1])):  # both broken
                    counters[2] = min(counters[2], step + after_steps)
        if step >= counters[2]:
            return STOPPED
    return RUNNING
