"""Loading YAML configuration, and the checked getters of the files not yet described by typed
models, with errors that name the file, key and fix.

The study, screen, twin spec, tag map, rig and consignment files are typed models
(`parcelfit.schema`); the dataset and external solver files, and the regions of interest
(`runs.regions.parse_region`, in dataset and rig files), still read their keys with the getters
below, which check each value with the same types (`schema.Number`, ...) so that every mistake
is reported the same way.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import yaml

from parcelfit.errors import ParcelfitError
from parcelfit.schema import Number, Pair, Text, suggest
from parcelfit.schema import check_keys as _check_keys
from parcelfit.schema import require_mapping as _require_mapping

T = TypeVar("T")


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader, reading numbers as YAML 1.2 does: ``1e-6`` and ``2E5`` are floats.
    PyYAML follows YAML 1.1, where a float needs a dot and a signed exponent, so ``1e-6`` came
    back as the text '1e-06' and a setting written that way was refused as not a number."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def load_yaml(path: str | Path) -> Any:
    """Parse a YAML file; a missing file or a syntax error becomes a `ParcelfitError`."""
    path = Path(path)
    if not path.is_file():
        raise ParcelfitError("file not found", file=path, fix="check the path")
    try:
        with path.open(encoding="utf-8") as fh:
            return yaml.load(fh, Loader=_Loader)  # a safe loader (SafeLoader subclass)
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


def _at(check: Callable[[Any], T], value: Any, *, file: str | Path | None, where: str) -> T:
    """``check(value)``, its `ParcelfitError` placed at ``where`` in ``file``."""
    try:
        return check(value)
    except ParcelfitError as exc:
        raise ParcelfitError(exc.message, file=file, where=where, fix=exc.fix) from None


def _label(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def require_mapping(value: Any, *, file: str | Path | None, where: str) -> Mapping[str, Any]:
    """Check that ``value`` is a mapping (a YAML dictionary)."""
    return _at(_require_mapping, value, file=file, where=where)


def check_keys(
    mapping: Mapping[str, Any],
    *,
    allowed: Iterable[str],
    required: Iterable[str] = (),
    file: str | Path | None,
    where: str,
) -> None:
    """Reject unknown keys (suggesting the closest known one) and report missing required keys."""
    _at(lambda m: _check_keys(m, allowed), mapping, file=file, where=where)
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
    check = Number(unit=unit, ge=minimum, le=maximum, nullable=allow_none).check
    return _at(check, mapping.get(key, default), file=file, where=_label(where, key))


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
    text = _at(Text().check, mapping.get(key, default), file=file, where=_label(where, key))
    return str(text)


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
    pair = _at(Pair(what=what, fix=fix, increasing=increasing).check, value, file=file, where=where)
    assert pair is not None  # not nullable
    return pair


__all__ = [
    "check_keys",
    "get_number",
    "get_pair",
    "get_str",
    "load_config",
    "load_yaml",
    "require_mapping",
    "suggest",
]
