"""The catalogue of simulation parameters: physical meaning, unit, published range and default.

Values are stored in user units (the published table's: N/mm, N/mm^2, mm, g) and converted to
SI exactly once, by `ParameterSpec.to_si`, before they reach a simulator. ``low``/``high`` are the
screening ranges (method.md section 5, where published; otherwise plausible ranges, marked
``published=False``); ``physical`` bounds are what a value may take at all.

Stage-one screening starts from 16 parameters for rigid-content consignments (KPBW, KP, BW) and
18 for the polybag PB (the two content parameters E_Co and zeta_Co are added). How each maps
to MuJoCo is stated in ``mapping`` and in ``parcelfit/sim/mujoco/README.md``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Annotated, Any

from pydantic import AfterValidator

from parcelfit.config import suggest
from parcelfit.errors import ParcelfitError, shown
from parcelfit.schema import Number

RIGID = "rigid"
SOFT = "soft"
# the slip speed [m/s] below which a static friction offset (mu_s_*) acts by default; the scene's
# `stick_speed` and a study file's check of `slip_speed` both start from it
STICK_SPEED = 0.005
# the per-contact friction law's static and dynamic thresholds [m/s] (sim/mujoco/friction.py):
# the published solver's defaults
STATIC_THRESHOLD = 0.001
DYNAMIC_THRESHOLD = 0.0015
# the time steps [s] a scene accepts (its ``timestep``, a rig's own step, a study's or a twin's)
MIN_TIMESTEP, MAX_TIMESTEP = 1e-5, 0.01
# the finest refinement of a model (a scene's every mesh spacing and time step divided by it, the
# calibration's convergence check): 4 makes a 30 mm mesh 7.5 mm and E1's step 1/19200 s
MAX_REFINEMENT = 4
# the values a scene's ``shell_dof`` and ``belt_friction`` take (`SceneOptions`); a study's
# simulator section and a twin's settings check against the same lists
SHELL_DOFS = ("auto", "full", "quadratic", "trilinear")
# the most cells an interpolated shell's grid takes along one axis (``shell_cells``): MuJoCo's
# multi-cell flexes cost more with every cell (a dense solve over their nodes)
MAX_SHELL_CELLS = 12


def shell_cells(value: Iterable[float]) -> tuple[int, int, int]:
    """An interpolated shell's grid of cells (along the parcel's length, width, height) as three
    whole numbers from 1 to `MAX_SHELL_CELLS`; anything else is refused."""
    cells = tuple(value)
    if len(cells) != 3 or not all(
        float(c).is_integer() and 1 <= c <= MAX_SHELL_CELLS for c in cells
    ):
        raise ParcelfitError(
            f"shell cells must be three whole numbers from 1 to {MAX_SHELL_CELLS}, got {cells}",
            fix="give cells along the length, width and height, e.g. 4,4,1",
        )
    return (int(cells[0]), int(cells[1]), int(cells[2]))


# ``shell_cells`` as a file writes it (a consignment file, a study's simulator section): each
# number checked where it stands (``shell_cells[1]: 13 is outside ...``), then the three as a
# whole by `shell_cells`, so the model holds the checked tuple
ShellCellsField = Annotated[
    tuple[Annotated[float, Number(ge=1, le=MAX_SHELL_CELLS)], ...], AfterValidator(shell_cells)
]


BELT_FRICTION = ("mujoco", "coulomb")
# how a contact's normal force follows its penetration, and how friction is decided
# (`SceneOptions.contact_law`, `SceneOptions.friction`; sim/mujoco/contact.py, friction.py)
CONTACT_LAWS = ("penalty", "impedance")
# how the penalty law's per-contact stiffness meets MuJoCo's solver (`SceneOptions.contact_mapping`;
# sim/mujoco/contact_cap.py): a lone vertex's inverse mass and every contact as MuJoCo keeps it,
# or MuJoCo's own inverse mass and the contacts it keeps of a capped pair weighted for the rest
CONTACT_MAPPINGS = ("vertex", "solver")
FRICTION_LAWS = ("contact", "geom")
# where the rigid-box reference's bottom carries contact (sim/rigidbox/geometry.py): the
# consignment's own bulge patch if it has one, else rim-bending; the outline at one pressure; the
# content's footprint; the outline with its rim beyond the content carrying only the rim's own
# weight; or that and what the packaging sheet's bending passes on from the content
BOTTOM_PATCHES = ("consignment", "outline", "content", "rim-weight", "rim-bending")
# how the rigid-box reference's walls meet the parcel (sim/rigidbox/contact.py): its outline, or
# its contact points
WALL_CONTACTS = ("outline", "points")
# which outline the rigid-box reference's walls and lead-ins meet: the packaging's (a rim as stiff
# as the content), or the content's (a rim that gives way at a wall)
WALL_OUTLINES = ("outline", "content")
# how the rigid-box reference damps a wall's and a lead-in's contact: at the damping ratio of the
# contact's own stiffness, or per unit area as its contact points
WALL_DAMPINGS = ("ratio", "area")
# how a flow splitter's rollers move the packaging (`SceneOptions.roller_surface`) and how the
# shell's grid cells are split into triangles (`SceneOptions.shell_diagonals`); a study's
# simulator section checks against the same lists
ROLLER_SURFACES = ("linear", "turning")
SHELL_DIAGONALS = ("radiating", "alternating")
# how a flex's mass is spread over its bodies (sim/mujoco/lumped_mass.py)
MASS_LUMPINGS = ("area", "equal")


@dataclass(frozen=True)
class Range:
    """Screening range and default in user units."""

    low: float
    high: float
    default: float


@dataclass(frozen=True)
class ParameterSpec:
    """One simulation parameter (values in ``unit``; ``si_factor`` converts to SI)."""

    name: str
    meaning: str
    unit: str  # user-facing unit; "-" for dimensionless
    si_unit: str
    si_factor: float
    ranges: Mapping[str, Range]  # by content kind: "rigid" or "soft"
    physical: tuple[float, float]  # admissible values at all, user units
    published: bool
    mapping: str

    def range_for(self, content_kind: str) -> Range:
        """Screening range and default for a content kind ("rigid" or "soft")."""
        if content_kind not in self.ranges:
            raise ParcelfitError(f"parameter {self.name} does not apply to {content_kind} contents")
        return self.ranges[content_kind]

    def check_physical(self, value: float) -> float:
        """``value`` (user unit) if it lies in the ``physical`` range, else a `ParcelfitError`
        naming the parameter, the value and the range (friction, stiffness, modulus, damping
        ratio, ... each has one: a negative friction or stiffness is no parcel)."""
        lo, hi = self.physical
        if not lo <= value <= hi:  # also refuses NaN
            unit = "" if self.unit == "-" else f" {self.unit}"
            raise ParcelfitError(
                f"{self.name} = {value:g}{unit} is outside its physical range "
                f"[{lo:g}, {hi:g}]{unit}",
                fix=f"give {self.meaning} from {lo:g} to {hi:g}"
                + (f" {self.unit}" if unit else " (dimensionless)"),
            )
        return value

    def si_range(self, content_kind: str) -> tuple[float, float]:
        """The screening range's ends for a content kind ("rigid" or "soft"), in SI."""
        r = self.range_for(content_kind)
        return self.to_si(r.low), self.to_si(r.high)

    def to_si(self, value: float) -> float:
        """Convert a value from the user unit to SI."""
        return value * self.si_factor

    def from_si(self, value: float) -> float:
        """Convert a value from SI to the user unit."""
        return value / self.si_factor


def _both(low: float, high: float, default: float) -> dict[str, Range]:
    r = Range(low, high, default)
    return {RIGID: r, SOFT: r}


_STIFF = (
    "per-contact solref (direct format) and constant solimp, derived so that the whole-face contact has "
    "this normal stiffness (sim/mujoco/contact.py)"
)
_DAMP = "contact damping ratio: direct-format damping = 2 * zeta * sqrt(stiffness)"

CATALOGUE: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        "k_CoPa",
        "contact stiffness content/packaging",
        "N/mm",
        "N/m",
        1e3,
        _both(100, 1000, 500),
        (1, 1e5),
        True,
        _STIFF,
    ),
    ParameterSpec(
        "k_MePa",
        "contact stiffness metal/packaging",
        "N/mm",
        "N/m",
        1e3,
        _both(100, 1000, 611),
        (1, 1e5),
        True,
        _STIFF,
    ),
    ParameterSpec(
        "k_BePa",
        "contact stiffness belt/packaging",
        "N/mm",
        "N/m",
        1e3,
        _both(100, 1000, 500),
        (1, 1e5),
        False,
        _STIFF,
    ),
    ParameterSpec(
        "mu_d_BePa",
        "dynamic friction belt/packaging",
        "-",
        "-",
        1.0,
        _both(0.3, 0.6, 0.45),
        (0, 2),
        True,
        "sliding friction of belt and roller geoms (priority wins)",
    ),
    ParameterSpec(
        "mu_d_MePa",
        "dynamic friction metal/packaging",
        "-",
        "-",
        1.0,
        _both(0.15, 0.35, 0.25),
        (0, 2),
        True,
        "sliding friction of metal geoms (priority wins)",
    ),
    ParameterSpec(
        "mu_s_MePa",
        "static friction offset metal/packaging",
        "-",
        "-",
        1.0,
        _both(0.0, 0.3, 0.15),
        (0, 1),
        True,
        "friction of a metal geom raised to mu_d + offset while the packaging's slip speed on it "
        "is below the stick threshold (updated every step)",
    ),
    ParameterSpec(
        "mu_s_BePa",
        "static friction offset belt/packaging",
        "-",
        "-",
        1.0,
        _both(0.0, 0.3, 0.1),
        (0, 1),
        False,
        "as mu_s_MePa, for belt and roller geoms",
    ),
    ParameterSpec(
        "mu_CoPa",
        "friction content/packaging",
        "-",
        "-",
        1.0,
        _both(0.2, 0.8, 0.4),
        (0, 2),
        False,
        "sliding friction of the content geom or flex (priority)",
    ),
    ParameterSpec(
        "E_Pa",
        "Young's modulus packaging",
        "N/mm^2",
        "Pa",
        1e6,
        {RIGID: Range(200, 1600, 1000), SOFT: Range(50, 200, 100)},
        (1, 1e5),
        True,
        "flex elasticity young of the packaging shell",
    ),
    ParameterSpec(
        "nu_Pa",
        "Poisson's ratio packaging",
        "-",
        "-",
        1.0,
        _both(0.2, 0.45, 0.3),
        (0, 0.49),
        False,
        "flex elasticity poisson of the packaging shell",
    ),
    ParameterSpec(
        "t_Pa",
        "shell thickness packaging",
        "mm",
        "m",
        1e-3,
        {RIGID: Range(0.2, 1.0, 0.5), SOFT: Range(0.05, 0.2, 0.1)},
        (0.01, 5),
        False,
        "flex elasticity thickness of the packaging shell",
    ),
    ParameterSpec(
        "zeta_Pa",
        "damping ratio packaging",
        "-",
        "-",
        1.0,
        _both(0.01, 0.1, 0.04),
        (0, 2),
        False,
        "flex Rayleigh damping beta = 2 zeta / omega_ref (omega_ref: the shell's first free bending mode)",
    ),
    ParameterSpec(
        "zeta_CoPa",
        "contact damping ratio content/packaging",
        "-",
        "-",
        1.0,
        _both(0.3, 1.5, 1.0),
        (0.01, 5),
        False,
        _DAMP,
    ),
    ParameterSpec(
        "zeta_BePa",
        "contact damping ratio belt/packaging",
        "-",
        "-",
        1.0,
        _both(0.3, 1.5, 1.0),
        (0.01, 5),
        False,
        _DAMP,
    ),
    ParameterSpec(
        "zeta_MePa",
        "contact damping ratio metal/packaging",
        "-",
        "-",
        1.0,
        _both(0.3, 1.5, 1.0),
        (0.01, 5),
        False,
        _DAMP,
    ),
    ParameterSpec(
        "m_Pa",
        "mass of the packaging (the content takes the rest)",
        "g",
        "kg",
        1e-3,
        {RIGID: Range(10, 40, 20), SOFT: Range(5, 20, 10)},
        (1, 1000),
        False,
        "flexcomp mass of the shell; content mass = consignment mass - m_Pa",
    ),
    ParameterSpec(
        "E_Co",
        "Young's modulus content",
        "N/mm^2",
        "Pa",
        1e6,
        {SOFT: Range(0.05, 0.5, 0.08)},
        (0.001, 100),
        True,
        "flex elasticity young of the soft content",
    ),
    ParameterSpec(
        "zeta_Co",
        "damping ratio content",
        "-",
        "-",
        1.0,
        {SOFT: Range(0.01, 0.1, 0.04)},
        (0, 2),
        True,
        "flex Rayleigh damping beta = 2 zeta / omega_ref of the soft content",
    ),
)

_BY_NAME = {p.name: p for p in CATALOGUE}


def parameter(name: str) -> ParameterSpec:
    """The catalogue entry called ``name``."""
    if name not in _BY_NAME:
        close = suggest(name, _BY_NAME)
        raise ParcelfitError(
            f"unknown parameter {shown(name)}",
            fix=f"did you mean {close!r}?" if close else f"known: {', '.join(_BY_NAME)}",
        )
    return _BY_NAME[name]


def to_catalogue_units(name: str, si_value: Any) -> Any:
    """A value (or array) of parameter ``name`` from SI to its catalogue unit; a name outside
    the catalogue (an external solver's own parameter) is passed through unchanged."""
    spec = _BY_NAME.get(name)
    return spec.from_si(si_value) if spec else si_value


def catalogue_unit(name: str) -> str:
    """The catalogue unit of parameter ``name`` ("SI" for a name outside the catalogue)."""
    spec = _BY_NAME.get(name)
    return spec.unit if spec else "SI"


def si_unit(name: str) -> str:
    """The SI unit of parameter ``name`` ("SI" for a name outside the catalogue)."""
    spec = _BY_NAME.get(name)
    return spec.si_unit if spec else "SI"


def parameters_for(content_kind: str) -> list[ParameterSpec]:
    """The screening candidates for a content kind: 16 for "rigid", 18 for "soft"."""
    return [p for p in CATALOGUE if content_kind in p.ranges]


def content_parameters(content_kind: str) -> list[ParameterSpec]:
    """The parameters of the content itself: those that apply to ``content_kind`` and to no
    other kind (for soft contents their stiffness and damping, for rigid contents none)."""
    return [p for p in CATALOGUE if set(p.ranges) == {content_kind}]


def defaults_si(content_kind: str) -> dict[str, float]:
    """Default value of every parameter for a content kind, in SI units."""
    return {
        p.name: p.to_si(p.range_for(content_kind).default) for p in parameters_for(content_kind)
    }


def resolve(
    content_kind: str,
    user_values: Mapping[str, float] | None = None,
    si_values: Mapping[str, float] | None = None,
    type_defaults: Mapping[str, float] | None = None,
) -> dict[str, float]:
    """Defaults overridden by values in user units and/or SI; every value checked (SI result).

    Precedence, lowest first: the catalogue's defaults, ``type_defaults`` (a consignment type's
    own defaults, user units), ``user_values`` (user units), ``si_values`` (SI).
    """
    out = defaults_si(content_kind)
    known = {p.name for p in parameters_for(content_kind)}
    layers = ((type_defaults or {}, False), (user_values or {}, False), (si_values or {}, True))
    for values, in_si in layers:
        for name, value in values.items():
            spec = parameter(name)
            if name not in known:
                raise ParcelfitError(
                    f"parameter {name} does not apply to {content_kind} contents",
                    fix=f"use one of: {', '.join(sorted(known))}",
                )
            user = spec.check_physical(spec.from_si(value) if in_si else float(value))
            out[name] = spec.to_si(user)
    return out


def parse_assignments(items: Iterable[str]) -> dict[str, float]:
    """Parse ``NAME=VALUE`` strings (user units) into a dict."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            sep = ""
        if sep and not math.isfinite(out[name.strip()]):
            raise ParcelfitError(
                f"{shown(item)} is not a finite number", fix="write NAME=VALUE, e.g. mu_d_BePa=0.4"
            )
        if not sep:
            raise ParcelfitError(
                f"cannot read {shown(item)}", fix="write NAME=VALUE, e.g. mu_d_BePa=0.4"
            )
    return out
