"""Tracking one video with its light-barrier log, writing tracked runs, and tracking a folder of
videos into one dataset (resumable).

One video: ``<out>/<stem>-tag<ID>.csv`` per parcel tag (columns t [s], x [m], y [m], theta [rad],
the parcel centre and the heading of its x axis; source: detected, fitted or filled; position_sd [m],
heading_sd [rad]: the smoother's standard deviations) and
``<out>/<stem>.quality.json``.

A folder: every video named ``RIG-CONSIGNMENT-SETTING-RUN.<ext>`` (e.g. ``E3-KPBW-1-07.mp4``)
becomes run ``RIG-CONSIGNMENT-SETTING-RUN`` of test case RIG/CONSIGNMENT/SETTING. Per video the
result goes to ``<out>/tracks/`` as above; a finished video is skipped when the command runs
again; a video that fails (unreadable, no reference tags, wrong family, no parcel tag) is listed
in ``<out>/track-all.json`` with the reason and the others go on. At the end ``<out>/dataset.yaml``
and ``<out>/runs/`` are written from every finished video; each test case carries its rig's
regions of interest and margin when the caller gives them (the CLI: from the rig files).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from parcelfit.atomic import write_text_atomic
from parcelfit.errors import ParcelfitError
from parcelfit.runs import (
    CaseData,
    Region,
    Run,
    TestCase,
    read_trajectory,
    save_dataset,
    write_trajectory,
)
from parcelfit.tracking.barriers import OUT_OF_ORDER_WORDS, late_start_words, read_sensor_log
from parcelfit.tracking.tagmap import TagMap
from parcelfit.tracking.track import (
    TrackOptions,
    VideoTrack,
    crossed_unseen,
    track_video,
    undecoded_words,
)

VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".m4v")
_REST = re.compile(r"^(?P<cons>[^-]+)-(?P<setting>\d+)-(?P<run>[^.]+)$")  # after RIG-


def track_one(
    video: str | Path,
    tag_map: TagMap,
    options: TrackOptions | None = None,
    *,
    sensor_log: str | Path | None = None,
    sensors: str = "1,2",
    progress: Callable[[int, int], None] | None = None,
) -> VideoTrack:
    """Track one video (`track_video`); with a light-barrier ``sensor_log`` (columns timestamp
    [s], sensor) every parcel tag's transit time [s] is the log's, from the first event of the
    start sensor to the next of the end sensor (``sensors``: ``START,END``)."""
    result = track_video(video, tag_map, options, progress=progress)
    if sensor_log is not None:
        start, _, end = sensors.partition(",")
        transit = read_sensor_log(sensor_log, start.strip(), end.strip())
        for t in result.tags.values():
            t.transit_time = transit
    return result


def write_video_track(result: VideoTrack, out: str | Path) -> list[Path]:
    """Write one CSV per tracked parcel tag and the quality report; returns the files."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    stem = result.video.stem
    files = []
    tags: dict[str, Any] = {}
    for tag_id, track in result.tags.items():
        entry: dict[str, Any] = {**track.quality, "crossings_s": track.crossings}
        entry["transit_time_s"] = track.transit_time
        if track.trajectory is not None:
            path = out / f"{stem}-tag{tag_id}.csv"
            write_trajectory(track.trajectory, path)
            files.append(path)
            entry["file"] = path.name
        tags[str(tag_id)] = entry
    quality = {"video": result.video.name, **result.quality, "parcel_tags": tags}
    qpath = out / f"{stem}.quality.json"
    write_text_atomic(qpath, json.dumps(quality, indent=2))  # last: its presence means done
    return [*files, qpath]


def case_of(video: Path | str, rigs: Iterable[str] = ()) -> tuple[TestCase, str]:
    """Test case and run id from a video's name ``RIG-CONSIGNMENT-SETTING-RUN``; ``video`` is
    its path, or its name without the extension as it is (``E3-KP.BW-1-07`` keeps its dot). A
    rig name that holds a ``-`` (``E3-far-plate``) is read when it is one of ``rigs``; the
    consignment's name cannot hold one. A name that reads as two test cases (``E3-far-2-1-07``
    with the rig ``E3-far`` known: also rig ``E3``, consignment ``far``) is refused."""
    stem, shown, file = (
        (video, video, None)
        if isinstance(video, str)
        else (
            video.stem,
            video.name,
            video,
        )
    )
    # the rig is the name's part before its first '-', or a known rig name holding one
    candidates = [r for r in rigs if "-" in r] + [stem.partition("-")[0]]
    readings: dict[tuple[str, str, int], None] = {}  # an ordered set
    for rig in candidates:
        if rig and stem.startswith(f"{rig}-") and (m := _REST.match(stem[len(rig) + 1 :])):
            readings[(rig, m["cons"], int(m["setting"]))] = None
    if len(readings) > 1:
        raise ParcelfitError(
            f"the name {shown!r} reads as more than one test case: "
            + "; ".join(f"rig {r}, consignment {c}, setting {n}" for r, c, n in readings),
            file=file,
            fix="rename it so that one reading fits (no '-' in the run id, a consignment "
            "name that is not a number)",
        )
    if not readings:
        near = max((r for r in candidates[:-1] if stem.startswith(f"{r}-")), key=len, default="")
        raise ParcelfitError(
            f"cannot read the test case from the name {shown!r}",
            file=file,
            fix=f"after the rig {near} give CONSIGNMENT-SETTING-RUN, e.g. {near}-KPBW-1-07"
            if near
            else "name videos RIG-CONSIGNMENT-SETTING-RUN, e.g. E3-KPBW-1-07.mp4 (a rig name "
            "with a '-' is read only for a known rig, e.g. one given to track-all with --rig)",
        )
    ((rig, cons, setting),) = readings
    return TestCase(rig, cons, setting), stem


def track_all(
    folder: str | Path,
    tag_map: TagMap,
    out: str | Path,
    *,
    options: TrackOptions | None = None,
    name: str | None = None,
    sensor_logs: str | Path | None = None,
    sensors: str = "1,2",
    on_video: Callable[[Path, str], None] | None = None,
    on_frame: Callable[[int, int], None] | None = None,
    regions: Mapping[str, tuple[tuple[Region, ...], float]] | None = None,
) -> dict[str, Any]:
    """Track every video of ``folder`` into a dataset in ``out``; returns the summary written to
    ``track-all.json`` (done, skipped, failed with reasons). With ``sensor_logs``, a folder of
    light-barrier logs named like the videos (``E3-KPBW-1-07.csv`` beside
    ``E3-KPBW-1-07.mp4``), every run's transit time [s] is its log's (`track_one`); a video
    without its log fails with that reason.

    Each test case takes its rig's regions of interest and margin [m] (where runs are
    compared) from ``regions`` (rig name -> (regions, margin), e.g. from the rig files). The
    rigs not in it are listed under ``whole_track`` in the summary: their runs are compared over
    the whole track. A rig name in ``regions`` may hold a ``-`` in the videos' names
    (`case_of`)."""
    folder, out = Path(folder), Path(out)
    if not folder.is_dir():
        raise ParcelfitError("not a folder", file=folder, fix="point at the folder of videos")
    logs = None if sensor_logs is None else Path(sensor_logs)
    if logs is not None and not logs.is_dir():
        raise ParcelfitError(
            "not a folder", file=logs, fix="point --sensor-logs at the folder of the logs"
        )
    videos = sorted(p for p in folder.iterdir() if p.suffix.lower() in VIDEO_SUFFIXES)
    if not videos:
        raise ParcelfitError(
            "no videos here", file=folder, fix=f"videos end in {', '.join(VIDEO_SUFFIXES)}"
        )
    tracks = out / "tracks"
    known = tuple(regions or ())  # rig names whose videos may hold a '-' in the rig's part
    summary: dict[str, Any] = {"done": [], "skipped": [], "failed": {}}
    say = on_video or (lambda video, state: None)
    for video in videos:
        if (tracks / f"{video.stem}.quality.json").is_file():
            summary["skipped"].append(video.name)
            say(video, "already tracked")
            continue
        say(video, "tracking")
        try:
            case_of(video, known)
            log = None if logs is None else logs / f"{video.stem}.csv"
            if log is not None and not log.is_file():
                raise ParcelfitError(
                    f"no light-barrier log {log.name} in {logs.name}/",
                    file=video,
                    fix="name each log like its video, with .csv",
                )
            result = track_one(
                video, tag_map, options, sensor_log=log, sensors=sensors, progress=on_frame
            )
            if not any(t.trajectory is not None for t in result.tags.values()):
                raise ParcelfitError(
                    f"no parcel tag ({', '.join(map(str, sorted(tag_map.parcel_tags)))}) was found",
                    file=video,
                    fix="check the tag map's parcel_tags and the tag family",
                )
            write_video_track(result, tracks)
            summary["done"].append(video.name)
            early = sorted({b for t in result.tags.values() for b in crossed_unseen(t.quality)})
            disordered = any(t.quality["barriers_out_of_order"] for t in result.tags.values())
            notes = [
                *([] if not early or log is not None else [late_start_words(early)]),
                *([OUT_OF_ORDER_WORDS] if disordered and log is None else []),
                *filter(None, [undecoded_words(result.quality)]),
            ]
            say(video, "; ".join(["done", *notes]))
        except ParcelfitError as exc:
            summary["failed"][video.name] = str(exc)
            say(video, f"failed: {exc}")
    cases: dict[TestCase, list[Run]] = {}
    for qfile in sorted(tracks.glob("*.quality.json")) if tracks.is_dir() else []:
        doc = json.loads(qfile.read_text(encoding="utf-8"))
        stem = qfile.name[: -len(".quality.json")]
        try:
            case, run_id = case_of(stem, known)
        except ParcelfitError as exc:  # tracked before with other --rig files: report, go on
            summary["failed"][qfile.name] = str(exc)
            continue
        entries = [e for e in doc["parcel_tags"].values() if e.get("file")]
        if not entries:
            continue
        best = max(entries, key=lambda e: e.get("measured_frames", e.get("detected_frames", 0)))
        traj = read_trajectory(tracks / best["file"])
        cases.setdefault(case, []).append(Run(run_id, case, traj, best.get("transit_time_s")))
    regions = regions or {}
    summary["whole_track"] = sorted({c.rig for c in cases if c.rig not in regions})
    if cases:
        save_dataset(
            out,
            name or folder.name,
            [CaseData(c, tuple(cases[c]), *regions.get(c.rig, ((), 0.0))) for c in sorted(cases)],
            description=f"tracked from the videos in {folder.name}/ with parcelfit track-all",
        )
    summary["dataset"] = str(out / "dataset.yaml") if cases else None
    (out / "track-all.json").write_text(json.dumps(summary, indent=2), encoding="utf-8")
    return summary
