"""Stored records that hold arrays: read and written by pydantic, arrays as lists of floats.

`results.py` (band, dependence curve, surrogate) and `identify.py` (`Identifiability`) build
their records on `ArrayRecord`, with `FloatArray` fields.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Annotated, Any, Self

import numpy as np
from pydantic import BaseModel, ConfigDict, PlainSerializer, PlainValidator


def float_list(a: np.ndarray | Sequence[float]) -> Any:
    """An array as (nested) lists of floats, for JSON."""
    return np.asarray(a, dtype=float).tolist()


def float_array(v: Any) -> np.ndarray:
    """A (nested) list of numbers as an array of floats."""
    return np.asarray(v, dtype=float)


# an array of floats, stored as (nested) lists of floats
FloatArray = Annotated[np.ndarray, PlainValidator(float_array), PlainSerializer(float_list)]


class ArrayRecord(BaseModel):
    """A stored record holding arrays: read and written by pydantic under its stored keys;
    equal only to itself (arrays have no single truth value)."""

    model_config = ConfigDict(frozen=True, populate_by_name=True, arbitrary_types_allowed=True)

    __eq__ = object.__eq__
    __hash__ = object.__hash__

    def to_json(self) -> dict[str, Any]:
        """The stored form."""
        return self.model_dump(by_alias=True)

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> Self:
        """Read the stored form."""
        return cls.model_validate(dict(doc))


__all__ = ["ArrayRecord", "FloatArray", "float_array", "float_list"]
