"""Regions of interest in the rig frame, for cropping trajectories to the sections that matter.

Only the sections where the parcel meets more than a plain belt enter the comparison between
simulation and experiment (method.md section 7). A region is either

* a box ``{x: [min, max], y: [min, max]}`` [m] (either axis may be left out: unbounded), or
* a polygon ``{polygon: [[x, y], ...]}`` [m] (at least three vertices, any orientation).

A sample is kept when its centre lies inside any region grown by the safety margin [m]: for a
box every bound moves out by the margin; for a polygon a point counts if it is inside or no
farther than the margin from an edge (exact Minkowski sum with a disc).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib.path import Path as MplPath

from parcelfit.config import get_pair
from parcelfit.errors import ParcelfitError, shown
from parcelfit.runs.trajectory import Trajectory
from parcelfit.schema import is_finite_number


@dataclass(frozen=True)
class Box:
    """Axis-aligned box in the rig frame [m]; infinite bounds leave an axis open."""

    xmin: float = -np.inf
    xmax: float = np.inf
    ymin: float = -np.inf
    ymax: float = np.inf

    def contains(self, xy: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Boolean mask of the (n, 2) points [m] inside the box grown by ``margin`` [m]."""
        x, y = xy[:, 0], xy[:, 1]
        return (
            (x >= self.xmin - margin)
            & (x <= self.xmax + margin)
            & (y >= self.ymin - margin)
            & (y <= self.ymax + margin)
        )


@dataclass(frozen=True)
class Polygon:
    """Simple polygon in the rig frame, vertices as an (k, 2) array [m]."""

    vertices: np.ndarray

    def contains(self, xy: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Boolean mask of the (n, 2) points [m] inside the polygon or within ``margin`` [m] of it."""
        inside = MplPath(self.vertices).contains_points(xy)
        if margin <= 0:
            return inside
        return inside | (_distance_to_edges(xy, self.vertices) <= margin)


Region = Box | Polygon


def _distance_to_edges(xy: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Shortest distance [m] from each point to the closed polyline through ``vertices``."""
    a = vertices
    b = np.roll(vertices, -1, axis=0)
    ab = b - a  # (k, 2)
    ap = xy[:, None, :] - a[None, :, :]  # (n, k, 2)
    denom = np.maximum((ab * ab).sum(axis=1), 1e-300)
    s = np.clip((ap * ab[None]).sum(axis=2) / denom[None], 0.0, 1.0)
    closest = a[None] + s[..., None] * ab[None]
    return np.sqrt(((xy[:, None, :] - closest) ** 2).sum(axis=2)).min(axis=1)


def _pair(value: Any, key: str, where: str, file: str | None) -> tuple[float, float]:
    return get_pair(
        value,
        file=file,
        where=where,
        what=f"{key} as [min, max] in metres with min < max",
        fix=f"write e.g. {key}: [0.5, 1.2]",
        increasing=True,
    )


def parse_region(
    spec: Mapping[str, Any], *, file: str | None = None, where: str = "regions"
) -> Region:
    """Build a region from its YAML form (``{x: [..], y: [..]}`` or ``{polygon: [[x, y], ...]}``)."""
    if not isinstance(spec, Mapping):
        raise ParcelfitError(
            f"a region must be a mapping, got {shown(spec)}",
            file=file,
            where=where,
            fix="write {x: [min, max], y: [min, max]} or {polygon: [[x, y], ...]}",
        )
    keys = set(spec)
    if keys == {"polygon"}:
        pts = (
            np.asarray(spec["polygon"], dtype=float) if _is_numeric_rows(spec["polygon"]) else None
        )
        if pts is None or pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3:
            raise ParcelfitError(
                "polygon must be a list of at least three [x, y] points in metres",
                file=file,
                where=where,
                fix="write polygon: [[0, -0.4], [1, -0.4], [1, 0.4]]",
            )
        return Polygon(pts)
    if keys and keys <= {"x", "y"}:
        box: dict[str, float] = {}
        for axis in ("x", "y"):
            if axis in spec:
                lo, hi = _pair(spec[axis], axis, where, file)
                box[f"{axis}min"], box[f"{axis}max"] = lo, hi
        return Box(**box)
    raise ParcelfitError(
        f"unknown region keys {sorted(map(str, keys))}",
        file=file,
        where=where,
        fix="use either x and/or y (a box) or polygon",
    )


def _is_numeric_rows(value: Any) -> bool:
    return isinstance(value, list | tuple) and all(
        isinstance(r, list | tuple) and all(is_finite_number(v) for v in r) for r in value
    )


def region_mask(
    trajectory: Trajectory, regions: Sequence[Region], margin: float = 0.0
) -> np.ndarray:
    """Boolean mask of the samples whose centre lies in any region grown by ``margin`` [m]."""
    if margin < 0:
        raise ParcelfitError(f"the safety margin must be >= 0 m, got {margin}")
    if not regions:
        return np.ones(len(trajectory), dtype=bool)
    xy = trajectory.xy
    mask = np.zeros(len(trajectory), dtype=bool)
    for region in regions:
        mask |= region.contains(xy, margin)
    return mask


def crop(trajectory: Trajectory, regions: Sequence[Region], margin: float = 0.0) -> Trajectory:
    """The samples of ``trajectory`` inside the regions grown by ``margin`` [m] (all if none)."""
    if not regions:
        return trajectory
    return trajectory.select(region_mask(trajectory, regions, margin))


@dataclass(frozen=True)
class Barrier:
    """A light barrier (real or virtual): a beam over the segment ``start``-``end`` in the rig
    frame [m]."""

    name: str
    start: tuple[float, float]
    end: tuple[float, float]
