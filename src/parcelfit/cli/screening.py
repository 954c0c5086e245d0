"""Before a calibration: the screening of parameters and the precision check (what a study's
test cases can determine)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table
from rich.text import Text

from parcelfit.cli.options import (
    ExecutorOption,
    WorkersOption,
    check_executor,
    workers_at_most,
)
from parcelfit.cli.output import console, cost_first, resumes, status_progress, stored_count


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

    check_executor(executor, ("serial", "local"))
    from parcelfit.study.estimate import screen_cost_line

    workers_at_most(workers)
    spec = load_screen(screen_file)
    folder = out or screen_file.parent / screen_file.stem
    resumes(stored_count(folder / "screen.sqlite", "screen", "simulations"))
    cost = screen_cost_line(spec, executor, workers)
    with console.status("screening") as status_line:
        stages, selection = run_screen(
            spec,
            folder,
            executor=executor,
            workers=workers,
            progress=cost_first(cost, status_progress(status_line, "screening: ")),
        )
    print_screen(stages, selection)
    console.print(Text(f"results in {folder} (selection.yaml, stageN-effects.csv, Pareto charts)"))


def print_screen(stages: Any, selection: dict[str, Any]) -> None:
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
                f"{', '.join(a.response for a in stage.ensemble_analyses)} (over each run's "
                "placements) are shown; the selection is made on dtw_xy and dtw_theta"
            )
    chosen, significant = selection["selected"], selection.get("significant", [])
    console.print(
        f"[bold]selected for calibration:[/] {', '.join(chosen) or 'none'}"
        + (
            " (the largest effects, at most `select` of them; "
            f"{len(significant)} of the {len(chosen)} significant"
            + (f": {', '.join(significant)})" if significant else ")")
            if chosen
            else ""
        ),
        markup=True,
    )


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
    from parcelfit.sim.params import parse_assignments
    from parcelfit.study.estimate import precision_cost_line
    from parcelfit.study.precision import half_width_text
    from parcelfit.study.precision_check import command_line, run_precision_check, stored_runs
    from parcelfit.study.studyfile import load_study

    check_executor(executor, ("serial", "local"))
    workers_at_most(workers)
    folder = out or study_file.parent / f"{study_file.stem}-precision"
    study = load_study(study_file)
    cost = precision_cost_line(study, placements, candidate or [], executor, workers)

    resumes(lambda: f"{stored_runs(folder)} simulations stored")
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
            progress=cost_first(cost, status_progress(status_line, "precision check: ")),
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
    tables = check.write_tables(folder, command, workers)
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
    console.print(Text(f"tables in {tables}"))
