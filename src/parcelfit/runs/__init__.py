"""Run data: trajectories, runs, datasets on disk, regions of interest.

Knows nothing of how runs were made (tracked video or simulation).
"""

from parcelfit.runs.dataset import (
    CaseData,
    Dataset,
    is_synthetic,
    load_dataset,
    read_truth,
    save_dataset,
)
from parcelfit.runs.io import check_trajectory_table, read_trajectory, write_trajectory
from parcelfit.runs.regions import Barrier, Box, Polygon, Region, crop, parse_region, region_mask
from parcelfit.runs.run import Run, TestCase
from parcelfit.runs.trajectory import COLUMNS, Trajectory, unwrap_angle

__all__ = [
    "COLUMNS",
    "Barrier",
    "Box",
    "CaseData",
    "Dataset",
    "Polygon",
    "Region",
    "Run",
    "TestCase",
    "Trajectory",
    "check_trajectory_table",
    "crop",
    "is_synthetic",
    "load_dataset",
    "parse_region",
    "read_trajectory",
    "read_truth",
    "region_mask",
    "save_dataset",
    "unwrap_angle",
    "write_trajectory",
]
