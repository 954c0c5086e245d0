"""Model-based fit of a motion-smeared tag to a frame (blur, spin and rolling shutter).

Where the detector misses a parcel tag, or where the exposure smears it so much that its
detected corners are biased (the smear pulls opposite corners apart and bends the edges of a
spinning tag), the tag's pose is fitted to the image instead: the tag's known pattern (OpenCV's
bitmap of it, with its one-bit white quiet zone) is rendered as the camera saw it and compared
with the frame pixel by pixel.

Model. The tag at pose p (the caller's parameters, e.g. x, y, heading in the rig frame) is the
homography H(p) from the pattern to its four projected corners in the frame. During the
exposure it moves with dp/dt (the motion model over neighbouring frames, `track.py`), so a fixed
pixel x sees, dt after the frame time, the pattern point M(dt) H(p)^-1 x with
M(dt) = H(p + dp/dt dt)^-1 H(p). The pattern smeared over the exposure,

    S(u) = mean_j pattern(M(tau_j) u),   tau_j spread evenly over the exposure (< 1 px apart),

is computed once on a grid of about 2 samples per image pixel (the pattern first blurred to a
pixel's footprint), and the modelled grey of pixel x is a * S(M(dt_r) H(p)^-1 x) + b, with
dt_r = (r / height - 0.5) * readout the rolling-shutter delay of its row r (a, b solved
linearly each time). Only pixels whose every sample falls on the tag or its quiet zone are
compared (the surface around a tag is unknown). p is found by `scipy.optimize.least_squares`;
S and the compared pixels are then rebuilt about the fitted pose (the heading turns the motion
in the pattern's frame) and p fitted again. The parameters' covariance is cluster-robust,
(J'J)^-1 (sum_g J_g' e_g e_g' J_g) (J'J)^-1 G / (G - 1) over the G blocks of `CLUSTER_BITS`
tag bits a side (J_g, e_g: the Jacobian rows and residuals of block g's pixels): neighbouring
pixels' residuals are not independent (H.264 blocks, the smear model's own error along an
edge), as the independent-pixel s^2 (J'J)^-1 (s^2 the residual variance) assumes. The fitted
pose is where the tag was at the frame time itself (the readout is modelled), so it needs no
rolling-shutter correction.
Approximations: M over the exposure is taken about the frame-time pose for every row (the
tag turns by at most w x readout / 2 between, about 5 degrees at 720 deg/s and 15 ms, which
turns its smear, not its position).

Written by hand because no library renders a motion-smeared, rolling-shutter AprilTag or fits
one; the sampling uses `cv2.remap`, the fit SciPy.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np
from scipy.optimize import least_squares

from parcelfit.tracking.detect import dictionary

_CELL_PX = 64  # pattern pixels per tag bit (cv2.remap interpolates in 1/32 pixel steps)
_STEP_PX = 0.1  # finite-difference step of the fit [px at the corners]
_MAX_NFEV = 20  # function evaluations per round
CLUSTER_BITS = 1.0  # side of the pixel blocks whose residuals the covariance sums [tag bits]


@dataclass(frozen=True)
class TagPattern:
    """A tag's bitmap in [0, 1] (black 0) with a one-bit white quiet zone; ``square``: the
    black square's corners (4, 2) in bitmap pixels, in OpenCV's corner order; ``bits``: bits
    across the black square; ``blurred``: blurred copies by sigma (`_blurred`)."""

    image: np.ndarray
    square: np.ndarray
    bits: int
    blurred: dict[float, np.ndarray] = field(default_factory=dict)


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
    their covariance ``cov`` (cluster-robust; ``cov_iid``: assuming independent pixels);
    ``corners`` (4, 2) [px, full frame] at the frame time; ``rms``: residual rms as a fraction
    of the tag's black-to-white contrast; ``contrast`` [grey levels]; ``pixels`` compared."""

    params: np.ndarray
    cov: np.ndarray
    cov_iid: np.ndarray
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
    rounds: int = 2,
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

    square = pattern.square.astype(np.float32)

    def homography(p: np.ndarray) -> np.ndarray:
        """pattern px -> patch px of the tag at pose p"""
        return cv2.getPerspectiveTransform(square, patch_corners(p).astype(np.float32))

    c0 = patch_corners(start)

    span = exposure / 2 + readout / 2  # the largest |dt| from the frame time

    def motion(base: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """M(dt) = H(base + dp/dt dt)^-1 H(base) for many dt [s]: where, dt later, the pattern
        point a pixel sees has moved to. The corners' paths are quadratics through their
        projections at -span, 0 and span (a rigid turn of w dt: error ~ r (w dt)^3 / 6, under
        0.01 px at 720 deg/s over 11.5 ms), so the camera model is evaluated 3 times."""
        h_base = homography(base)
        if span <= 0:
            return lambda dts: np.broadcast_to(np.eye(3), (len(dts), 3, 3))
        a, b, c = (patch_corners(base + rates * t) for t in (-span, 0.0, span))
        lin, quad = (c - a) / (2 * span), (a + c - 2 * b) / (2 * span * span)

        def at(dts: np.ndarray) -> np.ndarray:
            out = np.empty((len(dts), 3, 3))
            for i, t in enumerate(dts):
                pts = (b + lin * t + quad * t * t).astype(np.float32)
                out[i] = np.linalg.inv(cv2.getPerspectiveTransform(square, pts)) @ h_base
            return out

        return at

    side = float(np.mean(np.linalg.norm(c0 - np.roll(c0, 1, axis=0), axis=1)))
    ends = motion(start)(np.array([-exposure / 2, exposure / 2]))
    probe = np.array([[0, 0, 1], [0, 1, 1], [1, 0, 1], [1, 1, 1]], float).T
    probe[:2] *= pattern.image.shape[0]
    sweep = [e @ probe for e in ends]
    smear_tpl = float(
        np.max(np.linalg.norm(sweep[1][:2] / sweep[1][2] - sweep[0][:2] / sweep[0][2], axis=0))
    )
    tpl_per_px = pattern.bits * _CELL_PX / side
    smear = smear_tpl / tpl_per_px  # patch px
    m = int(min(max_samples, max(1, math.ceil(smear / 1.0))))
    taus = (np.arange(m) + 0.5) / m * exposure - exposure / 2
    # the smeared pattern S(u) = mean over the exposure of the pattern at M(tau) u, on a grid of
    # about 2 samples per patch pixel; the pattern is first blurred to a patch pixel's
    # footprint (a one-pixel box ~ sd 0.3 px, plus optics)
    image = _blurred(pattern, 0.45 * tpl_per_px)
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
    pix = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
    box = gx.shape
    # rolling shutter: a pixel in full-frame row r sees the tag dt_r = (r / height - 0.5) *
    # readout after the frame time, so at the pattern point M(dt_r) H(p)^-1 x (one M per row)
    rows = np.arange(ya, yb)
    row_dt = ((oy + (rows + 0.5) * d - 0.5) / frame_height - 0.5) * readout
    n_tpl = pattern.image.shape[0]
    g = max(1, math.floor(tpl_per_px / 2))  # pattern px per sample: about 2 per patch pixel
    ns = n_tpl // g
    gu, gv = np.meshgrid((np.arange(ns) + 0.5) * g - 0.5, (np.arange(ns) + 0.5) * g - 0.5)
    grid = np.stack([gu.ravel(), gv.ravel(), np.ones(gu.size)])
    lo, hi = 0.4 * _CELL_PX, n_tpl - 1 - 0.4 * _CELL_PX

    def prepare(base: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The smeared pattern, where it saw only the tag, and per-pixel row motions, about
        the pose ``base`` (the tag's heading turns the motion in the pattern's frame)."""
        acc = np.zeros(gu.size, np.float32)
        inside = np.ones(gu.size, bool)
        moved = motion(base)
        for m_tau in moved(taus):
            q = m_tau @ grid
            u, v = q[0] / q[2], q[1] / q[2]
            inside &= (u >= lo) & (u <= hi) & (v >= lo) & (v <= hi)
            acc += cv2.remap(
                image,
                u.astype(np.float32).reshape(ns, ns),
                v.astype(np.float32).reshape(ns, ns),
                cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_CONSTANT,
                borderValue=1.0,
            ).ravel()
        smeared = (acc / m).reshape(ns, ns)
        seen = inside.astype(np.float32).reshape(ns, ns)
        per_pixel = (
            moved(row_dt)[np.repeat(np.arange(len(row_dt)), xb - xa)].transpose(1, 2, 0).copy()
            if readout
            else None
        )  # (3, 3, pixels)
        return smeared, seen, per_pixel

    state: list[tuple[np.ndarray, np.ndarray, np.ndarray | None]] = []

    def sample(p: np.ndarray, with_mask: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        smeared, seen, per_pixel = state[-1]
        u0 = np.linalg.inv(homography(p)) @ pix
        q = (
            u0
            if per_pixel is None
            else [sum(per_pixel[i, j] * u0[j] for j in range(3)) for i in range(3)]
        )
        # smeared-grid coordinates of the pattern points
        su = ((q[0] / q[2] + 0.5) / g - 0.5).astype(np.float32).reshape(box)
        sv = ((q[1] / q[2] + 0.5) / g - 0.5).astype(np.float32).reshape(box)
        val = cv2.remap(
            smeared, su, sv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=1.0
        ).ravel()
        if not with_mask:
            return val.astype(np.float64), None
        ok = cv2.remap(seen, su, sv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT).ravel()
        return val.astype(np.float64), ok > 0.999

    def solve(p: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, float]:
        model, _ = sample(p, with_mask=False)
        a_mat = np.column_stack([model[mask], np.ones(int(mask.sum()))])
        (a, b), *_ = np.linalg.lstsq(a_mat, obs[mask], rcond=None)
        return a * model[mask] + b - obs[mask], float(a)

    k = len(start)
    x_scale = steps / _STEP_PX  # parameter units per pixel at the corners
    p = start.copy()
    result = None
    mask = np.zeros(0, bool)
    for _ in range(rounds):  # the smear model and the compared pixels follow the fit
        state.append(prepare(p))
        _, seen_mask = sample(p)
        assert seen_mask is not None
        mask = seen_mask
        if mask.sum() < 8 * pattern.bits * pattern.bits:
            return None

        last: list[tuple[np.ndarray, np.ndarray]] = []

        def fun(q: np.ndarray, mk: np.ndarray = mask, memo: list = last) -> np.ndarray:
            f = solve(q, mk)[0]
            memo[:] = [(q.copy(), f)]
            return f

        def jac(q: np.ndarray, mk: np.ndarray = mask, memo: list = last) -> np.ndarray:
            # forward differences of about 0.1 px at the corners: SciPy's own steps (1e-8
            # relative) vanish in the float32 sampling of the pattern
            f0 = memo[0][1] if memo and np.array_equal(memo[0][0], q) else fun(q, mk)
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
    jac = np.asarray(result.jac)
    try:
        bread = np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        return None
    # cluster-robust (sandwich) covariance: the residuals of neighbouring pixels are not
    # independent (compression blocks, the smear model's own error along a tag's edges), so
    # they are summed per block of CLUSTER_BITS x CLUSTER_BITS tag bits before squaring
    cell = max(1.0, CLUSTER_BITS * side / pattern.bits)
    px_, py_ = gx.ravel()[mask], gy.ravel()[mask]
    block = (px_ // cell).astype(np.int64) * 100003 + (py_ // cell).astype(np.int64)
    _, group = np.unique(block, return_inverse=True)
    scores = np.zeros((int(group.max()) + 1, k))
    np.add.at(scores, group, jac * res[:, None])
    n_groups = len(scores)
    meat = scores.T @ scores * (n_groups / max(1, n_groups - 1))
    cov = bread @ meat @ bread
    return SmearFit(
        params=p,
        cov=cov,
        cov_iid=s2 * bread,
        corners=np.asarray(corners_of(p), float),
        rms=math.sqrt(s2) / max(abs(a), 1e-9),
        contrast=abs(a),
        pixels=len(res),
    )


def _blurred(pattern: TagPattern, sigma: float) -> np.ndarray:
    """The pattern blurred by a Gaussian of ``sigma`` [pattern px], kept per (pattern, sigma)."""
    key = round(sigma, 1)
    if key not in pattern.blurred:
        if len(pattern.blurred) > 16:
            pattern.blurred.clear()
        pattern.blurred[key] = (
            cv2.GaussianBlur(pattern.image, (0, 0), key) if key > 0 else pattern.image
        )
    return pattern.blurred[key]
