"""The tracking commands: one video, a folder of videos, and the camera's calibration."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table
from rich.text import Text

from parcelfit.cli.options import at_most
from parcelfit.cli.output import console, frame_bar
from parcelfit.errors import ParcelfitError


def track(
    video: Annotated[Path, typer.Argument(help="A top-down video of one run.")],
    tags: Annotated[Path, typer.Option("--tags", help="The tag map (YAML).")],
    out: Annotated[Path, typer.Option("--out", help="Folder for the run files.")] = Path("tracks"),
    max_gap: Annotated[
        int, typer.Option(min=0, help="Longest gap filled by interpolation [frames].")
    ] = 5,
    sensor_log: Annotated[
        Path | None,
        typer.Option(help="Light-barrier log CSV (timestamp, sensor) for the transit time."),
    ] = None,
    sensors: Annotated[
        str, typer.Option(help="Start and end sensor ids in the log, START,END.")
    ] = "1,2",
) -> None:
    """Track the AprilTags of a video: one run file (t, x, y, theta) per parcel tag and a quality
    report (detection rate, gaps, reprojection error, transit time)."""
    from parcelfit.tracking import load_tag_map, track_one, write_video_track
    from parcelfit.tracking.barriers import OUT_OF_ORDER_WORDS, late_start_words
    from parcelfit.tracking.track import TrackOptions, crossed_unseen, undecoded_words

    tag_map = load_tag_map(tags)
    with frame_bar() as bar:
        task = bar.add_task(f"tracking {video.name}", total=None)
        result = track_one(
            video,
            tag_map,
            TrackOptions(max_gap=max_gap),
            sensor_log=sensor_log,
            sensors=sensors,
            progress=lambda k, n: bar.update(task, completed=k, total=n or None),
        )
    files = write_video_track(result, out)
    q = result.quality
    table = Table(
        title=f"{video.name}: {result.frames} frames at {result.fps:g} fps", title_justify="left"
    )
    for col in (
        "parcel tag",
        "measured (fitted)",
        "gaps (filled / missing frames)",
        "transit time [s]",
        "file",
    ):
        table.add_column(escape(col))  # units in [] are text, not Rich markup
    for tag_id, t in result.tags.items():
        table.add_row(
            str(tag_id),
            f"{t.quality['detection_rate'] * 100:.1f} % of {t.quality['frames_in_view']} frames"
            f" ({t.quality['fitted_frames']})",
            f"{len(t.quality['gaps'])} ({t.quality['interpolated_frames']} / {t.quality['missing_frames']})",
            "-" if t.transit_time is None else f"{t.transit_time:.3f}",
            "-" if t.trajectory is None else f"{video.stem}-tag{tag_id}.csv",
        )
    console.print(table)
    cut = undecoded_words(q)
    if cut:
        console.print(Text(cut, style="yellow"))
    for tag_id, t in result.tags.items():
        early = crossed_unseen(t.quality)
        if early and sensor_log is None:  # with a log the transit time is the log's
            console.print(Text(f"tag {tag_id}: {late_start_words(early)}", style="yellow"))
        if t.quality.get("barriers_out_of_order") and sensor_log is None:
            console.print(Text(f"tag {tag_id}: {OUT_OF_ORDER_WORDS}", style="yellow"))
    rp = q["reference_reprojection_px"]
    console.print(
        f"reference tags: reprojection error mean {rp['mean']:.2f} px, max {rp['max']:.2f} px; "
        f"{q['seconds_per_frame'] * 1e3:.0f} ms a frame"
    )
    if not q["parallax_corrected"]:
        console.print(f"[yellow]parallax {q['parallax_note']}[/]")
    timing = q["timing"]
    if timing["source"] == "estimated":
        console.print(
            f"camera timing not in the tag map: estimated exposure {timing['exposure_ms']:.1f} ms, "
            f"readout {timing['readout_ms']:.1f} ms from the fit of {timing['frames']} smeared "
            "frames (state it as timing: in the tag map if you know it)"
        )
    elif timing["source"] == "assumed none":
        console.print(f"camera timing: assumed none ({timing['reason']})")
    for tag_id, t in result.tags.items():
        gone = t.quality["discarded_by_smoother"]
        if gone:
            kept = t.quality["measured_frames"]
            console.print(
                f"[yellow]warning[/]: parcel tag {tag_id}: the smoother discarded {gone} of "
                f"{gone + kept} measured frames as outliers of the motion model (they are gaps in "
                "the run file; see discarded_by_smoother in the quality report)"
            )
    console.print(f"[green]done[/]: {len(files)} files in {out}")


def track_all_command(
    folder: Annotated[
        Path,
        typer.Argument(
            help="Folder of videos named RIG-CONSIGNMENT-SPEED_SETTING-RUN.mp4 (e.g. "
            "E3-KPBW-1-01.mp4)."
        ),
    ],
    tags: Annotated[Path, typer.Option("--tags", help="The tag map (YAML).")],
    out: Annotated[Path, typer.Option("--out", help="Dataset folder.")] = Path("dataset"),
    max_gap: Annotated[
        int, typer.Option(min=0, help="Longest gap filled by interpolation [frames].")
    ] = 5,
    sensor_logs: Annotated[
        Path | None,
        typer.Option(
            help="Folder of light-barrier log CSVs (timestamp, sensor), one per video with the "
            "video's name and .csv: the transit times are the logs'."
        ),
    ] = None,
    sensors: Annotated[
        str, typer.Option(help="Start and end sensor ids in the logs, START,END.")
    ] = "1,2",
    rig: Annotated[
        list[Path] | None,
        typer.Option(
            "--rig",
            metavar="RIG.yaml",
            help="A rig file of your own (repeatable): the test cases of its rig take its "
            "regions of interest and margin, where runs are compared, and its name may hold "
            "a '-' in the videos' names. Bundled rigs (E1, E2a, E2b, E3) are found by name.",
        ),
    ] = None,
) -> None:
    """Track a folder of videos into one dataset (resumable: finished videos are skipped; a bad
    video is reported and the others go on)."""
    from parcelfit.sim.mujoco import bundled_rig_names, load_rig, load_rig_files
    from parcelfit.tracking import load_tag_map, track_all
    from parcelfit.tracking.track import TrackOptions

    tag_map = load_tag_map(tags)
    # the user's rig file before a bundled rig of the same name
    rigs = {name: load_rig(name) for name in bundled_rig_names()}
    rigs.update(load_rig_files(rig or (), where="--rig"))
    with frame_bar() as bar:
        task = bar.add_task("frames", total=None)

        def on_video(video: Path, state: str) -> None:
            bar.console.print(f"  {video.name}: {state}", highlight=False)
            if state == "tracking":  # a new video's frames; a finished one keeps its full bar
                bar.update(task, description=video.name, completed=0, total=None)

        summary = track_all(
            folder,
            tag_map,
            out,
            options=TrackOptions(max_gap=max_gap),
            sensor_logs=sensor_logs,
            sensors=sensors,
            on_video=on_video,
            on_frame=lambda k, n: bar.update(task, completed=k, total=n or None),
            regions={name: (r.regions, r.margin) for name, r in rigs.items()},
        )
    console.print(
        f"{len(summary['done'])} tracked, {len(summary['skipped'])} already done, "
        f"{len(summary['failed'])} failed"
    )
    for name, reason in summary["failed"].items():
        console.print(f"[red]failed[/] {name}: {reason}", highlight=False)
    for name in summary["whole_track"]:
        console.print(
            f"[yellow]no rig file for {name}[/]: its runs are compared over the whole track; "
            f"give --rig {name}.yaml for its regions of interest",
            highlight=False,
        )
    if summary["dataset"]:
        console.print(f"[green]dataset[/]: {summary['dataset']}")
    if summary["failed"]:
        raise typer.Exit(1)


def camera_calibrate(
    video: Annotated[Path, typer.Argument(help="A video of a checkerboard moved around the view.")],
    tags: Annotated[
        Path, typer.Option("--tags", help="Tag map to write the camera into (created if missing).")
    ],
    board: Annotated[
        str, typer.Option(help="Inner corners of the board, COLUMNSxROWS (e.g. 9x6).")
    ] = "9x6",
    square: Annotated[
        float, typer.Option(help="Side of one square [m], the tag map's unit (e.g. 0.04).")
    ] = 0.04,
    max_frames: Annotated[int, typer.Option(min=5, help="Views used at most.")] = 40,
) -> None:
    """Fit the camera's intrinsics and lens distortion (OpenCV) and write them into the tag map."""
    from parcelfit.tracking.camera import calibrate_camera
    from parcelfit.tracking.tagmap import save_camera

    cols, sep, rows = board.lower().partition("x")
    if not sep or not all(n.isascii() and n.isdigit() and 2 <= int(n) <= 100 for n in (cols, rows)):
        raise ParcelfitError(
            f"cannot read --board {board!r}",
            fix="write COLUMNSxROWS with 2 to 100 inner corners each, e.g. 9x6",
        )
    at_most(max_frames, "--max-frames", 1000)
    if square <= 0:
        raise ParcelfitError(f"--square must be positive, got {square}", fix="give it in metres")
    if square >= 1:
        raise ParcelfitError(
            f"--square {square:g} m is not a checkerboard square",
            fix=f"give the side in metres, like the tag map (e.g. {square / 1000:g} for "
            f"{square:g} mm)",
        )
    with frame_bar() as bar:
        task = bar.add_task("finding the board", total=None)
        result = calibrate_camera(
            video,
            (int(cols), int(rows)),
            square,
            max_frames=max_frames,
            progress=lambda k, n: bar.update(task, completed=k, total=n or None),
        )
    cam = result.camera
    console.print(
        f"fx {cam.fx:.1f} px, fy {cam.fy:.1f} px, centre ({cam.cx:.1f}, {cam.cy:.1f}) px, "
        f"distortion {', '.join(f'{v:.4g}' for v in cam.distortion)}; "
        f"RMS reprojection error {result.rms:.3f} px over {result.views} views"
    )
    if result.rms > 1.0:
        console.print("[yellow]RMS above 1 px: use more, sharper views covering the whole image[/]")
    save_camera(tags, cam)
    console.print(f"[green]written[/] into {tags} (camera:)")
