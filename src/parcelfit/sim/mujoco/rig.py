"""Test rigs as data: conveying surfaces, walls, start pose, light barriers, regions of interest.

A rig file (YAML, SI units, angles in degrees counter-clockwise from the rig's x axis)::

    name: E3
    description: free text
    speeds:                       # speed setting -> drive name -> surface speed [m/s]
      1: {main: 1.56, strip: 1.64}
    surfaces:                     # things a parcel rides on
      - name: main
        type: belt                # belt | strips | rollers
        material: belt            # belt | roller | metal (selects the contact parameters)
        centre: [1.75, 0.0]       # centre of the conveying area [m]
        length: 4.5               # along the heading [m]
        width: 0.8                # across the heading [m]
        heading: 0                # direction of motion [deg]
        top: 0.0                  # height of the conveying surface [m]
        drive: main               # key into speeds
        # strips:  count, strip_width, pitch           (type strips)
        # rollers: rows, columns, radius, roller_width, swivel [deg]   (type rollers)
    walls:                        # vertical plates (guide plates, side walls)
      - {name: guide, material: metal, from: [0.35, -0.4], to: [1.5, -0.11], height: 0.1,
         base: 0.0, thickness: 0.003, lead_in: 0.01}   # lead_in: radius of a rounded
                                  # (rolled) upstream end [m], optional
    start: {position: [x, y], heading: 30, surface: strips,   # parcel centre, x axis, surface below
            scatter: {along: 0.01, across: 0.01, heading: 2}} # optional: hand placement, see below
    light_barriers:               # exactly two beams, crossed in this order
      - {name: LS1, from: [x, y], to: [x, y]}
      - {name: LS2, from: [x, y], to: [x, y]}
    regions: [{x: [-0.3, 1.6]}]   # regions of interest for comparisons (see parcelfit.runs.regions)
    margin: 0.02                  # [m]
    end: {x: [-1.0, 3.0], y: [-1.0, 1.0], duration: 3.0, after_last_barrier: 0.3}

``start.scatter`` describes how a hand-placed parcel varies from run to run: standard deviations
of a normal distribution along and across the start surface's heading [m] and of the heading
[deg], each draw cut off at 2.5 standard deviations. A simulation with a placement seed draws its
start pose from it (`Rig.placement`), so an ensemble of seeds gives a distribution of outcomes
like the repeated real runs of a test case; without a seed the parcel starts at the nominal pose.

The run ends when the parcel centre leaves the ``end`` box, ``after_last_barrier`` seconds
after it interrupts the second light barrier, or after ``duration`` seconds of simulated time.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from parcelfit.config import (
    check_keys,
    get_choice,
    get_number,
    get_pair,
    get_str,
    load_yaml,
    require_mapping,
)
from parcelfit.errors import ParcelfitError
from parcelfit.runs import Barrier, Region, parse_region
from parcelfit.sim.mujoco.bundled import bundled_names, resolve_file

MATERIALS = ("belt", "roller", "metal")
SURFACE_TYPES = ("belt", "strips", "rollers")
_SURFACE_KEYS = {
    "belt": (),
    "strips": ("count", "strip_width", "pitch"),
    "rollers": ("rows", "columns", "radius", "roller_width", "swivel"),
}
_COMMON = ("name", "type", "material", "centre", "length", "width", "heading", "top", "drive")
PLACEMENT_STREAM = 0x51ACE  # keeps placement draws apart from other seeded streams
SCATTER_CUT = 2.5  # placement draws are cut off at this many standard deviations


@dataclass(frozen=True)
class Surface:
    """A driven conveying surface (belt, strip set or roller matrix); SI units, degrees."""

    name: str
    type: str
    material: str
    centre: tuple[float, float]
    length: float
    width: float
    heading: float
    top: float
    drive: str
    extra: Mapping[str, float]

    def unit(self) -> np.ndarray:
        """Unit vector of the heading (direction of motion) in the plane."""
        a = np.radians(self.heading)
        return np.array([np.cos(a), np.sin(a)])


@dataclass(frozen=True)
class Wall:
    """A vertical plate from ``start`` to ``end`` [m], ``height`` above ``base`` [m]."""

    name: str
    material: str
    start: tuple[float, float]
    end: tuple[float, float]
    height: float
    base: float
    thickness: float
    lead_in: float = 0.0  # radius of the rounded upstream end at ``start`` [m]; 0: a plain edge


@dataclass(frozen=True)
class StartPose:
    """Where the parcel is put: centre [m], heading [deg], the surface it lies on, and the scatter
    of a hand placement (standard deviations along and across the surface [m], heading [deg])."""

    position: tuple[float, float]
    heading: float
    surface: str
    scatter: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class EndCondition:
    """When a run ends: centre leaves the box [m], time [s] after the last barrier, duration [s]."""

    x: tuple[float, float]
    y: tuple[float, float]
    duration: float
    after_last_barrier: float


@dataclass(frozen=True)
class Rig:
    """A test rig: surfaces, walls, start pose, light barriers, regions of interest, speeds."""

    name: str
    description: str
    speeds: Mapping[int, Mapping[str, float]]
    surfaces: tuple[Surface, ...]
    walls: tuple[Wall, ...]
    start: StartPose
    barriers: tuple[Barrier, Barrier]
    regions: tuple[Region, ...]
    margin: float
    end: EndCondition
    source: str = ""

    def surface(self, name: str) -> Surface:
        """The surface called ``name``."""
        for s in self.surfaces:
            if s.name == name:
                return s
        raise ParcelfitError(f"rig {self.name} has no surface {name!r}")

    def placement(self, seed: int) -> tuple[float, float, float]:
        """The start-pose offset (dx [m], dy [m], dheading [deg]) of placement ``seed``: a draw
        from ``start.scatter`` (normal, cut at 2.5 sd), along/across rotated into the rig frame."""
        rng = np.random.default_rng([PLACEMENT_STREAM, seed])
        along, across, heading = (
            float(np.clip(rng.standard_normal(), -SCATTER_CUT, SCATTER_CUT)) * sd
            for sd in self.start.scatter
        )
        u = self.surface(self.start.surface).unit()
        return (
            along * u[0] - across * u[1],
            along * u[1] + across * u[0],
            heading,
        )

    def drive_speeds(self, setting: int) -> Mapping[str, float]:
        """Surface speed [m/s] of every drive at a speed setting."""
        if setting not in self.speeds:
            raise ParcelfitError(
                f"rig {self.name} has no speed setting {setting}",
                fix=f"use one of {sorted(self.speeds)}",
            )
        return self.speeds[setting]


def _point(value: Any, *, file: str, where: str) -> tuple[float, float]:
    return get_pair(
        value, file=file, where=where, what="a point [x, y] in metres", fix="write e.g. [0.5, -0.4]"
    )


def _pair(value: Any, *, file: str, where: str) -> tuple[float, float]:
    return get_pair(
        value,
        file=file,
        where=where,
        what="[min, max] with min < max",
        fix="write e.g. [0.5, 1.2]",
        increasing=True,
    )


def parse_rig(doc: Any, file: str) -> Rig:
    """Build and check a `Rig` from its parsed YAML document."""
    doc = require_mapping(doc, file=file, where="top level")
    check_keys(
        doc,
        allowed=(
            "name",
            "description",
            "speeds",
            "surfaces",
            "walls",
            "start",
            "light_barriers",
            "regions",
            "margin",
            "end",
        ),
        required=("name", "speeds", "surfaces", "start", "light_barriers", "end"),
        file=file,
        where="top level",
    )
    name = get_str(doc, "name", file=file, where="")
    speeds_doc = require_mapping(doc["speeds"], file=file, where="speeds")
    speeds: dict[int, dict[str, float]] = {}
    for key, drives in speeds_doc.items():
        if isinstance(key, bool) or not isinstance(key, int) or key < 1:
            raise ParcelfitError(
                f"speed setting {key!r} must be an integer >= 1",
                file=file,
                where="speeds",
                fix="write e.g. `1: {main: 1.56}`",
            )
        drives = require_mapping(drives, file=file, where=f"speeds.{key}")
        speeds[key] = {
            str(d): get_number(
                drives, d, file=file, where=f"speeds.{key}", minimum=0.0, maximum=20.0, unit="m/s"
            )
            for d in drives
        }
    if not speeds:
        raise ParcelfitError(
            "no speed settings", file=file, where="speeds", fix="add `1: {drive: speed}`"
        )
    surfaces = []
    for i, s in enumerate(doc["surfaces"] or []):
        where = f"surfaces[{i}]"
        s = require_mapping(s, file=file, where=where)
        stype = get_choice(s, "type", SURFACE_TYPES, what="surface type", file=file, where=where)
        check_keys(
            s,
            allowed=_COMMON + _SURFACE_KEYS[stype],
            required=_COMMON + _SURFACE_KEYS[stype],
            file=file,
            where=where,
        )
        material = get_choice(s, "material", MATERIALS, what="material", file=file, where=where)
        drive = get_str(s, "drive", file=file, where=where)
        missing = [k for k, d in speeds.items() if drive not in d]
        if missing:
            raise ParcelfitError(
                f"drive {drive!r} has no speed in setting(s) {missing}",
                file=file,
                where=f"{where}.drive",
                fix=f"add {drive} to every speed setting",
            )
        extra = {k: get_number(s, k, file=file, where=where) for k in _SURFACE_KEYS[stype]}
        surfaces.append(
            Surface(
                name=get_str(s, "name", file=file, where=where),
                type=stype,
                material=material,
                centre=_point(s["centre"], file=file, where=f"{where}.centre"),
                length=get_number(
                    s, "length", file=file, where=where, minimum=1e-3, maximum=100, unit="m"
                ),
                width=get_number(
                    s, "width", file=file, where=where, minimum=1e-3, maximum=100, unit="m"
                ),
                heading=get_number(
                    s, "heading", file=file, where=where, minimum=-360, maximum=360, unit="deg"
                ),
                top=get_number(s, "top", file=file, where=where, minimum=-10, maximum=10, unit="m"),
                drive=drive,
                extra=extra,
            )
        )
    if not surfaces:
        raise ParcelfitError("a rig needs at least one surface", file=file, where="surfaces")
    names = [s.name for s in surfaces]
    if len(set(names)) != len(names):
        raise ParcelfitError("surface names must be unique", file=file, where="surfaces")
    walls = []
    for i, w in enumerate(doc.get("walls") or []):
        where = f"walls[{i}]"
        w = require_mapping(w, file=file, where=where)
        check_keys(
            w,
            allowed=("name", "material", "from", "to", "height", "base", "thickness", "lead_in"),
            required=("name", "from", "to", "height"),
            file=file,
            where=where,
        )
        material = get_choice(
            w, "material", MATERIALS, what="material", file=file, where=where, default="metal"
        )
        walls.append(
            Wall(
                name=get_str(w, "name", file=file, where=where),
                material=material,
                start=_point(w["from"], file=file, where=f"{where}.from"),
                end=_point(w["to"], file=file, where=f"{where}.to"),
                height=get_number(
                    w, "height", file=file, where=where, minimum=1e-3, maximum=10, unit="m"
                ),
                base=get_number(
                    w,
                    "base",
                    file=file,
                    where=where,
                    default=0.0,
                    minimum=-10,
                    maximum=10,
                    unit="m",
                ),
                thickness=get_number(
                    w,
                    "thickness",
                    file=file,
                    where=where,
                    default=0.003,
                    minimum=1e-4,
                    maximum=1,
                    unit="m",
                ),
                lead_in=get_number(
                    w,
                    "lead_in",
                    file=file,
                    where=where,
                    default=0.0,
                    minimum=0.0,
                    maximum=0.2,
                    unit="m",
                ),
            )
        )
    st = require_mapping(doc["start"], file=file, where="start")
    check_keys(
        st,
        allowed=("position", "heading", "surface", "scatter"),
        required=("position", "heading", "surface"),
        file=file,
        where="start",
    )
    scatter = (0.0, 0.0, 0.0)
    if st.get("scatter") is not None:
        sc = require_mapping(st["scatter"], file=file, where="start.scatter")
        check_keys(sc, allowed=("along", "across", "heading"), file=file, where="start.scatter")
        scatter = tuple(
            get_number(
                sc,
                key,
                file=file,
                where="start.scatter",
                default=0.0,
                minimum=0.0,
                maximum=maximum,
                unit=unit,
            )
            for key, maximum, unit in (
                ("along", 0.5, "m"),
                ("across", 0.5, "m"),
                ("heading", 90, "deg"),
            )
        )
    start = StartPose(
        _point(st["position"], file=file, where="start.position"),
        get_number(st, "heading", file=file, where="start", minimum=-360, maximum=360, unit="deg"),
        get_str(st, "surface", file=file, where="start"),
        scatter,  # type: ignore[arg-type]
    )
    if start.surface not in names:
        raise ParcelfitError(
            f"start.surface names no surface: {start.surface!r}",
            file=file,
            where="start.surface",
            fix=f"use one of {', '.join(names)}",
        )
    bars = doc["light_barriers"]
    if not isinstance(bars, list) or len(bars) != 2:
        raise ParcelfitError(
            "exactly two light barriers are needed",
            file=file,
            where="light_barriers",
            fix="list LS1 and LS2 in the order the parcel crosses them",
        )
    barriers = []
    for i, b in enumerate(bars):
        where = f"light_barriers[{i}]"
        b = require_mapping(b, file=file, where=where)
        check_keys(
            b,
            allowed=("name", "from", "to"),
            required=("name", "from", "to"),
            file=file,
            where=where,
        )
        barriers.append(
            Barrier(
                get_str(b, "name", file=file, where=where),
                _point(b["from"], file=file, where=f"{where}.from"),
                _point(b["to"], file=file, where=f"{where}.to"),
            )
        )
    regions = tuple(
        parse_region(r, file=file, where=f"regions[{k}]")
        for k, r in enumerate(doc.get("regions") or [])
    )
    end = require_mapping(doc["end"], file=file, where="end")
    check_keys(
        end,
        allowed=("x", "y", "duration", "after_last_barrier"),
        required=("x", "y", "duration"),
        file=file,
        where="end",
    )
    return Rig(
        name=name,
        description=str(doc.get("description", "") or ""),
        speeds=speeds,
        surfaces=tuple(surfaces),
        walls=tuple(walls),
        start=start,
        barriers=(barriers[0], barriers[1]),
        regions=regions,
        margin=get_number(doc, "margin", file=file, where="", default=0.0, minimum=0.0, unit="m")
        or 0.0,
        end=EndCondition(
            _pair(end["x"], file=file, where="end.x"),
            _pair(end["y"], file=file, where="end.y"),
            get_number(
                end, "duration", file=file, where="end", minimum=0.01, maximum=600, unit="s"
            ),
            get_number(
                end, "after_last_barrier", file=file, where="end", default=0.3, minimum=0, unit="s"
            ),
        ),
        source=file,
    )


def bundled_rig_names() -> list[str]:
    """Names of the rigs shipped with parcelfit."""
    return bundled_names("rigs")


def load_rig(name_or_path: str | Path) -> Rig:
    """Load a bundled rig by name (``E3``) or a rig file by path."""
    path = resolve_file("rigs", name_or_path, "rig")
    return parse_rig(load_yaml(path), str(path))
