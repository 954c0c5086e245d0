"""Finding the rig and consignment files shipped with parcelfit, or a user's own file; the base
of the backends that simulate them (`RigBackend`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from importlib.resources import files
from pathlib import Path
from typing import TYPE_CHECKING, Any, Generic, Self, TypeVar

from parcelfit.errors import ParcelfitError, shown

if TYPE_CHECKING:
    from parcelfit.sim.mujoco.consignment import Consignment
    from parcelfit.sim.mujoco.rig import Rig

OptionsT = TypeVar("OptionsT")


def bundled_names(kind: str) -> list[str]:
    """Names of the bundled files of a kind (``rigs`` or ``consignments``), without ``.yaml``."""
    folder = files("parcelfit.sim.mujoco").joinpath(kind)
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def resolve_file(kind: str, name_or_path: str | Path, what: str, key: str | None = None) -> Path:
    """A user's .yaml path as given, or the bundled file called ``key`` (default: the name)."""
    path = Path(name_or_path)
    if path.suffix.lower() in (".yaml", ".yml"):
        return path
    candidate = files("parcelfit.sim.mujoco").joinpath(kind).joinpath(f"{key or name_or_path}.yaml")
    if not candidate.is_file():
        raise ParcelfitError(
            f"unknown {what} {shown(str(name_or_path))}",
            fix=f"use one of {', '.join(bundled_names(kind))} or the path of a .yaml file",
        )
    return Path(str(candidate))


class RigBackend(Generic[OptionsT]):
    """What the MuJoCo model and the rigid-box reference share: their options (a frozen
    dataclass with a ``placement_seed`` field), the rigs and consignments given at construction
    (else bundled, loaded on first use), and copies with changed options or placement."""

    def __init__(
        self,
        options: OptionsT,
        rigs: Mapping[str, Rig] | None = None,
        consignments: Mapping[str, Consignment] | None = None,
    ) -> None:
        self.options = options
        self._rigs = dict(rigs or {})
        self._consignments = dict(consignments or {})

    def rig(self, name: str) -> Rig:
        """The rig called ``name`` (given at construction, else bundled)."""
        if name not in self._rigs:
            from parcelfit.sim.mujoco.rig import load_rig  # rig.py imports this module

            self._rigs[name] = load_rig(name)
        return self._rigs[name]

    def consignment(self, name: str) -> Consignment:
        """The consignment type called ``name`` (given at construction, else bundled)."""
        if name not in self._consignments:
            from parcelfit.sim.mujoco.consignment import load_consignment  # imports this module

            self._consignments[name] = load_consignment(name)
        return self._consignments[name]

    def with_options(self, **changes: Any) -> Self:
        """The same backend (rigs and consignments) with option fields changed."""
        return type(self)(replace(self.options, **changes), self._rigs, self._consignments)  # type: ignore[arg-type]

    def with_placement(self, seed: int | None) -> Self:
        """The same backend with placement ``seed`` (None: the nominal start pose)."""
        return self.with_options(placement_seed=seed)
