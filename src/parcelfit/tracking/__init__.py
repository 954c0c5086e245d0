"""Tracking: AprilTag videos to trajectories (t, x, y, theta) and transit times (method section 3).

Modules: `tagmap` (the tag map file), `detect` (OpenCV aruco, fast on large frames), `geometry`
(image -> rig frame, parallax), `track` (one video), `barriers` (transit times), `batch` (folders
of videos into a dataset), `camera` (intrinsics from a checkerboard video), `synthetic` (rendered
test videos with a known trajectory).
"""

from parcelfit.tracking.barriers import barrier_times, crossing_time, read_sensor_log
from parcelfit.tracking.batch import track_all, track_one, write_video_track
from parcelfit.tracking.tagmap import Camera, TagMap, load_tag_map
from parcelfit.tracking.track import TrackOptions, VideoTrack, track_video

__all__ = [
    "Camera",
    "TagMap",
    "TrackOptions",
    "VideoTrack",
    "barrier_times",
    "crossing_time",
    "load_tag_map",
    "read_sensor_log",
    "track_all",
    "track_one",
    "track_video",
    "write_video_track",
]
