"""From image pixels to the rig frame, with the tag's height above the belt corrected.

With camera intrinsics (K, distortion) the camera pose (R, t) is fitted to all reference-tag
corners (world points on z = 0) by ``cv2.solvePnP``. A pixel p of a tag at height h is
undistorted to the normalised ray r = (u, v, 1) in the camera frame, turned into the rig frame,
d = R^T r, from the camera centre C = -R^T t, and intersected with the plane z = h:

    P = C + s d,   s = (h - C_z) / d_z

which removes the parallax exactly (a tag 2 cm up, 1 m off-axis, under a camera 2 m high
appears ~10 mm off on the belt plane).

Without intrinsics, a homography H (``cv2.findHomography``, least squares over all reference
corners) maps pixels to the belt plane z = 0. It cannot know where the camera is, so a tag above
the plane keeps its parallax; the quality report says so.

Reprojection error: the pixel distance between the detected reference corners and their known
world positions projected back into the image (mean and maximum), the measure of how well the
frame's geometry is known.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.tracking.tagmap import Camera, TagMap


@dataclass
class PlaneMapper:
    """Maps pixels of a frame to rig coordinates [m] at a given height above the belt."""

    camera: Camera | None
    rvec: np.ndarray | None = None
    tvec: np.ndarray | None = None
    homography: np.ndarray | None = None
    reprojection_mean: float = float("nan")  # px
    reprojection_max: float = float("nan")  # px

    @property
    def corrects_parallax(self) -> bool:
        """Whether a tag's height is taken into account (needs camera intrinsics)."""
        return self.camera is not None

    def to_rig(self, pixels: np.ndarray, height: float = 0.0) -> np.ndarray:
        """Rig coordinates (n, 2) [m] of pixels (n, 2) on the plane z = ``height`` [m]."""
        pts = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        if self.camera is None:
            assert self.homography is not None
            return cv2.perspectiveTransform(pts, self.homography).reshape(-1, 2)
        assert self.rvec is not None and self.tvec is not None
        norm = cv2.undistortPoints(pts, self.camera.matrix, self.camera.dist).reshape(-1, 2)
        rays = np.column_stack([norm, np.ones(len(norm))])
        rot, _ = cv2.Rodrigues(self.rvec)
        centre = -rot.T @ self.tvec.reshape(3)
        d = rays @ rot  # = (R^T r)^T for every ray
        s = (height - centre[2]) / d[:, 2]
        return (centre + s[:, None] * d)[:, :2]

    def to_image(self, points: np.ndarray, height: float = 0.0) -> np.ndarray:
        """Pixels (n, 2) of rig points (n, 2) [m] at height ``height`` [m]."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if self.camera is None:
            assert self.homography is not None
            inv = np.linalg.inv(self.homography)
            return cv2.perspectiveTransform(pts.reshape(-1, 1, 2), inv).reshape(-1, 2)
        obj = np.column_stack([pts, np.full(len(pts), height)])
        img, _ = cv2.projectPoints(obj, self.rvec, self.tvec, self.camera.matrix, self.camera.dist)
        return img.reshape(-1, 2)


def fit_plane_mapper(
    tag_map: TagMap, detections: Mapping[int, np.ndarray], previous: PlaneMapper | None = None
) -> PlaneMapper | None:
    """Fit the frame's geometry to the reference tags seen (None if too few: under 4 corners
    without a camera model, or no tag at all)."""
    refs = [i for i in detections if i in tag_map.reference_tags]
    if not refs:
        return None
    world = np.concatenate([tag_map.reference_tags[i].corners() for i in refs])
    image = np.concatenate([detections[i] for i in refs])
    if tag_map.camera is None:
        if len(world) < 4:
            return None
        h, _ = cv2.findHomography(image, world, 0)
        if h is None:
            return None
        mapper = PlaneMapper(None, homography=h)
    else:
        cam = tag_map.camera
        obj = np.column_stack([world, np.zeros(len(world))])
        guess = previous is not None and previous.rvec is not None
        ok, rvec, tvec = cv2.solvePnP(
            obj,
            image,
            cam.matrix,
            cam.dist,
            rvec=None if not guess else previous.rvec.copy(),  # type: ignore[union-attr]
            tvec=None if not guess else previous.tvec.copy(),  # type: ignore[union-attr]
            useExtrinsicGuess=guess,
            flags=cv2.SOLVEPNP_ITERATIVE,
        )
        if not ok:
            return None
        mapper = PlaneMapper(cam, rvec=rvec, tvec=tvec)
    err = np.linalg.norm(mapper.to_image(world) - image, axis=1)
    mapper.reprojection_mean = float(err.mean())
    mapper.reprojection_max = float(err.max())
    return mapper


def tag_pose(mapper: PlaneMapper, corners: np.ndarray, height: float) -> tuple[float, float, float]:
    """Centre (x, y) [m] and heading [rad] of a tag from its image corners, at ``height`` [m].

    The centre is the mean of the four back-projected corners (exact: they are points of a
    square); the heading is the direction of the summed top and bottom edges (c0->c1 + c3->c2).
    """
    if corners.shape != (4, 2):
        raise ParcelfitError(f"expected 4 corners, got shape {corners.shape}")
    w = mapper.to_rig(corners, height)
    centre = w.mean(axis=0)
    edge = (w[1] - w[0]) + (w[2] - w[3])
    return float(centre[0]), float(centre[1]), float(np.arctan2(edge[1], edge[0]))


def parcel_pose(w: np.ndarray, offset: tuple[float, float]) -> tuple[float, float, float]:
    """Parcel centre (x, y) [m] and heading [rad] from a tag's four rig-frame corners ``w`` (4, 2)
    [m]: the heading as `tag_pose` takes it, the centre ``offset`` [m] (in the tag's frame) back
    from the tag's centre."""
    centre = w.mean(axis=0)
    edge = (w[1] - w[0]) + (w[2] - w[3])
    th = float(np.arctan2(edge[1], edge[0]))
    c, s = math.cos(th), math.sin(th)
    dx, dy = offset
    return float(centre[0] - (c * dx - s * dy)), float(centre[1] - (s * dx + c * dy)), th


def rolling_shutter_poses(
    corners: dict[int, tuple[np.ndarray, np.ndarray]],
    t: np.ndarray,
    readout: float,
    height: int,
    offset: tuple[float, float],
    iterations: int = 2,
) -> np.ndarray:
    """Parcel poses (n, 3) [m, m, rad] at the frame times ``t`` [s] from tag corners seen by a
    rolling shutter (NaN where unseen). ``corners[k]`` holds frame k's rig-frame corners (4, 2)
    [m] and their image rows [px]. A corner in row r was exposed at

        t_i = t_k + (r / height - 0.5) * readout,

    so it is moved back to t_k with the tag's rigid motion, p_i <- p_i - (v + w x (p_i - c)) dt_i,
    v the tag centre's velocity [m/s] and w its turn rate [rad/s], estimated by central
    differences over the detected frames from the previous iteration's poses."""
    n = len(t)
    out = np.full((n, 3), np.nan)
    dts = {k: (rows / height - 0.5) * readout for k, (_, rows) in corners.items()}
    pts = {k: w.copy() for k, (w, _) in corners.items()}
    keys = sorted(corners)
    for _ in range(iterations + 1):
        centre = np.full((n, 2), np.nan)
        head = np.full(n, np.nan)
        for k in keys:
            w = pts[k]
            centre[k] = w.mean(axis=0)
            edge = (w[1] - w[0]) + (w[2] - w[3])
            head[k] = math.atan2(edge[1], edge[0])
            out[k] = parcel_pose(w, offset)
        if len(keys) < 2:
            break
        ks = np.array(keys)
        head_u = np.unwrap(head[ks])
        vel = np.column_stack([np.gradient(centre[ks, j], t[ks]) for j in (0, 1)])
        turn = np.gradient(head_u, t[ks])
        for i, k in enumerate(keys):
            w0, dt = corners[k][0], dts[k]
            c = w0.mean(axis=0)
            rel = w0 - c
            moved = vel[i] + turn[i] * np.column_stack([-rel[:, 1], rel[:, 0]])
            pts[k] = w0 - moved * dt[:, None]
    return out
