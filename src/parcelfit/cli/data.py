"""A dataset's commands: the reference run of every test case and the transit-time statistics."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table
from rich.text import Text

from parcelfit.cli.options import DatasetArg
from parcelfit.cli.output import console, err_console


def reference(
    dataset: DatasetArg,
    as_json: Annotated[bool, typer.Option("--json", help="Print machine-readable JSON.")] = False,
) -> None:
    """Choose each test case's reference run (DTW distance matrices, method section 4)."""
    from parcelfit.analysis import reference_runs, reference_runs_doc
    from parcelfit.runs import load_dataset
    from parcelfit.runs.dataset import SYNTHETIC_NOTE

    ds = load_dataset(dataset)
    selections = reference_runs(ds)
    if as_json:
        if ds.synthetic:  # stdout stays JSON; every object also carries "synthetic": true
            err_console.print(Text(f"note: dataset {ds.name} is {SYNTHETIC_NOTE}"))
        sys.stdout.write(json.dumps(reference_runs_doc(selections, ds), indent=1) + "\n")
        return
    print_dataset(ds)
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
    print_dataset(ds)
    result = transit_statistics(ds, out, alpha=alpha, family=family)
    _print_tests(result.tests)
    for f in result.files:
        console.print(Text(f"wrote {f}"))


def print_dataset(ds: Any) -> None:
    """One line naming the dataset, its size and, for synthetic data, that it is SYNTHETIC."""
    from parcelfit.runs.dataset import SYNTHETIC_NOTE

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
