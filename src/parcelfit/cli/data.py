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
        if len(sel.run_ids) == 1:
            console.print(
                Text(
                    f"{sel.case.label} has one run: it is the reference without a comparison "
                    "(record more runs for a reference that represents the case)",
                    style="yellow",
                )
            )


def _rate(value: float) -> float:
    """--alpha: a rate strictly between 0 and 1."""
    if not 0.0 < value < 1.0:
        raise typer.BadParameter(f"{value:g} is not between 0 and 1 (e.g. 0.05)")
    return value


def stats(
    dataset: DatasetArg,
    out: Annotated[Path, typer.Option("--out", help="Folder for tables and box plots.")] = Path(
        "stats"
    ),
    alpha: Annotated[
        float,
        typer.Option(
            callback=_rate, help="False discovery rate for Benjamini-Hochberg, between 0 and 1."
        ),
    ] = 0.05,
    family: Annotated[
        str, typer.Option(help="Adjust per 'rig_setting' or over 'all' tests.")
    ] = "rig_setting",
) -> None:
    """Compare transit times between consignment types (Mann-Whitney U + Benjamini-Hochberg)."""
    from parcelfit.analysis import transit_statistics
    from parcelfit.errors import ParcelfitError
    from parcelfit.runs import load_dataset
    from parcelfit.runs.dataset import dataset_file
    from parcelfit.stats.transit import transit_time_table

    ds = load_dataset(dataset)
    print_dataset(ds)
    if transit_time_table(ds).empty:  # before any file is written
        raise ParcelfitError(
            "no run of this dataset has a transit time: nothing to compare",
            file=dataset_file(dataset),
            fix="give each run its transit_time [s] in the dataset file, or track the videos "
            "with light barriers in the tag map (or with --sensor-log)",
        )
    result = transit_statistics(ds, out, alpha=alpha, family=family)
    if result.tests.empty:
        console.print(
            "[yellow]no rig and speed setting holds two consignment types with transit times: "
            "nothing to compare[/]"
        )
    else:
        _print_tests(result.tests, alpha)
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


def _print_tests(tests: Any, alpha: float) -> None:
    """The table of the pairwise tests, with a note on pairs too small to reach ``alpha``."""
    from parcelfit.stats import significance_stars
    from parcelfit.stats.transit import smallest_p_value

    table = Table(
        title="Transit-time comparisons (two-sided Mann-Whitney U, BH-adjusted)",
        title_justify="left",
    )
    cols = ("rig", "setting", "A", "B", "n A", "n B", "median A [s]", "median B [s]", "p", "p adj.")
    for col in (*cols, ""):
        table.add_column(escape(col), justify="right" if col not in ("rig", "A", "B") else "left")
    small = []
    for _, r in tests.iterrows():
        table.add_row(
            r["rig"],
            str(r["speed_setting"]),
            r["type_a"],
            r["type_b"],
            str(r["n_a"]),
            str(r["n_b"]),
            f"{r['median_a_s']:.3f}",
            f"{r['median_b_s']:.3f}",
            f"{r['p_value']:.2g}",
            f"{r['p_adjusted']:.2g}",
            significance_stars(r["p_adjusted"]),
        )
        floor = smallest_p_value(int(r["n_a"]), int(r["n_b"]))
        if r["method"] == "exact" and floor > alpha:  # tied data take the asymptotic test
            small.append(f"{r['type_a']} ({r['n_a']}) vs {r['type_b']} ({r['n_b']}): {floor:.2g}")
    console.print(table)
    if small:
        console.print(
            Text(
                f"too few runs to reach {alpha:g} whatever the data (the smallest two-sided p "
                f"these counts allow): {'; '.join(small)}. Record more runs of those types.",
                style="yellow",
            )
        )
