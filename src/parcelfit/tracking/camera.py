"""Camera intrinsics and lens distortion from a checkerboard video (OpenCV's calibration).

Frames are sampled evenly (at most ``max_frames``); in each, the board's inner corners are found
(``cv2.findChessboardCornersSB``, on a frame shrunk to at most ~1600 px wide for speed, corners
refined at full size with ``cv2.cornerSubPix``); ``cv2.calibrateCamera`` fits the pinhole model
(fx, fy, cx, cy) and the distortion (k1, k2, p1, p2, k3) to all views. The RMS reprojection
error [px] says how well: well under 1 px is a good calibration.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.tracking.tagmap import Camera
from parcelfit.tracking.video import open_video


@dataclass(frozen=True)
class CameraCalibration:
    """The fitted camera, its RMS reprojection error [px] and the number of views used."""

    camera: Camera
    rms: float
    views: int


def calibrate_camera(
    video: str | Path,
    board: tuple[int, int],
    square: float,
    *,
    max_frames: int = 40,
    progress: Callable[[int, int], None] | None = None,
) -> CameraCalibration:
    """Fit intrinsics and distortion from a video of a checkerboard with ``board`` = (columns,
    rows) inner corners and squares of ``square`` metres."""
    cols, rows = board
    if cols < 3 or rows < 3:
        raise ParcelfitError(
            f"a board of {cols}x{rows} inner corners is too small", fix="use e.g. 9x6"
        )
    cap = open_video(video)
    total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) or max_frames
    step = max(1, total // max_frames)
    objp = np.zeros((cols * rows, 3), np.float32)
    objp[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square
    obj_pts, img_pts = [], []
    size = None
    k = 0
    try:
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            if k % step == 0:
                grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
                size = grey.shape[::-1]
                scale = max(1, int(np.ceil(grey.shape[1] / 1600)))
                small = cv2.resize(
                    grey,
                    (grey.shape[1] // scale, grey.shape[0] // scale),
                    interpolation=cv2.INTER_AREA,
                )
                found, corners = cv2.findChessboardCornersSB(small, (cols, rows))
                if found:
                    corners = (
                        ((corners.reshape(-1, 2) + 0.5) * scale - 0.5)
                        .astype(np.float32)
                        .reshape(-1, 1, 2)
                    )
                    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 0.001)
                    cv2.cornerSubPix(grey, corners, (5, 5), (-1, -1), criteria)
                    obj_pts.append(objp)
                    img_pts.append(corners)
            k += 1
            if progress:
                progress(k, total)
    finally:
        cap.release()
    if len(obj_pts) < 5 or size is None:
        raise ParcelfitError(
            f"the board was found in only {len(obj_pts)} frames (at least 5 needed)",
            file=video,
            fix=f"check --board {cols}x{rows} (inner corners, not squares) and that the board is in view",
        )
    rms, matrix, dist, _, _ = cv2.calibrateCamera(obj_pts, img_pts, size, None, None)
    d = dist.ravel()[:5]
    camera = Camera(
        float(matrix[0, 0]),
        float(matrix[1, 1]),
        float(matrix[0, 2]),
        float(matrix[1, 2]),
        tuple(float(v) for v in d),
        int(size[0]),
        int(size[1]),
    )
    return CameraCalibration(camera, float(rms), len(obj_pts))
