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


# the smallest image side [px] searched for tags: a 36h11 tag with its black border is 8 bits
# wide, so at under one pixel a bit nothing can be decoded
_MIN_SEARCH_PX = 8


def dictionary(family: str) -> cv2.aruco.Dictionary:
    """OpenCV's predefined dictionary of an AprilTag family."""
    if family not in DICTIONARIES:
        raise ParcelfitError(
            f"unknown tag family {family!r}", fix=f"use one of {', '.join(DICTIONARIES)}"
        )
    return cv2.aruco.getPredefinedDictionary(DICTIONARIES[family])


def _side(corners: np.ndarray) -> float:
    return float(np.mean(np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)))


def refine_by_edges(gray: np.ndarray, corners: np.ndarray, samples: int = 16) -> np.ndarray | None:
    """Corners (4, 2) [px] as intersections of lines fitted to the tag's four outer edges.

    Motion blur during the exposure turns each edge perpendicular to the motion into a ramp
    whose 50 % level lies where the edge was at mid-exposure, while the corners themselves are
    rounded off and pulled along the motion (opposite corners in opposite directions, a heading
    error). So along the middle 60 % of every edge, ``samples`` grey profiles are read along the
    edge normal (bilinear, ``cv2.remap``), each profile's crossing of the level halfway between
    its darkest inner and brightest outer value is found, a line is fitted through the crossings
    (``cv2.fitLine``, Huber) and adjacent lines are intersected. Written by hand: OpenCV has no
    sub-pixel line fit for blurred edges. Returns None when an edge gives too few crossings."""
    c = corners.astype(np.float64)
    side = _side(c)
    half = max(3.0, side / 8 * 1.2)  # profile reaches ~1.2 cells either side of the edge
    centre = c.mean(axis=0)
    offs = np.linspace(-half, half, int(2 * half) * 2 + 1)
    lines = []
    for i in range(4):
        p, q = c[i], c[(i + 1) % 4]
        d = (q - p) / np.linalg.norm(q - p)
        n = np.array([d[1], -d[0]])
        if np.dot((p + q) / 2 - centre, n) < 0:
            n = -n  # outward
        u = np.linspace(0.2, 0.8, samples)
        base = p + np.outer(u, q - p)  # (samples, 2)
        pts = base[:, None, :] + offs[None, :, None] * n  # (samples, len(offs), 2)
        prof = cv2.remap(
            gray,
            pts[..., 0].astype(np.float32),
            pts[..., 1].astype(np.float32),
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        ).astype(np.float64)
        inner = prof[:, : len(offs) // 2 + 1].min(axis=1)
        outer = prof[:, len(offs) // 2 :].max(axis=1)
        level = (inner + outer) / 2
        hits = []
        for j in range(samples):
            if outer[j] - inner[j] < 20:
                continue
            above = prof[j] >= level[j]
            # the crossing nearest the predicted edge (offset 0)
            idx = np.flatnonzero(~above[:-1] & above[1:])
            if not len(idx):
                continue
            k = idx[np.argmin(np.abs(offs[idx]))]
            f = (level[j] - prof[j, k]) / (prof[j, k + 1] - prof[j, k])
            o = offs[k] + f * (offs[k + 1] - offs[k])
            hits.append(base[j] + o * n)
        if len(hits) < samples // 2:
            return None
        vx, vy, x0, y0 = cv2.fitLine(
            np.array(hits, np.float32), cv2.DIST_HUBER, 0, 0.01, 0.01
        ).ravel()
        lines.append((np.array([x0, y0], float), np.array([vx, vy], float)))
    out = np.empty((4, 2))
    for i in range(4):
        (p1, d1), (p2, d2) = lines[i - 1], lines[i]  # corner i joins edge i-1 and edge i
        a = np.column_stack([d1, -d2])
        if abs(np.linalg.det(a)) < 1e-6:
            return None
        t = np.linalg.solve(a, p2 - p1)
        out[i] = p1 + t[0] * d1
    if np.max(np.linalg.norm(out - c, axis=1)) > 0.25 * side:
        return None
    return out


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
        # motion blur smears the tag's black border into its quiet zone and data cells: accept
        # up to 60 % wrong border bits (default 35 %) and correct as many data bits as the
        # family's Hamming distance allows (rate 1.0; a 36h11 tag: 5 bits). On rendered 8 ms
        # exposures at 1.6 m/s this decodes 45 of 45 frames where the defaults decode 3.
        params.maxErroneousBitsInBorderRate = 0.6
        params.errorCorrectionRate = 1.0
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
        self.edge_ids: set[int] = set()  # tags refined by their edges (`refine_by_edges`)

    def _detect(self, gray: np.ndarray, s: int) -> dict[int, np.ndarray]:
        if min(gray.shape[0], gray.shape[1]) // s < _MIN_SEARCH_PX:
            return {}  # no tag fits (and cv2.resize refuses a frame shrunk to 0 px)
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
            edges = refine_by_edges(gray, c) if tag_id in self.edge_ids else None
            found[tag_id] = self._subpix(gray, c) if edges is None else edges

    def _scale(self, found: dict[int, np.ndarray]) -> int:
        if not found:
            return 1
        smallest = min(_side(c) for c in found.values())
        return max(1, min(8, math.floor(smallest / self.min_side)))

    def detect(
        self,
        gray: np.ndarray,
        expected: set[int] | None = None,
        wanted: set[int] | None = None,
    ) -> dict[int, np.ndarray]:
        """Corners by tag id in a grey frame (uint8).

        ``expected`` tags (the reference tags, which should not move) seen last frame are
        refined in place; windows around the other tags seen in the last ``memory`` frames are
        searched (grown with the frames since it was seen); the whole frame is searched on the
        first frame, when an expected tag is missing, when a ``wanted`` tag (a parcel tag) seen
        recently is missing (at once, at the chosen and at twice the shrink factor: a
        motion-blurred tag often decodes only smaller), and every ``rescan`` frames (tags
        entering the view). The first frame is searched at shrink factors 1, 2 and 4 (blurred
        tags that fail at full resolution decode smaller)."""
        if gray.ndim != 2:
            raise ParcelfitError("the detector needs a single-channel (grey) frame")
        if gray.dtype != np.uint8:
            raise ParcelfitError(f"the detector needs an 8-bit frame, got {gray.dtype}")
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
        lost = bool(wanted) and any(
            i in self._memory and self._memory[i][1] < 5 and i not in found
            for i in wanted  # type: ignore[union-attr]
        )
        if not self._memory or missing or rescan_now or lost:
            self.full_frame_searches += 1
            if not self.downscale:
                whole: dict[int, np.ndarray] = {}
                for f in (1, 2, 4):
                    for tag_id, c in self._detect(gray, f).items():
                        whole.setdefault(tag_id, c)
                self.downscale = self._scale(whole) if whole else 0
            else:
                whole = self._detect(gray, s)
                if lost and not set(wanted) <= set(whole):  # type: ignore[arg-type]
                    for tag_id, c in self._detect(gray, 2 * s).items():
                        whole.setdefault(tag_id, c)
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
