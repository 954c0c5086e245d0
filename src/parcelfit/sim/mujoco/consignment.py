"""Consignment types as data: packed outer dimensions, mass, and the content inside.

A consignment file (YAML, SI units)::

    name: KPBW
    description: free text
    mass: 0.140                      # whole consignment [kg]
    outer: [0.275, 0.20, 0.02]       # packed outer length, width, height [m]
    content: {kind: rigid, size: [0.165, 0.125, 0.02]}   # kind: rigid | soft; size L, W, H [m]
    bulge: {depth: 0.004, footprint: 0.3}   # optional: the bottom bulges under the content
    parameters: {mu_d_BePa: 0.30}    # optional: this type's own defaults (catalogue units)
    shell: trilinear                 # optional: the packaging shell's degrees of freedom
    shell_cells: [4, 4, 1]           # optional: its grid of cells (length, width, height)
    rim_brace: 0.067                 # optional: braces across the rim cells (share of a wedge's)
    mesh_spacing: 0.0225             # optional: the packaging shell's mesh spacing [m]

``bulge`` (optional, rigid contents): a bubble mailer's bottom that bulges below the content's
face by ``depth`` [m] over a centred patch of ``footprint`` times the outer length and width
(`parcelfit.sim.mujoco.shell`), so that the parcel rides on that patch. Without it the bottom is
flat under the whole content.

``parameters`` (optional): defaults of simulation parameters that belong to this type's
materials rather than to the catalogue's generic midpoints (e.g. the friction of its outer
packaging), in the catalogue's units (`parcelfit.sim.params`). They replace the catalogue
default for this type only; a study, ``--set`` or a calibration still overrides them.

``shell`` (optional): how the packaging's vertices move when the scene leaves it to the type
(`SceneOptions.shell_dof` "auto", the default): ``quadratic`` (over 3 x 3 x 3 nodes),
``trilinear`` (2 x 2 x 2) or ``full`` (each vertex on its own). Without it: quadratic around a
rigid content, full around a soft one. ``shell_cells`` (optional, with an interpolated
``shell``): the field is interpolated within each cell of a grid of that many cells along the
parcel's length, width and height (MuJoCo's multi-cell flexes; default one cell), so that a
rim can bend apart from the face it borders. A type's choice is the cheapest shell that
reproduces the full shell at a fine step and mesh (the reference) on the E3 ensemble and keeps
its outcome when refined: BW and KP take a trilinear shell over 4 x 4 x 1 cells
(docs/research/multicell-shell.md), KP/BW over 5 x 5 x 1, whose cells' boundaries lie on its
content's ends (docs/research/rim-brace/), PB the full shell around its soft content. ``rim_brace``
(optional, with an interpolated ``shell`` whose cells' boundaries fall on the content's ends):
braces across the rim cells, as a share of the stiffness of an ideal wedge of the packaging's
sheets (`parcelfit.sim.mujoco.rim_brace`; default 0, none).

``mesh_spacing`` (optional, rigid contents): the spacing [m] of the packaging shell's mesh of
contact points for this type, where the scene does not set one (`SceneOptions.spacing`);
default 30 mm. KP takes 22.5 mm: on the 30 mm mesh whether its rim catches on E3's guide plate
changed with the time step (3 of 20 placements), on 22.5 mm it holds at half the step and on a
15 mm mesh (docs/research/kp-mesh.md).

The content must fit inside the outer dimensions (length and width strictly smaller, height not
larger). The packaging's mass is a simulation parameter (m_Pa); the content gets the rest.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated, Any

from pydantic import PlainValidator, model_validator

from parcelfit.config import load_yaml
from parcelfit.errors import ParcelfitError, shown
from parcelfit.schema import Choice, FileModel, Number, Text, parse
from parcelfit.sim.mujoco.bundled import bundled_names, resolve_file
from parcelfit.sim.params import RIGID, SHELL_DOFS, SOFT, ShellCellsField, resolve

# what a consignment file's ``shell`` takes: a scene's choices but "auto"
TYPE_SHELL_DOFS = tuple(d for d in SHELL_DOFS if d != "auto")


@dataclass(frozen=True)
class Consignment:
    """A consignment type: mass [kg], outer and content sizes (L, W, H) [m], content kind."""

    name: str
    description: str
    mass: float
    outer: tuple[float, float, float]
    content_kind: str
    content: tuple[float, float, float]
    source: str = ""
    bulge: tuple[float, float] | None = None  # depth [m], footprint [-] (see the module docstring)
    # this type's own defaults, (name, value in catalogue units), see the module docstring
    parameters: tuple[tuple[str, float], ...] = ()
    # the shell's degrees of freedom under the scene's "auto" (see the module docstring); None:
    # quadratic around a rigid content, full around a soft one
    shell: str | None = None
    # the grid of cells of that shell along the length, width and height (see the module
    # docstring); one cell unless the file says otherwise
    shell_cells: tuple[int, int, int] = (1, 1, 1)
    # braces across that shell's rim cells (see the module docstring); 0: none
    rim_brace: float = 0.0
    # the shell's mesh spacing [m] around a rigid content (see the module docstring); None: the
    # scene's default
    mesh_spacing: float | None = None

    @property
    def soft(self) -> bool:
        """Whether the content is soft (a 3-D flex, the polybag's) rather than a rigid box."""
        return self.content_kind == SOFT

    def parameter_values(
        self,
        user_values: Mapping[str, float] | None = None,
        si_values: Mapping[str, float] | None = None,
    ) -> dict[str, float]:
        """Every simulation parameter of this type in SI: the catalogue's defaults, this type's
        own (``parameters``), then ``user_values`` (catalogue units) and ``si_values`` (SI)."""
        return resolve(
            self.content_kind, user_values, si_values, type_defaults=dict(self.parameters)
        )


def _size(value: Any) -> tuple[float, float, float]:
    if (
        not isinstance(value, list | tuple)
        or len(value) != 3
        or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and 0.001 <= v <= 5
            for v in value
        )
    ):
        raise ParcelfitError(
            f"expected [length, width, height] in metres (1 mm to 5 m), got {shown(value)}",
            fix="write e.g. [0.275, 0.20, 0.02]",
        )
    return float(value[0]), float(value[1]), float(value[2])


def _description(value: Any) -> str:
    return str(value or "").strip()


_Size = Annotated[tuple[float, float, float], PlainValidator(_size)]


class ContentSection(FileModel):
    """``content``: its kind (rigid or soft) and size L, W, H [m]."""

    kind: Annotated[str, Choice((RIGID, SOFT), what="content kind")]
    """rigid (a rounded box) or soft (a volumetric body, e.g. a polybag's limp content)."""
    size: _Size
    """The content's length, width, height [m], [L, W, H]."""


class BulgeSection(FileModel):
    """``bulge``: depth [m] and footprint (fraction of the outer length and width)."""

    depth: Annotated[float, Number(unit="m", ge=0.0005, le=0.05)]
    """How far the bottom bulges below the content's face [m]."""
    footprint: Annotated[float, Number(ge=0.05, le=0.95)]
    """The bulging patch as a fraction of the outer length and width [-]."""


class ConsignmentFile(FileModel):
    """A consignment file as written (see the module docstring): mass [kg], sizes [m]."""

    name: Annotated[str, Text()]
    """The type's name: the name datasets and studies use; keep it the file's
    stem (not enforced: a variant file may keep the name of what it varies)."""
    description: Annotated[str, PlainValidator(_description)] = ""
    """Free text."""
    mass: Annotated[float, Number(unit="kg", ge=0.001, le=100)]
    """The whole consignment's mass [kg] (the packaging's share is the parameter m_Pa)."""
    outer: _Size
    """Packed outer length, width, height [m], [L, W, H]."""
    content: ContentSection
    """The content: its kind and size."""
    bulge: BulgeSection | None = None
    """A bottom that bulges under a rigid content (optional)."""
    parameters: dict[str, float] | None = None
    """This type's own parameter defaults, in the catalogue's units (e.g. its packaging's
    friction)."""
    shell: Annotated[str | None, Choice(TYPE_SHELL_DOFS, what="shell degrees of freedom")] = None
    """The packaging shell's degrees of freedom: quadratic, trilinear or full (default:
    quadratic around a rigid content, full around a soft one)."""
    shell_cells: ShellCellsField | None = None
    """An interpolated shell's grid of cells along length, width, height (default [1, 1, 1])."""
    rim_brace: Annotated[float | None, Number(ge=0, le=10)] = None
    """Braces across the interpolated shell's rim cells, as a share of an ideal wedge's
    stiffness (default 0: none)."""
    mesh_spacing: Annotated[float | None, Number(unit="m", ge=0.003, le=0.2)] = None
    """The packaging shell's mesh spacing around a rigid content [m] (default: the scene's,
    0.03)."""

    @model_validator(mode="after")
    def _content_fits(self) -> ConsignmentFile:
        inner, outer = self.content.size, self.outer
        if not (inner[0] < outer[0] and inner[1] < outer[1] and inner[2] <= outer[2]):
            raise ParcelfitError(
                f"content {inner} does not fit inside the outer dimensions {outer}",
                where="content.size",
                fix="make the content shorter and narrower than the packed parcel",
            )
        if self.bulge is not None:
            f = self.bulge.footprint
            if self.content.kind != RIGID:
                raise ParcelfitError(
                    "a bulge needs a rigid content", where="bulge", fix="remove the bulge"
                )
            if not (f * outer[0] < inner[0] and f * outer[1] < inner[1]):
                raise ParcelfitError(
                    f"the bulge's patch ({f} of the outer size) is not smaller than the content",
                    where="bulge.footprint",
                    fix=f"use a footprint below {min(inner[0] / outer[0], inner[1] / outer[1]):.2f}",
                )
        return self

    @model_validator(mode="after")
    def _cells_fit_the_shell(self) -> ConsignmentFile:
        for key in ("shell_cells", "rim_brace"):
            if getattr(self, key) is not None and self.shell not in ("trilinear", "quadratic"):
                raise ParcelfitError(
                    f"{key} needs an interpolated shell",
                    where=key,
                    fix=f"add `shell: trilinear` (or quadratic), or remove {key}",
                )
        return self

    @model_validator(mode="after")
    def _spacing_needs_a_rigid_content(self) -> ConsignmentFile:
        if self.mesh_spacing is not None and self.content.kind != RIGID:
            raise ParcelfitError(
                "mesh_spacing is the shell's around a rigid content",
                where="mesh_spacing",
                fix="remove it (a soft content's film takes the scene's soft_shell_spacing)",
            )
        return self

    @model_validator(mode="after")
    def _parameters_apply(self) -> ConsignmentFile:
        for name, value in (self.parameters or {}).items():
            try:
                resolve(self.content.kind, type_defaults={name: value})
            except ParcelfitError as exc:
                raise ParcelfitError(exc.message, where=f"parameters.{name}", fix=exc.fix) from None
        return self


def parse_consignment(doc: Any, file: str) -> Consignment:
    """Build and check a `Consignment` from its parsed YAML document; every error names
    ``file``, the key and the fix."""
    f = parse(ConsignmentFile, doc, file=file)
    return Consignment(
        name=f.name,
        description=f.description,
        mass=f.mass,
        outer=f.outer,
        content_kind=f.content.kind,
        content=f.content.size,
        source=file,
        bulge=None if f.bulge is None else (f.bulge.depth, f.bulge.footprint),
        parameters=tuple((f.parameters or {}).items()),
        shell=f.shell,
        shell_cells=f.shell_cells or (1, 1, 1),
        rim_brace=f.rim_brace or 0.0,
        mesh_spacing=f.mesh_spacing,
    )


BULGE_DEPTH = 0.004  # the bundled mailers' bulge depth [m] (BW.yaml), a script's default


def with_bulge(
    consignment: Consignment, footprint: float | None, depth: float = BULGE_DEPTH
) -> Consignment:
    """``consignment`` with its bottom bulging ``depth`` [m] below its content over ``footprint``
    (a share of the outer length and width); footprint 0: a flat bottom, None: as its file
    says. A negative footprint or a depth that is not positive is refused; whether the patch
    fits inside the content is checked where the packaging's shell is built."""
    if footprint is None:
        return consignment
    if footprint < 0 or (footprint > 0 and depth <= 0):
        raise ParcelfitError(
            f"bulge {footprint:g} ({depth:g} m deep): the footprint must be 0 (a flat bottom) "
            "or positive, and the depth positive",
            fix="give a share of the outline such as 0.5 and a depth such as 0.004",
        )
    return replace(consignment, bulge=(depth, footprint) if footprint > 0 else None)


def bundled_consignment_names() -> list[str]:
    """Names of the consignment types shipped with parcelfit."""
    return bundled_names("consignments")


def load_consignment(name_or_path: str | Path) -> Consignment:
    """Load a bundled consignment type by name (``KPBW``, ``KP/BW``) or a consignment file by path."""
    key = str(name_or_path).replace("/", "").upper()
    path = resolve_file("consignments", name_or_path, "consignment type", key)
    return parse_consignment(load_yaml(path), str(path))
