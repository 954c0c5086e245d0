"""The ``parcelfit`` command: a thin layer over the package's functions."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.table import Table

from parcelfit import __version__
from parcelfit.errors import ParcelfitError

app = typer.Typer(
    name="parcelfit",
    help="Calibrate physics simulations of parcels with flexible packaging against tracked experiments.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console()
err_console = Console(stderr=True)
F = TypeVar("F", bound=Callable[..., Any])


def friendly_errors(func: F) -> F:
    """Show a `ParcelfitError` as one red message and exit with status 2, without a traceback."""

    @wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except ParcelfitError as exc:
            err_console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
            raise typer.Exit(code=2) from None

    return wrapper  # type: ignore[return-value]


DatasetArg = Annotated[Path, typer.Argument(help="Dataset folder (holding dataset.yaml).")]


@app.command()
@friendly_errors
def version() -> None:
    """Print parcelfit's version."""
    console.print(f"parcelfit {__version__}")


@app.command()
@friendly_errors
def reference(
    dataset: DatasetArg,
    as_json: Annotated[bool, typer.Option("--json", help="Print machine-readable JSON.")] = False,
) -> None:
    """Choose each test case's reference run (DTW distance matrices, method section 4)."""
    from parcelfit.analysis import reference_runs
    from parcelfit.runs import load_dataset

    selections = reference_runs(load_dataset(dataset))
    if as_json:
        sys.stdout.write(json.dumps([s.to_dict() for s in selections.values()], indent=1) + "\n")
        return
    for sel in selections.values():
        table = Table(
            title=f"{sel.case.label}: reference run [bold]{sel.reference_id}[/]",
            title_justify="left",
        )
        table.add_column("run")
        table.add_column("row sum of D_combined", justify="right")
        table.add_column("transit time [s]", justify="right")
        for i, run_id in enumerate(sel.run_ids):
            mark = " *" if i == sel.index else ""
            tt = sel.transit_times[i]
            table.add_row(
                run_id + mark, f"{sel.row_sums[i]:.3f}", "-" if tt is None else f"{tt:.3f}"
            )
        console.print(table)


@app.command()
@friendly_errors
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

    result = transit_statistics(load_dataset(dataset), out, alpha=alpha, family=family)
    _print_tests(result.tests)
    for f in result.files:
        console.print(f"wrote {f}")


def _print_tests(tests: Any) -> None:
    from parcelfit.stats import significance_stars

    table = Table(
        title="Transit-time comparisons (two-sided Mann-Whitney U, BH-adjusted)",
        title_justify="left",
    )
    for col in ("rig", "setting", "A", "B", "median A [s]", "median B [s]", "p", "p adj.", ""):
        table.add_column(col, justify="right" if col not in ("rig", "A", "B") else "left")
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


@app.command()
@friendly_errors
def demo(
    out: Annotated[
        Path, typer.Option("--out", help="Folder for everything the demo writes.")
    ] = Path("parcelfit-demo"),
) -> None:
    """Run the analysis on the bundled SYNTHETIC example dataset: statistics and reference runs."""
    from parcelfit.analysis import reference_runs, transit_statistics, write_reference_runs
    from parcelfit.data import example_dataset_path
    from parcelfit.runs import load_dataset

    path = example_dataset_path()
    with console.status("loading the bundled example dataset"):
        ds = load_dataset(path)
    console.print(
        f"[bold]dataset[/] {ds.name}: {len(ds.cases)} test cases, {len(ds.runs())} runs "
        "[yellow](SYNTHETIC: simulated, not measured)[/]"
    )
    with console.status("transit-time statistics"):
        result = transit_statistics(ds, out / "stats")
    _print_tests(result.tests)
    with console.status("reference runs (DTW distance matrices)"):
        selections = reference_runs(ds)
    table = Table(title="Reference run per test case", title_justify="left")
    for col in (
        "test case",
        "reference run",
        "runs",
        "largest DTW_xy [m]",
        "largest DTW_theta [rad]",
    ):
        table.add_column(col)
    for s in selections.values():
        table.add_row(
            s.case.label,
            s.reference_id,
            str(len(s.run_ids)),
            f"{s.max_xy**0.5:.3f}",
            f"{s.max_theta**0.5:.3f}",
        )
    console.print(table)
    ref_file = write_reference_runs(selections, out / "reference_runs.json")
    console.print(f"[green]done[/]: results in {out}/ ({ref_file.name}, stats/)")


def main() -> None:
    """Entry point of the ``parcelfit`` console script."""
    app()


if __name__ == "__main__":
    main()
