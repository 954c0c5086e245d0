"""A video to trajectories: decode, detect, fit the frame's geometry, pose every parcel tag.

Per frame k (time t_k = k / fps [s]): tags are detected (`TagDetector`); when reference tags are
seen the image->rig geometry is fitted again (`fit_plane_mapper`; so a camera that shakes is
followed), else the last one is reused and the frame counted; every parcel tag seen gives the
tag's centre and heading at its height, and the parcel centre is

    (x, y) = tag centre - R(theta) * offset,     theta = tag heading.

With the camera's timing (exposure, rolling-shutter readout; from the tag map, else estimated
from the video by `estimate_timing`), frames in which
a parcel tag was missed, or smeared by more than ``fit_smear_cells`` of its bits, are measured
again by fitting the tag's pattern, smeared as the camera saw it, to the frame
(`parcelfit.tracking.fit`, `parcelfit.tracking.smear`); kept fits are flagged ``fitted`` in the
trajectory's ``source``. Frames where a parcel tag has no measurement between its first and last
one are gaps: gaps of at most ``max_gap`` frames are filled by linear interpolation (theta
unwrapped first), listed as interpolated and flagged ``filled`` (the others ``detected`` or
``fitted``); longer gaps stay missing (their samples are left out) and are listed too. With the
smoother on (each frame weighted by its own measurement sd), the measured frames carry its
posterior standard deviations (``position_sd``, ``heading_sd``; see `smooth_track`); measured
frames it discards as outliers become gaps and are counted (``discarded_by_smoother``), and a
change of motion restarts its motion model (``motion_restarts_s``). The
heading is unwrapped over the run. Decoding runs in a background thread (OpenCV releases the GIL
while decoding), so decoding and detection overlap on two cores.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.runs import Trajectory
from parcelfit.runs.io import MAX_SAMPLE_INTERVAL_S, MIN_SAMPLE_INTERVAL_S
from parcelfit.tracking.barriers import barrier_times
from parcelfit.tracking.detect import TagDetector, _side
from parcelfit.tracking.geometry import PlaneMapper, fit_plane_mapper, parcel_pose, tag_pose
from parcelfit.tracking.smear import Crop, SmearFitter, cut_around_tag, estimate_timing
from parcelfit.tracking.smooth import RESTART_AFTER, rts_smooth
from parcelfit.tracking.tagmap import TagMap, tag_corners


@dataclass(frozen=True)
class TrackOptions:
    """Tracking settings: longest gap filled [frames], detector settings."""

    max_gap: int = 5
    downscale: int = 0  # 0: chosen from the first frame
    min_side: float = 28.0  # px a tag keeps after shrinking
    refine: bool = True
    rescan: int = 10  # whole-frame search every this many frames, for tags entering the view
    smooth: bool = True  # constant-acceleration Kalman/RTS smoother over the track (`smooth.py`)
    edge_refine: bool = True  # parcel tag corners from fitted edge lines (blur-robust)
    max_reprojection_px: float = 5.0  # reference tags' mean reprojection error above: refused
    fit: bool = True  # model-based fit of the smeared tag (`fit.py`) where detection fails or blurs
    fit_smear_cells: float = 0.5  # detected frames fitted too above this smear [tag bits]
    fit_max_rms: float = 0.12  # a fit is kept when its residual rms is below this [contrast]
    estimate_timing: bool = True  # no timing in the tag map: estimated (`estimate_timing`)


@dataclass
class TagTrack:
    """One parcel tag's result: trajectory (parcel centre, SI), transit time, quality numbers."""

    tag_id: int
    trajectory: Trajectory | None
    transit_time: float | None
    crossings: dict[str, float | None]
    quality: dict[str, Any]


@dataclass
class VideoTrack:
    """Everything tracked in one video."""

    video: Path
    fps: float
    frames: int
    size: tuple[int, int]
    tags: dict[int, TagTrack]
    quality: dict[str, Any] = field(default_factory=dict)


# the smallest frame side [px] that can show a tag: OpenCV still decodes a 36h11 tag 8 px wide
# (one pixel a bit), which needs its white border around it; smaller frames are refused before
# any OpenCV call sees them (a 1 x 1 px frame shrunk for the detector has no pixel left)
MIN_FRAME_PX = 16


def open_video(path: str | Path) -> cv2.VideoCapture:
    """Open a video, or raise a clear error naming the file: missing, not a file, not
    decodable (a damaged or empty file), no frame, or frames under `MIN_FRAME_PX` pixels a side."""
    path = Path(path)
    if not path.is_file():
        raise ParcelfitError(
            "video not found" if not path.exists() else "not a video file",
            file=path,
            fix="check the path",
        )
    try:
        cap = cv2.VideoCapture(str(path))
    except cv2.error as exc:  # some backends raise instead of returning a closed capture
        raise ParcelfitError(
            f"cannot decode this video ({exc.__class__.__name__})",
            file=path,
            fix="convert it to H.264/HEVC MP4 with ffmpeg",
        ) from None
    if not cap.isOpened():
        raise ParcelfitError(
            "cannot decode this video", file=path, fix="convert it to H.264/HEVC MP4 with ffmpeg"
        )
    ok, frame = cap.read()
    if not ok or frame is None or frame.size == 0:
        cap.release()
        raise ParcelfitError(
            "the video has no frame that can be decoded (0 frames or a damaged file)",
            file=path,
            fix="check the file; convert it to H.264/HEVC MP4 with ffmpeg",
        )
    h, w = frame.shape[:2]
    if min(w, h) < MIN_FRAME_PX:
        cap.release()
        raise ParcelfitError(
            f"the video's frames are {w} x {h} px, too small to show a tag "
            f"(at least {MIN_FRAME_PX} px a side)",
            file=path,
            fix="track the camera's original recording, not a thumbnail or a cropped copy",
        )
    cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
    return cap


def frames_of(cap: cv2.VideoCapture, prefetch: int = 4) -> Iterator[np.ndarray]:
    """Grey frames of an open video, decoded in a background thread."""
    q: queue.Queue[np.ndarray | None] = queue.Queue(maxsize=prefetch)
    stop = threading.Event()

    def reader() -> None:
        try:
            while not stop.is_set():
                ok, frame = cap.read()
                if not ok:
                    break
                grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
                q.put(grey)
        finally:
            q.put(None)

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    try:
        while (item := q.get()) is not None:
            yield item
    finally:
        stop.set()
        while thread.is_alive():
            try:
                q.get_nowait()
            except queue.Empty:
                time.sleep(0.001)
        thread.join()


def _runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index ranges where ``mask`` is True."""
    padded = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(int)))
    return list(zip(edges[::2], edges[1::2], strict=True))


def fill_gaps(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    theta: np.ndarray,
    max_gap: int,
    sd: np.ndarray | None = None,
    fitted: np.ndarray | None = None,
) -> tuple[Trajectory | None, list[dict[str, Any]]]:
    """Trim to the first..last detection, unwrap theta, fill gaps <= ``max_gap`` frames linearly;
    returns the trajectory (None under two samples; its ``source`` says which samples were
    detected and which filled) and the list of gaps. ``sd`` (n, 2), the position [m] and heading
    [rad] standard deviations per frame, becomes the trajectory's position_sd and heading_sd,
    NaN in the filled frames (no standard deviation describes a linear interpolation).
    ``fitted`` (n,) marks the measured frames whose pose came from the model fit of the smeared
    tag (`parcelfit.tracking.fit`): their ``source`` is ``fitted``."""
    seen = np.isfinite(x)
    if seen.sum() < 2:
        return None, []
    first, last = np.flatnonzero(seen)[[0, -1]]
    t, x, y, theta = (a[first : last + 1].copy() for a in (t, x, y, theta))
    seen = seen[first : last + 1]
    was_fitted = (
        np.zeros(len(seen), bool) if fitted is None else np.asarray(fitted)[first : last + 1]
    )
    if sd is not None:
        sd = np.where(seen[:, None], sd[first : last + 1], np.nan)
    theta[seen] = np.unwrap(theta[seen])
    gaps = []
    keep = seen.copy()
    for a, b in _runs_of(~seen):
        filled = b - a <= max_gap
        gaps.append(
            {
                "from_s": float(t[a]),
                "to_s": float(t[b - 1]),
                "frames": int(b - a),
                "interpolated": bool(filled),
            }
        )
        if filled:
            for arr in (x, y, theta):
                arr[a:b] = np.interp(t[a:b], t[seen], arr[seen])
            keep[a:b] = True
    source = np.where(seen, np.where(was_fitted, "fitted", "detected"), "filled")
    traj = Trajectory(
        t=t[keep],
        x=x[keep],
        y=y[keep],
        theta=theta[keep],
        source=source[keep],
        position_sd=None if sd is None else sd[keep, 0],
        heading_sd=None if sd is None else sd[keep, 1],
    )
    return traj, gaps


def track_video(
    video: str | Path,
    tag_map: TagMap,
    options: TrackOptions | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> VideoTrack:
    """Track every parcel tag of ``tag_map`` through ``video`` (see the module docstring)."""
    opts = options or TrackOptions()
    video = Path(video)
    cap = open_video(video)
    fps = float(cap.get(cv2.CAP_PROP_FPS)) or 0.0
    if not fps > 0:
        cap.release()
        raise ParcelfitError(
            "the video does not state its frame rate",
            file=video,
            fix="write the frame rate into the container, e.g. ffmpeg -r FPS -i IN -c copy OUT",
        )
    if not 1 / MAX_SAMPLE_INTERVAL_S <= fps <= 1 / MIN_SAMPLE_INTERVAL_S:
        cap.release()
        raise ParcelfitError(
            f"the video states a frame rate of {fps:g} fps; a tracked run is sampled at "
            f"{1 / MAX_SAMPLE_INTERVAL_S:g} to {1 / MIN_SAMPLE_INTERVAL_S:g} fps",
            file=video,
            fix="write the camera's true frame rate into the container (ffmpeg -r FPS)",
        )
    total = max(0, int(cap.get(cv2.CAP_PROP_FRAME_COUNT)))  # some containers say -1
    size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
    cam = tag_map.camera
    if cam is not None and cam.width and (cam.width, cam.height) != size:
        cap.release()
        raise ParcelfitError(
            f"the camera model is for {cam.width}x{cam.height} px, the video is {size[0]}x{size[1]}",
            file=tag_map.source,
            where="camera",
            fix="calibrate the camera at the video's resolution (parcelfit camera-calibrate)",
        )
    for key, value in (("exposure_ms", tag_map.exposure), ("readout_ms", tag_map.readout)):
        if value > 1 / fps + 1e-9:  # both happen within one frame interval
            cap.release()
            raise ParcelfitError(
                f"timing.{key} is {value * 1e3:g} ms, longer than the video's frame interval "
                f"({1e3 / fps:.2f} ms at {fps:g} fps)",
                file=tag_map.source,
                where=f"timing.{key}",
                fix="give it in milliseconds, as the camera states it (shutter time; sensor "
                "readout, first to last row)",
            )
    if not opts.max_reprojection_px > 0:
        raise ParcelfitError(
            f"max_reprojection_px must be > 0, got {opts.max_reprojection_px}",
            fix="use a few pixels (default 5)",
        )
    detector = TagDetector(
        tag_map.family,
        downscale=opts.downscale,
        min_side=opts.min_side,
        refine=opts.refine,
        rescan=opts.rescan,
    )
    detector.edge_ids = set(tag_map.parcel_tags) if opts.edge_refine else set()
    expected = set(tag_map.reference_tags)
    parcel_ids = sorted(tag_map.parcel_tags)
    rows: dict[int, list[tuple[float, float, float]]] = {i: [] for i in parcel_ids}
    mapper: PlaneMapper | None = None
    reproj_mean, reproj_max, reused, geometry_missing = [], 0.0, 0, 0
    seen_any_reference = False
    other_ids: set[int] = set()
    centres: dict[int, dict[int, tuple[float, float, float]]] = {i: {} for i in parcel_ids}
    corners: dict[int, dict[int, tuple[np.ndarray, np.ndarray]]] = {i: {} for i in parcel_ids}
    # the camera's timing: from the tag map, else estimated after reading (`estimate_timing`)
    exposure, readout = tag_map.exposure, tag_map.readout
    estimating = opts.fit and opts.estimate_timing and not tag_map.timing_given
    fitting = opts.fit and tag_map.timing_given and (exposure > 0 or readout > 0)
    fitters = {
        i: SmearFitter(
            tag_map, i, corners[i], 1 / fps, size[1], opts.fit_smear_cells, opts.fit_max_rms
        )
        for i in parcel_ids
    }
    last_seen: dict[int, list[tuple[int, np.ndarray]]] = {i: [] for i in parcel_ids}
    started = time.perf_counter()
    k = 0
    try:
        for k, grey in enumerate(frames_of(cap)):
            found = detector.detect(grey, expected, wanted=set(parcel_ids))
            fitted = fit_plane_mapper(tag_map, found, mapper)
            if fitted is not None:
                mapper = fitted
                seen_any_reference = True
                reproj_mean.append(fitted.reprojection_mean)
                reproj_max = max(reproj_max, fitted.reprojection_max)
            elif mapper is not None:
                reused += 1
            other_ids |= set(found) - expected - set(parcel_ids)
            for tag_id in parcel_ids:
                if (fitting or estimating) and mapper is not None:
                    crop = cut_around_tag(grey, found.get(tag_id), last_seen[tag_id], k, opts.max_gap)
                    if crop is not None:
                        fitters[tag_id].crops[k] = Crop(*crop, mapper)
                    if tag_id in found:
                        last_seen[tag_id] = [*last_seen[tag_id][-1:], (k, found[tag_id])]
                if mapper is None or tag_id not in found:
                    rows[tag_id].append((math.nan, math.nan, math.nan))
                    if mapper is None:
                        geometry_missing += 1
                    continue
                tag = tag_map.parcel_tags[tag_id]
                px = found[tag_id]
                centres[tag_id][k] = (*px.mean(axis=0), _side(px))
                corners[tag_id][k] = (mapper.to_rig(px, tag.height), px[:, 1].copy())
                tx, ty, th = tag_pose(mapper, px, tag.height)
                dx, dy = tag.offset
                c, s = math.cos(th), math.sin(th)
                rows[tag_id].append((tx - (c * dx - s * dy), ty - (s * dx + c * dy), th))
            if fitting:
                for fitter in fitters.values():
                    fitter.run(k - SmearFitter.reach)
            if progress:
                progress(k + 1, total)
    finally:
        cap.release()
    frames = k + 1
    elapsed = time.perf_counter() - started
    if not seen_any_reference:
        raise ParcelfitError(
            f"no reference tag ({', '.join(map(str, sorted(expected)))}) was found in any frame"
            + (f"; other tags seen: {sorted(other_ids)}" if other_ids else ""),
            file=video,
            fix=f"check the tag map's reference_tags and family ({tag_map.family})",
        )
    reproj = float(np.mean(reproj_mean))
    if reproj > opts.max_reprojection_px:
        raise ParcelfitError(
            f"the reference tags do not fit the tag map: mean reprojection error {reproj:.1f} px "
            f"(max {reproj_max:.1f} px) is above {opts.max_reprojection_px:g} px",
            file=tag_map.source,
            where="reference_tags",
            fix="measure the reference tags' positions, sizes and angles again (a tag placed "
            "wrongly shifts every trajectory)",
        )
    t = np.arange(frames) / fps
    if tag_map.timing_given:
        timing: dict[str, Any] = {"source": "tag map"}
    elif estimating:
        timing = estimate_timing(list(fitters.values()), fps)
        exposure, readout = timing.pop("exposure"), timing.pop("readout")
        fitting = exposure > 0 or readout > 0
        for fitter in fitters.values():
            fitter.exposure, fitter.readout = exposure, readout
            if not fitting:
                fitter.crops.clear()
    else:
        timing = {
            "source": "assumed none",
            "reason": "not in the tag map, and not estimated (the smear fit or the timing "
            "estimate is switched off): no model fit of smeared tags, no rolling-shutter "
            "correction",
        }
    timing = {"exposure_ms": exposure * 1e3, "readout_ms": readout * 1e3, **timing}
    tags = {}
    fit_seconds, fit_count, fit_residuals = 0.0, 0, []
    for tag_id in parcel_ids:
        arr = np.array(rows[tag_id], dtype=float).reshape(-1, 3)
        detected = np.isfinite(arr[:, 0])
        meas_sd = np.tile(_MEASUREMENT_SD[1:], (len(arr), 1))
        fitted = np.zeros(len(arr), bool)
        if fitting:
            fitter = fitters[tag_id]
            fitter.run(frames)
            fit_seconds += fitter.seconds
            fit_count += fitter.tried
            fit_residuals += fitter.residuals
            fits = fitter.fits
            # smeared frames the fit did not support: their detection is trusted 3 times less
            for k_bad in fitter.unsupported:
                meas_sd[k_bad] *= 3
            tag = tag_map.parcel_tags[tag_id]
            for k_fit, (pose, sd_pos, sd_head, px) in fits.items():
                tx, ty, th = pose
                dx, dy = tag.offset
                c, s_ = math.cos(th), math.sin(th)
                arr[k_fit] = (tx - (c * dx - s_ * dy), ty - (s_ * dx + c * dy), th)
                # the parcel centre's sd: the tag centre's and the heading's share through the offset
                meas_sd[k_fit] = (math.hypot(sd_pos, math.hypot(dx, dy) * sd_head), sd_head)
                fitted[k_fit] = True
                w = tag_corners(tx, ty, tag.size, th)
                corners[tag_id][k_fit] = (w, np.full(4, size[1] / 2))  # at the frame time
                centres[tag_id][k_fit] = (*px.mean(axis=0), _side(px))
        if readout > 0:
            arr = rolling_shutter_poses(
                corners[tag_id], t, readout, size[1], tag_map.parcel_tags[tag_id].offset
            )
        before = np.isfinite(arr[:, 0])  # measured (detected or fitted), before the smoother
        gated, sd, restarts = 0, None, []
        if opts.smooth:
            arr, gated, sd, restarts = smooth_track(arr, 1 / fps, meas_sd)
        measured = np.isfinite(arr[:, 0])
        traj, gaps = fill_gaps(
            t, arr[:, 0], arr[:, 1], arr[:, 2], opts.max_gap, sd, fitted=fitted & measured
        )
        # in view: from the measurements before the smoother (a frame it discarded was seen)
        span = _frames_in_view(before, centres[tag_id], size)
        crossings: dict[str, float | None] = {}
        transit = None
        if traj is not None and tag_map.barriers:
            crossings = barrier_times(traj, tag_map.barriers, tag_map.parcel_tags[tag_id].outline)
            a, b = crossings[tag_map.barriers[0].name], crossings[tag_map.barriers[-1].name]
            if len(tag_map.barriers) >= 2 and a is not None and b is not None:
                transit = b - a
        tags[tag_id] = TagTrack(
            tag_id,
            traj,
            transit,
            crossings,
            {
                # the run file's counts: measured = detected + fitted (its source column)
                "measured_frames": int(measured.sum()),
                "detected_frames": int((measured & ~fitted).sum()),
                "fitted_frames": int((fitted & measured).sum()),
                "fitted_missed_frames": int((fitted & measured & ~detected).sum()),
                # frames the detector found the tag in, before fits and the smoother
                "detector_frames": int(detected.sum()),
                "frames_in_view": span,
                # frames in view at the clip's ends without any measurement (detected or fitted)
                "missed_at_clip_ends": int(span - _detected_span(before)),
                "smoothed": opts.smooth,
                # measurements (detected or fitted) the smoother discarded as outliers
                "discarded_by_smoother": gated,
                # times [s] where a change of motion (a spin's onset or stop, a catch) restarted
                # the smoother's motion model
                "motion_restarts_s": [float(t[j]) for j in restarts],
                # coverage: frames measured (detected or fitted) of the frames in view
                "detection_rate": float(measured.sum() / span) if span else 0.0,
                "gaps": gaps,
                "interpolated_frames": int(sum(g["frames"] for g in gaps if g["interpolated"])),
                "missing_frames": int(sum(g["frames"] for g in gaps if not g["interpolated"])),
            },
        )
    quality = {
        "frames": frames,
        "fps": fps,
        "size_px": list(size),
        "seconds_per_frame": elapsed / max(frames, 1),
        "reference_reprojection_px": {
            "mean": float(np.mean(reproj_mean)) if reproj_mean else None,
            "max": float(reproj_max) if reproj_mean else None,
        },
        "frames_without_reference_tags": reused + geometry_missing,
        "parallax_corrected": tag_map.camera is not None,
        "parallax_note": "tag heights corrected with the camera model"
        if tag_map.camera is not None
        else "NOT corrected: the tag map has no camera model, so a tag above the belt is "
        "mapped as if it lay on the belt plane (run parcelfit camera-calibrate)",
        "lens_distortion_corrected": tag_map.camera is not None,
        "detector": {
            "library": f"OpenCV {cv2.__version__} aruco, family {tag_map.family}",
            "downscale": detector.downscale,
            "subpixel_refinement": opts.refine,
            "full_frame_searches": detector.full_frame_searches,
        },
        "max_gap_filled_frames": opts.max_gap,
        # the camera timing the smear fit and the rolling-shutter correction used: from the
        # tag map, estimated (`estimate_timing`) or assumed none (no fit, no correction)
        "timing": timing,
        "smear_fit": {
            "on": fitting,
            "frames_tried": fit_count,
            "seconds_per_frame_tried": fit_seconds / fit_count if fit_count else None,
            # the mean residual of the kept fits: smallest at the right timing (docs/tracking.md)
            "residual_rms_mean": float(np.mean(fit_residuals)) if fit_residuals else None,
        },
        "other_tags_seen": sorted(other_ids),
    }
    if not any(t.trajectory is not None for t in tags.values()):
        raise ParcelfitError(
            f"no parcel tag ({', '.join(map(str, parcel_ids))}) was found"
            + (f"; other tags seen: {sorted(other_ids)}" if other_ids else ""),
            file=video,
            fix="check the tag map's parcel_tags and the tag family",
        )
    return VideoTrack(video, fps, frames, size, tags, quality)


# measurement sd of one frame: 0.3 mm and 0.5 degrees (the edge-fitted tag on rendered blurred
# frames); jerk densities 10 (m/s^3)^2 s and 1e3 (rad/s^3)^2 s: chosen on the rendered 4 and 8 ms
# videos, where they lowered the 4 ms / 720 deg/s heading max from 1.01 to 0.59 degrees
_MEASUREMENT_SD = (3e-4, 3e-4, math.radians(0.5))
_JERK_DENSITY = (10.0, 10.0, 1e3)


def smooth_track(
    arr: np.ndarray,
    dt: float,
    meas_sd: np.ndarray | None = None,
    restart_after: int = RESTART_AFTER,
) -> tuple[np.ndarray, int, np.ndarray | None, list[int]]:
    """Poses (n, 3) [m, m, rad] (NaN where unseen) replaced by their RTS-smoothed values at the
    seen frames (`parcelfit.tracking.smooth`); frames the smoother rejects as outliers become
    NaN. Returns the poses, how many frames were rejected, the smoother's posterior standard
    deviations (n, 2): position [m] (root mean square of the x and y sds) and heading [rad],
    NaN where the pose is NaN (None under 3 seen frames: nothing was smoothed), and the frames
    at which a change of motion (a spin's onset or stop, a catch) restarted the motion model in
    x, y or heading.

    ``meas_sd`` (n, 2): each frame's measurement sd, position [m] (per coordinate) and heading
    [rad] (default: `_MEASUREMENT_SD` in every frame, the edge-fitted detection; the model fit
    of a smeared tag gives its own). The sds are those of the smoothed estimate under the model:
    each frame measured with its sd, x, y and theta independent, constant acceleration with white jerk
    (`_JERK_DENSITY`). They grow at the track's ends and next to gaps and rejected frames; they
    know a frame's blur or fit only through ``meas_sd``. ``restart_after``: consecutive frames
    outside the gate that restart the motion model (0: never; `rts_smooth`)."""
    seen = np.isfinite(arr[:, 0])
    if seen.sum() < 3:
        return arr, 0, None, []
    out = arr.copy()
    out[seen, 2] = np.unwrap(arr[seen, 2])
    keep = seen.copy()
    sds = np.zeros((len(arr), 3))
    restarts: set[int] = set()
    for j in range(3):
        z = out[:, j]
        r = (
            np.full(len(z), _MEASUREMENT_SD[j] ** 2)
            if meas_sd is None
            else meas_sd[:, 0 if j < 2 else 1] ** 2
        )
        smoothed, sds[:, j], used, restarted = rts_smooth(
            z, dt, r, _JERK_DENSITY[j], restart_after=restart_after
        )
        restarts.update(restarted)
        out[seen, j] = smoothed[seen]
        keep &= used | ~seen
    rejected = int((seen & ~keep).sum())
    out[~keep] = np.nan
    sd = np.column_stack([np.sqrt((sds[:, 0] ** 2 + sds[:, 1] ** 2) / 2), sds[:, 2]])
    sd[~keep] = np.nan
    return out, rejected, sd, sorted(restarts)


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


def _detected_span(detected: np.ndarray) -> int:
    idx = np.flatnonzero(detected)
    return int(idx[-1] - idx[0] + 1) if len(idx) else 0


def _frames_in_view(
    detected: np.ndarray, centres: dict[int, tuple[float, float, float]], size: tuple[int, int]
) -> int:
    """Frames the tag was in view: its first..last detection, widened to the clip's start (end)
    when at its first (last) detection the tag was well inside the image (more than two tag
    sides from every border), so it cannot have just entered (left) the view."""
    idx = np.flatnonzero(detected)
    if not len(idx):
        return 0
    first, last = int(idx[0]), int(idx[-1])

    def inside(k: int) -> bool:
        x, y, side = centres[k]
        return min(x, y, size[0] - 1 - x, size[1] - 1 - y) > 2 * side

    start = 0 if inside(first) else first
    end = len(detected) - 1 if inside(last) else last
    return end - start + 1
