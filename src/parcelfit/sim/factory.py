"""Building a simulator from a configuration: the ``simulator`` section of a study or screen
file (`SimulatorSection`, checked on load), or a `SimulatorConfig` made in code.

The section's ``backend`` chooses: ``mujoco`` (a bundled or user rig and consignment, optional
``timestep`` [s], ``spacing`` [m] (the packaging mesh around a rigid content),
``film_spacing`` [m] (the film mesh around a soft content), ``membrane_cap`` [N/m],
``shell_dof`` (``auto``, ``full``,
``quadratic`` or ``trilinear``: the packaging shell's degrees of freedom, see `SceneOptions`),
``shell_cells`` (an interpolated shell's grid of cells, e.g. ``[4, 4, 1]``),
``shell_diagonals`` (``radiating`` or ``alternating``: how the shell's cells are split into
triangles), ``mass_lumping`` (``area`` or ``equal``: how the packaging's mass is spread over its
vertices, see `SceneOptions`), ``contact_law`` (``penalty`` or ``impedance``),
``contact_mapping`` (``vertex`` or ``solver``: how the penalty law's stiffness meets MuJoCo's
solver, see `SceneOptions`), ``friction``
(``contact``: per contact, or ``geom``: the former per-surface switch), ``belt_friction``
(``mujoco`` or ``coulomb``, with ``friction: geom``; see `SceneOptions`),
``roller_surface`` (``linear`` or ``turning``: how a flow splitter's rollers move the
packaging), ``stick_speed`` and ``slip_speed`` [m/s] (how the static friction offsets fade with
the slip speed, see `SceneOptions`), ``rig_timesteps`` (a time step [s] by rig name) and
``wall_limit`` [s]),
``rigidbox`` (the rigid-box reference, `parcelfit.sim.rigidbox`: a bundled or user rig and a
consignment with a rigid content, optional ``timestep`` [s], ``spacing`` [m] (its contact points),
``bottom_patch`` (``consignment``, ``outline``, ``content``, ``rim-weight`` or ``rim-bending``),
``wall_contact`` (``outline``, the default: walls meet the box's outline, or ``points``: its
contact points), ``wall_outline`` (``outline``, the default: the packaging's outline, or
``content``: the content's, a rim that gives way at a wall), ``wall_inset`` [m] (the
packaging's outline inset by this on every side), ``wall_damping`` (``ratio``,
the default: walls and lead-ins damped at the ratio of their contact's stiffness, or
``area``),
``stick_speed`` and ``slip_speed`` [m/s] (its
friction's static and dynamic threshold speeds, default 0.001 and 0.0015), ``roller_surface``
and ``wall_limit`` [s]; the MuJoCo scene's other settings are refused),
``external`` (a solver description file run as a command) or ``python`` (``factory:
package.module:callable``, imported and called: such a file runs code). A new named backend
adds its keys to `SimulatorSection` and `SimulatorConfig` and its construction to
`make_simulator`; everything that builds a simulator from a configuration (calibration,
screening, ``parcelfit simulate``, the demo) goes through `make_simulator`.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

from pydantic import model_validator

from parcelfit.errors import ParcelfitError, shown
from parcelfit.schema import Choice, FileModel, Number, Text
from parcelfit.sim.params import (
    BELT_FRICTION,
    BOTTOM_PATCHES,
    CONTACT_LAWS,
    CONTACT_MAPPINGS,
    FRICTION_LAWS,
    MASS_LUMPINGS,
    MAX_TIMESTEP,
    MIN_TIMESTEP,
    RIGID,
    ROLLER_SURFACES,
    SHELL_DIAGONALS,
    SHELL_DOFS,
    STICK_SPEED,
    WALL_CONTACTS,
    WALL_DAMPINGS,
    WALL_OUTLINES,
    ShellCellsField,
)
from parcelfit.sim.protocol import Simulator

if TYPE_CHECKING:
    from parcelfit.sim.mujoco import Consignment, Rig, SimOptions

BACKENDS = ("mujoco", "rigidbox", "external", "python")
# the MuJoCo scene's settings, which the rigid-box reference does not take
_MUJOCO_ONLY = (
    "film_spacing",
    "membrane_cap",
    "shell_dof",
    "shell_cells",
    "rim_brace",
    "shell_diagonals",
    "mass_lumping",
    "contact_law",
    "contact_mapping",
    "friction",
    "belt_friction",
    "rig_timesteps",
)
RIGIDBOX_STICK_SPEED = 0.001  # m/s, the rigid-box reference's default (RecurDyn's)
_SETTINGS = (
    "backend",
    "rig",
    "rigs",
    "consignment",
    "timestep",
    "spacing",
    "film_spacing",
    "membrane_cap",
    "shell_dof",
    "shell_cells",
    "rim_brace",
    "shell_diagonals",
    "mass_lumping",
    "contact_law",
    "contact_mapping",
    "friction",
    "belt_friction",
    "roller_surface",
    "stick_speed",
    "slip_speed",
    "rig_timesteps",
    "bottom_patch",
    "wall_contact",
    "wall_outline",
    "wall_inset",
    "wall_damping",
    "wall_limit",
    "external",
    "factory",
)
_NEEDS = {
    "mujoco": ("rig", "consignment"),
    "rigidbox": ("rig", "consignment"),
    "external": ("external",),
    "python": ("factory",),
}
DEFAULT_WALL_LIMIT = 600.0  # s, per simulation
# a setting whose SceneOptions field has another name (SceneOptions.soft_spacing is the soft
# content's own vertex spacing, so the film's setting cannot take that name)
_SCENE_NAMES = {"film_spacing": "soft_shell_spacing"}


def _check_needs(backend: str, settings: Any) -> None:
    """Refuse a configuration that leaves out what its backend needs, or gives the rigid-box
    reference a MuJoCo setting (or MuJoCo the rigid box's ``bottom_patch``, ``wall_contact``,
    ``wall_outline``, ``wall_inset`` or ``wall_damping``)."""
    for key in _NEEDS[backend]:
        if getattr(settings, key) is None:
            raise ParcelfitError(f"the {backend} backend needs {key!r}", fix=f"add `{key}:`")
    if settings.rigs is not None and backend not in ("mujoco", "rigidbox"):
        raise ParcelfitError(
            f"the {backend} backend does not take rigs",
            where="rigs",
            fix="remove it (rig files of the mujoco and rigidbox backends)",
        )
    if backend == "rigidbox":
        given = [k for k in _MUJOCO_ONLY if getattr(settings, k) is not None]
        if given:
            raise ParcelfitError(
                f"the rigidbox backend does not take {', '.join(given)}",
                fix="remove it (a setting of the MuJoCo scene)",
            )
    else:
        for key in ("bottom_patch", "wall_contact", "wall_outline", "wall_inset", "wall_damping"):
            if getattr(settings, key) is not None:
                raise ParcelfitError(
                    f"{key} is a setting of the rigidbox backend", where=key, fix="remove it"
                )


@dataclass(frozen=True)
class SimulatorConfig(Mapping[str, Any]):
    """A simulator's configuration (SI): ``backend`` and what it needs (mujoco: ``rig`` and
    ``consignment``, bundled names or ``.yaml`` paths, optional ``rigs`` (more rig files whose
    rigs the test cases may name), ``timestep`` [s], ``spacing``
    and ``film_spacing`` [m], ``membrane_cap`` [N/m], ``shell_dof``, ``shell_cells``,
    ``shell_diagonals``, ``mass_lumping``, ``belt_friction``, ``roller_surface``, ``stick_speed`` and
    ``slip_speed`` [m/s], ``rig_timesteps`` (rig name -> time step [s]); rigidbox: ``rig`` and
    ``consignment``, optional ``rigs``, ``timestep``, ``spacing``, ``bottom_patch``,
    ``stick_speed``, ``slip_speed``, ``roller_surface``, ``wall_contact``, ``wall_outline``,
    ``wall_inset``,
    ``wall_damping``;
    external: the solver description file ``external``;
    python: ``factory``),
    optional ``wall_limit`` [s] per simulation, and ``folder``: the folder of the file it came
    from (an external solver's runs go into ``folder/.external-runs``).

    It reads as the mapping of the settings given (``dict(config)``: the keys of the file's
    section that were set, without ``folder``), as the section did before it was typed."""

    backend: str
    rig: str | None = None
    rigs: tuple[str, ...] | None = None
    consignment: str | None = None
    timestep: float | None = None
    spacing: float | None = None
    film_spacing: float | None = None
    membrane_cap: float | None = None
    shell_dof: str | None = None
    shell_cells: tuple[int, int, int] | None = None
    rim_brace: float | None = None
    shell_diagonals: str | None = None
    mass_lumping: str | None = None
    contact_law: str | None = None
    contact_mapping: str | None = None
    friction: str | None = None
    belt_friction: str | None = None
    roller_surface: str | None = None
    stick_speed: float | None = None
    slip_speed: float | None = None
    rig_timesteps: Mapping[str, float] | None = None
    bottom_patch: str | None = None
    wall_contact: str | None = None
    wall_outline: str | None = None
    wall_inset: float | None = None
    wall_damping: str | None = None
    wall_limit: float | None = None
    external: str | None = None
    factory: str | None = None
    folder: Path = Path(".")

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ParcelfitError(
                f"unknown simulator backend {shown(self.backend)}",
                fix=f"use one of {list(BACKENDS)}",
            )
        _check_needs(self.backend, self)

    def __getitem__(self, key: str) -> Any:
        value = getattr(self, key, None) if key in _SETTINGS else None
        if value is None:
            raise KeyError(key)
        return value

    def __iter__(self) -> Iterator[str]:
        return (k for k in _SETTINGS if getattr(self, k) is not None)

    def __len__(self) -> int:
        return sum(1 for _ in self)


class SimulatorSection(FileModel):
    """``simulator`` of a study or screen file: the backend and what it needs (``timestep``
    [s], ``spacing`` and ``film_spacing`` [m], ``membrane_cap`` [N/m], ``shell_dof``,
    ``shell_cells``, ``shell_diagonals``, ``mass_lumping``, ``belt_friction``, ``roller_surface``, ``stick_speed``
    and ``slip_speed`` [m/s], ``rig_timesteps`` (rig name -> time step [s]), ``wall_limit``
    [s])."""

    backend: Annotated[str, Choice(BACKENDS, what="backend")]
    """mujoco (the MuJoCo model), rigidbox (the rigid-box reference), external (a solver run as
    a command) or python (a factory you write)."""
    rig: Annotated[str | None, Text()] = None
    """mujoco, rigidbox: a bundled rig name (E1, E2a, E2b, E3) or a rig .yaml file relative to
    this file (its stem must equal its name)."""
    rigs: list[Annotated[str, Text()]] | None = None
    """mujoco, rigidbox: more rig .yaml files, relative to this file, whose rigs the test cases
    may name (by the rig's name), e.g. the bench tests `parcelfit design` recommended."""
    consignment: Annotated[str | None, Text()] = None
    """mujoco, rigidbox: a bundled consignment type (KPBW, PB, KP, BW) or a consignment .yaml
    file relative to this file."""
    timestep: Annotated[float | None, Number(unit="s", ge=1e-9)] = None
    """Time step [s] (default: 1/2400 s with an interpolated shell, the rigid-content types',
    1/1200 s with a full shell, the soft ones', 1/2400 s for a full shell with Coulomb belt
    friction, each divided by the rig's step_refinement). A step given here is used on every
    rig as it is, not divided by step_refinement: give E1 and E2a theirs in `rig_timesteps`."""
    spacing: Annotated[float | None, Number(unit="m", ge=1e-9)] = None
    """Shell mesh spacing around a rigid content (rigidbox: its contact points' spacing) [m]
    (default 0.03)."""
    film_spacing: Annotated[float | None, Number(unit="m", ge=1e-9)] = None
    """Film mesh spacing around a soft content [m] (default 0.05)."""
    membrane_cap: Annotated[float | None, Number(unit="N/m", ge=1e-9)] = None
    """Largest in-plane stiffness E*t of the packaging shell [N/m] (default: none)."""
    shell_dof: Annotated[str | None, Choice(SHELL_DOFS, what="shell degrees of freedom")] = None
    """The packaging shell's degrees of freedom: auto (the consignment file's), full, quadratic
    or trilinear."""
    shell_cells: ShellCellsField | None = None
    """An interpolated shell's grid of cells along length, width, height, e.g. [4, 4, 1]."""
    rim_brace: Annotated[float | None, Number(unit="", ge=0, le=10)] = None
    """Braces across an interpolated shell's rim cells, as a share of an ideal wedge's stiffness
    (default 0: none; needs cells whose boundaries fall on the content's ends)."""
    shell_diagonals: Annotated[
        str | None, Choice(SHELL_DIAGONALS, what="split of the shell's cells")
    ] = None
    """How the shell's cells are split into triangles: radiating (default) or alternating."""
    mass_lumping: Annotated[
        str | None, Choice(MASS_LUMPINGS, what="spread of the packaging's mass")
    ] = None
    """How the packaging's mass is spread: area (lumped by area and volume, default) or equal
    (MuJoCo's equal shares)."""
    contact_law: Annotated[str | None, Choice(CONTACT_LAWS, what="contact law")] = None
    """penalty (default: the catalogue's stiffness and damping act as a spring and damper) or
    impedance (the former law)."""
    contact_mapping: Annotated[str | None, Choice(CONTACT_MAPPINGS, what="contact mapping")] = None
    """With the penalty law: vertex (default: each contact mapped with a lone shell vertex's
    inverse mass; an interpolated shell's face realises about half the catalogue's stiffness)
    or solver (MuJoCo's own inverse mass, and the 50 contacts it keeps of a pair weighted for
    the ones it drops: a face pressed flat realises it at 100 N/mm on 30 and 15 mm meshes, not
    converged on E3; docs/research/contact-cap.md)."""
    friction: Annotated[str | None, Choice(FRICTION_LAWS, what="friction law")] = None
    """contact (default: each contact's coefficient from its own slip) or geom (the former
    per-surface switch)."""
    belt_friction: Annotated[str | None, Choice(BELT_FRICTION, what="belt friction law")] = None
    """With friction: geom, the law on belts, strips and rollers: mujoco or coulomb."""
    roller_surface: Annotated[str | None, Choice(ROLLER_SURFACES, what="roller surface motion")] = (
        None
    )
    """How a flow splitter's rollers move the packaging: linear (default) or turning."""
    stick_speed: Annotated[float | None, Number(unit="m/s", ge=1e-9)] = None
    """Slip speed below which the static friction offset acts fully [m/s]."""
    slip_speed: Annotated[float | None, Number(unit="m/s", ge=1e-9)] = None
    """Slip speed above which only the dynamic friction acts [m/s] (above stick_speed)."""
    rig_timesteps: (
        dict[
            Annotated[str, Text()],
            Annotated[float, Number(unit="s", ge=MIN_TIMESTEP, le=MAX_TIMESTEP)],
        ]
        | None
    ) = None
    """A time step [s] by rig name, e.g. {E1: 0.000208333}."""
    bottom_patch: Annotated[str | None, Choice(BOTTOM_PATCHES, what="bottom contact patch")] = None
    """rigidbox: where the box touches the belt: consignment (its bulge patch, else
    rim-bending), outline, content, rim-weight (the outline, its rim carrying its own weight) or
    rim-bending (its own weight and what its bending passes on, from E_Pa, t_Pa, nu_Pa and
    k_BePa)."""
    wall_contact: Annotated[str | None, Choice(WALL_CONTACTS, what="wall contact")] = None
    """rigidbox: how walls meet the box: its outline (default) or its contact points."""
    wall_outline: Annotated[str | None, Choice(WALL_OUTLINES, what="wall outline")] = None
    """rigidbox: the outline walls and lead-ins meet: the packaging's (outline, default) or the
    content's (content: a rim that gives way at a wall)."""
    wall_inset: Annotated[float | None, Number(unit="m", ge=0.0)] = None
    """rigidbox: the packaging's outline that walls meet, inset by this on every side [m] (no
    nearer than the content's): a rim that has given way so far (default 0)."""
    wall_damping: Annotated[str | None, Choice(WALL_DAMPINGS, what="wall damping")] = None
    """rigidbox: walls and lead-ins damped at the ratio of their contact's stiffness (ratio,
    default) or per unit area (area)."""
    wall_limit: Annotated[float | None, Number(unit="s", ge=1e-9)] = None
    """Wall-clock limit of one simulation [s] (default 600)."""
    external: Annotated[str | None, Text()] = None
    """external: the solver description file (parcelfit.sim.external), relative to this file."""
    factory: Annotated[str | None, Text()] = None
    """python: package.module:callable returning a Simulator (the file then runs code)."""

    @model_validator(mode="after")
    def _backend_needs(self) -> SimulatorSection:
        _check_needs(self.backend, self)
        default = RIGIDBOX_STICK_SPEED if self.backend == "rigidbox" else STICK_SPEED
        stick = default if self.stick_speed is None else self.stick_speed
        if self.slip_speed is not None and self.slip_speed <= stick:
            raise ParcelfitError(
                f"slip_speed ({self.slip_speed} m/s) must exceed stick_speed ({stick} m/s): the "
                "static friction offset fades between the two",
                where="slip_speed",
                fix="give a slip_speed above stick_speed (e.g. stick_speed: 0.1, slip_speed: 1)",
            )
        return self

    def to_config(self, folder: Path) -> SimulatorConfig:
        """The configuration this section describes; the paths of ``.yaml`` rig, consignment and
        solver files made absolute (relative to ``folder``, the file's folder)."""
        given = self.model_dump(exclude_none=True)
        for key in ("rig", "consignment", "external"):
            if key in given and given[key].lower().endswith((".yaml", ".yml")):
                given[key] = str((folder / given[key]).resolve())
        if "rigs" in given:
            given["rigs"] = tuple(str((folder / r).resolve()) for r in given["rigs"])
        return SimulatorConfig(**given, folder=folder)


def make_simulator(config: SimulatorConfig) -> Simulator:
    """The simulator ``config`` describes (files are read and a python factory is called here)."""
    if config.backend == "mujoco":
        from parcelfit.sim.mujoco import (
            MujocoSimulator,
            SceneOptions,
            SimOptions,
            load_consignment,
        )

        assert config.rig is not None and config.consignment is not None  # checked on creation
        cons = load_consignment(config.consignment)
        numerics: dict[str, Any] = {
            _SCENE_NAMES.get(k, k): float(config[k])
            for k in (
                "timestep",
                "spacing",
                "film_spacing",
                "membrane_cap",
                "rim_brace",
                "stick_speed",
                "slip_speed",
            )
            if k in config
        }
        for key in (
            "contact_law",
            "contact_mapping",
            "friction",
            "belt_friction",
            "roller_surface",
            "shell_dof",
            "shell_cells",
            "shell_diagonals",
            "mass_lumping",
        ):
            if key in config:
                numerics[key] = config[key]
        if "rig_timesteps" in config:
            numerics["rig_timesteps"] = {k: float(v) for k, v in config["rig_timesteps"].items()}
        options = SimOptions(
            scene=SceneOptions(**numerics),
            wall_limit=DEFAULT_WALL_LIMIT if config.wall_limit is None else config.wall_limit,
        )
        return MujocoSimulator(options, rigs=_rigs(config), consignments={cons.name: cons})
    if config.backend == "rigidbox":
        from parcelfit.sim.mujoco import load_consignment
        from parcelfit.sim.rigidbox import RigidBoxOptions, RigidBoxSimulator

        assert config.rig is not None and config.consignment is not None  # checked on creation
        cons = load_consignment(config.consignment)
        if cons.soft:
            raise ParcelfitError(
                f"consignment {cons.name} has a soft content: the rigidbox backend represents "
                "rigid contents only",
                fix="use the mujoco backend",
            )
        given: dict[str, Any] = {
            k: float(config[k])
            for k in ("timestep", "spacing", "stick_speed", "slip_speed", "wall_inset")
            if k in config
        }
        for key in (
            "bottom_patch",
            "roller_surface",
            "wall_contact",
            "wall_outline",
            "wall_damping",
        ):
            if key in config:
                given[key] = config[key]
        if "stick_speed" in given and "slip_speed" not in given:
            given["slip_speed"] = 1.5 * given["stick_speed"]  # RecurDyn's defaults' ratio
        box = RigidBoxOptions(
            **given,
            wall_limit=DEFAULT_WALL_LIMIT if config.wall_limit is None else config.wall_limit,
        )
        return RigidBoxSimulator(box, rigs=_rigs(config), consignments={cons.name: cons})
    if config.backend == "external":
        from parcelfit.sim.external import ExternalSimulator, load_external_solver

        return ExternalSimulator(
            load_external_solver(config["external"]), workroot=config.folder / ".external-runs"
        )
    module, _, attr = str(config.factory).partition(":")
    try:
        factory = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ParcelfitError(
            f"cannot import the simulator factory {config.factory!r} ({exc})",
            fix="give it as package.module:callable, importable from here",
        ) from exc
    return factory()


def _rigs(config: SimulatorConfig) -> dict[str, Rig]:
    """The rigs of ``config`` by name: its ``rig`` and its ``rigs`` files (bundled rigs the
    simulators load by themselves); a name given twice is refused, naming the file."""
    from parcelfit.sim.mujoco import load_rig, load_rig_files

    assert config.rig is not None  # checked on creation
    rig = load_rig(config.rig)
    # a file that is ``rig`` again (a design on one of the study's rigs) is left out
    same = Path(config.rig).resolve()
    others = [p for p in config.rigs or () if Path(p).resolve() != same]
    return load_rig_files(others, {rig.name: rig}, where="simulator.rigs")


def mujoco_simulator(
    options: SimOptions, rigs: Sequence[Rig], consignments: Sequence[Consignment]
) -> Simulator:
    """A MuJoCo simulator of rigs and consignment types already loaded, its options given in
    full: a twin dataset's "real" runs (`parcelfit.synth`), each with its own belt speeds,
    start offset and mesh. A study's simulator comes from its file's section (`make_simulator`)."""
    from parcelfit.sim.mujoco import MujocoSimulator

    return MujocoSimulator(
        options,
        rigs={r.name: r for r in rigs},
        consignments={c.name: c for c in consignments},
    )


def content_kind(config: SimulatorConfig) -> str:
    """The content kind (``rigid`` or ``soft``, the catalogue's ranges) of the consignment
    ``config`` simulates: the consignment file's (mujoco, rigidbox); backends without one count
    as rigid."""
    if config.backend in ("mujoco", "rigidbox"):
        from parcelfit.sim.mujoco import load_consignment

        return load_consignment(config["consignment"]).content_kind
    return RIGID


__all__ = [
    "BACKENDS",
    "SimulatorConfig",
    "SimulatorSection",
    "content_kind",
    "make_simulator",
    "mujoco_simulator",
]
