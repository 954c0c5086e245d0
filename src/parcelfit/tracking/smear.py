"""The model fit of a parcel tag where detection missed or smeared it, and the camera's timing.

While a video is read, every parcel tag's frames in which it was missed, or detected but
smeared by more than ``fit_smear_cells`` of its bits, are cut out (`cut_around_tag`, `Crop`) and
fitted with the tag's pattern smeared as the camera saw it (`SmearFitter`, over
`parcelfit.tracking.fit.fit_smeared_tag`); the parcel's motion comes from the neighbouring
detections and fits. Without a timing in the tag map, the exposure and rolling-shutter readout
[s] are the ones whose fits leave the smallest residual (`estimate_timing`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from parcelfit.tracking.detect import _side
from parcelfit.tracking.fit import SmearFit, fit_smeared_tag, tag_pattern
from parcelfit.tracking.geometry import PlaneMapper, parcel_pose
from parcelfit.tracking.tagmap import TagMap, tag_corners


@dataclass(frozen=True)
class Crop:
    """A cut of one frame around a parcel tag, kept for the model fit (`SmearFitter`)."""

    patch: np.ndarray  # grey, shrunk by ``shrink``
    origin: tuple[int, int]  # full-frame px of the cut's top-left
    shrink: int
    mapper: PlaneMapper  # the frame's geometry


_FIT_SIDE_PX = 24  # cuts are shrunk so that the tag spans at most about twice this many pixels


def cut_around_tag(
    grey: np.ndarray,
    found: np.ndarray | None,
    last: list[tuple[int, np.ndarray]],
    k: int,
    max_gap: int,
) -> tuple[np.ndarray, tuple[int, int], int] | None:
    """A cut of frame ``k`` around the tag: around its detected corners ``found``, or, when it
    was missed, around where its last two detections ``last`` (frame, corners) move it (for up
    to 2 * ``max_gap`` frames after the last one). Returns (patch, origin (x, y), shrink)."""
    if found is not None:
        corners, grow = found, 0.0
    elif last and k - last[-1][0] <= 2 * max_gap:
        k1, c1 = last[-1]
        step = (
            (c1.mean(axis=0) - last[0][1].mean(axis=0)) / (k1 - last[0][0]) if len(last) > 1 else 0
        )
        corners, grow = c1 + step * (k - k1), 0.25 * (k - k1)
    else:
        return None
    side = _side(corners)
    d = max(1, math.floor(side / _FIT_SIDE_PX))
    margin = side * (0.75 + grow)
    h, w = grey.shape
    x0 = max(0, int(corners[:, 0].min() - margin))
    y0 = max(0, int(corners[:, 1].min() - margin))
    x0, y0 = x0 - x0 % d, y0 - y0 % d
    x1 = min(w, math.ceil(corners[:, 0].max() + margin))
    y1 = min(h, math.ceil(corners[:, 1].max() + margin))
    x1, y1 = x0 + (x1 - x0) // d * d, y0 + (y1 - y0) // d * d
    if x1 - x0 < 8 * d or y1 - y0 < 8 * d:
        return None
    patch = grey[y0:y1, x0:x1]
    if d > 1:
        patch = cv2.resize(patch, ((x1 - x0) // d, (y1 - y0) // d), interpolation=cv2.INTER_AREA)
    return patch.copy(), (x0, y0), d


@dataclass(frozen=True)
class FitPose:
    """One kept fit of a parcel tag: the tag's ``pose`` (x, y [m], heading [rad]) at the frame
    time, the fit's own standard deviations of its centre (per coordinate) [m] and heading
    [rad] (`SmearFit.cov`, cluster-robust), its image ``corners`` (4, 2) [px], the parcel
    centre's ``rates`` (vx, vy [m/s], turn rate [rad/s]) the fit's motion model assumed, and
    ``lag``: its centre row's rolling-shutter delay as a fraction of the readout (-0.5 to 0.5),
    the time at which the fit sees the tag, extrapolated to the frame time with ``rates``."""

    pose: np.ndarray
    sd_position: float
    sd_heading: float
    corners: np.ndarray
    rates: np.ndarray
    lag: float


def timing_uncertainty(
    exposure: float, readout: float, fps: float, estimated: bool
) -> tuple[float, float]:
    """The sds [s] of the exposure and readout used: stated in the tag map, a camera's figure
    (`TIMING_GIVEN_SD`: 2 % plus 0.1 ms); estimated (`estimate_timing`), half its last grid
    steps (T / 64 and T / 32 for the frame interval T)."""
    if estimated:
        return 1 / fps / 64, 1 / fps / 32
    rel, add = TIMING_GIVEN_SD
    return math.hypot(rel * exposure, add), math.hypot(rel * readout, add)


TIMING_GIVEN_SD = (0.02, 1e-4)


_TIMING_FRAMES = 8  # the most smeared detected frames the timing is estimated on
_TIMING_FAILED_RMS = 0.5  # the residual counted for a frame whose fit fails [contrast]


def estimate_timing(fitters: list[SmearFitter], fps: float) -> dict[str, Any]:
    """The camera's exposure and rolling-shutter readout [s], when the tag map does not state
    them, from the parcel tags' most smeared detected frames (up to `_TIMING_FRAMES`, by
    `SmearFitter.smear_rate`): the timing whose model fit leaves the smallest mean residual
    (`fit.py`; a wrong exposure smears, a wrong readout shears the modelled tag differently
    from the filmed one). Searched between 0 and one frame interval T: exposure on a grid of
    T / 8 steps (readout 0), then the readout on T / 4 steps, then each refined twice by half
    the step (the better of the two neighbours) and once more to the vertex of the parabola
    through the best point and its neighbours (inside the interval only). Returns a dict: ``exposure``, ``readout``
    [s], ``frames`` used, ``residual_rms`` (mean, best timing), ``source`` ("estimated"), or
    ``source`` "assumed none" when no frame smears by ``fit_smear_cells`` bits even at an
    exposure of a whole frame interval (then the timing cannot matter, nor be measured)."""
    frame = 1 / fps
    ranked = sorted(
        (
            (fitter.smear_rate(k), i, k)
            for i, fitter in enumerate(fitters)
            for k in fitter.crops
            if k in fitter.detections
        ),
        reverse=True,
    )
    chosen = []
    for rate, i, k in ranked[:_TIMING_FRAMES]:
        fitter = fitters[i]
        if rate * frame >= fitter.smear_cells:
            chosen.append((fitter, k))
    if not chosen:
        return {
            "exposure": 0.0,
            "readout": 0.0,
            "source": "assumed none",
            "reason": "no parcel tag moved fast enough to smear by "
            f"{fitters[0].smear_cells:g} bit even over a whole frame interval, so "
            "the timing cannot matter (nor be measured)",
        }
    memo: dict[tuple[float, float], float] = {}

    def cost(exposure: float, readout: float) -> float:
        key = (round(exposure, 7), round(readout, 7))
        if key not in memo:
            rms = []
            for fitter, k in chosen:
                tried = fitter.attempt(k, fitter.crops[k], key[0], key[1], always=True)
                fit = None if tried is None else tried[0]
                rms.append(_TIMING_FAILED_RMS if fit is None else min(fit.rms, _TIMING_FAILED_RMS))
            memo[key] = float(np.mean(rms))
        return memo[key]

    def best_on(grid: np.ndarray, other: float, exposure_axis: bool) -> float:
        pairs = [(v, other) if exposure_axis else (other, v) for v in grid]
        return float(grid[int(np.argmin([cost(*p) for p in pairs]))])

    def refine(value: float, step: float, other: float, exposure_axis: bool) -> float:
        for h in (step / 2, step / 4):
            grid = np.clip(np.array([value - h, value, value + h]), 0.0, frame)
            value = best_on(grid, other, exposure_axis)
        if value - h > 0 and value + h < frame:
            # the vertex of the parabola through the best point and its two neighbours
            pairs = [
                (v, other) if exposure_axis else (other, v) for v in (value - h, value, value + h)
            ]
            c = [cost(*pair) for pair in pairs]
            curv = c[0] - 2 * c[1] + c[2]
            if curv > 0:
                value += float(np.clip(h * (c[0] - c[2]) / (2 * curv), -h, h))
        return value

    exposure = best_on(np.linspace(0, frame, 9), 0.0, True)
    readout = best_on(np.linspace(0, frame, 5), exposure, False)
    exposure = refine(exposure, frame / 8, readout, True)
    readout = refine(readout, frame / 4, exposure, False)
    return {
        "exposure": exposure,
        "readout": readout,
        "frames": len(chosen),
        "residual_rms": cost(exposure, readout),
        "source": "estimated",
    }


class SmearFitter:
    """The model fit (`fit_smeared_tag`) of one parcel tag in the frames it was missed and in
    the frames it was detected but smeared by more than ``smear_cells`` bits, in frame
    order, run while the video is read (`run`, a few frames behind the detection, so that the
    fits use the main thread while the decoding thread reads on). The parcel's pose (centre x,
    y [m], heading [rad]) and motion at frame k come from a quadratic in time through its
    detections and fits within 4 frames (constant acceleration and turn-rate change), the
    tag's from the parcel's through its offset; a detected frame starts from its detection, a
    missed one from the prediction. A fit is kept when its residual is below
    ``max_rms``, it stays within half a tag and 15 degrees of its start, and its
    standard deviations are below 1 mm and 1 degree. ``fits``: per fitted frame, the tag's
    pose, the sds of its centre [m] and heading [rad], and its image corners [px];
    ``unsupported``: detected frames whose smear called for a fit that was not kept."""

    reach = 4  # frames either side in the motion model

    def __init__(
        self,
        tag_map: TagMap,
        tag_id: int,
        detections: dict[int, tuple[np.ndarray, np.ndarray]],
        dt: float,
        height: int,
        smear_cells: float,
        max_rms: float,
    ) -> None:
        self.tag = tag_map.parcel_tags[tag_id]
        self.pattern = tag_pattern(tag_map.family, tag_id)
        self.exposure, self.readout = tag_map.exposure, tag_map.readout
        self.detections = detections  # frame -> (rig corners, image rows), filled while reading
        self.dt, self.height = dt, height
        # fits: detected frames smeared above this [tag bits]; kept below this residual rms
        # [contrast] (`TrackOptions.fit_smear_cells`, `fit_max_rms`)
        self.smear_cells, self.max_rms = smear_cells, max_rms
        self.crops: dict[int, Crop] = {}
        self.fits: dict[int, FitPose] = {}
        self.unsupported: set[int] = set()
        self.tried, self.seconds = 0, 0.0
        self.residuals: list[float] = []  # kept fits' residual rms [fraction of the contrast]
        self._known: dict[int, np.ndarray] = {}  # frame -> the parcel's pose

    def _pose(self, k: int) -> np.ndarray | None:
        if k not in self._known and k in self.detections:
            # the motion model runs on the parcel centre (a near-straight path) and heading,
            # not on the tag centre, which circles the parcel centre when the parcel spins
            self._known[k] = np.array(parcel_pose(self.detections[k][0], self.tag.offset))
        return self._known.get(k)

    def run(self, until: int) -> None:
        """Fit the kept cuts of frames up to ``until`` (then dropped)."""
        for k in sorted(c for c in self.crops if c <= until):
            crop = self.crops.pop(k)
            t0 = time.perf_counter()
            self.tried += 1
            self._fit(k, crop)
            self.seconds += time.perf_counter() - t0

    def _motion(self, k: int) -> tuple[float, float, float, np.ndarray] | None:
        """The parcel's pose (x, y [m], heading [rad]) at frame k from the quadratic through its
        measured frames within `reach`, and the tag centre's velocity [m/s] and turn rate
        [rad/s]; None under two measured frames near k."""
        near_poses = [(j, self._pose(j)) for j in range(k - self.reach, k + self.reach + 1)]
        near = [(j, p) for j, p in near_poses if p is not None]
        if len(near) < 2:
            return None
        # each pose at its own time from frame k's: a fit's at its frame time, a detection's
        # its centre row's rolling-shutter delay later
        tk = np.array([(j - k) * self.dt + self._lag(j) for j, _ in near])
        poses = np.array([p for _, p in near])
        poses[:, 2] = np.unwrap(poses[:, 2])
        deg = 2 if len(near) >= 3 and np.ptp(tk) > 2 * self.dt else 1
        coef = [np.polyfit(tk, poses[:, j], deg) for j in range(3)]
        px_, py_, th = (float(c[-1]) for c in coef)
        vx, vy, w = (float(c[-2]) for c in coef)
        ox, oy = self._offset(th)
        return px_, py_, th, np.array([vx - w * oy, vy + w * ox, w])

    def _lag(self, k: int) -> float:
        """The time [s] after frame k's time at which its pose was seen: a detection's centre
        row's rolling-shutter delay, 0 for a fit (at the frame time) or an unseen frame."""
        if k in self.fits or k not in self.detections or not self.readout:
            return 0.0
        rows = self.detections[k][1]
        return (float(np.mean(rows)) / self.height - 0.5) * self.readout

    def _offset(self, th: float) -> tuple[float, float]:
        """The tag's offset from the parcel centre in the rig frame at heading ``th``."""
        dx, dy = self.tag.offset
        c_, s_ = math.cos(th), math.sin(th)
        return c_ * dx - s_ * dy, s_ * dx + c_ * dy

    def smear_rate(self, k: int) -> float:
        """How fast the tag smears at frame k: tag bits per second of exposure (its centre's
        speed plus its corners' turn); 0 when its motion is unknown."""
        motion = self._motion(k)
        if motion is None:
            return 0.0
        rates = motion[3]
        speed = math.hypot(*rates[:2]) + abs(rates[2]) * self.tag.size / math.sqrt(2)
        return speed / (self.tag.size / self.pattern.bits)

    def attempt(
        self, k: int, crop: Crop, exposure: float, readout: float, always: bool = False
    ) -> tuple[SmearFit | None, np.ndarray, bool] | None:
        """The fit of frame k with the given timing [s]: (fit or None, its start, whether k was
        detected); None when not tried (no motion known; a detected frame smeared under
        ``smear_cells`` bits, unless ``always``)."""
        tag = self.tag
        motion = self._motion(k)
        if motion is None:
            return None
        px_, py_, th, rates = motion
        ox, oy = self._offset(th)
        detected = k in self.detections
        if detected:
            start = np.array(parcel_pose(self.detections[k][0], (0.0, 0.0)))
            start[2] = th + math.remainder(start[2] - th, 2 * math.pi)
            smear = (math.hypot(*rates[:2]) + abs(rates[2]) * tag.size / math.sqrt(2)) * exposure
            if not always and smear < self.smear_cells * tag.size / self.pattern.bits:
                return None
        else:
            start = np.array([px_ + ox, py_ + oy, th])
        mapper = crop.mapper

        def corners_of(p: np.ndarray, m: PlaneMapper = mapper) -> np.ndarray:
            return m.to_image(tag_corners(p[0], p[1], tag.size, p[2]), tag.height)

        side_px = _side(corners_of(start))
        step_m = 0.1 * tag.size / side_px
        steps = np.array([step_m, step_m, 0.1 / (side_px / math.sqrt(2))])
        fit = fit_smeared_tag(
            crop.patch,
            crop.origin,
            crop.shrink,
            corners_of,
            start,
            steps,
            rates,
            self.pattern,
            exposure,
            readout,
            self.height,
        )
        return fit, start, detected

    def _fit(self, k: int, crop: Crop) -> None:
        tag = self.tag
        tried = self.attempt(k, crop, self.exposure, self.readout)
        if tried is None:
            return
        fit, start, detected = tried
        dx, dy = tag.offset
        if fit is None or not fit.rms <= self.max_rms:
            self.unsupported.update({k} if detected else set())
            return
        moved = fit.params - start
        sd_pos = math.sqrt(max(fit.cov[0, 0] + fit.cov[1, 1], 0.0) / 2)
        sd_head = math.sqrt(max(fit.cov[2, 2], 0.0))
        if (
            math.hypot(*moved[:2]) > tag.size / 2
            or abs(moved[2]) > math.radians(15)
            or sd_pos > 1e-3
            or sd_head > math.radians(1)
        ):
            self.unsupported.update({k} if detected else set())
            return
        self.residuals.append(fit.rms)
        tx, ty, th = fit.params
        c_, s_ = math.cos(th), math.sin(th)
        motion = self._motion(k)
        rates = np.zeros(3) if motion is None else motion[3].copy()
        ox, oy = self._offset(th)
        rates[:2] -= rates[2] * np.array([-oy, ox])  # the parcel centre's velocity
        self.fits[k] = FitPose(
            pose=fit.params,
            sd_position=sd_pos,
            sd_heading=sd_head,
            corners=fit.corners,
            rates=rates,
            lag=float(np.mean(fit.corners[:, 1])) / self.height - 0.5,
        )
        self._known[k] = np.array([tx - (c_ * dx - s_ * dy), ty - (s_ * dx + c_ * dy), th])
