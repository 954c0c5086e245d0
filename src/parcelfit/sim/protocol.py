"""The contract every simulator backend fulfils.

``Simulator.run(params, case) -> SimResult``: the parameters (SI units, names from the
parameter catalogue) and a test case (rig, consignment type, speed setting) go in; a simulated
`Run` sampled like the camera, a status, the wall time and diagnostics come out. A backend is
pure: the same inputs give the same result.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Protocol, runtime_checkable

from parcelfit.runs import Run, TestCase


class SimStatus(StrEnum):
    """How a simulation ended."""

    OK = "ok"  # reached its end condition with a finite, plausible state
    FAILED = "failed"  # the solver could not be run or its output could not be read
    UNSTABLE = "unstable"  # NaN, energy blow-up, or the parcel left the rig
    TIMEOUT = "timeout"  # the wall-clock limit was reached


@dataclass(frozen=True)
class SimResult:
    """One simulation: the simulated run (None unless there is a usable trajectory), its status,
    wall time [s], and free-form diagnostics (message, steps, warnings...)."""

    run: Run | None
    status: SimStatus
    wall_time: float
    diagnostics: Mapping[str, object] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when the status is ``ok``."""
        return self.status is SimStatus.OK


@runtime_checkable
class Simulator(Protocol):
    """Anything that simulates a test case for given parameters."""

    def run(self, params: Mapping[str, float], case: TestCase) -> SimResult:
        """Simulate ``case`` with ``params`` (SI units; missing ones take their defaults)."""
        ...
