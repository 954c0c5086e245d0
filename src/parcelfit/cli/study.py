"""A calibration study's commands: calibrate (with its live table), status and the HTML report.
Each reads or runs the study through `parcelfit.study.outcome` and prints the typed record it
returns (`parcelfit.cli.output.print_outcome`, `print_summary`, `print_verdict`)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.text import Text

from parcelfit.cli.options import WorkersOption, check_executor, workers_at_most
from parcelfit.cli.output import (
    CalibrationDisplay,
    console,
    iterations_text,
    print_outcome,
    print_summary,
    print_synthetic,
    print_verdict,
    resumes,
    status_progress,
    stored_count,
)

if TYPE_CHECKING:
    from parcelfit.study.status import ValidationStatus


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
    from parcelfit.study.outcome import calibrate_study
    from parcelfit.study.store import STORE_FILE

    check_executor(executor, ("serial", "local", "dask"))
    workers_at_most(workers)
    folder = out or study_file.parent / study_file.stem
    resumes(stored_count(folder / STORE_FILE, "fit", "evaluations"))
    with CalibrationDisplay(console) as display:
        outcome = calibrate_study(
            study_file,
            folder,
            executor=executor,
            scheduler=scheduler,
            workers=workers,
            animation=animation,
            restart=restart,
            started=display.started,
            progress=display.update,
        )
    print_outcome(console, outcome)


def status(
    study_dir: Annotated[
        Path,
        typer.Argument(
            help="Study folder (holding study.sqlite), or a demo's folder (its calibration/)."
        ),
    ],
    as_json: Annotated[bool, typer.Option("--json", help="Print machine-readable JSON.")] = False,
) -> None:
    """Show the state of a running or finished calibration study."""
    from parcelfit.study.outcome import study_summary
    from parcelfit.study.status import study_folder

    summary = study_summary(study_folder(study_dir))
    info = summary.status
    if as_json:
        sys.stdout.write(json.dumps(info.to_json(), indent=1) + "\n")
        return
    record = info.study or {}
    name = record.get("name", "?")
    print_synthetic(console, info)
    counts = ", ".join(f"{n} {s}" for s, n in info.by_status.items())
    console.print(
        Text.assemble(
            (str(name), "bold"),
            f": {info.evaluations} evaluations" + (f" ({counts})" if counts else ""),
            f", {iterations_text(info.last_iteration)}",
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
    print_summary(console, summary)
    print_verdict(console, summary.verdict)


def _verdict_word(v: ValidationStatus) -> str:
    if v.status == "pending":
        return "pending (running, or interrupted: resumes with calibrate)"
    if v.status != "ok":
        return f"failed (the simulation ended {v.status})"
    return "passed" if v.passed else "failed"


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
    from parcelfit.study.status import folder_verdict

    with console.status("report") as status_line:
        path = build_report(
            folder,
            out=out,
            screen=screen,
            key_frames=frames,
            animation=animation,
            progress=status_progress(status_line, "report: "),
        )
    console.print(f"[bold green]report:[/] {escape(str(path.resolve()))}")
    print_verdict(console, folder_verdict(folder))
