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

from parcelfit.errors import ParcelfitError, one_line, shown
from parcelfit.schema import Number, Pair, Text, suggest
from parcelfit.schema import check_keys as _check_keys
from parcelfit.schema import require_mapping as _require_mapping

T = TypeVar("T")


# what a YAML document may hold: at most this many values added by aliases (``*name``
# repeating an ``&name`` anchor; nine nested anchors of nine, a "billion laughs", would expand a
# few kilobytes to 387 million values) and at most this many levels of nesting
MAX_ALIAS_VALUES = 100_000
MAX_DEPTH = 50
# the largest YAML file read [bytes]: a study, rig or dataset file is kilobytes
MAX_YAML_BYTES = 16 * 2**20


class _Refused(yaml.MarkedYAMLError):
    """A document the loader refuses (aliases expanding too far, nesting too deep, a key written
    twice, a value that cannot be read), at a place in the file, with the fix."""

    def __init__(self, problem: str, mark: Any, fix: str) -> None:
        super().__init__(problem=problem, problem_mark=mark)
        self.fix = fix


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader, reading numbers as YAML 1.2 does: ``1e-6`` and ``2E5`` are floats.
    PyYAML follows YAML 1.1, where a float needs a dot and a signed exponent, so ``1e-6`` came
    back as the text '1e-06' and a setting written that way was refused as not a number.

    It also refuses, with the line: a document whose aliases expand past `MAX_ALIAS_VALUES`
    values or that refers to itself, nesting deeper than `MAX_DEPTH`, a key written twice in a
    mapping (PyYAML keeps the last silently), and a value PyYAML cannot construct (a date such as
    2024-13-45, a whole number of more than 4300 digits)."""

    def __init__(self, stream: Any) -> None:
        super().__init__(stream)
        self._values = 0  # values composed so far, each alias counting the values it repeats
        self._by_aliases = 0  # of which the aliases added
        self._sizes: dict[int, int] = {}  # values in a composed node (by id), aliases expanded
        self._depth = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            node = super().compose_node(parent, index)
            size = self._sizes.get(id(node))
            if size is None:  # the anchored value is still being composed: it holds itself
                raise _Refused(
                    f"the alias *{event.anchor} refers to a value that contains it",
                    event.start_mark,
                    "write the value out instead of the recursive alias",
                )
            self._values += size
            self._by_aliases += size
            if self._by_aliases > MAX_ALIAS_VALUES:
                raise _Refused(
                    f"aliases (*name) expand the document to more than {MAX_ALIAS_VALUES} values",
                    event.start_mark,
                    "write the values out, or repeat fewer of them through aliases",
                )
            return node
        self._depth += 1
        if self._depth > MAX_DEPTH:
            raise _Refused(
                f"values nested more than {MAX_DEPTH} levels deep",
                self.peek_event().start_mark,
                "flatten the document",
            )
        start = self._values
        node = super().compose_node(parent, index)
        self._depth -= 1
        self._values += 1
        self._sizes[id(node)] = self._values - start
        return node

    def compose_mapping_node(self, anchor: Any) -> Any:
        node = super().compose_mapping_node(anchor)
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:  # the keys as written (before any `<<` merge)
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag.endswith(":merge"):
                continue
            key = self.construct_object(key_node)
            try:
                first = seen.get(key)
            except TypeError:  # an unhashable key: construct_mapping refuses it
                continue
            line = key_node.start_mark.line + 1
            if first is not None:
                raise _Refused(
                    f"the key {shown(key)} is written twice (lines {first} and {line}); YAML "
                    "would keep only the last value",
                    key_node.start_mark,
                    "delete one of the two, or merge them",
                )
            seen[key] = line
        return node

    def construct_object(self, node: Any, deep: bool = False) -> Any:
        try:
            return super().construct_object(node, deep=deep)
        except (ValueError, OverflowError) as exc:  # e.g. month 13, a 5000-digit number
            raise _Refused(
                f"cannot read the value {shown(node.value)} ({one_line(str(exc))[:100]})",
                node.start_mark,
                "correct the value there (quote it to keep it as text)",
            ) from None


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def load_yaml(path: str | Path) -> Any:
    """Parse a YAML file (the one way parcelfit reads YAML); a missing file, a syntax error and a
    document `_Loader` refuses (aliases expanding too far, nesting too deep, a key written twice)
    become a `ParcelfitError` naming the file and the line."""
    path = Path(path)
    if not path.is_file():
        raise ParcelfitError("file not found", file=path, fix="check the path")
    try:
        size = path.stat().st_size
        if size > MAX_YAML_BYTES:
            raise ParcelfitError(
                f"the file is {size / 2**20:.0f} MiB, more than the {MAX_YAML_BYTES // 2**20} MiB "
                "a parcelfit YAML file may be",
                file=path,
                fix="check that this is the right file",
            )
        data = path.read_bytes()
    except OSError as exc:
        raise ParcelfitError(
            f"cannot read the file ({exc.strerror or exc})",
            file=path,
            fix="check that it is a readable file",
        ) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ParcelfitError(
            f"not UTF-8 text (byte {exc.start}: {data[exc.start : exc.start + 1]!r})",
            file=path,
            fix="save the file as UTF-8",
        ) from None
    try:
        return yaml.load(text, Loader=_Loader)  # a safe loader (SafeLoader subclass)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else None
        if isinstance(exc, _Refused):
            raise ParcelfitError(exc.problem, file=path, where=where, fix=exc.fix) from None
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
