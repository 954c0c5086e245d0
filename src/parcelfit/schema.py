"""Typed models of the YAML files a person writes (pydantic v2), with errors that name the file,
the key and the fix.

A file kind is a `FileModel` subclass whose fields are annotated with the value types below
(`Number`, `Whole`, `Flag`, `Text`, `Choice`, `Pair`); each type checks its value with the same
message and fix as parcelfit's hand-written checks had. `parse` validates a parsed document and
turns the first pydantic error into a `ParcelfitError`: the place is the path of keys to the
value (``parameters.mu_d_BePa.low``, ``light_barriers[0].from``, ``top level`` for the file's
own keys), the message and fix those of the type or validator that refused it.

A validator refuses a value by raising `ParcelfitError` (message and fix; ``where``, if given,
is a place below the value being checked, e.g. a key inside a section). Models check their
keys before anything else: an unknown key is reported with the closest known one, a missing
required key with the line to add.

Units are the file's: a model holds what the file says, the loader converts to SI once.

Every field carries its description as an attribute docstring (the string below it), and each
value type states its JSON Schema (with the unit of a `Number` as ``x-unit``): `json_schema`
gives a file kind's schema, from which the reference of the documentation is generated.

The getters of `parcelfit.config` (for the files not yet described by models) check their
values with the same types, so each message is written once.
"""

from __future__ import annotations

import difflib
import math
import sys
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    GetCoreSchemaHandler,
    GetJsonSchemaHandler,
    model_validator,
)
from pydantic import ValidationError as _ValidationError
from pydantic.json_schema import GenerateJsonSchema, JsonSchemaValue
from pydantic_core import core_schema

from parcelfit.errors import ParcelfitError, shown

M = TypeVar("M", bound="FileModel")

_MAPPING_FIX = "write it as `key: value` lines"


def suggest(name: str, known: Iterable[str]) -> str | None:
    """The known name closest to ``name``: a case-insensitive match first, else the nearest by difflib."""
    known = list(known)
    for k in known:
        if k.lower() == str(name).lower():
            return k
    if len(str(name)) > 100:  # no name is this long; difflib would take long on it
        return None
    lowered = {k.lower(): k for k in known}
    close = difflib.get_close_matches(str(name).lower(), list(lowered), n=1)
    return lowered[close[0]] if close else None


def check_keys(data: Mapping[Any, Any], allowed: Iterable[str], *, fix: str | None = None) -> None:
    """Refuse a key of ``data`` outside ``allowed``, suggesting the closest known key (or ``fix``)."""
    allowed = list(allowed)
    for key in data:
        if key not in allowed:
            close = suggest(str(key), allowed)
            hint = f"did you mean {close!r}?" if close else f"known keys: {', '.join(allowed)}"
            raise ParcelfitError(f"unknown key {shown(key)}", fix=fix or hint)


def require_mapping(data: Any) -> Mapping[Any, Any]:
    """``data`` if it is a mapping (a YAML dictionary), else a `ParcelfitError`."""
    if not isinstance(data, Mapping):
        raise ParcelfitError(
            f"expected a mapping of keys to values, got {type(data).__name__}", fix=_MAPPING_FIX
        )
    return data


def is_finite_number(value: Any) -> bool:
    """``value`` is an int or float (never true/false) that a float holds, finite; a YAML whole
    number of 400 digits is not (``math.isfinite`` would raise OverflowError on it)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    if isinstance(value, int):
        return abs(value) <= sys.float_info.max
    return math.isfinite(value)


class FileModel(BaseModel):
    """A section of a file (or a whole file): a mapping whose keys are the fields (or their
    aliases); unknown keys are refused with a suggestion, missing required keys named."""

    model_config = ConfigDict(
        extra="forbid", frozen=True, arbitrary_types_allowed=True, use_attribute_docstrings=True
    )

    @classmethod
    def prepare(cls, data: Any) -> Any:
        """Reshape the raw value before the mapping and key checks (e.g. ``[low, high]``)."""
        return data

    @classmethod
    def allowed_keys(cls, data: Mapping[Any, Any]) -> list[str]:
        """The keys this section accepts (its fields, by alias)."""
        return [f.alias or name for name, f in cls.model_fields.items()]

    @model_validator(mode="before")
    @classmethod
    def _check_mapping_and_keys(cls, data: Any) -> Any:
        data = require_mapping(cls.prepare(data))
        check_keys(data, cls.allowed_keys(data))
        return data


# -- value types: use as ``Annotated[float, Number(unit="s", ge=0)]`` ------------------------


@dataclass(frozen=True)
class _Plain:
    """An annotation whose ``check`` replaces pydantic's own validation of the value."""

    def check(self, value: Any) -> Any:  # pragma: no cover - overridden
        raise NotImplementedError

    def __get_pydantic_core_schema__(
        self, source: Any, handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        return core_schema.no_info_plain_validator_function(self.check)

    def json_schema(self) -> dict[str, Any]:  # pragma: no cover - overridden
        """The JSON Schema of the values ``check`` accepts."""
        return {}

    def __get_pydantic_json_schema__(
        self, schema: core_schema.CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        out = self.json_schema()
        if getattr(self, "nullable", False):
            unit = out.pop("x-unit", None)
            out = {"anyOf": [out, {"type": "null"}]}
            if unit:
                out["x-unit"] = unit
        return out


def _bounds(ge: float | None, le: float | None) -> dict[str, float]:
    return {
        **({} if ge is None else {"minimum": ge}),
        **({} if le is None else {"maximum": le}),
    }


@dataclass(frozen=True)
class Number(_Plain):
    """A finite number (ints and floats, never true/false or text) in ``[ge, le]``, as float;
    ``nullable``: null is allowed (None). ``unit`` appears in the messages."""

    unit: str = ""
    ge: float | None = None
    le: float | None = None
    nullable: bool = False

    def check(self, value: Any) -> float | None:
        if value is None and self.nullable:
            return None
        if not is_finite_number(value):
            raise ParcelfitError(
                f"expected a number{f' in {self.unit}' if self.unit else ''}, got {shown(value)}",
                fix="write a plain number" + (" or null" if self.nullable else ""),
            )
        if (self.ge is not None and value < self.ge) or (self.le is not None and value > self.le):
            raise ParcelfitError(
                f"{value} is outside [{self.ge}, {self.le}]{f' {self.unit}' if self.unit else ''}",
                fix="use a value inside that range",
            )
        return float(value)

    def json_schema(self) -> dict[str, Any]:
        return {
            "type": "number",
            # as floats: Number(ge=0) and Number(ge=0.0) are equal, and whichever a model met
            # first would otherwise decide how the bound is written
            **_bounds(
                None if self.ge is None else float(self.ge),
                None if self.le is None else float(self.le),
            ),
            **({"x-unit": self.unit} if self.unit else {}),
        }


@dataclass(frozen=True)
class Whole(_Plain):
    """A whole number in ``[ge, le]``: 4.0 is 4, but 2.9 or "two" is an error, never truncated;
    ``nullable``: null is allowed (None)."""

    ge: int | None = None
    le: int | None = None
    nullable: bool = False

    def check(self, value: Any) -> int | None:
        if value is None and self.nullable:
            return None
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParcelfitError(
                f"expected a whole number, got {shown(value)}", fix="write a whole number such as 4"
            )
        if (self.ge is not None and value < self.ge) or (self.le is not None and value > self.le):
            bounds = f"at least {self.ge}" if self.le is None else f"in [{self.ge}, {self.le}]"
            raise ParcelfitError(
                f"{shown(value)} is out of range", fix=f"use a whole number {bounds}"
            )
        return value

    def json_schema(self) -> dict[str, Any]:
        return {"type": "integer", **_bounds(self.ge, self.le)}


@dataclass(frozen=True)
class Flag(_Plain):
    """true or false; a text such as "false" is an error, never read as true."""

    def check(self, value: Any) -> bool:
        if not isinstance(value, bool):
            raise ParcelfitError(
                f"expected true or false, got {shown(value)}",
                fix="write true or false without quotes",
            )
        return value

    def json_schema(self) -> dict[str, Any]:
        return {"type": "boolean"}


@dataclass(frozen=True)
class Text(_Plain):
    """A non-empty text, stripped (a whole number is taken as its text, e.g. a rig called 3);
    ``nullable``: null is allowed (None)."""

    nullable: bool = False

    def check(self, value: Any) -> str | None:
        if value is None and self.nullable:
            return None
        if isinstance(value, int) and not isinstance(value, bool):
            value = str(value)
        if not isinstance(value, str) or not value.strip():
            raise ParcelfitError(
                f"expected a non-empty text, got {shown(value)}", fix="write a name"
            )
        return value.strip()

    def json_schema(self) -> dict[str, Any]:
        return {"type": "string", "minLength": 1}


@dataclass(frozen=True)
class Choice(_Plain):
    """A text that must be one of ``choices``; ``what`` names it in the message."""

    choices: tuple[str, ...]
    what: str

    def check(self, value: Any) -> str:
        text = Text().check(value)
        if text not in self.choices:
            raise ParcelfitError(
                f"unknown {self.what} {shown(text)}", fix=f"use one of {', '.join(self.choices)}"
            )
        return str(text)

    def json_schema(self) -> dict[str, Any]:
        return {"type": "string", "enum": list(self.choices)}


@dataclass(frozen=True)
class Pair(_Plain):
    """A list of two finite numbers as a tuple of floats (``increasing``: the first below the
    second); ``what`` and ``fix`` word the message; ``nullable``: null is allowed (None)."""

    what: str = "two numbers [a, b]"
    fix: str = "write [a, b]"
    increasing: bool = False
    nullable: bool = False

    def check(self, value: Any) -> tuple[float, float] | None:
        if value is None and self.nullable:
            return None
        ok = (
            isinstance(value, list | tuple)
            and len(value) == 2
            and all(is_finite_number(v) for v in value)
        )
        if not ok or (self.increasing and not value[0] < value[1]):
            raise ParcelfitError(f"expected {self.what}, got {shown(value)}", fix=self.fix)
        return float(value[0]), float(value[1])

    def json_schema(self) -> dict[str, Any]:
        return {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2}


def or_default(default: Callable[[], Any]) -> BeforeValidator:
    """An absent-or-empty section (null, ``{}``, ``[]``) takes ``default()``, as ``x or {}`` did."""
    return BeforeValidator(lambda value: value if value else default())


def keys_in(allowed: Callable[[], Iterable[str]]) -> BeforeValidator:
    """A mapping whose keys must be in ``allowed()`` (e.g. the catalogue's parameter names)."""

    def check(value: Any) -> Any:
        check_keys(require_mapping(value), sorted(allowed()))
        return value

    return BeforeValidator(check)


# -- JSON Schema ------------------------------------------------------------------------------


class _FileSchema(GenerateJsonSchema):
    """pydantic's generator, with values checked by a plain function (no declared input type)
    described by their field's description alone, and without titles made from field names."""

    def handle_invalid_for_json_schema(
        self, schema: core_schema.CoreSchema, error_info: str
    ) -> JsonSchemaValue:
        return {}

    def field_title_should_be_set(self, schema: Any) -> bool:
        return False


def json_schema(model: type[FileModel]) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of the files ``model`` reads, keys by their YAML names."""
    return model.model_json_schema(by_alias=True, schema_generator=_FileSchema)


# -- pydantic errors to ParcelfitError --------------------------------------------------------


def parse(model: type[M], data: Any, *, file: str | Path | None) -> M:
    """Validate ``data`` (a parsed YAML document) against ``model``; the first error becomes a
    `ParcelfitError` naming ``file``, the place in it and the fix."""
    try:
        return model.model_validate(data)
    except _ValidationError as exc:
        raise to_parcelfit_error(exc, data, file=file) from None


def to_parcelfit_error(
    exc: _ValidationError, data: Any, *, file: str | Path | None
) -> ParcelfitError:
    """The first error of ``exc`` as a `ParcelfitError` (``data``: the validated document, to
    tell list positions ``[0]`` from keys ``.0``)."""
    err = exc.errors(include_url=False)[0]
    loc = tuple(err["loc"])
    kind = err["type"]
    cause = (err.get("ctx") or {}).get("error")
    if isinstance(cause, ParcelfitError):
        return ParcelfitError(
            cause.message, file=file, where=_join(_place(loc, data), cause.where), fix=cause.fix
        )
    if kind == "missing":
        key = loc[-1]
        return ParcelfitError(
            f"missing required key {key!r}",
            file=file,
            where=_place(loc[:-1], data) or "top level",
            fix=f"add `{key}:`",
        )
    if kind in ("dict_type", "model_type", "mapping_type"):
        return ParcelfitError(
            f"expected a mapping of keys to values, got {type(err['input']).__name__}",
            file=file,
            where=_place(loc, data) or "top level",
            fix=_MAPPING_FIX,
        )
    if kind in ("list_type", "tuple_type"):
        return ParcelfitError(
            f"expected a list, got {shown(err['input'])}",
            file=file,
            where=_place(loc, data) or "top level",
            fix="write it as a YAML list [a, b, ...]",
        )
    return ParcelfitError(  # a pydantic check without a parcelfit message (should not happen)
        err["msg"], file=file, where=_place(loc, data) or "top level", fix="correct this value"
    )


def _place(loc: tuple[Any, ...], data: Any) -> str:
    """``("a", "b", 0)`` as ``a.b[0]`` when ``b`` holds a list in ``data``, else ``a.b.0``."""
    text = ""
    node = data
    for key in loc:
        if key == "[key]":  # pydantic's marker for a mapping's key rather than its value
            continue
        if isinstance(key, int) and isinstance(node, list):
            text += f"[{key}]"
            node = node[key] if 0 <= key < len(node) else None
        else:
            text += f".{key}" if text else str(key)
            node = node.get(key) if isinstance(node, Mapping) else None
    return text


def _join(place: str, below: str | None) -> str:
    if not below:
        return place or "top level"
    return f"{place}.{below}" if place else below


__all__ = [
    "Choice",
    "FileModel",
    "Flag",
    "Number",
    "Pair",
    "Text",
    "Whole",
    "check_keys",
    "is_finite_number",
    "json_schema",
    "keys_in",
    "or_default",
    "parse",
    "require_mapping",
    "suggest",
    "to_parcelfit_error",
]
