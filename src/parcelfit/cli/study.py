"""A calibration study's commands: calibrate (with its live table), status and the HTML report,
and what they print of a study: the recommended parameters, what the data determine and the
verdict."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table
from rich.text import Text

from parcelfit.cli.options import WorkersOption, check_executor, workers_at_most
from parcelfit.cli.output import console, resumes, status_progress, stored_count
from parcelfit.errors import ParcelfitError
from parcelfit.progress import ProgressCallback, ProgressEvent

if TYPE_CHECKING:
    from parcelfit.study.details import CaseCost
    from parcelfit.study.status import StudyStatus, ValidationStatus


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

    check_executor(executor, ("serial", "local", "dask"))
    workers_at_most(workers)
    study = load_study(study_file)
    folder = out or study_file.parent / study_file.stem
    resumes(stored_count(folder / "study.sqlite", "fit", "evaluations"))
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

    calibrate_live(run, study.name, folder, cost)


def calibrate_live(
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
    print_verdict(folder)
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


def _print_parts(parts: list[CaseCost]) -> None:
    """The per-case parts of a joint or ensemble evaluation's cost."""
    table = Table(title=Text("its cost, case by case"), title_justify="left")
    for col in ("case", "weight", "cost", "parts"):
        table.add_column(col, justify="left" if col in ("case", "parts") else "right")
    for p in parts:
        if p.trajectory_term is not None:
            se = "" if p.se is None else f" (se {p.se:.3g})"
            tt = "-" if p.transit_term is None else f"{p.transit_term:.3g}"
            adjusted = " (adjusted times)" if p.adjusted_transit_times is not None else ""
            what = f"trajectories {p.trajectory_term:.3g}{se}, transit {tt}{adjusted}"
            what += f", {len(p.seeds)} placements"
        else:
            what = f"DTW_xy {p.dtw_xy:.3g} m, DTW_theta {p.dtw_theta:.3g} rad"
        table.add_row(p.case, f"{p.weight:g}", f"{p.cost:.4g}", what)
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
    print_verdict(study_dir)


_LEVEL_STYLE = {"trustworthy": "green", "incomplete": "yellow", "not trustworthy": "red"}


def print_verdict(folder: Path, tail: str = "") -> None:
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
            progress=status_progress(status_line, "report: "),
        )
    console.print(f"[bold green]report:[/] {escape(str(path.resolve()))}")
    print_verdict(folder)

