"""Consignment types as data: packed outer dimensions, mass, and the content inside.

A consignment file (YAML, SI units)::

    name: KPBW
    description: free text
    mass: 0.140                      # whole consignment [kg]
    outer: [0.275, 0.20, 0.02]       # packed outer length, width, height [m]
    content: {kind: rigid, size: [0.165, 0.125, 0.02]}   # kind: rigid | soft; size L, W, H [m]

The content must fit inside the outer dimensions (length and width strictly smaller, height not
larger). The packaging's mass is a simulation parameter (m_Pa); the content gets the rest.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from parcelfit.config import check_keys, get_choice, get_number, get_str, load_yaml, require_mapping
from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco.bundled import bundled_names, resolve_file
from parcelfit.sim.params import RIGID, SOFT


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


def _size(value: Any, *, file: str, where: str) -> tuple[float, float, float]:
    if (
        not isinstance(value, list | tuple)
        or len(value) != 3
        or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and 0.001 <= v <= 5
            for v in value
        )
    ):
        raise ParcelfitError(
            f"expected [length, width, height] in metres (1 mm to 5 m), got {value!r}",
            file=file,
            where=where,
            fix="write e.g. [0.275, 0.20, 0.02]",
        )
    return float(value[0]), float(value[1]), float(value[2])


def parse_consignment(doc: Any, file: str) -> Consignment:
    """Build and check a `Consignment` from its parsed YAML document."""
    doc = require_mapping(doc, file=file, where="top level")
    check_keys(
        doc,
        allowed=("name", "description", "mass", "outer", "content"),
        required=("name", "mass", "outer", "content"),
        file=file,
        where="top level",
    )
    content = require_mapping(doc["content"], file=file, where="content")
    check_keys(
        content, allowed=("kind", "size"), required=("kind", "size"), file=file, where="content"
    )
    kind = get_choice(
        content, "kind", (RIGID, SOFT), what="content kind", file=file, where="content"
    )
    outer = _size(doc["outer"], file=file, where="outer")
    inner = _size(content["size"], file=file, where="content.size")
    if not (inner[0] < outer[0] and inner[1] < outer[1] and inner[2] <= outer[2]):
        raise ParcelfitError(
            f"content {inner} does not fit inside the outer dimensions {outer}",
            file=file,
            where="content.size",
            fix="make the content shorter and narrower than the packed parcel",
        )
    return Consignment(
        name=get_str(doc, "name", file=file, where=""),
        description=str(doc.get("description", "") or "").strip(),
        mass=get_number(doc, "mass", file=file, where="", minimum=0.001, maximum=100, unit="kg"),
        outer=outer,
        content_kind=kind,
        content=inner,
        source=file,
    )


def bundled_consignment_names() -> list[str]:
    """Names of the consignment types shipped with parcelfit."""
    return bundled_names("consignments")


def load_consignment(name_or_path: str | Path) -> Consignment:
    """Load a bundled consignment type by name (``KPBW``, ``KP/BW``) or a consignment file by path."""
    key = str(name_or_path).replace("/", "").upper()
    path = resolve_file("consignments", name_or_path, "consignment type", key)
    return parse_consignment(load_yaml(path), str(path))
