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
