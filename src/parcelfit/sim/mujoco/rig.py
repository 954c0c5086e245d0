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
        nose_radius: 0.02         # optional (belt, strips): radius of the end drums [m]; 0 (the
                                  # default): square ends
        # end_heading: 0          # optional (strips): the strips' downstream ends lie on a line
                                  # at this heading [deg] through the set's end centre, each
                                  # strip as much longer or shorter as that takes (a staggered
                                  # merge whose ends run along the next belt); absent: all
                                  # strips as long as ``length``, their ends square to them
        # strips:  count, strip_width, pitch           (type strips)
        # rollers: rows, columns, radius, roller_width, swivel [deg]   (type rollers)
    walls:                        # vertical plates (guide plates, side walls)
      - {name: guide, material: metal, from: [0.35, -0.4], to: [1.5, -0.11], height: 0.1,
         base: 0.0, thickness: 0.003, lead_in: 0.01}   # lead_in: radius of a rounded
                                  # (rolled) upstream end [m], optional
    start: {position: [x, y], heading: 30, surface: strips,   # parcel centre, x axis, surface below
            align: centre,                                    # optional: centre | right | left
            scatter: {along: 0.01, across: 0.01, heading: 2}} # optional: hand placement, see below
    light_barriers:               # exactly two beams, crossed in this order
      - {name: LS1, from: [x, y], to: [x, y]}
      - {name: LS2, from: [x, y], to: [x, y]}
    regions: [{x: [-0.3, 1.6]}]   # regions of interest for comparisons (see parcelfit.runs.regions)
    margin: 0.02                  # [m]
    end: {x: [-1.0, 3.0], y: [-1.0, 1.0], duration: 3.0, after_last_barrier: 0.3}
    step_refinement: 1            # optional: this rig needs steps this many times finer than
                                  # the default (1/2400 s rigid, 1/1200 s soft contents)

``start.scatter`` describes how a hand-placed parcel varies from run to run: standard deviations
of a normal distribution along and across the start surface's heading [m] and of the heading
[deg], each draw cut off at 2.5 standard deviations. A simulation with a placement seed draws its
start pose from it (`Rig.placement`), so an ensemble of seeds gives a distribution of outcomes
like the repeated real runs of a test case; without a seed the parcel starts at the nominal pose.

``start.align`` says how a hand lays parcels of different sizes: ``centre`` (the default) puts
every consignment type's centre at ``position``; ``right`` (``left``) puts the middle of its
right (left) side, looking along the start surface's direction, at ``position``, as a hand laying
each specimen against a line would. The centre then lies half the parcel's extent across the
surface to the left (right) of ``position``: with Delta the parcel's heading minus the surface's,
that half extent is (L |sin Delta| + W |cos Delta|) / 2 for its outer length L and width W
(`Rig.start_centre`).

``step_refinement`` is the rig's own demand on the time step: where its outcome converges only
at finer steps (E1's transfer onto a fast belt, 2; E2a's roller module, where the polybag stalled
at 1/1200 s, 2), every run on it divides the default step by this. A study's ``rig_timesteps``
or an explicit ``timestep`` overrides it.

The run ends when the parcel centre leaves the ``end`` box, ``after_last_barrier`` seconds
after it has interrupted both light barriers, or after ``duration`` seconds of simulated time.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BeforeValidator, Field, PlainValidator, field_validator, model_validator

from parcelfit.config import load_yaml
from parcelfit.errors import ParcelfitError, shown
from parcelfit.runs import Barrier, Region, parse_region
from parcelfit.runs.run import MAX_SPEED_SETTING
from parcelfit.schema import (
    Choice,
    FileModel,
    Number,
    Pair,
    Text,
    Whole,
    or_default,
    parse,
    require_mapping,
)
from parcelfit.sim.mujoco.bundled import bundled_names, resolve_file

MATERIALS = ("belt", "roller", "metal")
SURFACE_TYPES = ("belt", "strips", "rollers")
_SURFACE_KEYS = {
    "belt": (),
    "strips": ("count", "strip_width", "pitch"),
    "rollers": ("rows", "columns", "radius", "roller_width", "swivel"),
}
_COMMON = ("name", "type", "material", "centre", "length", "width", "heading", "top", "drive")
_NOSED = ("belt", "strips")  # surface types that may have rounded ends (``nose_radius``)
MAX_NOSE_RADIUS = 0.2  # [m]
PLACEMENT_STREAM = 0x51ACE  # keeps placement draws apart from other seeded streams
SCATTER_CUT = 2.5  # placement draws are cut off at this many standard deviations
SPEED_STREAM = 0x5BEED  # keeps drive-speed draws apart from the placement draws of one seed


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
    # radius of the drums a belt or strip runs round at its two ends [m]; 0: square ends
    nose_radius: float = 0.0
    # strips only: the heading [deg] of the line the strips' downstream ends lie on (None: each
    # strip ``length`` long, the ends square to the heading)
    end_heading: float | None = None

    def unit(self) -> np.ndarray:
        """Unit vector of the heading (direction of motion) in the plane."""
        a = np.radians(self.heading)
        return np.array([np.cos(a), np.sin(a)])

    def parts(self) -> list[tuple[str, np.ndarray, float, float]]:
        """The belt, or each strip of a strip set, as (name, centre [m], length [m], width [m]);
        none for a roller matrix. With ``end_heading`` a strip at offset o across the set keeps
        its upstream end and ends on the line at that heading through the set's end centre:
        it is s = -o (n x e) / (u x e) longer (u the heading, n across it, e the end line)."""
        u = self.unit()
        n = np.array([-u[1], u[0]])
        c = np.asarray(self.centre, dtype=float)
        if self.type == "belt":
            return [(self.name, c, self.length, self.width)]
        if self.type != "strips":
            return []
        k = int(self.extra["count"])
        out = []
        for i in range(k):
            offset = (i - (k - 1) / 2) * self.extra["pitch"]
            extra = 0.0
            if self.end_heading is not None:
                a = np.radians(self.end_heading)
                e = np.array([np.cos(a), np.sin(a)])
                extra = (
                    -offset * float(n[0] * e[1] - n[1] * e[0]) / float(u[0] * e[1] - u[1] * e[0])
                )
            out.append(
                (
                    f"{self.name}_{i}",
                    c + offset * n + extra / 2 * u,
                    self.length + extra,
                    self.extra["strip_width"],
                )
            )
        return out


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
    align: str = "centre"  # centre | right | left: which part of a parcel lies at ``position``


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
    step_refinement: int = 1  # the default time step is divided by this on this rig

    def surface(self, name: str) -> Surface:
        """The surface called ``name``."""
        for s in self.surfaces:
            if s.name == name:
                return s
        raise ParcelfitError(f"rig {self.name} has no surface {name!r}")

    def placement(self, seed: int) -> tuple[float, float, float]:
        """The start-pose offset (dx [m], dy [m], dheading [deg]) of placement ``seed``: a draw
        from ``start.scatter`` (normal, cut at 2.5 sd), along/across rotated into the rig frame.
        A negative seed is the mirror image of the positive one's draw (every offset negated;
        the scatter is symmetric, so it is a draw of the same distribution: the antithetic
        placements of ``cost.mirrored``)."""
        if seed < 0:
            dx, dy, dh = self.placement(-seed)
            return -dx, -dy, -dh
        return self.draw_placement(np.random.default_rng([PLACEMENT_STREAM, seed]))

    def draw_placement(self, rng: np.random.Generator) -> tuple[float, float, float]:
        """A start-pose offset (dx [m], dy [m], dheading [deg]) drawn with ``rng`` from
        ``start.scatter`` as `placement` draws it (a twin's "real" runs draw from the same
        distribution with their own random stream)."""
        along, across, heading = (
            float(np.clip(rng.standard_normal(), -SCATTER_CUT, SCATTER_CUT)) * sd
            for sd in self.start.scatter
        )
        return (*self.start_shift(along, across), heading)

    def drives(self) -> list[str]:
        """The names of the rig's drives (every key of every speed setting), sorted."""
        return sorted({d for sp in self.speeds.values() for d in sp})

    def speed_factors(self, seed: int, deviation: float) -> dict[str, float]:
        """Drive -> speed factor [-] of run ``seed``: each drive's short-term deviation from its
        mean speed, 1 + U(-deviation, deviation) (method.md: real belt speeds deviate up to 3 %
        short-term), drawn as `draw_speed_factors` draws it with the seed's own stream; a
        negative seed mirrors the positive one's deviations (1 - (f - 1))."""
        if seed < 0:
            return {d: 2.0 - f for d, f in self.speed_factors(-seed, deviation).items()}
        return self.draw_speed_factors(np.random.default_rng([SPEED_STREAM, seed]), deviation)

    def draw_speed_factors(self, rng: np.random.Generator, deviation: float) -> dict[str, float]:
        """Drive -> 1 + U(-deviation, deviation) [-] drawn with ``rng``, one per drive in sorted
        order (a twin's "real" runs draw from the same distribution with their own stream)."""
        return {d: 1 + float(rng.uniform(-deviation, deviation)) for d in self.drives()}

    def start_centre(self, length: float, width: float) -> tuple[float, float]:
        """The nominal start of the centre [m] of a parcel of outer ``length`` and ``width`` [m]
        under ``start.align`` (module docstring): ``start.position`` itself for ``centre``, else
        moved across the start surface by half the parcel's extent across it."""
        x, y = self.start.position
        if self.start.align == "centre":
            return x, y
        delta = math.radians(self.start.heading - self.surface(self.start.surface).heading)
        half = 0.5 * (length * abs(math.sin(delta)) + width * abs(math.cos(delta)))
        dx, dy = self.start_shift(0.0, half if self.start.align == "right" else -half)
        return float(x + dx), float(y + dy)

    def start_shift(self, along: float, across: float) -> tuple[float, float]:
        """The rig-frame offset (dx, dy) [m] of a start moved ``along`` and ``across`` [m] its
        surface (across: to the left of the surface's direction)."""
        u = self.surface(self.start.surface).unit()
        return along * u[0] - across * u[1], along * u[1] + across * u[0]

    def drive_speeds(self, setting: int) -> Mapping[str, float]:
        """Surface speed [m/s] of every drive at a speed setting."""
        if setting not in self.speeds:
            raise ParcelfitError(
                f"rig {self.name} has no speed setting {setting}",
                fix=f"use one of {sorted(self.speeds)}",
            )
        return self.speeds[setting]

    def with_drum_ends(self, radius: float) -> Rig:
        """The rig with every belt and strip set running round drums of ``radius`` [m] at its
        ends (0: square ends), in place of the rig file's ``nose_radius``."""
        if not 0.0 <= radius <= MAX_NOSE_RADIUS:
            raise ParcelfitError(
                f"drum radius {radius:g} m is outside [0, {MAX_NOSE_RADIUS:g}] m",
                fix="give the radius in metres, e.g. 0.02",
            )
        nosed = [s for s in self.surfaces if s.type in _NOSED]
        if any(2 * radius >= s.length for s in nosed):
            raise ParcelfitError(
                f"drum radius {radius:g} m leaves no flat top on a surface of rig {self.name}",
                fix="make the radius less than half the shortest belt",
            )
        surfaces = tuple(
            replace(s, nose_radius=radius) if s.type in _NOSED else s for s in self.surfaces
        )
        return replace(self, surfaces=surfaces)


# -- the file as written (its units: m, m/s, s, deg) ----------------------------------

_Point = Annotated[
    tuple[float, float], Pair(what="a point [x, y] in metres", fix="write e.g. [0.5, -0.4]")
]
_Interval = Annotated[
    tuple[float, float],
    Pair(what="[min, max] with min < max", fix="write e.g. [0.5, 1.2]", increasing=True),
]
_Heading = Annotated[float, Number(unit="deg", ge=-360, le=360)]
_Size = Annotated[float, Number(unit="m", ge=1e-3, le=100)]
_Height = Annotated[float, Number(unit="m", ge=-10, le=10)]
_Extra = Annotated[float | None, Number()]
_SURFACE_TYPE = Choice(SURFACE_TYPES, what="surface type")
_MATERIAL = Choice(MATERIALS, what="material")
# how far [m] start.position may lie beyond its surface's edge (a side laid on the edge, start.align)
START_OFF_SURFACE = 0.01
# start.align: which part of a parcel lies at start.position
START_ALIGNMENTS = ("centre", "right", "left")
# the shortest wall or light barrier [m]: a plate or beam of no length is a typo (from = to)
MIN_SEGMENT = 1e-3
# how far [m] a light barrier or a surface may lie wholly outside the end box: a parcel's front
# edge still breaks a beam just beyond the box its centre must stay in; one further off is never
# reached (often a value written in mm)
BARRIER_OUTSIDE_END = 1.0


def _description(value: Any) -> str:
    return str(value or "")


def _drive_name(value: Any) -> str:
    return str(value)


def _speed_settings(value: Any) -> Any:
    """``speeds`` must map whole numbers >= 1 to drives (checked before the drives' speeds)."""
    for key in require_mapping(value):
        if isinstance(key, bool) or not isinstance(key, int) or not 1 <= key <= MAX_SPEED_SETTING:
            raise ParcelfitError(
                f"speed setting {shown(key)} must be an integer from 1 to {MAX_SPEED_SETTING}",
                fix="write e.g. `1: {main: 1.56}`",
            )
    if not value:
        raise ParcelfitError("no speed settings", fix="add `1: {drive: speed}`")
    return value


def _two_barriers(value: Any) -> Any:
    if not isinstance(value, list) or len(value) != 2:
        raise ParcelfitError(
            "exactly two light barriers are needed",
            fix="list LS1 and LS2 in the order the parcel crosses them",
        )
    return value


def _region(value: Any) -> Region:
    return parse_region(value, where="")


class SurfaceEntry(FileModel):
    """One of ``surfaces``: the common keys and those of its type (``count``, ``strip_width``,
    ``pitch`` for strips; ``rows``, ``columns``, ``radius``, ``roller_width``, ``swivel`` for
    rollers). Lengths in m, ``heading`` and ``swivel`` in degrees."""

    name: Annotated[str, Text()]
    """The surface's name (unique in the rig)."""
    type: Annotated[str, _SURFACE_TYPE]
    """belt, strips (a set of parallel strip belts) or rollers (a roller matrix)."""
    material: Annotated[str, _MATERIAL]
    """Which contact parameters apply: belt or roller (_BePa), metal (_MePa)."""
    centre: _Point
    """Centre of the conveying area in the rig frame [m], [x, y]."""
    length: _Size
    """Length along the heading [m]."""
    width: _Size
    """Width across the heading [m]."""
    heading: _Heading
    """Direction of motion, counter-clockwise from the rig's x axis [deg]."""
    top: _Height
    """Height of the conveying surface above z = 0 [m]."""
    drive: Annotated[str, Text()]
    """The drive whose speed it runs at (a key of each speed setting in `speeds`)."""
    count: _Extra = None
    """strips: number of strips."""
    strip_width: _Extra = None
    """strips: width of one strip [m]."""
    pitch: _Extra = None
    """strips: distance between the strips' centre lines [m]."""
    rows: _Extra = None
    """rollers: rows of rollers."""
    columns: _Extra = None
    """rollers: columns of rollers."""
    radius: _Extra = None
    """rollers: roller radius [m]."""
    roller_width: _Extra = None
    """rollers: width of one roller [m]."""
    swivel: _Extra = None
    """rollers: swivel angle of the rollers' axes [deg]."""
    nose_radius: Annotated[float, Number(unit="m", ge=0.0, le=MAX_NOSE_RADIUS)] = 0.0
    """belt, strips: radius of the drums at both ends [m] (0: square ends)."""
    end_heading: Annotated[float | None, Number(unit="deg", ge=-360, le=360)] = None
    """strips: the strips' downstream ends lie on a line at this heading [deg] (a staggered
    merge); absent: square ends."""

    @classmethod
    def allowed_keys(cls, data: Mapping[Any, Any]) -> list[str]:
        """The common keys and those of the surface's type (checked first)."""
        if "type" not in data:
            raise ParcelfitError("missing required key 'type'", fix="add `type:`")
        try:
            stype = _SURFACE_TYPE.check(data["type"])
        except ParcelfitError as exc:
            raise ParcelfitError(exc.message, where="type", fix=exc.fix) from None
        return [
            *_COMMON,
            *_SURFACE_KEYS[stype],
            *(("nose_radius",) if stype in _NOSED else ()),
            *(("end_heading",) if stype == "strips" else ()),
        ]

    @model_validator(mode="after")
    def _type_keys(self) -> SurfaceEntry:
        for key in _SURFACE_KEYS[self.type]:
            if getattr(self, key) is None:
                raise ParcelfitError(f"missing required key {key!r}", fix=f"add `{key}:`")
        if self.end_heading is not None:
            a, b = math.radians(self.heading), math.radians(self.end_heading)
            if abs(math.sin(b - a)) < math.sin(math.radians(5)):
                raise ParcelfitError(
                    f"end_heading {self.end_heading:g} deg runs (nearly) along the strips "
                    f"(heading {self.heading:g} deg): their ends cannot lie on it",
                    where="end_heading",
                    fix="give the heading of the belt the strips end at, e.g. 0",
                )
            half = (self.count - 1) / 2 * self.pitch  # type: ignore[operator]
            stretch = half * abs(math.cos(b - a) / math.sin(b - a))
            if self.length - stretch <= 2 * self.nose_radius + 0.05:
                raise ParcelfitError(
                    f"with end_heading {self.end_heading:g} deg the outermost strip would be "
                    f"{self.length - stretch:.3f} m long",
                    where="end_heading",
                    fix="make the strips longer or the end line less oblique",
                )
        if 2 * self.nose_radius >= self.length:
            raise ParcelfitError(
                f"nose_radius {self.nose_radius:g} m leaves no flat top on a surface "
                f"{self.length:g} m long",
                where="nose_radius",
                fix="make the radius less than half the length",
            )
        return self

    @property
    def extra(self) -> dict[str, float]:
        """The keys of the surface's type, in their documented order."""
        return {key: getattr(self, key) for key in _SURFACE_KEYS[self.type]}


class WallEntry(FileModel):
    """One of ``walls``: a plate ``from`` - ``to`` [m], ``height`` above ``base`` [m]."""

    name: Annotated[str, Text()]
    """The wall's name."""
    material: Annotated[str, _MATERIAL] = "metal"
    """Which contact parameters apply: metal (default, _MePa), belt or roller."""
    start: Annotated[_Point, Field(alias="from")]
    """The wall's upstream end in the rig frame [m], [x, y] (key `from`)."""
    end: Annotated[_Point, Field(alias="to")]
    """The wall's downstream end in the rig frame [m], [x, y] (key `to`)."""
    height: Annotated[float, Number(unit="m", ge=1e-3, le=10)]
    """Height of the plate [m]."""
    base: _Height = 0.0
    """Height of its lower edge above z = 0 [m]."""
    thickness: Annotated[float, Number(unit="m", ge=1e-4, le=1)] = 0.003
    """Thickness of the plate [m]."""
    lead_in: Annotated[float, Number(unit="m", ge=0.0, le=0.2)] = 0.0
    """Radius of a rounded (rolled) upstream end [m] (0: none)."""


class ScatterSection(FileModel):
    """``start.scatter``: standard deviations along and across [m] and of the heading [deg]."""

    along: Annotated[float, Number(unit="m", ge=0.0, le=0.5)] = 0.0
    """Standard deviation of a hand placement along the start surface's heading [m]."""
    across: Annotated[float, Number(unit="m", ge=0.0, le=0.5)] = 0.0
    """Standard deviation across the heading [m]."""
    heading: Annotated[float, Number(unit="deg", ge=0.0, le=90)] = 0.0
    """Standard deviation of the heading [deg]."""


class StartSection(FileModel):
    """``start``: the parcel's centre [m], heading [deg], the surface below, the scatter."""

    position: _Point
    """The parcel's nominal start in the rig frame [m], [x, y]: its centre, or with `align`
    `right` or `left` the middle of that side."""
    heading: _Heading
    """The parcel's nominal heading (its x axis), counter-clockwise from the rig's x axis [deg]."""
    surface: Annotated[str, Text()]
    """The surface the parcel starts on."""
    align: Annotated[str, Choice(START_ALIGNMENTS, what="alignment")] = "centre"
    """Which part of every consignment type lies at `position`: its centre, or the middle of
    its right or left side looking along the start surface's direction (a hand laying each
    specimen against a line; wider types then start further across)."""
    scatter: ScatterSection | None = None
    """The scatter of a hand placement (draws cut off at 2.5 standard deviations); seeded
    placements draw from it."""


class BarrierEntry(FileModel):
    """One of ``light_barriers``: its name and the beam's ends [m]."""

    name: Annotated[str, Text()]
    """The light barrier's name."""
    start: Annotated[_Point, Field(alias="from")]
    """One end of the beam in the rig frame [m], [x, y] (key `from`)."""
    end: Annotated[_Point, Field(alias="to")]
    """The other end [m], [x, y] (key `to`)."""


class EndSection(FileModel):
    """``end``: the box [m] the centre must stay in, the duration [s] and the time [s] after
    the last barrier."""

    x: _Interval
    """The run ends when the parcel centre leaves this x interval [m], [low, high]."""
    y: _Interval
    """... or this y interval [m], [low, high]."""
    duration: Annotated[float, Number(unit="s", ge=0.01, le=600)]
    """... or after this much simulated time [s]."""
    after_last_barrier: Annotated[float, Number(unit="s", ge=0)] = 0.3
    """... or this long after the parcel has interrupted both light barriers [s]."""


class RigFile(FileModel):
    """A rig file as written (see the module docstring)."""

    name: Annotated[str, Text()]
    """The rig's name: the name datasets and studies use; keep it the file's
    stem (not enforced: a variant file may keep the name of what it varies)."""
    description: Annotated[str, PlainValidator(_description)] = ""
    """Free text."""
    speeds: Annotated[
        dict[
            int,
            dict[
                Annotated[str, PlainValidator(_drive_name)],
                Annotated[float, Number(unit="m/s", ge=0.0, le=20.0)],
            ],
        ],
        BeforeValidator(_speed_settings),
    ]
    """Speed setting (whole number) -> drive name -> surface speed [m/s]."""
    surfaces: Annotated[tuple[SurfaceEntry, ...], or_default(tuple)]
    """The driven surfaces a parcel rides on."""
    walls: Annotated[tuple[WallEntry, ...], or_default(tuple)] = ()
    """Vertical plates: guide plates, side walls."""
    start: StartSection
    """The parcel's start pose and its scatter."""
    light_barriers: Annotated[tuple[BarrierEntry, BarrierEntry], BeforeValidator(_two_barriers)]
    """Exactly two beams, crossed in this order: the transit time runs from the first to the
    second."""
    regions: Annotated[
        tuple[Annotated[Region, PlainValidator(_region)], ...], or_default(tuple)
    ] = ()
    """Regions of interest in the rig frame where runs are compared (boxes {x: [a, b], y: [c,
    d]} or {polygon: [[x, y], ...]}) [m]."""
    margin: Annotated[float, Number(unit="m", ge=0.0)] = 0.0
    """Safety margin around the regions [m]."""
    step_refinement: Annotated[int, Whole(ge=1, le=64)] = 1
    """This rig's runs take steps this many times finer than the default."""
    end: EndSection
    """When a run ends."""

    @field_validator("surfaces")
    @classmethod
    def _named_surfaces(cls, value: tuple[SurfaceEntry, ...]) -> tuple[SurfaceEntry, ...]:
        if not value:
            raise ParcelfitError("a rig needs at least one surface", fix="add a surface")
        names = [s.name for s in value]
        if len(set(names)) != len(names):
            raise ParcelfitError(
                "surface names must be unique", fix="give every surface its own name"
            )
        return value

    @model_validator(mode="after")
    def _references(self) -> RigFile:
        for i, s in enumerate(self.surfaces):
            missing = [k for k, d in self.speeds.items() if s.drive not in d]
            if missing:
                raise ParcelfitError(
                    f"drive {shown(s.drive)} has no speed in setting(s) {missing}",
                    where=f"surfaces[{i}].drive",
                    fix=f"add {s.drive} to every speed setting",
                )
        names = [s.name for s in self.surfaces]
        if self.start.surface not in names:
            raise ParcelfitError(
                f"start.surface names no surface: {shown(self.start.surface)}",
                where="start.surface",
                fix=f"use one of {', '.join(names)}",
            )
        first, second = (x.name for x in self.light_barriers)
        if first == second:
            raise ParcelfitError(
                f"both light barriers are named {shown(first)}",
                where="light_barriers[1].name",
                fix="give each its own name (e.g. LS1 and LS2)",
            )
        for key, entries in (("walls", self.walls), ("light_barriers", self.light_barriers)):
            for i, w in enumerate(entries):
                if math.dist(w.start, w.end) < MIN_SEGMENT:
                    raise ParcelfitError(
                        f"{shown(w.name)} has no length: from {list(w.start)} to {list(w.end)}",
                        where=f"{key}[{i}]",
                        fix="give its two ends in metres, at least 1 mm apart",
                    )
        (x_lo, x_hi), (y_lo, y_hi) = self.end.x, self.end.y
        for i, sf in enumerate(self.surfaces):
            # its centre line; a surface nowhere near the box is a unit's mistake (mm for m)
            h = math.radians(sf.heading)
            half = (sf.length / 2 * math.cos(h), sf.length / 2 * math.sin(h))
            a = (sf.centre[0] - half[0], sf.centre[1] - half[1])
            b = (sf.centre[0] + half[0], sf.centre[1] + half[1])
            off = _segment_box_distance(a, b, (x_lo, x_hi), (y_lo, y_hi)) - sf.width / 2
            if off > BARRIER_OUTSIDE_END:
                raise ParcelfitError(
                    f"surface {shown(sf.name)} lies {off:.3g} m outside the end box (x "
                    f"{list(self.end.x)}, y {list(self.end.y)}): no run can reach it",
                    where=f"surfaces[{i}].centre",
                    fix="give its centre, length and width in metres in the rig frame",
                )
        below = self.surfaces[names.index(self.start.surface)]
        # the start's offset from the surface's centre along and across its heading [m]
        a = math.radians(below.heading)
        dx = self.start.position[0] - below.centre[0]
        dy = self.start.position[1] - below.centre[1]
        along, across = dx * math.cos(a) + dy * math.sin(a), -dx * math.sin(a) + dy * math.cos(a)
        # along the heading the surface reaches as far as its longest strip does (strips whose
        # ends lie on a line at end_heading differ in length and are shifted along)
        ahead = behind = below.length / 2
        if below.type == "strips" and below.end_heading is not None:
            u = np.array([math.cos(a), math.sin(a)])
            centre = np.asarray(below.centre, dtype=float)
            for _, c, length, _ in _surface(below).parts():
                mid = float((c - centre) @ u)
                ahead, behind = max(ahead, mid + length / 2), max(behind, length / 2 - mid)
        if (
            not -behind - START_OFF_SURFACE <= along <= ahead + START_OFF_SURFACE
            or abs(across) > below.width / 2 + START_OFF_SURFACE
        ):
            raise ParcelfitError(
                f"start.position {list(self.start.position)} lies off its surface "
                f"{shown(below.name)} ({along:+.3f} m along and {across:+.3f} m across from its "
                f"centre; it spans {-behind:+.3g} to {ahead:+.3g} m along and "
                f"+-{below.width / 2:.3g} m across)",
                where="start.position",
                fix="put the start over the start surface, or name the surface it lies on",
            )
        px, py = self.start.position
        # with align right or left the position is the middle of a side: the centre lies up to
        # half a parcel (under 0.5 m) across from it, to the left of a right side (looking
        # along the start surface) and to the right of a left side; some of that reach must
        # lie in the box
        reach = {"centre": 0.0, "right": 0.5, "left": -0.5}[self.start.align]
        h = math.radians(below.heading)
        far = (px - reach * math.sin(h), py + reach * math.cos(h))
        if _segment_box_distance((px, py), far, (x_lo, x_hi), (y_lo, y_hi)) > 0:
            raise ParcelfitError(
                f"start.position {list(self.start.position)} lies outside the end box (x "
                f"{list(self.end.x)}, y {list(self.end.y)}): every run would end before it began",
                where="start.position",
                fix="widen end.x and end.y to hold the start and the whole path, or move the start",
            )
        for i, b in enumerate(self.light_barriers):
            # the distance of the segment from the box: 0 where some point of it lies inside
            off = _segment_box_distance(b.start, b.end, (x_lo, x_hi), (y_lo, y_hi))
            if off > BARRIER_OUTSIDE_END:
                raise ParcelfitError(
                    f"light barrier {shown(b.name)} lies {off:.3g} m outside the end box (x "
                    f"{list(self.end.x)}, y {list(self.end.y)}): no run can reach it",
                    where=f"light_barriers[{i}]",
                    fix="give its ends in metres in the rig frame, within the end box",
                )
        return self


def _segment_box_distance(
    a: tuple[float, float],
    b: tuple[float, float],
    xs: tuple[float, float],
    ys: tuple[float, float],
) -> float:
    """The least distance [m] between the segment a-b [m] and the box xs x ys [m] (0 where they
    meet), from 1001 points along the segment (a check for a typo, not geometry that needs to
    be exact)."""
    t = np.linspace(0.0, 1.0, 1001)
    x = a[0] + t * (b[0] - a[0])
    y = a[1] + t * (b[1] - a[1])
    dx = np.maximum(np.maximum(xs[0] - x, x - xs[1]), 0.0)
    dy = np.maximum(np.maximum(ys[0] - y, y - ys[1]), 0.0)
    return float(np.min(np.hypot(dx, dy)))


def _surface(s: SurfaceEntry) -> Surface:
    """The `Surface` of a checked ``surfaces`` entry."""
    return Surface(
        name=s.name,
        type=s.type,
        material=s.material,
        centre=s.centre,
        length=s.length,
        width=s.width,
        heading=s.heading,
        top=s.top,
        drive=s.drive,
        extra=s.extra,
        nose_radius=s.nose_radius,
        end_heading=s.end_heading,
    )


def parse_rig(doc: Any, file: str) -> Rig:
    """Build and check a `Rig` from its parsed YAML document; every error names ``file``, the
    key and the fix."""
    f = parse(RigFile, doc, file=file)
    scatter = f.start.scatter
    a, b = f.light_barriers
    return Rig(
        name=f.name,
        description=f.description,
        speeds={setting: dict(drives) for setting, drives in f.speeds.items()},
        surfaces=tuple(_surface(s) for s in f.surfaces),
        walls=tuple(
            Wall(
                name=w.name,
                material=w.material,
                start=w.start,
                end=w.end,
                height=w.height,
                base=w.base,
                thickness=w.thickness,
                lead_in=w.lead_in,
            )
            for w in f.walls
        ),
        start=StartPose(
            position=f.start.position,
            heading=f.start.heading,
            surface=f.start.surface,
            align=f.start.align,
            scatter=(0.0, 0.0, 0.0)
            if scatter is None
            else (scatter.along, scatter.across, scatter.heading),
        ),
        barriers=(Barrier(a.name, a.start, a.end), Barrier(b.name, b.start, b.end)),
        regions=f.regions,
        margin=f.margin,
        end=EndCondition(f.end.x, f.end.y, f.end.duration, f.end.after_last_barrier),
        source=file,
        step_refinement=f.step_refinement,
    )


def bundled_rig_names() -> list[str]:
    """Names of the rigs shipped with parcelfit."""
    return bundled_names("rigs")


def load_rig(name_or_path: str | Path) -> Rig:
    """Load a bundled rig by name (``E3``) or a rig file by path."""
    path = resolve_file("rigs", name_or_path, "rig")
    return parse_rig(load_yaml(path), str(path))


def load_rig_files(
    paths: Sequence[str | Path],
    taken: Mapping[str, Rig] | None = None,
    *,
    where: str | None = None,
) -> dict[str, Rig]:
    """The rigs of the rig files ``paths`` by name, after those already ``taken``; a name given
    twice (among the files or in ``taken``) is refused naming the file and ``where``."""
    out = dict(taken or {})
    for path in paths:
        rig = load_rig(path)
        if rig.name in out:
            raise ParcelfitError(
                f"two rigs are named {rig.name}",
                file=str(path),
                where=where,
                fix="give each rig file once, with a name of its own",
            )
        out[rig.name] = rig
    return out
