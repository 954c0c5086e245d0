"""Data shipped with parcelfit (example datasets, rig and consignment files)."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

EXAMPLE_DATASET = "twin"


def example_dataset_path(name: str = EXAMPLE_DATASET) -> Path:
    """Folder of a bundled example dataset. These datasets are SYNTHETIC (simulated), not measured."""
    path = Path(str(files("parcelfit.data") / "examples" / name))
    if not (path / "dataset.yaml").is_file():
        from parcelfit.errors import ParcelfitError

        raise ParcelfitError(f"no bundled example dataset {name!r}", fix=f"use {EXAMPLE_DATASET!r}")
    return path
