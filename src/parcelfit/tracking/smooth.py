"""Kalman filter and Rauch-Tung-Striebel smoother over a whole track (positions and heading).

Each coordinate (x, y [m], unwrapped theta [rad]) follows its own constant-acceleration model
with white jerk of spectral density q; state s = (p, v, a), frame step dt [s]:

    s_k+1 = F s_k + w,   F = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]],
    Q = q [[dt^5/20, dt^4/8, dt^3/6], [dt^4/8, dt^3/3, dt^2/2], [dt^3/6, dt^2/2, dt]],
    z_k = p_k + e,   e ~ N(0, r_k)      (r_k: the frame's measurement variance; NaN: no frame).

Forward (filter): predict s- = F s, P- = F P F' + Q; update with K = P- H' / (H P- H' + r),
s = s- + K (z - H s-), P = (I - K H) P-. A measurement whose innovation exceeds ``gate``
standard deviations is dropped (one bad frame cannot pull the track). Backward (RTS):
C = P_k F' (P-_k+1)^-1, s_k <- s_k + C (s_k+1 - s-_k+1), P_k <- P_k + C (P_k+1 - P-_k+1) C'.
Written by hand (a few lines of NumPy): SciPy has no Kalman smoother.
"""

from __future__ import annotations

import numpy as np


def rts_smooth(
    z: np.ndarray, dt: float, r: np.ndarray, q: float, gate: float = 5.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed positions, their standard deviations and the frames used (not gated, not NaN)
    of the series ``z`` (one coordinate, NaN where unseen) sampled every ``dt`` [s], with
    measurement variances ``r`` and jerk spectral density ``q`` (see the module docstring)."""
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
    s = np.array([z[seen[0]], 0.0, 0.0])
    p = np.diag([r[seen[0]], 1e2, 1e4])
    xs, ps, xp, pp = (np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros((n, 3)), np.zeros((n, 3, 3)))
    used = np.zeros(n, bool)
    for k in range(n):
        if k:
            s, p = f @ s, f @ p @ f.T + qm
        xp[k], pp[k] = s, p
        if np.isfinite(z[k]):
            innov, var = z[k] - s[0], p[0, 0] + r[k]
            if innov * innov <= gate * gate * var:
                gain = p[:, 0] / var
                s = s + gain * innov
                p = p - np.outer(gain, p[0, :])
                used[k] = True
        xs[k], ps[k] = s, p
    for k in range(n - 2, -1, -1):
        c = ps[k] @ f.T @ np.linalg.inv(pp[k + 1])
        xs[k] = xs[k] + c @ (xs[k + 1] - xp[k + 1])
        ps[k] = ps[k] + c @ (ps[k + 1] - pp[k + 1]) @ c.T
    return xs[:, 0], np.sqrt(np.maximum(ps[:, 0, 0], 0)), used
