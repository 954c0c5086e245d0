"""The tracking figure of the docs: a rendered frame with the detected tags drawn, and the
trajectory tracked from the video against the truth.

    python scripts/figure_tracking.py

Writes docs/figures/tracking-frame.png. The video is SYNTHETIC (parcelfit.tracking.synthetic):
tilted camera with lens distortion, tag 25 mm above the belt, motion blur, noise, H.264.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import cv2
import numpy as np
import yaml
from matplotlib.figure import Figure

from parcelfit.tracking import load_tag_map, track_video
from parcelfit.tracking.detect import TagDetector
from parcelfit.tracking.synthetic import conveyor_scene, render_video, s_curve, scene_tag_map

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "tracking-frame.png"


def main() -> None:
    tmp = Path(tempfile.mkdtemp())
    scene = conveyor_scene(exposure=1 / 250)
    truth = render_video(tmp / "run.mp4", scene, s_curve, seed=1)
    doc = scene_tag_map(scene)
    (tmp / "tags.yaml").write_text(yaml.safe_dump(doc))
    result = track_video(tmp / "run.mp4", load_tag_map(tmp / "tags.yaml"))
    traj = result.tags[7].trajectory
    cap = cv2.VideoCapture(str(tmp / "run.mp4"))
    cap.set(cv2.CAP_PROP_POS_FRAMES, 60)
    _, frame = cap.read()
    cap.release()
    grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    found = TagDetector().detect(grey)
    shown = cv2.cvtColor(grey, cv2.COLOR_GRAY2RGB)
    for tag_id, c in found.items():
        colour = (230, 80, 20) if tag_id == 7 else (30, 160, 60)
        cv2.polylines(shown, [np.round(c * 16).astype(np.int32)], True, colour, 2, cv2.LINE_AA, 4)
        cv2.circle(shown, tuple(np.round(c[0]).astype(int)), 5, (200, 0, 200), -1)
        cv2.putText(
            shown,
            f"id {tag_id}",
            tuple(np.round(c.max(axis=0) + np.array([4, 0])).astype(int)),
            cv2.FONT_HERSHEY_SIMPLEX,
            1.0,
            colour,
            2,
        )
    k = np.round(traj.t * 60).astype(int)
    err = np.hypot(traj.x - truth["x"][k], traj.y - truth["y"][k]) * 1e3
    fig = Figure(figsize=(13, 4.2), layout="constrained")
    a0, a1, a2 = fig.subplots(1, 3, width_ratios=[1.6, 1, 1])
    a0.imshow(shown)
    a0.set_title("frame 60: detected tags (green: reference, orange: parcel)", fontsize=9)
    a0.axis("off")
    a1.plot(truth["x"], truth["y"] * 1e3, color="#999", lw=4, label="truth")
    a1.plot(traj.x, traj.y * 1e3, color="#d35400", lw=1.2, label="tracked")
    a1.set_xlabel("x [m]")
    a1.set_ylabel("y [mm]")
    a1.set_title(f"parcel centre (error mean {err.mean():.2f} mm, max {err.max():.2f} mm)")
    a1.legend()
    a2.plot(truth["t"], np.degrees(truth["theta"]), color="#999", lw=4, label="truth")
    a2.plot(traj.t, np.degrees(traj.theta), color="#d35400", lw=1.2, label="tracked")
    a2.set_xlabel("t [s]")
    a2.set_ylabel("theta [deg]")
    a2.set_title("heading")
    fig.suptitle(
        "SYNTHETIC video (rendered): tilted camera, lens distortion, tag 25 mm up, blur, noise, H.264"
    )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT, dpi=90)
    print(f"wrote {OUT} (error mean {err.mean():.3f} mm, max {err.max():.3f} mm)")


if __name__ == "__main__":
    main()
