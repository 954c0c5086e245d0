"""The search space of a calibration: named parameters with bounds, mapped to the unit cube.

Each parameter has bounds (low, high) in its own unit (whatever the caller uses consistently;
the calibration loop uses SI) and optionally a log scale. The optimiser works on the unit cube:

    u = (x - low) / (high - low)                    (linear)
    u = (log x - log low) / (log high - log low)    (log scale, needs low > 0)

so that parameters with different units weigh the same before the GP learns its own length
scale per parameter.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from parcelfit.errors import ParcelfitError


@dataclass(frozen=True)
class Dimension:
    """One parameter: name, bounds and scale."""

    name: str
    low: float
    high: float
    log: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise ParcelfitError(
                f"parameter {self.name}: bounds must be finite with low < high, "
                f"got ({self.low}, {self.high})"
            )
        if self.log and self.low <= 0:
            raise ParcelfitError(
                f"parameter {self.name}: a log scale needs low > 0, got {self.low}"
            )


class Space:
    """An ordered set of dimensions with conversions to and from the unit cube."""

    def __init__(self, dims: Sequence[Dimension]) -> None:
        if not dims:
            raise ParcelfitError("a search space needs at least one parameter")
        names = [d.name for d in dims]
        if len(set(names)) != len(names):
            raise ParcelfitError(f"duplicate parameter names in {names}")
        self.dims = tuple(dims)

    @classmethod
    def from_bounds(cls, bounds: Mapping[str, tuple[float, float] | Mapping[str, object]]) -> Space:
        """Build from ``{name: (low, high)}`` or ``{name: {low:, high:, log:}}``."""
        dims = []
        for name, b in bounds.items():
            if isinstance(b, Mapping):
                dims.append(
                    Dimension(name, float(b["low"]), float(b["high"]), bool(b.get("log", False)))
                )  # type: ignore[arg-type]
            else:
                low, high = b
                dims.append(Dimension(name, float(low), float(high)))
        return cls(dims)

    @property
    def names(self) -> list[str]:
        """Parameter names in order."""
        return [d.name for d in self.dims]

    def __len__(self) -> int:
        return len(self.dims)

    def to_unit(self, params: Mapping[str, float]) -> np.ndarray:
        """Map a parameter dict to a point of the unit cube (values outside are clipped)."""
        missing = [n for n in self.names if n not in params]
        if missing:
            raise ParcelfitError(f"parameters missing: {missing}")
        u = np.empty(len(self.dims))
        for i, d in enumerate(self.dims):
            x = float(params[d.name])
            if d.log:
                u[i] = (math.log(max(x, d.low)) - math.log(d.low)) / (
                    math.log(d.high) - math.log(d.low)
                )
            else:
                u[i] = (x - d.low) / (d.high - d.low)
        return np.clip(u, 0.0, 1.0)

    def from_unit(self, u: np.ndarray) -> dict[str, float]:
        """Map a point of the unit cube to a parameter dict."""
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        out = {}
        for i, d in enumerate(self.dims):
            if d.log:
                out[d.name] = float(
                    math.exp(math.log(d.low) + u[i] * (math.log(d.high) - math.log(d.low)))
                )
            else:
                out[d.name] = float(d.low + u[i] * (d.high - d.low))
        return out
