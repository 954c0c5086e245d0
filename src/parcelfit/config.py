"""Loading YAML configuration and checking it, with errors that name the file, key and fix.

Every configuration file parcelfit reads (datasets, rigs, studies, tag maps) goes through these
helpers, so every mistake is reported the same way.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import yaml

from parcelfit.errors import ParcelfitError


def load_yaml(path: str | Path) -> Any:
    """Parse a YAML file; a missing file or a syntax error becomes a `ParcelfitError`."""
    path = Path(path)
    if not path.is_file():
        raise ParcelfitError("file not found", file=path, fix="check the path")
    try:
        with path.open(encoding="utf-8") as fh:
            return yaml.safe_load(fh)
    except UnicodeDecodeError as exc:
        raise ParcelfitError(
            f"not UTF-8 text (byte {exc.start}: {exc.object[exc.start : exc.start + 1]!r})",
            file=path,
            fix="save the file as UTF-8",
        ) from None
    except OSError as exc:
        raise ParcelfitError(
            f"cannot read the file ({exc.strerror or exc})",
            file=path,
            fix="check that it is a readable file",
        ) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else None
        problem = getattr(exc, "problem", None) or str(exc)
        raise ParcelfitError(
            f"malformed YAML: {problem}",
            file=path,
            where=where,
            fix="correct the YAML syntax there",
        ) from exc


def suggest(name: str, known: Iterable[str]) -> str | None:
    """The known name closest to ``name``: a case-insensitive match first, else the nearest by difflib."""
    known = list(known)
    for k in known:
        if k.lower() == str(name).lower():
            return k
    lowered = {k.lower(): k for k in known}
    close = difflib.get_close_matches(str(name).lower(), list(lowered), n=1)
    return lowered[close[0]] if close else None


def require_mapping(value: Any, *, file: str | Path | None, where: str) -> Mapping[str, Any]:
    """Check that ``value`` is a mapping (a YAML dictionary)."""
    if not isinstance(value, Mapping):
        raise ParcelfitError(
            f"expected a mapping of keys to values, got {type(value).__name__}",
            file=file,
            where=where,
            fix="write it as `key: value` lines",
        )
    return value


def check_keys(
    mapping: Mapping[str, Any],
    *,
    allowed: Iterable[str],
    required: Iterable[str] = (),
    file: str | Path | None,
    where: str,
) -> None:
    """Reject unknown keys (suggesting the closest known one) and report missing required keys."""
    allowed = list(allowed)
    for key in mapping:
        if key not in allowed:
            close = suggest(str(key), allowed)
            fix = f"did you mean {close!r}?" if close else f"known keys: {', '.join(allowed)}"
            raise ParcelfitError(f"unknown key {key!r}", file=file, where=where, fix=fix)
    for key in required:
        if key not in mapping:
            raise ParcelfitError(
                f"missing required key {key!r}", file=file, where=where, fix=f"add `{key}:`"
            )


def get_number(
    mapping: Mapping[str, Any],
    key: str,
    *,
    file: str | Path | None,
    where: str,
    default: float | None = None,
    minimum: float | None = None,
    maximum: float | None = None,
    allow_none: bool = False,
    unit: str = "",
) -> float | None:
    """Read a finite number (optionally bounded); ``None`` only if ``allow_none``."""
    value = mapping.get(key, default)
    label = f"{where}.{key}" if where else key
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ParcelfitError(
            f"expected a number{f' in {unit}' if unit else ''}, got {value!r}",
            file=file,
            where=label,
            fix="write a plain number" + (" or null" if allow_none else ""),
        )
    if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
        raise ParcelfitError(
            f"{value} is outside [{minimum}, {maximum}]{f' {unit}' if unit else ''}",
            file=file,
            where=label,
            fix="use a value inside that range",
        )
    return float(value)


def get_int(
    mapping: Mapping[str, Any],
    key: str,
    *,
    file: str | Path | None,
    where: str,
    default: int | None = None,
    minimum: int | None = None,
    maximum: int | None = None,
) -> int:
    """Read a whole number (optionally bounded); 2.9 or "two" is an error, never truncated."""
    value = mapping.get(key, default)
    label = f"{where}.{key}" if where else key
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParcelfitError(
            f"expected a whole number, got {value!r}",
            file=file,
            where=label,
            fix="write a whole number such as 4",
        )
    if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
        bounds = f"at least {minimum}" if maximum is None else f"in [{minimum}, {maximum}]"
        raise ParcelfitError(
            f"{value} is out of range", file=file, where=label, fix=f"use a whole number {bounds}"
        )
    return value


def get_bool(
    mapping: Mapping[str, Any], key: str, *, file: str | Path | None, where: str, default: bool
) -> bool:
    """Read true or false; a text such as "false" is an error, never read as true."""
    value = mapping.get(key, default)
    if not isinstance(value, bool):
        raise ParcelfitError(
            f"expected true or false, got {value!r}",
            file=file,
            where=f"{where}.{key}" if where else key,
            fix="write true or false without quotes",
        )
    return value


def get_choice(
    mapping: Mapping[str, Any],
    key: str,
    choices: Iterable[str],
    *,
    what: str,
    file: str | Path | None,
    where: str,
    default: str | None = None,
) -> str:
    """Read a text that must be one of ``choices`` (``what`` names it in the error)."""
    choices = list(choices)
    value = get_str(mapping, key, file=file, where=where, default=default)
    if value not in choices:
        raise ParcelfitError(
            f"unknown {what} {value!r}",
            file=file,
            where=f"{where}.{key}" if where else key,
            fix=f"use one of {', '.join(choices)}",
        )
    return value


def load_config(
    path: str | Path, *, allowed: Iterable[str], required: Iterable[str] = ()
) -> Mapping[str, Any]:
    """Read a YAML file whose top level is a mapping, and check its keys."""
    doc = require_mapping(load_yaml(path), file=path, where="top level")
    check_keys(doc, allowed=allowed, required=required, file=path, where="top level")
    return doc


def get_str(
    mapping: Mapping[str, Any],
    key: str,
    *,
    file: str | Path | None,
    where: str,
    default: str | None = None,
) -> str:
    """Read a non-empty string."""
    value = mapping.get(key, default)
    if isinstance(value, int) and not isinstance(value, bool):
        value = str(value)
    if not isinstance(value, str) or not value.strip():
        raise ParcelfitError(
            f"expected a non-empty text, got {value!r}",
            file=file,
            where=f"{where}.{key}" if where else key,
            fix="write a name",
        )
    return value.strip()


def get_pair(
    value: Any,
    *,
    file: str | Path | None,
    where: str,
    what: str = "two numbers [a, b]",
    fix: str = "write [a, b]",
    increasing: bool = False,
) -> tuple[float, float]:
    """Read a list of two finite numbers (``increasing``: the first below the second); the
    message names ``what`` was expected."""
    ok = (
        isinstance(value, list | tuple)
        and len(value) == 2
        and all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in value
        )
    )
    if not ok or (increasing and not value[0] < value[1]):
        raise ParcelfitError(f"expected {what}, got {value!r}", file=file, where=where, fix=fix)
    return float(value[0]), float(value[1])
