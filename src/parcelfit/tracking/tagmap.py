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
from typing import Any

import numpy as np
import yaml

from parcelfit.config import (
    check_keys,
    get_choice,
    get_number,
    get_pair,
    load_config,
    require_mapping,
)
from parcelfit.errors import ParcelfitError
from parcelfit.runs import Barrier

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


def tag_corners(x: float, y: float, size: float, angle: float) -> np.ndarray:
    """Corners of a square tag centred at (x, y) [m], side ``size`` [m], heading ``angle`` [rad],
    in OpenCV's order: top-left, top-right, bottom-right, bottom-left of the upright tag."""
    h = size / 2
    local = np.array([[-h, h], [h, h], [h, -h], [-h, -h]])
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    return local @ rot.T + np.array([x, y])


def _pair(value: Any, *, file: Path, where: str) -> tuple[float, float]:
    return get_pair(value, file=file, where=where)


def _tag_id(key: Any, *, file: Path, where: str) -> int:
    try:
        tag_id = int(key)
    except (TypeError, ValueError):
        tag_id = -1
    if tag_id < 0 or str(tag_id) != str(key).strip():
        raise ParcelfitError(
            f"tag ids are whole numbers >= 0, got {key!r}",
            file=file,
            where=where,
            fix="use the tag's id number as the key",
        )
    return tag_id


def load_tag_map(path: str | Path) -> TagMap:
    """Read and check a tag map file (see the module docstring)."""
    path = Path(path)
    doc = load_config(
        path,
        allowed=("family", "reference_tags", "parcel_tags", "camera", "light_barriers", "timing"),
        required=("reference_tags", "parcel_tags"),
    )
    family = get_choice(
        doc, "family", FAMILIES, what="tag family", file=path, where="", default="tag36h11"
    )
    refs: dict[int, ReferenceTag] = {}
    for key, value in require_mapping(
        doc["reference_tags"], file=path, where="reference_tags"
    ).items():
        where = f"reference_tags.{key}"
        tag_id = _tag_id(key, file=path, where=where)
        m = require_mapping(value, file=path, where=where)
        check_keys(
            m,
            allowed=("x", "y", "size", "angle"),
            required=("x", "y", "size"),
            file=path,
            where=where,
        )
        refs[tag_id] = ReferenceTag(
            tag_id,
            float(get_number(m, "x", file=path, where=where, unit="m")),  # type: ignore[arg-type]
            float(get_number(m, "y", file=path, where=where, unit="m")),  # type: ignore[arg-type]
            float(get_number(m, "size", file=path, where=where, minimum=1e-3, maximum=2, unit="m")),  # type: ignore[arg-type]
            math.radians(
                float(get_number(m, "angle", file=path, where=where, default=0, unit="deg"))
            ),  # type: ignore[arg-type]
        )
    if len(refs) < 1:
        raise ParcelfitError(
            "no reference tags",
            file=path,
            where="reference_tags",
            fix="list at least one (four recommended)",
        )
    parcels: dict[int, ParcelTag] = {}
    for key, value in require_mapping(doc["parcel_tags"], file=path, where="parcel_tags").items():
        where = f"parcel_tags.{key}"
        tag_id = _tag_id(key, file=path, where=where)
        if tag_id in refs:
            raise ParcelfitError(
                f"tag {tag_id} is both a reference and a parcel tag",
                file=path,
                where=where,
                fix="give every tag one role",
            )
        m = require_mapping(value, file=path, where=where)
        check_keys(
            m,
            allowed=("size", "height", "offset", "outline"),
            required=("size",),
            file=path,
            where=where,
        )
        outline = m.get("outline")
        parcels[tag_id] = ParcelTag(
            tag_id,
            float(get_number(m, "size", file=path, where=where, minimum=1e-3, maximum=2, unit="m")),  # type: ignore[arg-type]
            float(
                get_number(
                    m, "height", file=path, where=where, default=0, minimum=0, maximum=2, unit="m"
                )
            ),  # type: ignore[arg-type]
            _pair(m.get("offset", [0, 0]), file=path, where=f"{where}.offset"),
            None if outline is None else _pair(outline, file=path, where=f"{where}.outline"),
        )
    if not parcels:
        raise ParcelfitError(
            "no parcel tags", file=path, where="parcel_tags", fix="list the parcel's tag"
        )
    camera = None
    if doc.get("camera") is not None:
        m = require_mapping(doc["camera"], file=path, where="camera")
        check_keys(
            m,
            allowed=("fx", "fy", "cx", "cy", "distortion", "width", "height"),
            required=("fx", "fy", "cx", "cy"),
            file=path,
            where="camera",
        )
        dist = m.get("distortion", [0, 0, 0, 0, 0])
        if (
            not isinstance(dist, list)
            or len(dist) not in (4, 5, 8)
            or not all(isinstance(v, int | float) for v in dist)
        ):
            raise ParcelfitError(
                f"expected 4, 5 or 8 distortion coefficients, got {dist!r}",
                file=path,
                where="camera.distortion",
                fix="write [k1, k2, p1, p2, k3] (OpenCV's order)",
            )
        camera = Camera(
            *(
                # a focal length is at least a pixel (fx: 0 would divide by zero when mapping)
                float(
                    get_number(  # type: ignore[arg-type]
                        m,
                        k,
                        file=path,
                        where="camera",
                        minimum=1 if k in ("fx", "fy") else 0,
                        unit="px",
                    )
                )
                for k in ("fx", "fy", "cx", "cy")
            ),  # type: ignore[arg-type]
            distortion=tuple(float(v) for v in dist),
            width=int(get_number(m, "width", file=path, where="camera", default=0, minimum=0)),  # type: ignore[arg-type]
            height=int(get_number(m, "height", file=path, where="camera", default=0, minimum=0)),  # type: ignore[arg-type]
        )
    barriers = []
    raw = doc.get("light_barriers") or []
    if not isinstance(raw, list):
        raise ParcelfitError(
            "expected a list of barriers",
            file=path,
            where="light_barriers",
            fix="write - {id, from, to}",
        )
    for i, b in enumerate(raw):
        where = f"light_barriers[{i}]"
        m = require_mapping(b, file=path, where=where)
        check_keys(
            m, allowed=("id", "from", "to"), required=("id", "from", "to"), file=path, where=where
        )
        barriers.append(
            Barrier(
                str(m["id"]),
                _pair(m["from"], file=path, where=f"{where}.from"),
                _pair(m["to"], file=path, where=f"{where}.to"),
            )
        )
    timing = require_mapping(doc.get("timing") or {}, file=path, where="timing")
    check_keys(timing, allowed=("exposure_ms", "readout_ms"), file=path, where="timing")
    exposure, readout = (
        float(get_number(timing, k, file=path, where="timing", default=0, minimum=0, maximum=100))  # type: ignore[arg-type]
        * 1e-3
        for k in ("exposure_ms", "readout_ms")
    )
    return TagMap(family, refs, parcels, camera, tuple(barriers), path, exposure, readout)


def save_camera(path: str | Path, camera: Camera) -> None:
    """Write ``camera`` into the tag map at ``path`` (keeping its other keys and comments lost)."""
    path = Path(path)
    doc = yaml.safe_load(path.read_text(encoding="utf-8")) if path.is_file() else {}
    doc = doc or {}
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
