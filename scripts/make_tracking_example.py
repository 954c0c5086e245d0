"""Render the sample video of the user guide's "Track your videos": examples/tracking/.

    python scripts/make_tracking_example.py

A SYNTHETIC top-down video (`parcelfit.tracking.synthetic`, 960 x 540 px, 30 fps, 2 s) of the
envelope of examples/own-rig crossing rig D1's stretch of belt, seen by a tilted camera with lens
distortion: four reference tags near the corners of the stretch, the parcel's tag 15 mm above
the belt. Its name follows `parcelfit track-all`'s convention (RIG-CONSIGNMENT-SPEED_SETTING-RUN).
The tag map beside it (tags.yaml) is written by hand; this script checks that it describes the
scene. The camera is left out of the tag map: the guide fits it with `parcelfit
camera-calibrate` from a checkerboard video rendered for the same camera (`board_video`).
"""

from __future__ import annotations

from pathlib import Path

import yaml

from parcelfit.tracking.synthetic import (
    conveyor_scene,
    render_checkerboard_video,
    render_video,
    s_curve,
    scene_tag_map,
)

OUT = Path(__file__).resolve().parents[1] / "examples" / "tracking"
SIZE = (960, 540)


def scene():
    """The sample video's scene (the camera of `board_video` too)."""
    return conveyor_scene(
        *SIZE,
        fps=30.0,
        duration=2.0,
        noise_sd=1.0,
        crf=23,
        parcel_height=0.015,
        parcel_outline=(0.24, 0.17),
    )


def board_video(target: str | Path, frames: int = 12) -> Path:
    """A checkerboard video (9 x 6 inner corners, 40 mm squares) seen by the sample's camera."""
    return render_checkerboard_video(target, scene().camera, frames=frames)


def main() -> None:
    s = scene()
    render_video(OUT / "D1-envelope-1-01.mp4", s, s_curve, seed=1)
    written = yaml.safe_load((OUT / "tags.yaml").read_text(encoding="utf-8"))
    truth = scene_tag_map(s, camera=False)
    assert written["reference_tags"] == truth["reference_tags"], "tags.yaml: reference tags"
    assert written["parcel_tags"] == truth["parcel_tags"], "tags.yaml: parcel tag"
    print(f"wrote {OUT / 'D1-envelope-1-01.mp4'}")


if __name__ == "__main__":
    main()
