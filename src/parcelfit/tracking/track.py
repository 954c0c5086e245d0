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
posterior standard deviations (``position_sd``, ``heading_sd``; see `smooth_track`, and
`smooth_scaled` for a fitted frame's sd and the camera timing's share); measured
frames it discards as outliers become gaps and are counted (``discarded_by_smoother``), and a
change of motion restarts its motion model (``motion_restarts_s``). The
heading is unwrapped over the run. Decoding runs in a background thread (OpenCV releases the GIL
while decoding), so decoding and detection overlap on two cores.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.runs import Trajectory
from parcelfit.runs.io import MAX_SAMPLE_INTERVAL_S, MIN_SAMPLE_INTERVAL_S
from parcelfit.tracking.barriers import barrier_times, broken_at_start, passed_at_start
from parcelfit.tracking.detect import TagDetector, _side
from parcelfit.tracking.geometry import (
    PlaneMapper,
    fit_plane_mapper,
    rolling_shutter_poses,
    tag_pose,
)
from parcelfit.tracking.smear import (
    Crop,
    SmearFitter,
    cut_around_tag,
    estimate_timing,
    timing_uncertainty,
)
from parcelfit.tracking.smooth import RESTART_AFTER, rts_smooth
from parcelfit.tracking.tagmap import TagMap, tag_corners
from parcelfit.tracking.video import frames_of, open_video, stated_frames

# frames the container may state beyond those decoded before the tracking commands say the
# decoder stopped early (container counts can be estimates off by a frame)
UNDECODED_FRAMES_NOTED = 2


def crossed_unseen(quality: dict[str, Any]) -> list[str]:
    """The barriers a tag's track (its ``quality``) crossed before the video shows it: broken,
    or passed, at its first sample (`barriers_broken_at_start`, `barriers_passed_at_start`)."""
    return [*quality["barriers_broken_at_start"], *quality["barriers_passed_at_start"]]


def undecoded_words(quality: dict[str, Any]) -> str | None:
    """What the tracking commands say when the decoder stopped before the frames the container
    states (a damaged file; FFmpeg's own messages are quiet), or None."""
    stated, frames = quality.get("frames_in_container"), quality.get("frames", 0)
    if not stated or stated - frames <= UNDECODED_FRAMES_NOTED:
        return None
    return (
        f"decoded {frames} of the {stated} frames the video states: the file may be damaged "
        f"after frame {frames}, and the tracks end there (check it, or convert it with ffmpeg)"
    )


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
                    crop = cut_around_tag(
                        grey, found.get(tag_id), last_seen[tag_id], k, opts.max_gap
                    )
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
    timing_sd = timing_uncertainty(exposure, readout, fps, timing["source"] == "estimated")
    timing = {
        "exposure_ms": exposure * 1e3,
        "readout_ms": readout * 1e3,
        # the timing's uncertainty the fitted frames' sds include (`FitPose.timing_sd`)
        "sd_ms": [v * 1e3 for v in timing_sd],
        **timing,
    }
    tags = {}
    fit_seconds, fit_count, fit_residuals = 0.0, 0, []
    for tag_id in parcel_ids:
        arr = np.array(rows[tag_id], dtype=float).reshape(-1, 3)
        detected = np.isfinite(arr[:, 0])
        # each frame's measurement variance: base (a detection's; a fit's floor) plus the
        # fit's own, which the smoother's residuals may widen; a fit's motion rates and the
        # time its rates were extrapolated over (`smooth_scaled`)
        base_var = np.tile(np.square(_MEASUREMENT_SD[1:]), (len(arr), 1))
        fit_var = np.zeros((len(arr), 2))
        model_rates = np.full((len(arr), 3), np.nan)
        lags = np.zeros(len(arr))
        fitted = np.zeros(len(arr), bool)
        if fitting:
            fitter = fitters[tag_id]
            fitter.run(frames)
            fit_seconds += fitter.seconds
            fit_count += fitter.tried
            fit_residuals += fitter.residuals
            # smeared frames the fit did not support: their detection is trusted 3 times less
            for k_bad in fitter.unsupported:
                base_var[k_bad] *= 9
            tag = tag_map.parcel_tags[tag_id]
            arm = math.hypot(*tag.offset)
            for k_fit, fp in fitter.fits.items():
                tx, ty, th = fp.pose
                dx, dy = tag.offset
                c, s_ = math.cos(th), math.sin(th)
                arr[k_fit] = (tx - (c * dx - s_ * dy), ty - (s_ * dx + c * dy), th)
                # the parcel centre's sd: the tag centre's and the heading's share through the
                # offset
                fit_var[k_fit] = (fp.sd_position**2 + (arm * fp.sd_heading) ** 2, fp.sd_heading**2)
                base_var[k_fit] = np.square(_FIT_SD_FLOOR)
                model_rates[k_fit], lags[k_fit] = fp.rates, fp.lag
                fitted[k_fit] = True
                w = tag_corners(tx, ty, tag.size, th)
                corners[tag_id][k_fit] = (w, np.full(4, size[1] / 2))  # at the frame time
                centres[tag_id][k_fit] = (*fp.corners.mean(axis=0), _side(fp.corners))
        if readout > 0:
            arr = rolling_shutter_poses(
                corners[tag_id], t, readout, size[1], tag_map.parcel_tags[tag_id].offset
            )
        before = np.isfinite(arr[:, 0])  # measured (detected or fitted), before the smoother
        gated, sd, restarts, scale = 0, None, [], [1.0, 1.0]
        if opts.smooth:
            arr, gated, sd, restarts, scale = smooth_scaled(
                arr,
                1 / fps,
                base_var,
                fit_var,
                model_rates,
                np.abs(lags) * readout,
                np.abs(lags) * timing_sd[1],
            )
        measured = np.isfinite(arr[:, 0])
        traj, gaps = fill_gaps(
            t, arr[:, 0], arr[:, 1], arr[:, 2], opts.max_gap, sd, fitted=fitted & measured
        )
        # in view: from the measurements before the smoother (a frame it discarded was seen)
        span = _frames_in_view(before, centres[tag_id], size)
        crossings: dict[str, float | None] = {}
        transit = None
        # beams the parcel already broke, or lay wholly beyond, at its first sample: crossed
        # before it was seen
        broken_first: list[str] = []
        passed_first: list[str] = []
        out_of_order = False
        if traj is not None and tag_map.barriers:
            outline = tag_map.parcel_tags[tag_id].outline
            crossings = barrier_times(traj, tag_map.barriers, outline)
            broken_first = [b.name for b in tag_map.barriers if broken_at_start(traj, b, outline)]
            passed_first = passed_at_start(traj, tag_map.barriers, outline)
            a, b = crossings[tag_map.barriers[0].name], crossings[tag_map.barriers[-1].name]
            if len(tag_map.barriers) >= 2 and a is not None and b is not None:
                # the last broken before the first: the tag map lists them out of order
                out_of_order = b <= a
                transit = None if out_of_order else b - a
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
                # lambda (position, heading): the factor the fits' own variances were widened
                # by to match the smoother's residuals (`smooth_scaled`), and the medians of the
                # run file's position_sd [m] and heading_sd [rad] over its measured frames
                "fit_variance_scale": scale,
                "position_sd_median": _median(None if traj is None else traj.position_sd),
                "heading_sd_median": _median(None if traj is None else traj.heading_sd),
                # coverage: frames measured (detected or fitted) of the frames in view
                "detection_rate": float(measured.sum() / span) if span else 0.0,
                "gaps": gaps,
                # light barriers already broken at the first sample (crossing time not known)
                "barriers_broken_at_start": broken_first,
                # light barriers the parcel lay wholly beyond at the first sample (passed unseen)
                "barriers_passed_at_start": passed_first,
                # the last barrier broken before the first: no transit time (the tag map's
                # light_barriers are not in the order the parcel crosses them)
                "barriers_out_of_order": out_of_order,
                "interpolated_frames": int(sum(g["frames"] for g in gaps if g["interpolated"])),
                "missing_frames": int(sum(g["frames"] for g in gaps if not g["interpolated"])),
            },
        )
    quality = {
        "frames": frames,
        # the frames the container states exactly (None: it states none); more than
        # `UNDECODED_FRAMES_NOTED` above `frames`: the decoder stopped early (a damaged file)
        "frames_in_container": stated_frames(video),
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


# the smallest measurement sd of a fitted frame: 0.02 mm and 0.012 degrees (added in quadrature)
_FIT_SD_FLOOR = (2e-5, math.radians(0.012))


def smooth_scaled(
    arr: np.ndarray,
    dt: float,
    base_var: np.ndarray,
    fit_var: np.ndarray,
    model_rates: np.ndarray,
    reach: np.ndarray,
    timing_lag: np.ndarray,
) -> tuple[np.ndarray, int, np.ndarray | None, list[int], list[float]]:
    """`smooth_track` with honest standard deviations for the fitted frames. Arrays are per
    frame; variances (n, 2) are per position coordinate [m^2] and heading [rad^2].

    Each frame's measurement variance is base_var + lambda fit_var + rate_var. A fit sees the
    tag ``reach`` [s] from the frame time (its centre row's rolling-shutter delay) and moves it
    to the frame time with its motion model's rates ``model_rates`` (n, 3) (vx, vy [m/s] of the
    parcel centre, turn rate [rad/s]; NaN where not fitted): rate_var is the error that costs,
    (smoothed rate - model rate)^2 reach^2 (`RATE_SD_FACTOR` times), the smoothed rates from a
    first pass; large next to an abrupt change of motion, which the model's quadratic rounds
    off. lambda (position, heading) >= 1 makes the fitted frames' mean normalised squared
    residual (`rts_smooth`'s ``nis``) about 1: from lambda = 1, lambda <- max(1, lambda x that
    mean), smoothed again, up to `LAMBDA_PASSES` times (until it changes by under 5 %); so
    fits whose own sds are too small for the scatter the smoother sees are widened, never
    narrowed. A timing off by its sd shifts every fit by
    the smoothed rate times ``timing_lag`` [s] (the readout's sd times the centre row's lag):
    a bias common to neighbouring frames, which smoothing does not average away, so its
    variance is added to the smoothed one. Returns `smooth_track`'s results and lambda."""
    n = len(arr)
    fitted = fit_var[:, 0] > 0
    if not fitted.any() and np.isnan(model_rates).all() and not np.any(timing_lag):
        # nothing fitted: no lambda, no rate miss and no timing bias, so the first pass is the
        # result (the passes below would repeat it)
        out, gated, sd, restarts = smooth_track(arr, dt, np.sqrt(base_var + fit_var))
        return out, gated, sd, restarts, [1.0, 1.0]
    rates = np.zeros((n, 3))
    smooth_track(arr, dt, np.sqrt(base_var + fit_var), rates=rates)
    miss = np.nan_to_num(model_rates - rates) * reach[:, None]
    rate_var = RATE_SD_FACTOR**2 * np.column_stack(
        [(miss[:, 0] ** 2 + miss[:, 1] ** 2) / 2, miss[:, 2] ** 2]
    )
    nis = np.full((n, 3, 2), np.nan)
    scale = np.ones(2)
    for i in range(LAMBDA_PASSES + 1):
        var = base_var + scale * fit_var + rate_var
        result = smooth_track(arr, dt, np.sqrt(var), nis=nis)
        grown = scale.copy()
        for j, cols in enumerate(([0, 1], [2])):
            vals = nis[fitted][:, cols, NIS_KIND]
            vals = vals[np.isfinite(vals)]
            if len(vals) >= 3:
                grown[j] = max(1.0, scale[j] * float(np.mean(vals)))
        if i == LAMBDA_PASSES or np.allclose(grown, scale, rtol=0.05):
            break
        scale = grown
    out, gated, sd, restarts = result
    if sd is not None:
        bias = rates * timing_lag[:, None]
        sd = np.sqrt(
            sd**2 + np.column_stack([(bias[:, 0] ** 2 + bias[:, 1] ** 2) / 2, bias[:, 2] ** 2])
        )
    return out, gated, sd, restarts, [float(v) for v in scale]


RATE_SD_FACTOR = 1.0
LAMBDA_PASSES = 4
NIS_KIND = 1  # 0: the filter's innovations, 1: the smoother's residuals


def smooth_track(
    arr: np.ndarray,
    dt: float,
    meas_sd: np.ndarray | None = None,
    restart_after: int = RESTART_AFTER,
    nis: np.ndarray | None = None,
    rates: np.ndarray | None = None,
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
            z,
            dt,
            r,
            _JERK_DENSITY[j],
            restart_after=restart_after,
            nis=None if nis is None else nis[:, j],
            rates=None if rates is None else rates[:, j],
        )
        restarts.update(restarted)
        out[seen, j] = smoothed[seen]
        keep &= used | ~seen
    rejected = int((seen & ~keep).sum())
    out[~keep] = np.nan
    sd = np.column_stack([np.sqrt((sds[:, 0] ** 2 + sds[:, 1] ** 2) / 2), sds[:, 2]])
    sd[~keep] = np.nan
    return out, rejected, sd, sorted(restarts)


def _median(values: np.ndarray | None) -> float | None:
    """The median of the finite values, None when there are none."""
    if values is None or not np.isfinite(values).any():
        return None
    return float(np.nanmedian(values))


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
