"""What several commands share: their option types (executor, workers, speed setting, table
format) and the checks of option values made before any work starts."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer

from parcelfit.errors import ParcelfitError

DatasetArg = Annotated[Path, typer.Argument(help="Dataset folder (holding dataset.yaml).")]
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


SpeedDeviationOption = Annotated[
    float,
    typer.Option(
        min=0.0,
        max=0.99,
        help="Short-term deviation of every drive from its mean speed, as a fraction: each "
        "placement draws its drives' speeds from mean x (1 +- this), uniformly. 0: drives at "
        "their mean speeds.",
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


def worker_count(workers: int | None) -> int:
    """The worker processes a local executor uses: ``workers``, else one per core."""
    return workers or os.cpu_count() or 1


def at_most(value: int | None, option: str, bound: int) -> None:
    """A clear error for a count option (``--workers``, ``--repeat``, ...) above ``bound``."""
    if value is not None and value > bound:
        raise ParcelfitError(
            f"{option} {value} is more than {bound}", fix=f"use {option} {bound} or less"
        )


def workers_at_most(workers: int | None) -> None:
    from parcelfit.sim.executors import MAX_WORKERS

    at_most(workers, "--workers", MAX_WORKERS)


def check_executor(kind: str | None, kinds: tuple[str, ...]) -> None:
    """A clear error for an --executor that this command cannot use."""
    if kind is not None and kind not in kinds:
        raise ParcelfitError(
            f"unknown executor {kind!r} for this command", fix=f"use {' or '.join(kinds)}"
        )


def check_paths(*paths: Path | None) -> None:
    """Refuse at once, before any work, an output path the file system cannot hold (too long:
    the command group shows the error as one line); the paths are not created."""
    for path in paths:
        if path is not None:
            path.exists()  # raises OSError (ENAMETOOLONG) for a path too long
