"""The tag map file: where the reference tags are, what the parcel tags are, the camera.

```yaml
family: tag36h11                 # AprilTag family (tag36h11, tag25h9, tag16h5, tag36h10)
reference_tags:                  # on the belt plane z = 0, rig frame
  0: {x: 0.0, y: 0.0, size: 0.08, angle: 0}     # centre [m], black-square side [m], deg CCW
parcel_tags:
  5: {size: 0.06, height: 0.025, offset: [0.0, 0.0], outline: [0.275, 0.20]}
camera:                          # optional: OpenCV pinhole model [px]
  {fx: 1000, fy: 1000, cx: 640, cy: 360, distortion: [0, 0, 0, 0, 0], width: 1280, height: 720}
timing: {exposure_ms: 4, readout_ms: 15}   # optional: the camera's exposure and rolling-shutter
                                 # readout (first to last row) [ms]; 0 = global shutter
light_barriers:                  # optional: virtual barriers, segments in the rig frame [m]
  - {id: start, from: [0.2, -0.5], to: [0.2, 0.5]}
  - {id: end, from: [1.0, -0.5], to: [1.0, 0.5]}
```

Conventions: rig frame x along the belt, y across it, z up. A tag's corners are numbered as
OpenCV returns them (top-left, top-right, bottom-right, bottom-left of the upright tag); its
heading is the direction from the first to the second corner, counter-clockwise from x. A parcel
tag is mounted with that edge along the parcel's x axis, so the parcel's theta is the tag's
heading; ``offset`` is the tag centre relative to the parcel centre in the parcel frame [m];
``height`` is the tag's height above the belt plane [m]; ``outline`` the parcel's length and
width [m] (for light barriers; without it the centre point crosses them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import yaml
from pydantic import BeforeValidator, Field, PlainValidator, field_validator, model_validator

from parcelfit.config import load_yaml
from parcelfit.errors import ParcelfitError, shown
from parcelfit.runs import Barrier
from parcelfit.schema import (
    Choice,
    FileModel,
    Number,
    Pair,
    Text,
    Whole,
    is_finite_number,
    or_default,
    parse,
)

FAMILIES = ("tag36h11", "tag25h9", "tag16h5", "tag36h10")


@dataclass(frozen=True)
class ReferenceTag:
    """A tag fixed on the belt plane: centre [m], side of the black square [m], angle [rad]."""

    id: int
    x: float
    y: float
    size: float
    angle: float

    def corners(self) -> np.ndarray:
        """The four corners (OpenCV order) in the rig frame, (4, 2) [m]."""
        return tag_corners(self.x, self.y, self.size, self.angle)


@dataclass(frozen=True)
class ParcelTag:
    """A tag on a parcel: side [m], height above the belt [m], offset [m], outline [m] or None."""

    id: int
    size: float
    height: float
    offset: tuple[float, float] = (0.0, 0.0)
    outline: tuple[float, float] | None = None


@dataclass(frozen=True)
class Camera:
    """OpenCV pinhole camera: focal lengths and principal point [px], distortion, image size."""

    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    width: int = 0
    height: int = 0

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=float)

    @property
    def dist(self) -> np.ndarray:
        """Distortion coefficients (k1, k2, p1, p2, k3)."""
        return np.asarray(self.distortion, dtype=float)


@dataclass(frozen=True)
class TagMap:
    """A parsed, checked tag map (SI units, radians)."""

    family: str
    reference_tags: dict[int, ReferenceTag]
    parcel_tags: dict[int, ParcelTag]
    camera: Camera | None = None
    barriers: tuple[Barrier, ...] = ()
    source: Path | None = field(default=None, compare=False)
    exposure: float = 0.0  # s
    readout: float = 0.0  # s, rolling shutter: first to last image row
    timing_given: bool = False  # the file has a ``timing`` block (else it is estimated)


def tag_corners(x: float, y: float, size: float, angle: float) -> np.ndarray:
    """Corners of a square tag centred at (x, y) [m], side ``size`` [m], heading ``angle`` [rad],
    in OpenCV's order: top-left, top-right, bottom-right, bottom-left of the upright tag."""
    h = size / 2
    local = np.array([[-h, h], [h, h], [h, -h], [-h, -h]])
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    return local @ rot.T + np.array([x, y])


def _tag_id(key: Any) -> int:
    try:
        tag_id = int(key)
    except (TypeError, ValueError):
        tag_id = -1
    if tag_id < 0 or str(tag_id) != str(key).strip():
        raise ParcelfitError(
            f"tag ids are whole numbers >= 0, got {shown(key)}",
            fix="use the tag's id number as the key",
        )
    return tag_id


def _distortion(value: Any) -> tuple[float, ...]:
    if (
        not isinstance(value, list)
        or len(value) not in (4, 5, 8)
        or not all(is_finite_number(v) for v in value)
    ):
        raise ParcelfitError(
            f"expected 4, 5 or 8 distortion coefficients, got {shown(value)}",
            fix="write [k1, k2, p1, p2, k3] (OpenCV's order)",
        )
    return tuple(float(v) for v in value)


def _barrier_list(value: Any) -> Any:
    if not isinstance(value, list):
        raise ParcelfitError("expected a list of barriers", fix="write - {id, from, to}")
    # a rig file names its barriers with `name`: copied from there, it means `id`
    out = []
    for entry in value:
        if isinstance(entry, dict) and "name" in entry:
            if "id" in entry:
                raise ParcelfitError(
                    "a light barrier has both `id` and `name`",
                    fix="keep one: `name` (as in the rig file) is read as `id`",
                )
            entry = {("id" if k == "name" else k): v for k, v in entry.items()}
        out.append(entry)
    return out


_TagId = Annotated[int, PlainValidator(_tag_id)]
_Metres = Annotated[float, Number(unit="m")]
_TagSize = Annotated[float, Number(unit="m", ge=1e-3, le=2)]


class ReferenceTagEntry(FileModel):
    """One of ``reference_tags``: centre [m], side [m], angle [deg CCW]."""

    x: _Metres
    """The tag centre's x in the rig frame [m]."""
    y: _Metres
    """The tag centre's y in the rig frame [m]."""
    size: _TagSize
    """Side of the tag's black square [m]."""
    angle: Annotated[float, Number(unit="deg")] = 0.0
    """The tag's rotation, counter-clockwise from the rig's x axis [deg]."""


class ParcelTagEntry(FileModel):
    """One of ``parcel_tags``: side, height, offset and outline [m]."""

    size: _TagSize
    """Side of the tag's black square [m]."""
    height: Annotated[float, Number(unit="m", ge=0, le=2)] = 0.0
    """Height of the tag above the belt plane [m] (the parcel's height)."""
    offset: Annotated[tuple[float, float], Pair()] = (0.0, 0.0)
    """The tag centre relative to the parcel centre, in the parcel's frame [m], [x, y]."""
    outline: Annotated[tuple[float, float] | None, Pair(nullable=True)] = None
    """The parcel's length and width [m], for light barriers crossed by its outline."""


class CameraSection(FileModel):
    """``camera``: focal lengths (>= 1) and principal point [px], distortion, image size [px]."""

    # a focal length is at least a pixel (fx: 0 would divide by zero when mapping)
    fx: Annotated[float, Number(unit="px", ge=1)]
    """Focal length in x [px]."""
    fy: Annotated[float, Number(unit="px", ge=1)]
    """Focal length in y [px]."""
    cx: Annotated[float, Number(unit="px", ge=0)]
    """Principal point x [px]."""
    cy: Annotated[float, Number(unit="px", ge=0)]
    """Principal point y [px]."""
    distortion: Annotated[tuple[float, ...], PlainValidator(_distortion)] = (0.0,) * 5
    """OpenCV's distortion coefficients k1, k2, p1, p2, k3 [-]."""
    width: Annotated[int, Whole(ge=0, le=100_000)] = 0
    """Image width [px] (the video's)."""
    height: Annotated[int, Whole(ge=0, le=100_000)] = 0
    """Image height [px]."""


class BarrierEntry(FileModel):
    """One of ``light_barriers``: its id and the segment's ends [m]."""

    id: Annotated[str, Text()]
    """The light barrier's id (or key `name`, as in the rig file)."""
    start: Annotated[tuple[float, float], Pair(), Field(alias="from")]
    """One end of the virtual barrier in the rig frame [m], [x, y] (key `from`)."""
    end: Annotated[tuple[float, float], Pair(), Field(alias="to")]
    """The other end [m], [x, y] (key `to`)."""


class TimingSection(FileModel):
    """``timing``: exposure and rolling-shutter readout [ms], 0 to 100."""

    exposure_ms: Annotated[float, Number(ge=0, le=100)] = 0.0
    """The camera's exposure time [ms] (0 to 100)."""
    readout_ms: Annotated[float, Number(ge=0, le=100)] = 0.0
    """The rolling shutter's readout time, first to last row [ms] (0 to 100; 0: global shutter)."""


class TagMapFile(FileModel):
    """A tag map file as written (see the module docstring)."""

    family: Annotated[str, Choice(FAMILIES, what="tag family")] = "tag36h11"
    """The tag family: tag36h11 (default), tag25h9, tag16h5 or tag36h10."""
    reference_tags: dict[_TagId, ReferenceTagEntry]
    """Tags fixed on the belt plane z = 0, by id: they define the rig frame in the video (four
    recommended)."""
    parcel_tags: dict[_TagId, ParcelTagEntry]
    """Tags on parcels, by id."""
    camera: CameraSection | None = None
    """The camera's intrinsics and distortion (written by `parcelfit camera-calibrate`)."""
    light_barriers: Annotated[
        list[BarrierEntry], BeforeValidator(_barrier_list), or_default(list)
    ] = Field(default_factory=list)
    """Virtual light barriers (the transit time is the last crossing minus the first)."""
    timing: Annotated[TimingSection, or_default(dict)] = Field(default_factory=TimingSection)
    """Exposure and rolling-shutter readout, for the model fit of motion-smeared tags
    (optional)."""

    @field_validator("reference_tags")
    @classmethod
    def _some_reference(cls, value: dict[int, ReferenceTagEntry]) -> dict[int, ReferenceTagEntry]:
        if not value:
            raise ParcelfitError("no reference tags", fix="list at least one (four recommended)")
        return value

    @field_validator("parcel_tags")
    @classmethod
    def _some_parcel(cls, value: dict[int, ParcelTagEntry]) -> dict[int, ParcelTagEntry]:
        if not value:
            raise ParcelfitError("no parcel tags", fix="list the parcel's tag")
        return value

    @model_validator(mode="after")
    def _one_role(self) -> TagMapFile:
        seen: set[str] = set()
        for i, b in enumerate(self.light_barriers):
            if b.id in seen:
                raise ParcelfitError(
                    f"two light barriers have the id {b.id!r}",
                    where=f"light_barriers[{i}]",
                    fix="give each barrier its own id",
                )
            seen.add(b.id)
            if math.dist(b.start, b.end) < 1e-3:  # from = to: a typo, a beam of no length
                raise ParcelfitError(
                    f"light barrier {b.id!r} has no length: from {list(b.start)} to {list(b.end)}",
                    where=f"light_barriers[{i}]",
                    fix="give its two ends in metres, at least 1 mm apart",
                )
        for tag_id in self.parcel_tags:
            if tag_id in self.reference_tags:
                raise ParcelfitError(
                    f"tag {tag_id} is both a reference and a parcel tag",
                    where=f"parcel_tags.{tag_id}",
                    fix="give every tag one role",
                )
        return self


def load_tag_map(path: str | Path) -> TagMap:
    """Read and check a tag map file (see the module docstring); angles become radians and
    times seconds here."""
    path = Path(path)
    f = parse(TagMapFile, load_yaml(path), file=path)
    refs = {
        i: ReferenceTag(i, t.x, t.y, t.size, math.radians(t.angle))
        for i, t in f.reference_tags.items()
    }
    parcels = {
        i: ParcelTag(i, t.size, t.height, t.offset, t.outline) for i, t in f.parcel_tags.items()
    }
    camera = None
    if f.camera is not None:
        c = f.camera
        camera = Camera(c.fx, c.fy, c.cx, c.cy, c.distortion, c.width, c.height)
    barriers = tuple(Barrier(b.id, b.start, b.end) for b in f.light_barriers)
    return TagMap(
        f.family,
        refs,
        parcels,
        camera,
        barriers,
        path,
        f.timing.exposure_ms * 1e-3,
        f.timing.readout_ms * 1e-3,
        "timing" in f.model_fields_set,
    )


def save_camera(path: str | Path, camera: Camera) -> None:
    """Write ``camera`` into the tag map at ``path`` (keeping its other keys and comments lost)."""
    path = Path(path)
    doc = (load_yaml(path) if path.is_file() else None) or {}
    doc["camera"] = {
        "fx": camera.fx,
        "fy": camera.fy,
        "cx": camera.cx,
        "cy": camera.cy,
        "distortion": [float(v) for v in camera.distortion],
        "width": camera.width,
        "height": camera.height,
    }
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")


__all__ = [
    "FAMILIES",
    "Camera",
    "ParcelTag",
    "ReferenceTag",
    "TagMap",
    "load_tag_map",
    "save_camera",
    "tag_corners",
]
