"""After a calibration: what it predicts for a design it was not fitted on, and which experiment
would narrow its open parameters most."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer
from rich.text import Text

from parcelfit.cli.options import (
    AnyExecutorOption,
    SchedulerOption,
    SettingOption,
    SpeedDeviationOption,
    TableFormatOption,
    WorkersOption,
    check_executor,
    check_paths,
    workers_at_most,
)
from parcelfit.cli.output import console, elapsed_text, progress_bar, resumes, stored_count
from parcelfit.study.defaults import (
    DESIGN_PLACEMENTS,
    NUMERICAL_RUNS,
    PREDICT_PLACEMENTS,
    SCATTER_RUNS,
)


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
        int | None,
        typer.Option(
            min=1,
            show_default=False,
            help=f"Seeded placements simulated per parameter set [default: {PREDICT_PLACEMENTS}; "
            "1 for a simulator that cannot place its runs, such as an external solver].",
        ),
    ] = None,
    seed: Annotated[
        int, typer.Option(min=0, help="Seed of the drawn sets and the placements.")
    ] = 0,
    speed_deviation: SpeedDeviationOption = 0.03,
    scatter_runs: Annotated[
        int,
        typer.Option(
            min=2,
            help="Runs of the recommended parameters per fitted and validation case, for the "
            "real runs' scatter.",
        ),
    ] = SCATTER_RUNS,
    numerical_runs: Annotated[
        int,
        typer.Option(
            min=0,
            help="Placements at which the recommended parameters run on the design by the "
            "model and the refined model, for the model's numerical error (0: none).",
        ),
    ] = NUMERICAL_RUNS,
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

    check_executor(executor, ("serial", "local", "dask"))
    workers_at_most(workers)
    check_paths(out)
    resumes() if out is None else resumes(
        stored_count(out / PREDICT_STORE, "screen", "simulations")
    )
    # the bar appears with the first simulation, not before the inputs are checked
    started = time.perf_counter()
    bar, show = progress_bar("predict")
    try:
        prediction = run_prediction(
            study_dir,
            rig,
            consignment,
            setting,
            sets=sets,
            placements=placements,
            seed=seed,
            speed_deviation=speed_deviation,
            scatter_runs=scatter_runs,
            numerical_runs=numerical_runs,
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
    console.print(
        Text(
            f"wrote {prediction.out} (tables, prediction.json) and {page} in "
            f"{elapsed_text(started)} (this run's wall time)"
        )
    )


def design(
    study_dir: Annotated[
        Path, typer.Argument(help="A finished calibration's folder (or the demo's folder).")
    ],
    candidate: Annotated[
        list[str] | None,
        typer.Option(
            metavar="RIG/TYPE/SETTING",
            help="A candidate test case (repeatable; default: every rig x setting x type, the "
            "rigs being the bundled ones, the study's rig files and --rig's, the types the "
            "bundled ones and the study's consignment file).",
        ),
    ] = None,
    rig: Annotated[
        list[str] | None,
        typer.Option(
            metavar="RIG.yaml",
            help="A rig file whose settings x every type are candidates too, e.g. a bench "
            "test of examples/bench/ (repeatable).",
        ),
    ] = None,
    sets: Annotated[
        int, typer.Option(min=2, help="Parameter sets drawn from the plausible set.")
    ] = 20,
    placements: Annotated[
        int | None,
        typer.Option(
            min=1,
            show_default=False,
            help=f"Seeded placements simulated per set and candidate [default: {DESIGN_PLACEMENTS}; "
            "1 for a simulator that cannot place its runs, such as an external solver].",
        ),
    ] = None,
    runs: Annotated[
        int, typer.Option(min=1, help="Real runs the expected interval widths assume.")
    ] = 10,
    seed: Annotated[
        int, typer.Option(min=0, help="Seed of the drawn sets and the placements.")
    ] = 0,
    speed_deviation: SpeedDeviationOption = 0.03,
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

    check_executor(executor, ("serial", "local", "dask"))
    workers_at_most(workers)
    check_paths(out)
    resumes() if out is None else resumes(stored_count(out / DESIGN_STORE, "screen", "simulations"))
    started = time.perf_counter()
    bar, show = progress_bar("design")
    try:
        result = rank_experiments(
            study_dir,
            candidates=candidate or (),
            rig_files=rig or (),
            sets=sets,
            placements=placements,
            runs=runs,
            seed=seed,
            speed_deviation=speed_deviation,
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
    for line in result.notes:
        console.print(Text(f"note: {line}", style="yellow"), highlight=False)
    console.print(
        Text(
            f"wrote {result.out} (candidates, ranking, design.json) in {elapsed_text(started)} "
            "(this run's wall time)"
        )
    )
