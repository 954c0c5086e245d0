"""Tracking speed on full-size frames: 5312 x 2988 H.264, decoding included, against decoding alone.

    python benchmarks/bench_track.py [--frames 120] [--keep DIR]

Renders (once; reused from --keep) a 5312 x 2988, 60 fps H.264 video of the synthetic conveyor
scene (tilted camera, lens distortion, blur, noise; four reference tags, one parcel tag), then
measures in the same run:

* decode: reading every frame with OpenCV and converting it to grey (what tracking must do);
* track: `parcelfit.tracking.track_video` (decode in a background thread + detection + geometry).

Prints frames per second of both, the ratio track/decode (goal: <= 1.5) and the tracking
accuracy on this video (mean / max position error, max heading error).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import yaml

from parcelfit.tracking import load_tag_map, track_video
from parcelfit.tracking.synthetic import conveyor_scene, render_video, s_curve, scene_tag_map


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
    args = ap.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp())
    folder.mkdir(parents=True, exist_ok=True)
    scene = conveyor_scene(5312, 2988, exposure=1 / 500, blur_samples=2, duration=args.frames / 60)
    video = folder / f"conveyor-5312x2988-{args.frames}.mp4"
    truth_file = video.with_suffix(".truth.npz")
    if not video.is_file() or not truth_file.is_file():
        t0 = time.perf_counter()
        truth = render_video(video, scene, s_curve, seed=5)
        np.savez(truth_file, **truth)
        print(f"rendered {video.name} in {time.perf_counter() - t0:.0f} s")
    truth = dict(np.load(truth_file))
    doc = scene_tag_map(scene)
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


if __name__ == "__main__":
    main()
