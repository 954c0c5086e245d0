"""The demo command: every stage on the bundled SYNTHETIC twin dataset, each result printed as
it comes."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from parcelfit.cli.data import print_dataset
from parcelfit.cli.options import WorkersOption, check_executor, worker_count, workers_at_most
from parcelfit.cli.output import (
    CalibrationDisplay,
    console,
    print_outcome,
    print_verdict,
    resumes,
    say_cost,
    status_progress,
)
from parcelfit.cli.screening import print_screen
from parcelfit.errors import ParcelfitError


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
    transfer check on E1, the convergence check on both), up to about 25 minutes on 2 cores.
    --quick: an 8-run screen and at most 16
    evaluations, about 5 minutes. --full: the published protocol (fractional then full
    factorial screen, at most 80 evaluations), 25 minutes or more: the calibration stops when
    its validation passes. The expected cost is printed before the simulations start."""
    import time

    from parcelfit.demo import STAGES, Demo
    from parcelfit.study.folderlock import check_writable
    from parcelfit.study.outcome import CalibrationStart, calibration_outcome
    from parcelfit.study.status import folder_verdict
    from parcelfit.study.store import STORE_FILE
    from parcelfit.study.studyfile import load_study

    if quick and full:
        raise ParcelfitError("--quick and --full exclude each other", fix="choose one")
    check_executor(executor, ("serial", "local"))
    resumes()
    workers_at_most(workers)
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
    print_dataset(ds)
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
    say_cost(d.expected_cost(worker_count(workers)))
    rule(3, f" (profile {d.profile.name})")
    with console.status("screening") as status_line:
        stages, selection = d.screen(status_progress(status_line, "screening: "))
    print_screen(stages, selection)
    rule(4)
    folder = out / "calibration"
    check_writable(folder, (STORE_FILE,))  # before the live display starts
    with CalibrationDisplay(console) as display:
        display.started(CalibrationStart(load_study(d.files[1]).name, folder, None))
        result = d.calibration(display.update)
    print_outcome(console, calibration_outcome(result))
    rule(5)
    with console.status("simulating the polybag example"):
        example = d.stricter_example()
    console.print(example["description"])
    rule(6)
    with console.status("report") as status_line:
        report = d.report(status_progress(status_line, "report: "))
    minutes = (time.perf_counter() - t0) / 60
    console.print(f"[bold green]report:[/] {escape(str(report.resolve()))}")
    print_verdict(console, folder_verdict(out), f" ({minutes:.1f} min)")
