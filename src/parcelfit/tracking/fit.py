"""Model-based fit of a motion-smeared tag to a frame (blur, spin and rolling shutter).

Where the detector misses a parcel tag, or where the exposure smears it so much that its
detected corners are biased (the smear pulls opposite corners apart and bends the edges of a
spinning tag), the tag's pose is fitted to the image instead: the tag's known pattern (OpenCV's
bitmap of it, with its one-bit white quiet zone) is rendered as the camera saw it and compared
with the frame pixel by pixel.

Model, in image pixels. The tag at the frame time t_k is the homography H from the pattern to
four corners; the corners are the starting corners moved by a similarity (shift du, dv, turn
dphi, scale 1 + ds about their centre): the four fitted parameters. During the exposure the tag
moves rigidly with its image velocity v [px/s] and turn rate w [rad/s] (from a motion model over
neighbouring frames, `track.py`). Image row r is exposed around t_k + (r / height - 0.5) * readout
(rolling shutter), so the pixel p at row r sees, at the sub-exposure times tau_j (``samples``
spread evenly over the exposure),

    dt = tau_j + (r / height - 0.5) * readout,
    p0 = c + R(-w dt) (p - c - v dt),       pattern point = H^-1 p0,

and its modelled grey is a * mean_j pattern(H^-1 p0) + b (a, b solved linearly each time; the
pattern is pre-blurred to the pixel's footprint). Only pixels whose every sample falls on the tag
or its quiet zone are compared (the surface around a tag is unknown). The four parameters are
found by `scipy.optimize.least_squares`; their covariance s^2 (J'J)^-1 (s^2 the residual
variance) gives the centre's and heading's standard deviations. The fitted corners are where
the tag was at t_k itself (the readout is modelled), so they need no rolling-shutter correction.

Written by hand because no library renders a motion-smeared, rolling-shutter AprilTag or fits
one; the rendering uses `cv2.remap`, the fit SciPy.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from scipy.optimize import least_squares

from parcelfit.tracking.detect import dictionary

_CELL_PX = 64  # pattern pixels per tag bit (cv2.remap interpolates in 1/32 pixel steps)
_STEP_PX = 0.1  # finite-difference step of the fit [px at the corners]
_MAX_NFEV = 20  # function evaluations per round


@dataclass(frozen=True)
class TagPattern:
    """A tag's bitmap in [0, 1] (black 0) with a one-bit white quiet zone; ``square``: the
    black square's corners (4, 2) in bitmap pixels, in OpenCV's corner order; ``bits``: bits
    across the black square."""

    image: np.ndarray
    square: np.ndarray
    bits: int


@lru_cache(maxsize=32)
def tag_pattern(family: str, tag_id: int) -> TagPattern:
    """The bitmap of tag ``tag_id`` of ``family`` (see `TagPattern`)."""
    d = dictionary(family)
    bits = d.markerSize + 2
    side = bits * _CELL_PX
    img = cv2.aruco.generateImageMarker(d, tag_id, side, borderBits=1)
    img = cv2.copyMakeBorder(img, *(4 * [_CELL_PX]), cv2.BORDER_CONSTANT, value=255)
    q, n = float(_CELL_PX), float(_CELL_PX + side)
    square = np.array([[q, q], [n, q], [n, n], [q, n]]) - 0.5
    return TagPattern(img.astype(np.float32) / 255.0, square, bits)


@dataclass(frozen=True)
class SmearFit:
    """A fitted tag: ``params`` (the pose, in the units of the caller's ``corners_of``) and
    their covariance ``cov``; ``corners`` (4, 2) [px, full frame] at the frame time; ``rms``:
    residual rms as a fraction of the tag's black-to-white contrast; ``contrast`` [grey levels];
    ``pixels`` compared."""

    params: np.ndarray
    cov: np.ndarray
    corners: np.ndarray
    rms: float
    contrast: float
    pixels: int


def _angle(c: np.ndarray) -> float:
    e = (c[1] - c[0]) + (c[2] - c[3])
    return math.atan2(e[1], e[0])


def fit_smeared_tag(
    patch: np.ndarray,
    origin: tuple[int, int],
    shrink: int,
    corners_of: Callable[[np.ndarray], np.ndarray],
    start: np.ndarray,
    steps: np.ndarray,
    rates: np.ndarray,
    pattern: TagPattern,
    exposure: float,
    readout: float,
    frame_height: int,
    max_samples: int = 16,
    rounds: int = 1,
) -> SmearFit | None:
    """Fit the smeared tag to ``patch`` (grey, a cut of the frame at ``origin`` (x, y) [full px],
    shrunk by the integer ``shrink``). The tag's pose at the frame time is a parameter vector p
    (e.g. x, y [m], heading [rad] in the rig frame) whose black-square corners in the frame
    are ``corners_of(p)`` (4, 2) [full px]; ``start``: the first p; ``steps``: finite-difference
    steps of p (about 0.1 px at the corners each); ``rates``: dp/dt (the tag's motion, per s)
    over the exposure; ``rounds``: fits, each over the pixels the last one saw. ``exposure``
    and rolling-shutter ``readout`` [s], ``frame_height`` [full px]. Returns None when too few
    pixels can be compared or the fit fails (module docstring)."""
    d = float(shrink)
    ox, oy = origin
    to_patch = np.array([ox - 0.5, oy - 0.5])
    start = np.asarray(start, float)
    steps = np.asarray(steps, float)
    rates = np.asarray(rates, float)

    def patch_corners(p: np.ndarray) -> np.ndarray:
        return (np.asarray(corners_of(p), float) - to_patch) / d - 0.5

    c0 = patch_corners(start)
    # the tag's image motion over the exposure (velocity [patch px/s], turn [rad/s]) from dp/dt
    delta = 1e-3
    ca, cb = patch_corners(start - rates * delta), patch_corners(start + rates * delta)
    vel = (cb.mean(axis=0) - ca.mean(axis=0)) / (2 * delta)
    turn = math.remainder(_angle(cb) - _angle(ca), 2 * math.pi) / (2 * delta)
    side = float(np.mean(np.linalg.norm(c0 - np.roll(c0, 1, axis=0), axis=1)))
    radius = side / math.sqrt(2)
    smear = (float(np.linalg.norm(vel)) + abs(turn) * radius) * exposure
    m = int(min(max_samples, max(1, math.ceil(smear / 1.0))))
    taus = (np.arange(m) + 0.5) / m * exposure - exposure / 2
    # the pattern blurred to a patch pixel's footprint (box of one pixel ~ sd 0.3, plus optics)
    tpl_per_px = pattern.bits * _CELL_PX / side
    image = _blurred(pattern, round(0.45 * tpl_per_px, 1))
    h_img, w_img = patch.shape
    # the pixels that can see the tag during the exposure (box around the smeared tag)
    reach = side * (pattern.bits + 2) / pattern.bits / 2 + smear + 2
    cc = c0.mean(axis=0)
    xa, xb = max(0, int(cc[0] - reach)), min(w_img, math.ceil(cc[0] + reach) + 1)
    ya, yb = max(0, int(cc[1] - reach)), min(h_img, math.ceil(cc[1] + reach) + 1)
    if xb - xa < 8 or yb - ya < 8:
        return None
    gx, gy = np.meshgrid(np.arange(xa, xb, dtype=float), np.arange(ya, yb, dtype=float))
    obs = patch[ya:yb, xa:xb].astype(np.float64).ravel()
    px, py = gx.ravel(), gy.ravel()
    rows_full = oy + (py + 0.5) * d - 0.5
    dts = taus[:, None] + ((rows_full / frame_height - 0.5) * readout)[None, :]  # (m, n)
    cos_t, sin_t = np.cos(-turn * dts), np.sin(-turn * dts)
    n_tpl = pattern.image.shape[0]
    lo, hi = 0.4 * _CELL_PX, n_tpl - 1 - 0.4 * _CELL_PX
    square = pattern.square.astype(np.float32)

    def sample(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cs = patch_corners(p)
        c = cs.mean(axis=0)
        hinv = np.linalg.inv(cv2.getPerspectiveTransform(square, cs.astype(np.float32)))
        rx = px[None, :] - c[0] - vel[0] * dts
        ry = py[None, :] - c[1] - vel[1] * dts
        x0 = c[0] + cos_t * rx - sin_t * ry
        y0 = c[1] + sin_t * rx + cos_t * ry
        w = hinv[2, 0] * x0 + hinv[2, 1] * y0 + hinv[2, 2]
        u = (hinv[0, 0] * x0 + hinv[0, 1] * y0 + hinv[0, 2]) / w
        v = (hinv[1, 0] * x0 + hinv[1, 1] * y0 + hinv[1, 2]) / w
        inside = np.all((u >= lo) & (u <= hi) & (v >= lo) & (v <= hi), axis=0)
        val = cv2.remap(
            image,
            u.astype(np.float32),
            v.astype(np.float32),
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=1.0,
        )
        return val.mean(axis=0), inside

    def solve(p: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, float]:
        model, _ = sample(p)
        a_mat = np.column_stack([model[mask], np.ones(int(mask.sum()))])
        (a, b), *_ = np.linalg.lstsq(a_mat, obs[mask], rcond=None)
        return a * model[mask] + b - obs[mask], float(a)

    k = len(start)
    x_scale = steps / _STEP_PX  # parameter units per pixel at the corners
    p = start.copy()
    result = None
    mask = np.zeros(0, bool)
    for _ in range(rounds):  # the compared pixels follow the fit
        _, mask = sample(p)
        if mask.sum() < 8 * pattern.bits * pattern.bits:
            return None

        def fun(q: np.ndarray, mk: np.ndarray = mask) -> np.ndarray:
            return solve(q, mk)[0]

        def jac(q: np.ndarray, mk: np.ndarray = mask) -> np.ndarray:
            # forward differences of about 0.1 px at the corners: SciPy's own steps (1e-8
            # relative) vanish in the float32 sampling of the pattern
            f0 = fun(q, mk)
            return np.column_stack(
                [(fun(q + steps * e, mk) - f0) / steps[i] for i, e in enumerate(np.eye(k))]
            )

        try:
            result = least_squares(
                fun,
                p,
                jac=jac,
                method="trf",
                max_nfev=_MAX_NFEV,
                x_scale=x_scale,
                ftol=1e-6,
                xtol=1e-5,
            )
        except (np.linalg.LinAlgError, ValueError):
            return None
        p = result.x
    assert result is not None
    res, a = solve(p, mask)
    s2 = float(res @ res) / max(1, len(res) - k)
    try:
        cov = s2 * np.linalg.inv(result.jac.T @ result.jac)
    except np.linalg.LinAlgError:
        return None
    return SmearFit(
        params=p,
        cov=cov,
        corners=np.asarray(corners_of(p), float),
        rms=math.sqrt(s2) / max(abs(a), 1e-9),
        contrast=abs(a),
        pixels=len(res),
    )


@lru_cache(maxsize=64)
def _blurred_cached(family_key: int, sigma: float) -> np.ndarray:
    pattern = _PATTERNS[family_key]
    return cv2.GaussianBlur(pattern.image, (0, 0), sigma) if sigma > 0 else pattern.image


_PATTERNS: dict[int, TagPattern] = {}


def _blurred(pattern: TagPattern, sigma: float) -> np.ndarray:
    key = id(pattern)
    _PATTERNS[key] = pattern
    return _blurred_cached(key, sigma)
