"""Analysis of a dataset of real runs: transit-time statistics and reference runs, written to files.

Output files (in the folder given):

* ``transit_times.csv``: rig, consignment, speed_setting, run_id, transit_time_s
* ``transit_time_tests.csv``: the pairwise Mann-Whitney U tests (see `parcelfit.stats.transit`)
* ``transit_times.png`` / ``.svg``: box plots with significance brackets
* ``reference_runs.json``: per test case the reference run, row sums, matrices and their scales
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from parcelfit.figures import save_figure
from parcelfit.metrics import ReferenceSelection, select_reference
from parcelfit.runs import Dataset, TestCase
from parcelfit.stats import compare_transit_times, transit_time_boxplots, transit_time_table


@dataclass(frozen=True)
class StatsResult:
    """Transit times, pairwise tests and the files written."""

    times: pd.DataFrame
    tests: pd.DataFrame
    files: list[Path]


def transit_statistics(
    dataset: Dataset, out: Path, alpha: float = 0.05, family: str = "rig_setting"
) -> StatsResult:
    """Run the pairwise transit-time tests and write the tables and box plots into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    times = transit_time_table(dataset)
    tests = compare_transit_times(dataset, alpha=alpha, family=family)
    files = [out / "transit_times.csv", out / "transit_time_tests.csv"]
    times.to_csv(files[0], index=False)
    tests.to_csv(files[1], index=False)
    if not times.empty:
        files += save_figure(
            transit_time_boxplots(times, tests, dataset_title(dataset)), out / "transit_times"
        )
    return StatsResult(times, tests, files)


def dataset_title(dataset: Dataset) -> str:
    """Title for figures: the dataset's name, marked SYNTHETIC where it was not measured."""
    return f"{dataset.name} (SYNTHETIC data)" if dataset.synthetic else dataset.name


def reference_runs(dataset: Dataset) -> dict[TestCase, ReferenceSelection]:
    """The reference run of every test case (section 4), with each case's regions of interest."""
    return {case: select_reference(dataset.cases[case]) for case in sorted(dataset.cases)}


def reference_runs_doc(
    selections: dict[TestCase, ReferenceSelection], dataset: Dataset
) -> list[dict[str, object]]:
    """The selections as JSON-ready objects, one per test case, each naming its dataset and
    whether the data are synthetic."""
    return [
        {"dataset": dataset.name, "synthetic": dataset.synthetic, **s.to_dict()}
        for s in selections.values()
    ]


def write_reference_runs(
    selections: dict[TestCase, ReferenceSelection], dataset: Dataset, path: Path
) -> Path:
    """Write the selections as JSON (a list, one object per test case, see `reference_runs_doc`)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(reference_runs_doc(selections, dataset), indent=1), encoding="utf-8")
    return path
