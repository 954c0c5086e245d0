"""Kalman filter and Rauch-Tung-Striebel smoother over a whole track (positions and heading).

Each coordinate (x, y [m], unwrapped theta [rad]) follows its own constant-acceleration model
with white jerk of spectral density q; state s = (p, v, a), frame step dt [s]:

    s_k+1 = F s_k + w,   F = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]],
    Q = q [[dt^5/20, dt^4/8, dt^3/6], [dt^4/8, dt^3/3, dt^2/2], [dt^3/6, dt^2/2, dt]],
    z_k = p_k + e,   e ~ N(0, r_k)      (r_k: the frame's measurement variance; NaN: no frame).

Forward (filter): predict s- = F s, P- = F P F' + Q; update with K = P- H' / (H P- H' + r),
s = s- + K (z - H s-), P = (I - K H) P-. A measurement whose innovation exceeds ``gate``
standard deviations, (z - H s-)^2 > gate^2 (H P- H' + r), is dropped (one bad frame cannot pull
the track). Backward (RTS): C = P_k F' (P-_k+1)^-1, s_k <- s_k + C (s_k+1 - s-_k+1),
P_k <- P_k + C (P_k+1 - P-_k+1) C'.

Change of motion. White jerk cannot start a spin within one frame (720 deg/s in 1/60 s needs an
acceleration of 750 rad/s^2, about 180 of the model's standard deviations per step), so after an
abrupt onset, stop or catch every frame lies outside the gate and, the prediction running on
with the old motion, stays outside: the gate alone discarded every frame after a spin onset.
So when ``restart_after`` (2) measured frames in a row fail the gate, the motion is taken to
have changed, not the measurements to be wrong: velocity and acceleration start afresh in the
steps into the first rejected frame j and into the frame before it (the change happened after
the last accepted frame, or within the gate one frame earlier),

    P-_k = F P_k-1 F' + Q + diag(0, V, A),   k = j - 1, j    (V, A: `_DIFFUSE`),

and the filter runs again from frame j - 1. The position stays continuous; velocity and
acceleration on either side are estimated from their own side's frames only, and the RTS pass
uses the same P-_k, so the smoothed track keeps the kink and its standard deviations grow next to
it (fewer frames inform the motion there). A lone bad frame (the next one passes the gate) is
still dropped; each step is freed at most once. Written by hand (a few lines of NumPy): SciPy
has no Kalman smoother.
"""

from __future__ import annotations

import numpy as np

# prior variances of velocity and acceleration where the motion starts afresh (the track's start
# and a change of motion): (units/s)^2 and (units/s^2)^2, wide for metres and radians alike
_DIFFUSE = (1e2, 1e4)
RESTART_AFTER = 2  # consecutive measured frames outside the gate that restart the motion


def rts_smooth(
    z: np.ndarray,
    dt: float,
    r: np.ndarray,
    q: float,
    gate: float = 5.0,
    restart_after: int = RESTART_AFTER,
    nis: np.ndarray | None = None,
    rates: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
    """Smoothed positions, their standard deviations, the frames used (not gated, not NaN) and
    the frames where the motion was restarted (a change of motion, module docstring) of the
    series ``z`` (one coordinate, NaN where unseen) sampled every ``dt`` [s], with measurement
    variances ``r`` and jerk spectral density ``q``; ``restart_after`` consecutive measured
    frames outside the gate restart the motion (0: never). ``nis`` (n, 2), when given, receives
    each used frame's normalised squared innovation (filter: (z - H s-)^2 / (H P- H' + r)) and
    normalised squared residual (smoother: (z - p)^2 / (r - P), p and P smoothed), NaN
    elsewhere: about 1 each when the variances ``r`` are right. ``rates`` (n,), when given,
    receives the smoothed rate of change (units/s)."""
    n = len(z)
    f = np.array([[1, dt, dt * dt / 2], [0, 1, dt], [0, 0, 1]])
    qm = q * np.array(
        [
            [dt**5 / 20, dt**4 / 8, dt**3 / 6],
            [dt**4 / 8, dt**3 / 3, dt**2 / 2],
            [dt**3 / 6, dt**2 / 2, dt],
        ]
    )
    seen = np.flatnonzero(np.isfinite(z))
    s0 = np.array([z[seen[0]], 0.0, 0.0])
    p0 = np.diag([r[seen[0]], *_DIFFUSE])
    xs, ps, xp, pp = (np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros((n, 3)), np.zeros((n, 3, 3)))
    used = np.zeros(n, bool)
    free = np.zeros(n, bool)  # steps k-1 -> k whose velocity and acceleration start afresh
    restarts: list[int] = []
    rejected: list[int] = []  # the measured frames rejected in a row
    k = 0
    while k < n:
        if k == 0:
            s, p = s0, p0
        else:
            s, p = f @ xs[k - 1], f @ ps[k - 1] @ f.T + qm
            if free[k]:
                p = p + np.diag([0.0, *_DIFFUSE])
        xp[k], pp[k] = s, p
        used[k] = False
        if np.isfinite(z[k]):
            innov, var = z[k] - s[0], p[0, 0] + r[k]
            if innov * innov <= gate * gate * var:
                gain = p[:, 0] / var
                s = s + gain * innov
                p = p - np.outer(gain, p[0, :])
                used[k] = True
                rejected = []
            else:
                rejected.append(k)
        xs[k], ps[k] = s, p
        if restart_after and len(rejected) >= restart_after and not free[rejected[0]]:
            # a change of motion, not outliers: from the step before the first rejected frame
            # on (the change happened between the last accepted frame and it, or one frame
            # earlier within the gate), velocity and acceleration start afresh; filter again
            first = rejected[0]
            steps = [j for j in range(max(1, first - 1), first + 1) if j <= k]
            free[steps] = True
            restarts.append(first)
            rejected = []
            k = steps[0]
            continue
        k += 1
    for k in range(n - 2, -1, -1):
        c = ps[k] @ f.T @ np.linalg.inv(pp[k + 1])
        xs[k] = xs[k] + c @ (xs[k + 1] - xp[k + 1])
        ps[k] = ps[k] + c @ (ps[k + 1] - pp[k + 1]) @ c.T
    if rates is not None:
        rates[:] = xs[:, 1]
    if nis is not None:
        nis[:] = np.nan
        u = np.flatnonzero(used)
        nis[u, 0] = (z[u] - xp[u, 0]) ** 2 / (pp[u, 0, 0] + r[u])
        nis[u, 1] = (z[u] - xs[u, 0]) ** 2 / np.maximum(r[u] - ps[u, 0, 0], 1e-3 * r[u])
    return xs[:, 0], np.sqrt(np.maximum(ps[:, 0, 0], 0)), used, restarts
