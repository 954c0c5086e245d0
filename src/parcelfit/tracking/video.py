"""Opening a video with clear errors, and its grey frames decoded in a background thread."""

from __future__ import annotations

import os
import queue
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from parcelfit.errors import ParcelfitError

# the smallest frame side [px] that can show a tag: OpenCV still decodes a 36h11 tag 8 px wide
# (one pixel a bit), which needs its white border around it; smaller frames are refused before
# any OpenCV call sees them (a 1 x 1 px frame shrunk for the detector has no pixel left)
MIN_FRAME_PX = 16

# FFmpeg's own log level inside OpenCV (AV_LOG_QUIET): a damaged file made FFmpeg print its
# messages ("moov atom not found") on the terminal beside parcelfit's error, which names the
# file and the fix. A level set in the environment is kept (e.g. 16, FFmpeg's errors).
_FFMPEG_QUIET = "-8"
# OpenCV reads it once, when its FFmpeg backend first opens or writes a video in the process:
# set on import of parcelfit.tracking (which imports this module), before any video is opened
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", _FFMPEG_QUIET)
_DECODER_WORDS = "convert it to H.264/HEVC MP4 with ffmpeg (OPENCV_FFMPEG_LOGLEVEL=16 shows the decoder's own error)"


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
            fix=_DECODER_WORDS,
        ) from None
    if not cap.isOpened():
        raise ParcelfitError("cannot decode this video", file=path, fix=_DECODER_WORDS)
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


def stated_frames(path: str | Path) -> int | None:
    """The frame count a video's container states exactly (PyAV's count of the video stream),
    or None where it states none: OpenCV estimates one from the duration for such containers
    (Matroska, WebM), which counts an audio track's length, so only an exact count can tell a
    decoder that stopped early."""
    import av

    try:
        with av.open(str(path)) as container:
            count = int(container.streams.video[0].frames)
    except (av.FFmpegError, IndexError, OSError):
        return None
    return count if count > 0 else None


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
