"""The ``parcelfit`` command: a thin layer over the package's functions."""

from __future__ import annotations

import contextlib
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, NoReturn

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import Progress, TimeElapsedColumn
from rich.table import Table
from rich.text import Text
from typer.core import TyperGroup

from parcelfit import __version__
from parcelfit.errors import ParcelfitError, os_error
from parcelfit.progress import ProgressCallback, ProgressEvent

if TYPE_CHECKING:
    from parcelfit.simulate import CaseSimulation
    from parcelfit.study.status import StudyStatus, ValidationStatus


class _Commands(TyperGroup):
    """The command group. Errors are handled here, once for every command: a `ParcelfitError`,
    and an `OSError` a user can fix (a path too long, a full disk: `parcelfit.errors.os_error`),
    is shown as one red message and exits with status 2, without a traceback. Ctrl-C prints
    one line, for a resumable command (`_resumes`) with what it stored and how to resume, and
    exits with status 130."""

    def invoke(self, ctx: typer.Context) -> Any:
        _resumable.clear()
        try:
            return super().invoke(ctx)
        except ParcelfitError as exc:
            _fail(exc)
        except OSError as exc:  # a path too long, a full disk: wherever a file is written
            error = os_error(exc)
            if error is None:
                raise
            _fail(error)
        except KeyboardInterrupt:  # Ctrl-C: the workers are stopped already (Executor.close)
            stored = _resumable.pop("stored", None)
            text = "interrupted"
            if stored is not None:
                with contextlib.suppress(Exception):  # what is stored, if it can be read
                    kept = stored()
                    text += "" if kept is None else f": {kept}"
                text += "; rerun the same command to resume"
            err_console.print(Text(text), highlight=False, soft_wrap=True)
            raise typer.Exit(code=130) from None


_resumable: dict[str, Callable[[], str | None]] = {}


def _resumes(stored: Callable[[], str | None] = lambda: None) -> None:
    """Declare the running command resumable: interrupted (Ctrl-C), it says
    ``interrupted: <stored()>; rerun the same command to resume`` and exits with status 130.
    ``stored`` words what is kept, e.g. "12 evaluations stored" (None: not counted)."""
    _resumable["stored"] = stored


def _stored(db: Path, kind: str, what: str) -> Callable[[], str]:
    """How many finished evaluations of ``kind`` the store ``db`` holds, as "N what stored"."""

    def count() -> str:
        from parcelfit.study.store import Store

        n = 0
        if db.is_file():
            store = Store(db, readonly=True)
            try:
                n = sum(e.status != "pending" for e in store.evaluations(kind))
            finally:
                store.close()
        return f"{n} {what} stored"

    return count


def _fail(exc: ParcelfitError) -> NoReturn:
    """Print ``exc`` as one red line on stderr and exit with status 2."""
    # user text (paths, keys, run ids) is printed as it is, never read as Rich markup
    message = Text.assemble(("error:", "bold red"), " ", str(exc))
    err_console.print(message, highlight=False, soft_wrap=True)
    raise typer.Exit(code=2) from None


app = typer.Typer(
    name="parcelfit",
    help="Calibrate physics simulations of parcels with flexible packaging against tracked experiments.",
    cls=_Commands,
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # help texts are plain text: units such as [s] or [mm] must not be read as Rich markup
    rich_markup_mode=None,
)
console = Console()
err_console = Console(stderr=True)


def _check_paths(*paths: Path | None) -> None:
    """Refuse at once, before any work, an output path the file system cannot hold (too long:
    the command group shows the error as one line); the paths are not created."""
    for path in paths:
        if path is not None:
            path.exists()  # raises OSError (ENAMETOOLONG) for a path too long


def _progress(status: Any, prefix: str) -> ProgressCallback:
    """A progress callback for a long job: on a terminal it updates the spinner's line; when
    the output goes to a log or CI (where the spinner shows nothing) it prints one line per
    event, i.e. per finished evaluation."""

    def say(event: ProgressEvent) -> None:
        if console.is_terminal:
            status.update(f"{prefix}{event.message}")
        else:
            console.print(Text(f"{prefix}{event.message}"), highlight=False)

    return say


DatasetArg = Annotated[Path, typer.Argument(help="Dataset folder (holding dataset.yaml).")]


@app.command()
def version() -> None:
    """Print parcelfit's version."""
    console.print(f"parcelfit {__version__}")


@app.command()
def reference(
    dataset: DatasetArg,
    as_json: Annotated[bool, typer.Option("--json", help="Print machine-readable JSON.")] = False,
) -> None:
    """Choose each test case's reference run (DTW distance matrices, method section 4)."""
    from parcelfit.analysis import SYNTHETIC_NOTE, reference_runs, reference_runs_doc
    from parcelfit.runs import load_dataset

    ds = load_dataset(dataset)
    selections = reference_runs(ds)
    if as_json:
        if ds.synthetic:  # stdout stays JSON; every object also carries "synthetic": true
            err_console.print(Text(f"note: dataset {ds.name} is {SYNTHETIC_NOTE}"))
        sys.stdout.write(json.dumps(reference_runs_doc(selections, ds), indent=1) + "\n")
        return
    _print_dataset(ds)
    for sel in selections.values():
        table = Table(
            title=f"{escape(sel.case.label)}: reference run [bold]{escape(sel.reference_id)}[/]",
            title_justify="left",
        )
        table.add_column("run")
        table.add_column("row sum of D_combined", justify="right")
        table.add_column(escape("transit time [s]"), justify="right")
        for i, run_id in enumerate(sel.run_ids):
            mark = " *" if i == sel.index else ""
            tt = sel.transit_times[i]
            table.add_row(
                run_id + mark, f"{sel.row_sums[i]:.3f}", "-" if tt is None else f"{tt:.3f}"
            )
        console.print(table)


@app.command()
def stats(
    dataset: DatasetArg,
    out: Annotated[Path, typer.Option("--out", help="Folder for tables and box plots.")] = Path(
        "stats"
    ),
    alpha: Annotated[
        float, typer.Option(help="False discovery rate for Benjamini-Hochberg.")
    ] = 0.05,
    family: Annotated[
        str, typer.Option(help="Adjust per 'rig_setting' or over 'all' tests.")
    ] = "rig_setting",
) -> None:
    """Compare transit times between consignment types (Mann-Whitney U + Benjamini-Hochberg)."""
    from parcelfit.analysis import transit_statistics
    from parcelfit.runs import load_dataset

    ds = load_dataset(dataset)
    _print_dataset(ds)
    result = transit_statistics(ds, out, alpha=alpha, family=family)
    _print_tests(result.tests)
    for f in result.files:
        console.print(Text(f"wrote {f}"))


def _print_dataset(ds: Any) -> None:
    """One line naming the dataset, its size and, for synthetic data, that it is SYNTHETIC."""
    from parcelfit.analysis import SYNTHETIC_NOTE

    line = Text.assemble(
        ("dataset", "bold"), f" {ds.name}: {len(ds.cases)} test cases, {len(ds.runs())} runs"
    )
    if ds.synthetic:
        line.append(f" ({SYNTHETIC_NOTE})", style="yellow")
    console.print(line)


def _print_tests(tests: Any) -> None:
    from parcelfit.stats import significance_stars

    table = Table(
        title="Transit-time comparisons (two-sided Mann-Whitney U, BH-adjusted)",
        title_justify="left",
    )
    for col in ("rig", "setting", "A", "B", "median A [s]", "median B [s]", "p", "p adj.", ""):
        table.add_column(escape(col), justify="right" if col not in ("rig", "A", "B") else "left")
    for _, r in tests.iterrows():
        table.add_row(
            r["rig"],
            str(r["speed_setting"]),
            r["type_a"],
            r["type_b"],
            f"{r['median_a_s']:.3f}",
            f"{r['median_b_s']:.3f}",
            f"{r['p_value']:.2g}",
            f"{r['p_adjusted']:.2g}",
            significance_stars(r["p_adjusted"]),
        )
    console.print(table)


TableFormatOption = Annotated[
    str, typer.Option("--format", metavar="[csv|parquet]", help="Table file format.")
]
AnyExecutorOption = Annotated[
    str,
    typer.Option(
        metavar="[serial|local|dask]",
        help="Where simulations run: local (worker processes), serial or dask.",
    ),
]
SchedulerOption = Annotated[
    str | None, typer.Option(help="Dask scheduler address, e.g. tcp://HOST:8786.")
]
WorkersOption = Annotated[
    int | None,
    typer.Option(
        min=1,
        help="Worker processes simulating in parallel (default: one per core; a file's "
        "executor.workers where the command reads a file).",
    ),
]
ExecutorOption = Annotated[
    str | None,
    typer.Option(
        metavar="[serial|local]",
        help="Where simulations run: local (worker processes) or serial (in this process, one "
        "at a time; for debugging). Default: the file's executor.kind, else local.",
    ),
]
SettingOption = Annotated[
    int,
    typer.Option(
        "--speed-setting",
        "--setting",
        min=1,
        help="Speed setting of the rig (speed_setting in dataset, study and screen files).",
    ),
]


def _workers(workers: int | None) -> int:
    """The worker processes a local executor uses: ``workers``, else one per core."""
    return workers or os.cpu_count() or 1


def _say_cost(estimate: Any) -> None:
    """Print a job's expected cost (`parcelfit.sim.cost.Estimate`) before it starts."""
    console.print(Text(estimate.text(), style="cyan"), highlight=False)


def _cost_first(line: str, progress: ProgressCallback) -> ProgressCallback:
    """``progress``, printing the job's expected cost ``line`` at the first event: once its
    files, data and simulator are read and checked, so that an error found while reading them
    is the only line a refused job prints."""
    said: list[bool] = []

    def say(event: ProgressEvent) -> None:
        if not said:
            said.append(True)
            console.print(Text(line, style="cyan"), highlight=False)
        progress(event)

    return say


@app.command()
def demo(
    out: Annotated[
        Path, typer.Option("--out", help="Folder for everything the demo writes.")
    ] = Path("parcelfit-demo"),
    quick: Annotated[
        bool, typer.Option("--quick", help="A smoke run: small screen, short calibration.")
    ] = False,
    full: Annotated[
        bool, typer.Option("--full", help="The full published protocol (slower).")
    ] = False,
    executor: Annotated[
        str | None,
        typer.Option(
            metavar="[serial|local]",
            help="Where simulations run: local (worker processes, the default) or serial (in "
            "this process, one at a time; for debugging).",
        ),
    ] = None,
    workers: WorkersOption = None,
    animation: Annotated[
        bool,
        typer.Option(help="Write an animation of the calibrated run and embed it in the report."),
    ] = True,
) -> None:
    """End to end on the bundled SYNTHETIC twin dataset: statistics, reference runs, screening,
    calibration with validation, and the HTML report. Rerunning resumes.

    Without a flag: the published 32-run screen of all 16 parameters, then a joint calibration
    of KP/BW on E3 and E1 (at most 60 evaluations, validated on E3 at speed setting 2, a
    transfer check on E1), about 10 minutes on 2 cores. --quick: an 8-run screen and at most 16
    evaluations, about 3 minutes. --full: the published protocol (fractional then full
    factorial screen, at most 80 evaluations), 3 minutes or more: the calibration stops when
    its validation passes. The expected cost is printed before the simulations start."""
    import time

    from parcelfit.demo import STAGES, Demo
    from parcelfit.study.studyfile import load_study

    if quick and full:
        raise ParcelfitError("--quick and --full exclude each other", fix="choose one")
    _check_executor(executor, ("serial", "local"))
    _resumes()
    _workers_at_most(workers)
    t0 = time.perf_counter()
    d = Demo(
        out,
        "quick" if quick else "full" if full else "default",
        executor=executor,
        workers=workers,
        animation=animation,
    )

    def rule(k: int, extra: str = "") -> None:
        console.rule(f"{k}/{len(STAGES)} {STAGES[k - 1]}{extra}")

    with console.status("loading the bundled twin dataset"):
        ds = d.dataset
    _print_dataset(ds)
    rule(1)
    with console.status("Mann-Whitney U tests"):
        result = d.statistics()
    sig = result.tests[result.tests["significant"]]
    console.print(
        f"{len(sig)} of {len(result.tests)} consignment pairs differ significantly; "
        f"box plots in {out / 'stats'}"
    )
    rule(2)
    with console.status("DTW distance matrices"):
        selections = d.reference_runs()
    table = Table(title="Reference run per test case", title_justify="left")
    for col in ("test case", "reference run", "runs"):
        table.add_column(col)
    for s in selections.values():
        table.add_row(s.case.label, s.reference_id, str(len(s.run_ids)))
    console.print(table)
    _say_cost(d.expected_cost(_workers(workers)))
    rule(3, f" (profile {d.profile.name})")
    with console.status("screening") as status_line:
        stages, selection = d.screen(_progress(status_line, "screening: "))
    _print_screen(stages, selection)
    rule(4)
    _calibrate_live(d.calibration, load_study(d.files[1]).name, out / "calibration")
    rule(5)
    with console.status("simulating the polybag example"):
        example = d.stricter_example()
    console.print(example["description"])
    rule(6)
    with console.status("report") as status_line:
        report = d.report(_progress(status_line, "report: "))
    minutes = (time.perf_counter() - t0) / 60
    console.print(f"[bold green]report:[/] {escape(str(report.resolve()))}")
    _print_verdict(out, f" ({minutes:.1f} min)")


def _at_most(value: int | None, option: str, bound: int) -> None:
    """A clear error for a count option (``--workers``, ``--repeat``, ...) above ``bound``."""
    if value is not None and value > bound:
        raise ParcelfitError(
            f"{option} {value} is more than {bound}", fix=f"use {option} {bound} or less"
        )


def _workers_at_most(workers: int | None) -> None:
    from parcelfit.sim.executors import MAX_WORKERS

    _at_most(workers, "--workers", MAX_WORKERS)


def _check_executor(kind: str | None, kinds: tuple[str, ...]) -> None:
    """A clear error for an --executor that this command cannot use."""
    if kind is not None and kind not in kinds:
        raise ParcelfitError(
            f"unknown executor {kind!r} for this command", fix=f"use {' or '.join(kinds)}"
        )


@app.command()
def report(
    folder: Annotated[
        Path, typer.Argument(help="A study folder, or a folder holding calibration/ (the demo's).")
    ],
    out: Annotated[
        Path | None, typer.Option(help="The HTML file (default: report.html inside FOLDER).")
    ] = None,
    screen: Annotated[
        Path | None, typer.Option(help="A screening folder (default: screen/ beside the study).")
    ] = None,
    frames: Annotated[
        bool, typer.Option(help="Show the calibrated run's key frames (drawn by the calibration).")
    ] = True,
    animation: Annotated[
        bool,
        typer.Option(
            help="Embed the animation of the calibrated run (written by `calibrate --animation`)."
        ),
    ] = False,
) -> None:
    """Write the self-contained HTML report of a calibration study."""
    from parcelfit.report import build_report

    with console.status("report") as status_line:
        path = build_report(
            folder,
            out=out,
            screen=screen,
            key_frames=frames,
            animation=animation,
            progress=_progress(status_line, "report: "),
        )
    console.print(f"[bold green]report:[/] {escape(str(path.resolve()))}")
    _print_verdict(folder)


@app.command()
def synth(
    spec: Annotated[Path, typer.Argument(help="Twin specification YAML (cases, truth, settings).")],
    out: Annotated[Path, typer.Option("--out", help="Folder for the dataset.")] = Path("twin"),
    executor: Annotated[
        str | None,
        typer.Option(
            metavar="[serial|local]",
            help="Where simulations run: local (worker processes; the default for more than "
            "one worker) or serial (in this process, one at a time; for debugging).",
        ),
    ] = None,
    workers: WorkersOption = None,
) -> None:
    """Make a SYNTHETIC twin-experiment dataset from hidden true parameters (and truth.yaml)."""
    from parcelfit.synth import load_twin_spec, make_twin_dataset

    _check_executor(executor, ("serial", "local"))
    _check_paths(out)
    _resumes()
    from parcelfit.synth import expected_cost

    _workers_at_most(workers)
    tw = load_twin_spec(spec)
    workers = _workers(workers)
    total = len(tw.cases) * tw.settings.runs
    serial = executor == "serial" or (executor is None and workers <= 1)
    where = "in this process" if serial else f"on {workers} processes"
    console.print(
        f"[bold]twin dataset[/] {tw.name}: {len(tw.cases)} test cases x {tw.settings.runs} runs "
        f"{where} [yellow](SYNTHETIC)[/]"
    )
    _say_cost(expected_cost(tw, 1 if serial else workers))
    with Progress(*Progress.get_default_columns(), TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task("simulating twin runs", total=total)

        def step(event: ProgressEvent) -> None:
            bar.update(task, completed=event.done)
            bar.console.print(Text(f"  {event.message}"), highlight=False)

        path = make_twin_dataset(
            out,
            tw.cases,
            tw.truth,
            settings=tw.settings,
            seed=tw.seed,
            name=tw.name,
            workers=workers,
            executor=executor,
            progress=step,
            rigs=tw.rigs(),
            consignments=tw.consignments(),
        )
    truth_file = path.parent / "truth.yaml"
    console.print(f"[green]done[/]: {escape(str(path))} and {escape(str(truth_file))}")


def _frame_bar() -> Progress:
    return Progress(*Progress.get_default_columns(), TimeElapsedColumn(), console=console)


@app.command()
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
    from parcelfit.tracking.track import TrackOptions

    tag_map = load_tag_map(tags)
    with _frame_bar() as bar:
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
        table.add_column(col)
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


@app.command("track-all")
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
) -> None:
    """Track a folder of videos into one dataset (resumable: finished videos are skipped; a bad
    video is reported and the others go on)."""
    from parcelfit.tracking import load_tag_map, track_all
    from parcelfit.tracking.track import TrackOptions

    tag_map = load_tag_map(tags)
    with _frame_bar() as bar:
        task = bar.add_task("frames", total=None)

        def on_video(video: Path, state: str) -> None:
            bar.console.print(f"  {video.name}: {state}", highlight=False)
            bar.update(task, description=video.name, completed=0)

        summary = track_all(
            folder,
            tag_map,
            out,
            options=TrackOptions(max_gap=max_gap),
            on_video=on_video,
            on_frame=lambda k, n: bar.update(task, completed=k, total=n or None),
        )
    console.print(
        f"{len(summary['done'])} tracked, {len(summary['skipped'])} already done, "
        f"{len(summary['failed'])} failed"
    )
    for name, reason in summary["failed"].items():
        console.print(f"[red]failed[/] {name}: {reason}", highlight=False)
    if summary["dataset"]:
        console.print(f"[green]dataset[/]: {summary['dataset']}")
    if summary["failed"]:
        raise typer.Exit(1)


@app.command("camera-calibrate")
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
    _at_most(max_frames, "--max-frames", 1000)
    if square <= 0:
        raise ParcelfitError(f"--square must be positive, got {square}", fix="give it in metres")
    if square >= 1:
        raise ParcelfitError(
            f"--square {square:g} m is not a checkerboard square",
            fix=f"give the side in metres, like the tag map (e.g. {square / 1000:g} for "
            f"{square:g} mm)",
        )
    with _frame_bar() as bar:
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


@app.command()
def simulate(
    rig: Annotated[
        str, typer.Option(help="Bundled rig name (E1, E2a, E2b, E3) or a rig .yaml file.")
    ] = "E3",
    consignment: Annotated[
        str,
        typer.Option(
            help="Bundled consignment type (KPBW, PB, KP, BW) or a consignment .yaml file."
        ),
    ] = "KPBW",
    setting: SettingOption = 1,
    set_: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar="NAME=VALUE",
            help="A parameter in the catalogue's unit (see `parcelfit params`); repeatable.",
        ),
    ] = None,
    out: Annotated[Path, typer.Option(help="Trajectory file to write (.csv or .parquet).")] = Path(
        "run.csv"
    ),
    video: Annotated[
        Path | None,
        typer.Option(help="Also write a top-view animation (.gif, or .mp4 with ffmpeg)."),
    ] = None,
    timestep: Annotated[
        float | None,
        typer.Option(
            help="Time step [s].", show_default="1/2400 s (rigid contents), 1/1200 s (soft)"
        ),
    ] = None,
    spacing: Annotated[
        float, typer.Option(help="Shell mesh spacing for rigid contents [m].")
    ] = 0.03,
    film_spacing: Annotated[
        float | None,
        typer.Option(
            help="Film mesh spacing around a soft content [m].",
            show_default="0.05 m",
        ),
    ] = None,
    membrane_cap: Annotated[
        float | None,
        typer.Option(
            help="Largest in-plane stiffness E*t of the packaging shell [N/m]: the shell keeps "
            "its bending stiffness (see the simulator's README, Resolution).",
        ),
    ] = None,
    belt_friction: Annotated[
        str,
        typer.Option(
            help="Friction law on belts, strips and rollers: mujoco (MuJoCo's contacts) or "
            "coulomb (Coulomb forces at the contact points; see the simulator's README, Sliding).",
        ),
    ] = "mujoco",
    shell_dof: Annotated[
        str,
        typer.Option(
            help="The packaging shell's degrees of freedom: auto (the consignment file's "
            "shell if it names one, e.g. trilinear over 4 x 4 x 1 cells for the bundled "
            "rigid-content types; else quadratic around a rigid content, full around a soft "
            "one), full (one per vertex; give a fine --timestep, "
            "e.g. 0.000208333 for 1/4800 s), quadratic or trilinear (see the simulator's "
            "README, Spin).",
        ),
    ] = "auto",
    shell_cells: Annotated[
        str | None,
        typer.Option(
            help="An interpolated shell's grid of cells along the parcel's length, width and "
            "height, e.g. 4,4,1 (default: the consignment file's with its own shell, else one).",
        ),
    ] = None,
    mass_lumping: Annotated[
        str,
        typer.Option(
            help="How the packaging's (and a soft content's) mass is spread over the bodies that "
            "carry it: area (lumped by area and volume) or equal (MuJoCo's own equal shares, "
            "the former model).",
        ),
    ] = "area",
    wall_limit: Annotated[float, typer.Option(help="Wall-clock limit [s].")] = 600.0,
    seed: Annotated[
        int | None,
        typer.Option(
            help="Placement seed: draw the start pose from the rig's hand-placement scatter "
            "(default: the nominal pose; with --repeat, 0).",
            min=0,
        ),
    ] = None,
    repeat: Annotated[
        int,
        typer.Option(
            help="Simulate an ensemble of this many placements (seeds SEED, SEED+1, ...) and "
            "summarise transit times and rotations.",
            min=1,
        ),
    ] = 1,
    workers: WorkersOption = None,
) -> None:
    """Simulate one test case with MuJoCo and write the run (t, x, y, theta; SI units).

    With --repeat N, simulate N seeded placements and write each run (OUT with -s<seed> before
    its suffix), a summary table (OUT with -ensemble.csv) and print the ensemble statistics."""
    from parcelfit.runs import write_trajectory
    from parcelfit.sim.ensemble import MAX_PLACEMENTS
    from parcelfit.simulate import case_simulation

    _at_most(repeat, "--repeat", MAX_PLACEMENTS)
    _at_most(seed, "--seed", 2**32 - 1)
    _workers_at_most(workers)
    _check_paths(out, video)  # before a simulation of minutes
    run = case_simulation(
        rig,
        consignment,
        setting,
        set_ or [],
        record_vertices=video is not None,
        timestep=timestep,
        spacing=spacing,
        film_spacing=film_spacing,
        membrane_cap=membrane_cap,
        shell_dof=shell_dof,
        shell_cells=shell_cells,
        belt_friction=belt_friction,
        mass_lumping=mass_lumping,
        wall_limit=wall_limit,
    )
    case = run.case
    if repeat > 1:
        if video is not None:
            raise ParcelfitError("--video works with one run only", fix="leave out --repeat")
        _simulate_ensemble(run, seed or 0, repeat, _workers(workers), out)
        return
    with console.status(f"simulating {case.label}"):
        result, frames = run.simulator.with_placement(seed).run_with_frames(run.params, case)
    d = result.diagnostics
    colour = "green" if result.ok else "red"
    console.print(
        f"[{colour}]{result.status.value}[/]: {d.get('message')}; {d.get('simulated_time', 0):.3f} s "
        f"simulated in {result.wall_time:.2f} s wall ({d.get('steps_per_second', 0):.0f} steps/s)"
    )
    if result.run is not None:
        tt = result.run.transit_time
        console.print(
            f"transit time: {'not measured (a light barrier was not crossed)' if tt is None else f'{tt:.4f} s'}"
        )
        console.print(Text(f"wrote {write_trajectory(result.run.trajectory, out)}"))
    if video is not None and frames is not None:
        from parcelfit.sim.mujoco.render import animate_run

        with console.status("rendering the animation"):
            console.print(Text(f"wrote {animate_run(run.rig, frames, video, title=case.label)}"))
    if not result.ok:
        raise typer.Exit(code=1)


def _shell_text(dof: str, cells: tuple[int, int, int]) -> str:
    """A shell for a table: its degrees of freedom and, if more than one, its cells."""
    if cells == (1, 1, 1):
        return dof
    return f"{dof}, {cells[0]} x {cells[1]} x {cells[2]} cells"


def _simulate_ensemble(run: CaseSimulation, first: int, n: int, workers: int, out: Path) -> None:
    """Simulate ``n`` placements from seed ``first`` (`parcelfit.simulate.simulate_placements`)
    with a progress bar; print their table and summary."""
    import math

    from rich.markup import escape

    from parcelfit.simulate import simulate_placements

    case = run.case
    with Progress(*Progress.get_default_columns(), TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task(f"{case.label}: {n} placements", total=n)
        done = simulate_placements(run, first, n, workers, out, lambda: bar.advance(task))
    rows, st, table_path = done.rows, done.summary, done.table
    table = Table(title=f"{case.label}: {n} placements (seeds {first}-{first + n - 1})")
    for col in ("seed", "status", "transit time [s]", "rotation [deg]", "outcome"):
        table.add_column(escape(col), justify="right" if col != "status" else "left")
    for r in rows:
        table.add_row(
            str(r["seed"]),
            r["status"],
            "-" if r["transit_time_s"] is None else f"{r['transit_time_s']:.3f}",
            "-" if r["rotation_deg"] is None else f"{r['rotation_deg']:.1f}",
            r["outcome"],
        )
    console.print(table)
    console.print(
        f"rotation [deg]: median {math.degrees(st.rotation_median):.1f} "
        f"(quartiles {math.degrees(st.rotation_q25):.1f}-{math.degrees(st.rotation_q75):.1f}, "
        f"max {math.degrees(st.rotation_max):.1f}); > 90 deg in {st.share_over_90:.0%}, "
        f"> 180 deg in {st.share_over_180:.0%}; {st.spins} spins, {st.slides} slides",
        markup=False,
    )
    console.print(
        f"transit time [s]: median {st.transit_median:.3f}, mean {st.transit_mean:.3f} "
        f"+- {st.transit_sem:.3f} (standard error); rank correlation with rotation "
        f"{st.rank_correlation:.2f}",
        markup=False,
    )
    console.print(f"wrote {n} runs and {table_path}", markup=False)
    if st.n_ok < st.n:
        raise typer.Exit(code=1)


@app.command()
def rigs() -> None:
    """List the bundled test rigs with their speed settings."""
    from parcelfit.sim.mujoco import bundled_rig_names, load_rig

    table = Table(title="Bundled rigs (parcelfit simulate --rig NAME)", title_justify="left")
    for col in ("rig", "surfaces", "speed settings [m/s]", "light barriers"):
        table.add_column(escape(col))  # units in [] are text, not Rich markup
    for name in bundled_rig_names():
        r = load_rig(name)
        speeds = "; ".join(
            f"{k}: " + ", ".join(f"{d} {v:g}" for d, v in r.speeds[k].items())
            for k in sorted(r.speeds)
        )
        table.add_row(
            name,
            ", ".join(f"{s.name} ({s.type})" for s in r.surfaces),
            speeds,
            " -> ".join(b.name for b in r.barriers),
        )
    console.print(table)
    from parcelfit.sim.mujoco import SceneOptions, bundled_consignment_names, load_consignment

    table = Table(title="Bundled consignment types (--consignment NAME)", title_justify="left")
    for col in (
        "type",
        "mass [g]",
        "outer L x W x H [mm]",
        "content",
        "content L x W x H [mm]",
        "packaging shell",
    ):
        table.add_column(escape(col))
    default_scene = SceneOptions()
    for name in bundled_consignment_names():
        c = load_consignment(name)
        table.add_row(
            name,
            f"{c.mass * 1e3:g}",
            " x ".join(f"{v * 1e3:g}" for v in c.outer),
            c.content_kind,
            " x ".join(f"{v * 1e3:g}" for v in c.content),
            _shell_text(*default_scene.shell_of(c)),
        )
    console.print(table)


@app.command()
def params(
    consignment: Annotated[
        str,
        typer.Option(
            help="Bundled consignment type (or a consignment .yaml file) whose parameters to list."
        ),
    ] = "KPBW",
) -> None:
    """List the simulation parameters with units, screening ranges and defaults."""
    from parcelfit.sim.mujoco import load_consignment
    from parcelfit.sim.params import parameters_for

    cons = load_consignment(consignment)
    specs = parameters_for(cons.content_kind)
    own = dict(cons.parameters)
    table = Table(
        title=f"{len(specs)} parameters for {cons.name} ({cons.content_kind} content); "
        "* = published screening range"
        + ("; ^ = this type's own default (its consignment file)" if own else ""),
        title_justify="left",
    )
    for col in ("name", "meaning", "unit", "low", "high", "default"):
        table.add_column(col, justify="right" if col in ("low", "high", "default") else "left")
    for p in specs:
        r = p.range_for(cons.content_kind)
        table.add_row(
            p.name + (" *" if p.published else ""),
            p.meaning,
            p.unit,
            f"{r.low:g}",
            f"{r.high:g}",
            f"{own[p.name]:g} ^" if p.name in own else f"{r.default:g}",
        )
    console.print(table)


@app.command()
def calibrate(
    study_file: Annotated[Path, typer.Argument(help="Study file (YAML).")],
    out: Annotated[
        Path | None,
        typer.Option(help="Study folder (default: next to the study file, named after it)."),
    ] = None,
    executor: Annotated[
        str | None,
        typer.Option(
            metavar="[serial|local|dask]",
            help="Where simulations run: local (worker processes), serial (in this process, "
            "one at a time; for debugging) or dask (a Dask cluster, see --scheduler). Default: "
            "the study file's executor.kind, else local.",
        ),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Dask scheduler address, e.g. tcp://HOST:8786 (the study file's "
            "executor.scheduler)."
        ),
    ] = None,
    workers: WorkersOption = None,
    animation: Annotated[
        bool,
        typer.Option(
            help="Also write an animation of the calibrated run (MuJoCo studies; "
            "`report --animation` embeds it)."
        ),
    ] = False,
    restart: Annotated[
        bool,
        typer.Option(
            "--restart",
            help="Start the study afresh: first move the folder's study.sqlite, runs/, "
            "results.json and figures/ into earlier-TIME/ inside it.",
        ),
    ] = False,
) -> None:
    """Calibrate by batch Bayesian optimisation; rerunning the same command resumes the study
    (a finished study only has its results, figures and key frames written again)."""
    from parcelfit.study.calibration import Calibration
    from parcelfit.study.estimate import calibration_cost_line
    from parcelfit.study.store import STORE_FILE
    from parcelfit.study.studyfile import load_study

    _check_executor(executor, ("serial", "local", "dask"))
    _workers_at_most(workers)
    study = load_study(study_file)
    folder = out or study_file.parent / study_file.stem
    _resumes(_stored(folder / "study.sqlite", "fit", "evaluations"))
    cost = calibration_cost_line(study, executor, workers, (folder / STORE_FILE).exists())

    def run(progress: ProgressCallback) -> Any:
        calibration = Calibration(
            study,
            folder,
            executor=executor,
            scheduler=scheduler,
            workers=workers,
            progress=progress,
            animation=animation,
            restart=restart,
        )
        result = calibration.run()
        if calibration.set_aside is not None:
            console.print(Text(f"the earlier study's outputs are in {calibration.set_aside}"))
        return result

    _calibrate_live(run, study.name, folder, cost)


def _calibrate_live(
    run: Callable[[ProgressCallback], Any], name: str, folder: Path, cost: str | None = None
) -> Any:
    """Run a calibration (``run(progress)``) with a live status table; then print how it
    stopped, the recommended parameters and where its figures are. Until its first event (while
    the data are read and the reference runs chosen) a spinner stands in for the table, so that
    an error found then (a test case the dataset lacks, ...) is the only line printed."""
    from rich.live import Live

    from parcelfit.study.folderlock import check_writable
    from parcelfit.study.status import study_status
    from parcelfit.study.store import STORE_FILE

    check_writable(folder, (STORE_FILE,))  # before the live display starts
    state: dict[str, ProgressEvent | None] = {"p": None}

    def render() -> Table:
        p = state["p"]
        table = Table(
            title=Text(f"calibration {name} -> {folder}"),
            title_justify="left",
            show_header=False,
        )
        table.add_column(style="bold")
        table.add_column()
        assert p is not None  # the table shows from the first event on
        verdict = {None: "not yet", True: "[green]passed[/]", False: "[red]failed[/]"}[
            p.last_validation
        ]
        table.add_row("iteration", f"{p.iteration} (0 = initial design)")
        table.add_row("evaluations", f"{p.done} done, {p.running} running, budget {p.total}")
        table.add_row("best cost", "-" if p.best_cost is None else f"{p.best_cost:.4g}")
        table.add_row("last validation", verdict)
        table.add_row("last event", Text(p.message))
        return table

    starting = console.status(Text(f"calibration {name}: starting (reference runs, workers)"))
    starting.start()
    lives: list[Live] = []

    def update(p: ProgressEvent) -> None:
        state["p"] = p
        if not lives:
            starting.stop()
            if cost is not None:  # said once the study is read and checked, before the table
                console.print(Text(cost, style="cyan"), highlight=False)
            lives.append(Live(render(), console=console, refresh_per_second=4, transient=False))
            lives[0].start()
        lives[0].update(render())
        if not console.is_terminal:  # a log or CI: the table shows only at the end
            best = "-" if p.best_cost is None else f"{p.best_cost:.4g}"
            console.print(
                Text(f"{p.message} ({p.done}/{p.total} evaluations, best cost {best})"),
                highlight=False,
            )

    try:
        result = run(update)
    finally:
        starting.stop()
        for live in lives:
            live.stop()
        # the display stopped; outside a terminal its last line is left open: end it, so that
        # what follows (an error too) starts on a line of its own
        console.print()
    console.print(
        Text.assemble(
            (result.stop_reason, "bold"),
            f" after {result.evaluations} evaluations: {_iterations_text(result.last_iteration)}; "
            f"study folder {result.folder}",
        )
    )
    _print_recommendation(study_status(folder))
    _print_determined(folder)
    console.print(
        Text(f"figures in {folder / 'figures'} ({len(result.figures) // 2} figures, PNG and SVG)")
    )
    _print_verdict(folder)
    return result


def _iterations_text(last: int | None) -> str:
    """The iterations done, in the one numbering (0 = initial design, k >= 1 optimiser batches)."""
    if last is None:
        return "no iteration yet"
    if last == 0:
        return "the initial design (iteration 0)"
    return "the initial design (iteration 0) and " + (
        "iteration 1" if last == 1 else f"iterations 1-{last}"
    )


def _print_recommendation(info: StudyStatus) -> None:
    """The study's recommended parameters (what it validates and reports), or while it runs the
    lowest-cost ones so far; the same for `calibrate` and `status`."""
    rec, low = info.recommended, info.lowest_cost
    if rec is not None:
        at = "" if rec.iteration is None else f", evaluated in iteration {rec.iteration}"
        _print_params(rec.params, f"recommended parameters (cost {rec.cost:.4g}{at})")
        if low is not None and low.params != rec.params:
            console.print(
                f"the lowest single cost was {low.cost:.4g} (iteration {low.iteration}); "
                "the recommendation is the evaluated point with the lowest GP mean cost "
                "(optimizer: {recommend: posterior_mean}, the default)",
                markup=False,
            )
    elif low is not None:
        _print_params(
            low.params,
            f"lowest-cost parameters so far (cost {low.cost:.4g}, iteration "
            f"{low.iteration}); the study recommends its parameters when it stops",
        )
    shown = info.shown
    if shown is not None and shown.parts:
        _print_parts(shown.parts)


def _print_parts(parts: list[dict[str, Any]]) -> None:
    """The per-case parts of a joint or ensemble evaluation's cost."""
    table = Table(title=Text("its cost, case by case"), title_justify="left")
    for col in ("case", "weight", "cost", "parts"):
        table.add_column(col, justify="left" if col in ("case", "parts") else "right")
    for p in parts:
        if "trajectory_term" in p:
            se = "" if p.get("se") is None else f" (se {p['se']:.3g})"
            tt = "-" if p.get("transit_term") is None else f"{p['transit_term']:.3g}"
            adjusted = " (adjusted times)" if "adjusted_transit_times" in p else ""
            what = f"trajectories {p['trajectory_term']:.3g}{se}, transit {tt}{adjusted}"
            what += f", {len(p.get('seeds') or [])} placements"
        else:
            what = f"DTW_xy {p['dtw_xy']:.3g} m, DTW_theta {p['dtw_theta']:.3g} rad"
        table.add_row(str(p["case"]), f"{p['weight']:g}", f"{p['cost']:.4g}", what)
    console.print(table)


def _print_params(params: dict[str, float], title: str) -> None:
    from parcelfit.sim.params import catalogue_unit, to_catalogue_units

    table = Table(title=Text(title), title_justify="left")
    table.add_column("parameter")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for name, value in params.items():
        table.add_row(name, f"{to_catalogue_units(name, value):.5g}", catalogue_unit(name))
    console.print(table)


@app.command()
def screen(
    screen_file: Annotated[Path, typer.Argument(help="Screen file (YAML).")],
    out: Annotated[
        Path | None, typer.Option(help="Screen folder (default: next to the file, named after it).")
    ] = None,
    executor: ExecutorOption = None,
    workers: WorkersOption = None,
) -> None:
    """Screen parameters: fractional -> full factorial designs, effects, Pareto charts, a selection."""
    from parcelfit.study.screening import load_screen, run_screen

    _check_executor(executor, ("serial", "local"))
    from parcelfit.study.estimate import screen_estimate

    _workers_at_most(workers)
    spec = load_screen(screen_file)
    folder = out or screen_file.parent / screen_file.stem
    _resumes(_stored(folder / "screen.sqlite", "screen", "simulations"))
    kind = executor or spec.executor.get("kind", "local")
    n = 1 if kind == "serial" else _workers(workers or spec.executor.get("workers"))
    cost = screen_estimate(spec, n).text("the first stage; later stages follow from it")
    with console.status("screening") as status_line:
        stages, selection = run_screen(
            spec,
            folder,
            executor=executor,
            workers=workers,
            progress=_cost_first(cost, _progress(status_line, "screening: ")),
        )
    _print_screen(stages, selection)
    console.print(Text(f"results in {folder} (selection.yaml, stageN-effects.csv, Pareto charts)"))


def _print_screen(stages: Any, selection: dict[str, Any]) -> None:
    """The strongest effects of every screening stage, and the selection."""
    for k, stage in enumerate(stages, start=1):
        table = Table(
            title=f"stage {k}: {stage.kind} factorial over {len(stage.factors)} parameters "
            f"({stage.analyses[0].method} errors)",
            title_justify="left",
        )
        for col in ("response", "term", "effect", "|t|", "p", ""):
            table.add_column(col, justify="right" if col in ("effect", "|t|", "p") else "left")
        for a in [*stage.analyses, *stage.ensemble_analyses]:
            for _, r in a.table.head(6).iterrows():
                table.add_row(
                    a.response,
                    r["term"],
                    f"{r['effect']:.3g}",
                    f"{abs(r['t']):.3g}",
                    f"{r['p_value']:.2g}",
                    "*" if r["significant"] else "",
                )
        console.print(table)
        if stage.ensemble_analyses:
            console.print(
                "spin_share and median_rotation (over each run's placements) are shown; "
                "the selection is made on dtw_xy and dtw_theta"
            )
    console.print(
        f"[bold]selected for calibration:[/] {', '.join(selection['selected']) or 'none'}"
    )


@app.command()
def precision(
    study_file: Annotated[Path, typer.Argument(help="Study file (YAML).")],
    placements: Annotated[
        int, typer.Option(min=2, help="Seeded placements per case and parameter end.")
    ] = 10,
    candidate: Annotated[
        list[str] | None,
        typer.Option(
            metavar="RIG/CONSIGNMENT/SPEED_SETTING",
            help="A further test case to judge, e.g. E1/KPBW/2; repeatable.",
        ),
    ] = None,
    at: Annotated[
        list[str] | None,
        typer.Option(
            metavar="NAME=VALUE",
            help="A parameter's value (catalogue units) at the point to judge at, else the "
            "centre of its range; repeatable.",
        ),
    ] = None,
    adjust_transit: Annotated[
        bool,
        typer.Option(
            "--adjust-transit",
            help="Compare transit times adjusted for the belt speeds each run rode at.",
        ),
    ] = False,
    out: Annotated[
        Path | None,
        typer.Option(help="Output folder (default: next to the file, named STEM-precision)."),
    ] = None,
    executor: ExecutorOption = None,
    workers: WorkersOption = None,
) -> None:
    """Which parameters can the study's test cases determine, before calibrating (resumable)."""
    from parcelfit.atomic import write_text_atomic
    from parcelfit.sim.params import parse_assignments
    from parcelfit.study.estimate import precision_estimate
    from parcelfit.study.precision import half_width_text
    from parcelfit.study.precision_check import TABLE_FILE, command_line, run_precision_check
    from parcelfit.study.studyfile import load_study

    _check_executor(executor, ("serial", "local"))
    _workers_at_most(workers)
    folder = out or study_file.parent / f"{study_file.stem}-precision"
    study = load_study(study_file)
    kind = executor or study.executor.get("kind", "local")
    n = 1 if kind == "serial" else _workers(workers or study.executor.get("workers"))
    cost = precision_estimate(study, placements, candidate or [], n).text(
        "runs kept from an earlier check are not simulated again"
    )

    def stored() -> str:
        from parcelfit.study.precision_check import STATISTICS_FILE

        cache = folder / STATISTICS_FILE
        runs = json.loads(cache.read_text(encoding="utf-8"))["runs"] if cache.is_file() else {}
        return f"{len(runs)} simulations stored"

    _resumes(stored)
    with console.status("precision check") as status_line:
        check = run_precision_check(
            study_file,
            folder,
            placements=placements,
            candidates=candidate or [],
            at=parse_assignments(at or []),
            adjust_transit=adjust_transit,
            executor=executor,
            workers=workers,
            progress=_cost_first(cost, _progress(status_line, "precision check: ")),
        )
    command = command_line(
        "parcelfit precision",
        study_file,
        placements=placements,
        candidates=candidate or [],
        at=at or [],
        adjust_transit=adjust_transit,
        repeated=True,
    )
    text = check.markdown(command, workers)
    write_text_atomic(folder / TABLE_FILE, text)
    table = Table(title="95 % half-width as a share of the range (joint; * within 10 %)")
    table.add_column("cases")
    for name in check.names:
        table.add_column(name, justify="right")
    for title, p in check.rows():
        table.add_row(Text(title), *(half_width_text(h) for h in p.joint))
    console.print(table)
    for title, found in check.subsets(top=1):
        best = found[0]
        console.print(Text(f"best {len(best.names)} to calibrate on {title}: {best.widths_text()}"))
    console.print(Text(f"tables in {folder / TABLE_FILE}"))


@app.command()
def status(
    study_dir: Annotated[Path, typer.Argument(help="Study folder (holding study.sqlite).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print machine-readable JSON.")] = False,
) -> None:
    """Show the state of a running or finished calibration study."""
    from parcelfit.study.status import study_status

    info = study_status(study_dir)
    if as_json:
        sys.stdout.write(json.dumps(info.to_json(), indent=1) + "\n")
        return
    record = info.study or {}
    name = record.get("name", "?")
    if info.synthetic:
        from parcelfit.analysis import SYNTHETIC_NOTE

        console.print(Text(f"dataset {info.dataset} ({SYNTHETIC_NOTE})", style="yellow"))
    counts = ", ".join(f"{n} {s}" for s, n in info.by_status.items())
    console.print(
        Text.assemble(
            (str(name), "bold"),
            f": {info.evaluations} evaluations" + (f" ({counts})" if counts else ""),
            f", {_iterations_text(info.last_iteration)}",
            f", reference run {info.reference_run}",
            f", stopped: {info.stop_reason or 'not yet'}",
        )
    )
    for v in info.validations:
        on = f" on {v.case}" if v.case else ""
        console.print(
            f"  validation after iteration {v.after_iteration}{on}: {_verdict_word(v)}",
            markup=False,
        )
    note = (record.get("optimizer") or {}).get("note")
    if note:
        console.print(Text(f"note: {note}", style="yellow"))
    _print_recommendation(info)
    _print_determined(study_dir)
    _print_verdict(study_dir)


_LEVEL_STYLE = {"trustworthy": "green", "incomplete": "yellow", "not trustworthy": "red"}


def _print_verdict(folder: Path, tail: str = "") -> None:
    """Every check on a line of its own (published criteria, band test, transfer check,
    parameters determined) and the one overall verdict (`parcelfit.study.verdict`), for a
    study folder or a folder holding ``calibration/`` (the demo's)."""
    from parcelfit.study.status import folder_verdict
    from parcelfit.study.store import STORE_FILE

    inner = folder / "calibration"
    verdict = folder_verdict(
        inner if not (folder / STORE_FILE).is_file() and (inner / STORE_FILE).is_file() else folder
    )
    *checks, _ = verdict.lines()
    for line in checks:
        console.print(Text(line), highlight=False)
    console.print(
        Text.assemble(
            ("verdict: ", "bold"), (verdict.text, f"bold {_LEVEL_STYLE[verdict.level]}"), tail
        ),
        highlight=False,
    )


def _print_determined(folder: Path) -> None:
    """Which parameters the data determine, from a finished study's results (nothing while it
    runs): an undetermined parameter's value above is one of many equally good ones."""
    from parcelfit.sim.params import catalogue_unit, to_catalogue_units
    from parcelfit.study.results import read_results

    try:
        results = read_results(folder)
    except ParcelfitError:
        return
    ident = None if results is None else results.identifiability
    if ident is None:
        return
    words = []
    for p in ident.parameters:
        lo, hi = (float(to_catalogue_units(p.name, v)) for v in p.interval)
        unit = catalogue_unit(p.name)
        unit = "" if unit in ("-", "SI") else f" {unit}"
        if p.determined:
            words.append(f"{p.name} determined: {(lo + hi) / 2:.4g} +- {(hi - lo) / 2:.2g}{unit}")
        elif p.verdict == "undetermined":
            words.append(f"{p.name} NOT determined (its value above is as good as any in range)")
        else:
            words.append(f"{p.name} {p.verdict}: {lo:.4g} - {hi:.4g}{unit}")
    console.print(Text("what the data determine: " + "; ".join(words)), markup=False)


def _verdict_word(v: ValidationStatus) -> str:
    if v.status == "pending":
        return "pending (running, or interrupted: resumes with calibrate)"
    if v.status != "ok":
        return f"failed (the simulation ended {v.status})"
    return "passed" if v.passed else "failed"


def _progress_bar(job: str) -> tuple[Progress, ProgressCallback]:
    """A progress bar and the callback that drives it: on a terminal the bar appears with the
    first event (not before the inputs are checked); when the output goes to a log or CI, one
    line per event (`_progress`'s convention). Stop the bar when the job ends."""
    bar = Progress(*Progress.get_default_columns(), TimeElapsedColumn(), console=console)
    task = bar.add_task(job, total=None)

    def show(event: ProgressEvent) -> None:
        if not console.is_terminal:
            console.print(Text(event.message), highlight=False)
            return
        bar.start()
        bar.update(task, description=event.message, completed=event.done, total=event.total)

    return bar, show


@app.command()
def predict(
    study_dir: Annotated[
        Path, typer.Argument(help="A finished calibration's folder (or the demo's folder).")
    ],
    rig: Annotated[
        str, typer.Option(help="Bundled rig name (E1, E2a, E2b, E3) or a rig .yaml file.")
    ],
    consignment: Annotated[
        str,
        typer.Option(
            help="Bundled consignment type (KPBW, PB, KP, BW) or a consignment .yaml file."
        ),
    ],
    setting: SettingOption = 1,
    sets: Annotated[
        int, typer.Option(min=1, help="Parameter sets drawn from the plausible set.")
    ] = 20,
    placements: Annotated[
        int, typer.Option(min=1, help="Seeded placements simulated per parameter set.")
    ] = 10,
    seed: Annotated[
        int, typer.Option(min=0, help="Seed of the drawn sets and the placements.")
    ] = 0,
    out: Annotated[
        Path | None,
        typer.Option(help="Output folder (default: predict-RIG-TYPE-SETTING in the study folder)."),
    ] = None,
    table_format: TableFormatOption = "csv",
    executor: AnyExecutorOption = "local",
    scheduler: SchedulerOption = None,
    workers: WorkersOption = None,
) -> None:
    """Predict a design from a calibration: parameter sets the data cannot rule out times seeded
    placements; the predictive distributions of transit time, rotation, exit position and
    heading, how much of their spread the parameters cause, and what each undetermined
    parameter moves. Rerunning the same command resumes."""
    from parcelfit.report.prediction import PAGE_FILE, terminal_table, write_prediction_page
    from parcelfit.study.predict import PREDICT_STORE
    from parcelfit.study.predict import predict as run_prediction

    _check_executor(executor, ("serial", "local", "dask"))
    _workers_at_most(workers)
    _check_paths(out)
    _resumes() if out is None else _resumes(_stored(out / PREDICT_STORE, "screen", "simulations"))
    # the bar appears with the first simulation, not before the inputs are checked
    bar, show = _progress_bar("predict")
    try:
        prediction = run_prediction(
            study_dir,
            rig,
            consignment,
            setting,
            sets=sets,
            placements=placements,
            seed=seed,
            out=out,
            executor=executor,
            workers=workers,
            scheduler=scheduler,
            table_format=table_format,
            progress=show,
            on_cost=lambda line: console.print(Text(line, style="cyan"), highlight=False),
        )
    finally:
        bar.stop()
    assert prediction.out is not None
    page = write_prediction_page(prediction, prediction.out / PAGE_FILE)
    console.print(terminal_table(prediction))
    for line in prediction.notes:
        console.print(Text(f"note: {line}", style="yellow"), highlight=False)
    for line in prediction.sentences:
        console.print(Text(line), highlight=False)
    console.print(Text(f"wrote {prediction.out} (tables, prediction.json) and {page}"))


@app.command()
def design(
    study_dir: Annotated[
        Path, typer.Argument(help="A finished calibration's folder (or the demo's folder).")
    ],
    candidate: Annotated[
        list[str] | None,
        typer.Option(
            metavar="RIG/TYPE/SETTING",
            help="A candidate test case (repeatable; default: every bundled rig x setting x "
            "consignment type).",
        ),
    ] = None,
    rig: Annotated[
        list[str] | None,
        typer.Option(
            metavar="RIG.yaml",
            help="A rig file whose settings x every bundled type are candidates too, e.g. a "
            "bench test of examples/bench/ (repeatable).",
        ),
    ] = None,
    sets: Annotated[
        int, typer.Option(min=2, help="Parameter sets drawn from the plausible set.")
    ] = 10,
    placements: Annotated[
        int, typer.Option(min=1, help="Seeded placements simulated per set and candidate.")
    ] = 5,
    runs: Annotated[
        int, typer.Option(min=1, help="Real runs the expected interval widths assume.")
    ] = 10,
    seed: Annotated[
        int, typer.Option(min=0, help="Seed of the drawn sets and the placements.")
    ] = 0,
    out: Annotated[
        Path | None, typer.Option(help="Output folder (default: design in the study folder).")
    ] = None,
    table_format: TableFormatOption = "csv",
    executor: AnyExecutorOption = "local",
    scheduler: SchedulerOption = None,
    workers: WorkersOption = None,
) -> None:
    """Rank candidate experiments by how much each would narrow the intervals of the
    parameters the calibration leaves open: the expected interval after --runs real runs and
    the runs each needs. Rerunning the same command resumes."""
    from parcelfit.report.prediction import design_tables
    from parcelfit.study.design import DESIGN_STORE, rank_experiments

    _check_executor(executor, ("serial", "local", "dask"))
    _workers_at_most(workers)
    _check_paths(out)
    _resumes() if out is None else _resumes(_stored(out / DESIGN_STORE, "screen", "simulations"))
    bar, show = _progress_bar("design")
    try:
        result = rank_experiments(
            study_dir,
            candidates=candidate or (),
            rig_files=rig or (),
            sets=sets,
            placements=placements,
            runs=runs,
            seed=seed,
            out=out,
            executor=executor,
            workers=workers,
            scheduler=scheduler,
            table_format=table_format,
            progress=show,
            on_cost=lambda line: console.print(Text(line, style="cyan"), highlight=False),
        )
    finally:
        bar.stop()
    if not result.parameters:
        console.print("every calibrated parameter is determined: no further experiment needed")
        return
    for table in design_tables(result):
        console.print(table)
    console.print(Text(f"wrote {result.out} (candidates, ranking, design.json)"))


def main() -> None:
    """Entry point of the ``parcelfit`` console script."""
    app()


if __name__ == "__main__":
    main()
