"""Tracking speed on full-size frames: 5312 x 2988 H.264, decoding included, against decoding alone.

    python benchmarks/bench_track.py [--frames 120] [--keep DIR] [--motion EXPOSURE_MS,SPIN_DEG_S]

Renders (once; reused from --keep) a 5312 x 2988, 60 fps H.264 video of the synthetic conveyor
scene (tilted camera, lens distortion, blur, noise; four reference tags, one parcel tag), then
measures in the same run:

* decode: reading every frame with OpenCV and converting it to grey (what tracking must do);
* track: `parcelfit.tracking.track_video` (decode in a background thread + detection + geometry).

Prints frames per second of both, the ratio track/decode (goal: <= 1.5) and the tracking
accuracy on this video (mean / max position error, max heading error).

``--motion 8,720`` renders instead the fast case of the motion benchmark at full size: the parcel
at 1.6 m/s spinning at 720 deg/s, an 8 ms exposure stated in the tag map (45 frames, 0.75 s),
so every frame's tag is also fitted by the smear model (`parcelfit.tracking.fit`); it prints the
fit's cost per frame as well.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import yaml

from parcelfit.tracking import load_tag_map, track_video
from parcelfit.tracking.synthetic import (
    conveyor_scene,
    render_video,
    s_curve,
    scene_tag_map,
    straight_spin,
)


def decode_only(path: Path) -> tuple[int, float]:
    """Frames decoded and converted to grey, and the seconds it took."""
    cap = cv2.VideoCapture(str(path))
    n = 0
    t0 = time.perf_counter()
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        n += 1
    cap.release()
    return n, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--keep", type=Path, default=None, help="folder to keep the rendered video in")
    ap.add_argument("--motion", default=None, help="EXPOSURE_MS,SPIN_DEG_S: the fast spinning case")
    args = ap.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp())
    folder.mkdir(parents=True, exist_ok=True)
    path, exposure_ms = s_curve, 2.0
    if args.motion:
        exposure_ms, spin = (float(v) for v in args.motion.split(","))
        path = straight_spin(1.6, spin)
        px_per_m = 5312 / 1.6 * 0.9
        smear_px = (1.6 + math.radians(spin) * 0.1) * exposure_ms * 1e-3 * px_per_m
        scene = conveyor_scene(
            5312,
            2988,
            exposure=exposure_ms * 1e-3,
            blur_samples=max(3, math.ceil(smear_px / 0.8)),
            duration=0.75,
            parcel_height=0.02,
            tag_offset=(0.05, 0.0),
        )
        video = folder / f"conveyor-5312x2988-e{exposure_ms:g}-s{spin:g}.mp4"
    else:
        scene = conveyor_scene(
            5312, 2988, exposure=1 / 500, blur_samples=2, duration=args.frames / 60
        )
        video = folder / f"conveyor-5312x2988-{args.frames}.mp4"
    truth_file = video.with_suffix(".truth.npz")
    if not video.is_file() or not truth_file.is_file():
        t0 = time.perf_counter()
        truth = render_video(video, scene, path, seed=5)
        np.savez(truth_file, **truth)
        print(f"rendered {video.name} in {time.perf_counter() - t0:.0f} s")
    truth = dict(np.load(truth_file))
    doc = scene_tag_map(scene)
    if args.motion:
        doc["timing"] = {"exposure_ms": exposure_ms, "readout_ms": 0}
    tags = folder / "tags.yaml"
    tags.write_text(yaml.safe_dump(doc))
    tag_map = load_tag_map(tags)
    decode_only(video)  # warm the file cache
    n, decode_s = decode_only(video)
    t0 = time.perf_counter()
    result = track_video(video, tag_map)
    track_s = time.perf_counter() - t0
    traj = result.tags[scene.parcel_tag_id].trajectory
    k = np.round(traj.t * 60).astype(int)
    pos = np.hypot(traj.x - truth["x"][k], traj.y - truth["y"][k]) * 1e3
    head = np.degrees(np.abs(traj.theta - truth["theta"][k]))
    print(f"video: {n} frames of {result.size[0]} x {result.size[1]} px, H.264")
    print(f"decode only : {n / decode_s:6.1f} frames/s")
    print(f"track       : {result.frames / track_s:6.1f} frames/s (decoding included)")
    print(f"ratio track/decode: {track_s / decode_s * n / result.frames:.2f} (goal <= 1.5)")
    print(
        f"accuracy: detected {len(traj)}/{result.frames} frames; position error mean "
        f"{pos.mean():.2f} mm, max {pos.max():.2f} mm; heading error max {head.max():.2f} deg"
    )
    print(f"detector: {result.quality['detector']}")
    fit = result.quality["smear_fit"]
    if fit["on"] and fit["seconds_per_frame_tried"] is not None:
        fitted = result.tags[scene.parcel_tag_id].quality["fitted_frames"]
        print(
            f"smear fit: {fitted} frames fitted of {fit['frames_tried']} tried, "
            f"{fit['seconds_per_frame_tried'] * 1e3:.0f} ms per frame tried "
            f"({fit['seconds_per_frame_tried'] * fit['frames_tried'] / track_s * 100:.0f} % of "
            "the tracking time)"
        )


if __name__ == "__main__":
    main()
