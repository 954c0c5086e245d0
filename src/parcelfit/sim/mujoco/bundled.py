"""Finding the rig and consignment files shipped with parcelfit, or a user's own file."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from parcelfit.errors import ParcelfitError, shown


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
