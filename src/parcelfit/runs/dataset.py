"""Datasets of runs on disk: a folder with ``dataset.yaml`` and one trajectory file per run.

``dataset.yaml``::

    name: my-experiments            # required
    description: free text          # optional
    synthetic: false                # optional; true marks data that was not measured
    test_cases:                     # required, one entry per test case
      - rig: E3                     # required
        consignment: KPBW           # required
        speed_setting: 1            # required, integer >= 1
        regions:                    # optional, regions of interest (see parcelfit.runs.regions)
          - {x: [0.2, 1.4]}
        margin: 0.02                # optional, safety margin around the regions [m]
        runs:                       # required, at least one
          - id: E3-KPBW-1-01        # required, unique in the dataset
            file: runs/E3-KPBW-1-01.csv   # required, inside the folder (.csv or .parquet)
            transit_time: 1.234     # optional [s]; null where no light barrier was crossed

Trajectory files follow the schema of `parcelfit.runs.io`. A run file must lie inside the
dataset folder (no absolute paths, no ``..`` leading out, no symbolic link pointing out), and
every run has its own file.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from parcelfit.atomic import write_text_atomic
from parcelfit.config import check_keys, get_number, get_str, load_yaml, require_mapping
from parcelfit.errors import ParcelfitError, shown
from parcelfit.runs.io import read_trajectory, write_trajectory
from parcelfit.runs.regions import Box, Polygon, Region, parse_region
from parcelfit.runs.run import MAX_SPEED_SETTING, Run, TestCase

DATASET_FILE = "dataset.yaml"
MAX_TRANSIT_TIME_S = 600.0  # a parcel crosses a test rig in seconds; more is a unit mistake
_TOP_KEYS = ("name", "description", "synthetic", "test_cases")
_CASE_KEYS = ("rig", "consignment", "speed_setting", "regions", "margin", "runs")
_RUN_KEYS = ("id", "file", "transit_time")


@dataclass(frozen=True)
class CaseData:
    """The runs of one test case and the regions of interest used to compare them."""

    case: TestCase
    runs: tuple[Run, ...]
    regions: tuple[Region, ...] = ()
    margin: float = 0.0

    def run(self, run_id: str) -> Run:
        """The run with this id."""
        for r in self.runs:
            if r.id == run_id:
                return r
        raise ParcelfitError(f"no run {run_id!r} in test case {self.case.label}")


@dataclass(frozen=True)
class Dataset:
    """Runs grouped by test case, as loaded from a dataset folder."""

    name: str
    cases: dict[TestCase, CaseData]
    description: str = ""
    synthetic: bool = False
    root: Path | None = field(default=None, compare=False)

    def __getitem__(self, case: TestCase | str) -> CaseData:
        key = TestCase.parse(case) if isinstance(case, str) else case
        if key not in self.cases:
            known = ", ".join(c.label for c in sorted(self.cases))
            raise ParcelfitError(
                f"test case {key.label} is not in dataset {self.name!r}", fix=f"use one of: {known}"
            )
        return self.cases[key]

    def runs(self) -> list[Run]:
        """All runs, test case by test case."""
        return [r for c in sorted(self.cases) for r in self.cases[c].runs]


SYNTHETIC_NOTE = "SYNTHETIC: simulated from hidden true parameters, not measured"
"""What every output that shows synthetic data says of them."""


def dataset_file(folder: str | Path) -> Path:
    """The ``dataset.yaml`` of a dataset given as its folder or as that file itself."""
    path = Path(folder)
    return path if path.is_file() else path / DATASET_FILE


def is_synthetic(folder: str | Path) -> bool | None:
    """Whether a dataset's ``dataset.yaml`` (the dataset given as its folder or that file)
    marks its data synthetic, without loading the runs (None when there is no readable
    ``dataset.yaml``)."""
    file = dataset_file(folder)
    try:
        doc = load_yaml(file)
    except (OSError, ParcelfitError):
        return None
    return isinstance(doc, dict) and doc.get("synthetic") is True


def read_truth(folder: str | Path, consignment: str) -> dict[str, float]:
    """The hidden true parameters of ``consignment`` (catalogue units) of a synthetic twin
    dataset, from the ``truth.yaml`` its maker wrote beside ``dataset.yaml``; empty when there
    is none (real data, or a type the twin does not hold)."""
    path = Path(folder) / "truth.yaml"
    if not path.is_file():
        return {}
    doc = load_yaml(path) or {}
    return {k: float(v) for k, v in (doc.get("truth", {}).get(consignment) or {}).items()}


def load_dataset(folder: str | Path) -> Dataset:
    """Load and check a dataset folder (or the path of its ``dataset.yaml``)."""
    file = dataset_file(folder)
    folder = file.parent
    if not file.is_file():
        raise ParcelfitError(
            f"no {DATASET_FILE} here",
            file=folder,
            fix=f"point at a folder that holds a {DATASET_FILE}",
        )
    doc = require_mapping(load_yaml(file), file=file, where="top level")
    check_keys(
        doc, allowed=_TOP_KEYS, required=("name", "test_cases"), file=file, where="top level"
    )
    name = get_str(doc, "name", file=file, where="")
    synthetic = doc.get("synthetic", False)
    if not isinstance(synthetic, bool):
        raise ParcelfitError(
            "synthetic must be true or false",
            file=file,
            where="synthetic",
            fix="write synthetic: true",
        )
    cases_doc = doc["test_cases"]
    if not isinstance(cases_doc, list) or not cases_doc:
        raise ParcelfitError(
            "test_cases must be a non-empty list",
            file=file,
            where="test_cases",
            fix="add `- rig: ...` entries",
        )
    cases: dict[TestCase, CaseData] = {}
    seen_ids: dict[str, str] = {}
    seen_files: dict[Path, str] = {}
    root = folder.resolve()
    for i, entry in enumerate(cases_doc):
        where = f"test_cases[{i}]"
        entry = require_mapping(entry, file=file, where=where)
        check_keys(
            entry,
            allowed=_CASE_KEYS,
            required=("rig", "consignment", "speed_setting", "runs"),
            file=file,
            where=where,
        )
        setting = entry["speed_setting"]
        if (
            isinstance(setting, bool)
            or not isinstance(setting, int)
            or not 1 <= setting <= MAX_SPEED_SETTING
        ):
            raise ParcelfitError(
                f"speed_setting must be an integer from 1 to {MAX_SPEED_SETTING}, "
                f"got {shown(setting)}",
                file=file,
                where=f"{where}.speed_setting",
                fix="write the rig's speed setting number, e.g. speed_setting: 1",
            )
        case = TestCase(
            get_str(entry, "rig", file=file, where=where),
            get_str(entry, "consignment", file=file, where=where),
            setting,
        )
        if case in cases:
            raise ParcelfitError(
                f"test case {case.label} appears twice",
                file=file,
                where=where,
                fix="merge the two entries into one",
            )
        regions_doc = entry.get("regions", []) or []
        if not isinstance(regions_doc, list):
            raise ParcelfitError(
                "regions must be a list",
                file=file,
                where=f"{where}.regions",
                fix="write regions: [{x: [min, max]}]",
            )
        regions = tuple(
            parse_region(r, file=str(file), where=f"{where}.regions[{k}]")
            for k, r in enumerate(regions_doc)
        )
        margin = get_number(
            entry, "margin", file=file, where=where, default=0.0, minimum=0.0, unit="m"
        )
        runs_doc = entry["runs"]
        if not isinstance(runs_doc, list) or not runs_doc:
            raise ParcelfitError(
                "runs must be a non-empty list",
                file=file,
                where=f"{where}.runs",
                fix="add `- id: ...` entries with file and transit_time",
            )
        runs = []
        for k, run_doc in enumerate(runs_doc):
            rwhere = f"{where}.runs[{k}]"
            run_doc = require_mapping(run_doc, file=file, where=rwhere)
            check_keys(run_doc, allowed=_RUN_KEYS, required=("id", "file"), file=file, where=rwhere)
            run_id = get_str(run_doc, "id", file=file, where=rwhere)
            if run_id in seen_ids:
                raise ParcelfitError(
                    f"duplicate run id {shown(run_id)} (also at {seen_ids[run_id]})",
                    file=file,
                    where=f"{rwhere}.id",
                    fix="give every run its own id",
                )
            seen_ids[run_id] = rwhere
            transit = get_number(
                run_doc,
                "transit_time",
                file=file,
                where=rwhere,
                default=None,
                allow_none=True,
                unit="s",
            )
            if transit is not None and not 0 < transit <= MAX_TRANSIT_TIME_S:
                raise ParcelfitError(
                    f"transit_time must be positive and at most {MAX_TRANSIT_TIME_S:g} s, got {transit:g}",
                    file=file,
                    where=f"{rwhere}.transit_time",
                    fix="give seconds (divide milliseconds by 1000), or null",
                )
            traj_path = _run_file(root, get_str(run_doc, "file", file=file, where=rwhere))
            if traj_path is None:
                raise ParcelfitError(
                    f"run file {shown(run_doc['file'])} lies outside the dataset folder",
                    file=file,
                    where=f"{rwhere}.file",
                    fix="copy the file into the dataset folder and give its path relative to it",
                )
            if traj_path in seen_files:
                raise ParcelfitError(
                    f"run file {shown(run_doc['file'])} is also the file of {seen_files[traj_path]}",
                    file=file,
                    where=f"{rwhere}.file",
                    fix="give every run its own trajectory file",
                )
            seen_files[traj_path] = rwhere
            if not traj_path.is_file():
                raise ParcelfitError(
                    f"trajectory file {shown(traj_path.name)} not found",
                    file=file,
                    where=f"{rwhere}.file",
                    fix="give the path relative to the dataset folder",
                )
            runs.append(
                Run(
                    id=run_id,
                    case=case,
                    trajectory=read_trajectory(traj_path),
                    transit_time=transit,
                )
            )
        cases[case] = CaseData(case=case, runs=tuple(runs), regions=regions, margin=margin or 0.0)
    return Dataset(
        name=name,
        cases=cases,
        description=str(doc.get("description", "") or ""),
        synthetic=synthetic,
        root=folder,
    )


def _run_file(root: Path, name: str) -> Path | None:
    """The resolved path of a run file named in ``dataset.yaml``, None if it is absolute or
    resolves (through ``..`` or a symbolic link) to a place outside ``root``."""
    if Path(name).is_absolute():
        return None
    path = (root / name).resolve()
    return path if path.is_relative_to(root) else None


def _region_doc(region: Region) -> dict[str, Any]:
    if isinstance(region, Polygon):
        return {"polygon": region.vertices.tolist()}
    doc: dict[str, Any] = {}
    for axis in ("x", "y"):
        lo, hi = getattr(region, f"{axis}min"), getattr(region, f"{axis}max")
        if lo != float("-inf") or hi != float("inf"):
            doc[axis] = [float(lo), float(hi)]
    return doc


def save_dataset(
    folder: str | Path,
    name: str,
    cases: Iterable[CaseData] | Sequence[CaseData],
    *,
    description: str = "",
    synthetic: bool = False,
    file_format: str = "csv",
) -> Path:
    """Write a dataset folder (``dataset.yaml`` and ``runs/<id>.<format>``); returns the yaml path."""
    if file_format not in ("csv", "parquet"):
        raise ParcelfitError(f"unknown file format {file_format!r}", fix="use csv or parquet")
    folder = Path(folder)
    entries = []
    for cd in cases:
        runs_doc = []
        for run in cd.runs:
            rel = Path("runs") / f"{run.id}.{file_format}"
            write_trajectory(run.trajectory, folder / rel)
            runs_doc.append(
                {"id": run.id, "file": rel.as_posix(), "transit_time": run.transit_time}
            )
        entry: dict[str, Any] = {
            "rig": cd.case.rig,
            "consignment": cd.case.consignment,
            "speed_setting": cd.case.speed_setting,
        }
        if cd.regions:
            entry["regions"] = [_region_doc(r) for r in cd.regions]
            entry["margin"] = cd.margin
        entry["runs"] = runs_doc
        entries.append(entry)
    doc = {"name": name, "description": description, "synthetic": synthetic, "test_cases": entries}
    path = folder / DATASET_FILE
    return write_text_atomic(path, yaml.safe_dump(doc, sort_keys=False))


__all__ = ["DATASET_FILE", "Box", "CaseData", "Dataset", "Polygon", "load_dataset", "save_dataset"]
