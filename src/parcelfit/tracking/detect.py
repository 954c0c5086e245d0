"""AprilTag detection with OpenCV's aruco module, fast on large frames.

Detecting on a 5312 x 2988 frame takes 250-350 ms. We detect on a frame shrunk by an integer
factor ``s`` (area averaging), where the tags are still >= ``min_side`` pixels wide, map the
corners back to full resolution,

    p_full = (p_small + 0.5) * s - 0.5          (OpenCV's pixel-centre convention)

and refine each corner at full resolution with ``cv2.cornerSubPix`` (the tag's outer corner, a
black-square-on-white-border corner, is exactly the saddle that function finds). After the
first frame, detection runs in windows around the tags seen in the last ``memory`` frames (grown
by ``search_margin`` tag sides, more the longer a tag has been missing), and over the whole frame
when an expected (reference) tag is missing and every ``rescan`` frames, for tags entering.
OpenCV's own AprilTag refinement (``CORNER_REFINE_APRILTAG``) is accurate but ~7 s a frame at this
size, which is why the refinement here is done by hand.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from parcelfit.errors import ParcelfitError

DICTIONARIES = {
    "tag36h11": cv2.aruco.DICT_APRILTAG_36h11,
    "tag25h9": cv2.aruco.DICT_APRILTAG_25h9,
    "tag16h5": cv2.aruco.DICT_APRILTAG_16h5,
    "tag36h10": cv2.aruco.DICT_APRILTAG_36h10,
}


def dictionary(family: str) -> cv2.aruco.Dictionary:
    """OpenCV's predefined dictionary of an AprilTag family."""
    if family not in DICTIONARIES:
        raise ParcelfitError(
            f"unknown tag family {family!r}", fix=f"use one of {', '.join(DICTIONARIES)}"
        )
    return cv2.aruco.getPredefinedDictionary(DICTIONARIES[family])


def _side(corners: np.ndarray) -> float:
    return float(np.mean(np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)))


class TagDetector:
    """Detect tags of one family in grey frames; corners (4, 2) [px] by tag id."""

    def __init__(
        self,
        family: str = "tag36h11",
        *,
        downscale: int = 0,
        min_side: float = 28.0,
        search_margin: float = 1.5,
        refine: bool = True,
        rescan: int = 10,
        memory: int = 30,
    ) -> None:
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
        self._detector = cv2.aruco.ArucoDetector(dictionary(family), params)
        self.downscale = downscale  # 0: chosen from the first frame's tag sizes
        self.min_side = min_side
        self.search_margin = search_margin
        self.refine = refine
        self.rescan = rescan
        self.memory = memory
        self._memory: dict[int, tuple[np.ndarray, int]] = {}  # id -> (corners, frames since seen)
        self._frame = -1
        self.full_frame_searches = 0

    def _detect(self, gray: np.ndarray, s: int) -> dict[int, np.ndarray]:
        # INTER_LINEAR: ~40x faster than INTER_AREA on a full 5312 x 2988 frame; the shrunk
        # frame only has to find the tags, their corners are refined at full resolution
        small = (
            gray
            if s == 1
            else cv2.resize(
                gray, (gray.shape[1] // s, gray.shape[0] // s), interpolation=cv2.INTER_LINEAR
            )
        )
        corners, ids, _ = self._detector.detectMarkers(small)
        out: dict[int, np.ndarray] = {}
        if ids is None:
            return out
        for c, i in zip(corners, ids.ravel(), strict=True):
            out[int(i)] = (c.reshape(4, 2).astype(np.float64) + 0.5) * s - 0.5
        return out

    def _subpix(self, gray: np.ndarray, corners: np.ndarray) -> np.ndarray:
        criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
        win = int(max(2, min(12, _side(corners) / 10)))
        pts = corners.astype(np.float32).reshape(-1, 1, 2)
        cv2.cornerSubPix(gray, pts, (win, win), (-1, -1), criteria)
        return pts.reshape(4, 2).astype(np.float64)

    def _refine(
        self, gray: np.ndarray, todo: dict[int, np.ndarray], found: dict[int, np.ndarray]
    ) -> None:
        for tag_id, c in todo.items():
            found[tag_id] = self._subpix(gray, c)

    def _scale(self, found: dict[int, np.ndarray]) -> int:
        if not found:
            return 1
        smallest = min(_side(c) for c in found.values())
        return max(1, min(8, math.floor(smallest / self.min_side)))

    def detect(self, gray: np.ndarray, expected: set[int] | None = None) -> dict[int, np.ndarray]:
        """Corners by tag id in a grey frame (uint8).

        ``expected`` tags (the reference tags, which should not move) seen last frame are
        refined in place; windows around the other tags seen in the last ``memory`` frames are
        searched (grown with the frames since it was seen); the whole frame is searched on the
        first frame, when an expected tag is missing, and every ``rescan`` frames (tags entering
        the view)."""
        if gray.ndim != 2:
            raise ParcelfitError("the detector needs a single-channel (grey) frame")
        self._frame += 1
        s = self.downscale or 1
        found: dict[int, np.ndarray] = {}
        h, w = gray.shape
        rescan_now = self._frame % self.rescan == 0
        refined_ids: set[int] = set()
        if self.refine and expected and not rescan_now:
            # tags that should not move (the reference tags) and were seen last frame: refine
            # their last corners in place (cornerSubPix, ~15 us) instead of detecting them again
            for tag_id in expected:
                last = self._memory.get(tag_id)
                if last is None or last[1] != 0:
                    continue
                refined = self._subpix(gray, last[0])
                shift = refined - last[0]
                # a camera that shakes moves the four corners together; a corner that slid to
                # another saddle (a data bit) moves on its own: then detect the tag again
                spread = float(np.max(np.linalg.norm(shift - shift.mean(axis=0), axis=1)))
                win = max(2.0, min(12.0, _side(last[0]) / 10))
                if spread < 0.3 and float(np.max(np.linalg.norm(shift, axis=1))) < 0.5 * win:
                    found[tag_id] = refined
                    refined_ids.add(tag_id)
        for tag_id, (corners, age) in self._memory.items():
            if tag_id in found:
                continue
            side = _side(corners)
            grow = self.search_margin * side * (1 + 0.5 * age)
            lo = np.floor(corners.min(axis=0) - grow).astype(int)
            hi = np.ceil(corners.max(axis=0) + grow).astype(int)
            x0, y0 = max(0, lo[0]), max(0, lo[1])
            x1, y1 = min(w, hi[0]), min(h, hi[1])
            x0, y0 = x0 - x0 % s, y0 - y0 % s  # keep the shrunk pixel grid aligned
            if x1 - x0 < 8 * s or y1 - y0 < 8 * s:
                continue
            for hit, c in self._detect(gray[y0:y1, x0:x1], s).items():
                found.setdefault(hit, c + np.array([x0, y0]))
        missing = expected is not None and not expected <= set(found)
        if not self._memory or missing or rescan_now:
            self.full_frame_searches += 1
            if not self.downscale:
                whole = self._detect(gray, 1)
                self.downscale = self._scale(whole) if whole else 0
            else:
                whole = self._detect(gray, s)
            for tag_id, c in whole.items():
                found.setdefault(tag_id, c)
        if self.refine:
            self._refine(gray, {i: c for i, c in found.items() if i not in refined_ids}, found)
        aged = {i: (c, a + 1) for i, (c, a) in self._memory.items() if a + 1 < self.memory}
        aged.update({i: (c, 0) for i, c in found.items()})
        self._memory = aged
        return found

    def reset(self) -> None:
        """Forget the last positions (a new video)."""
        self._memory = {}
        self._frame = -1
