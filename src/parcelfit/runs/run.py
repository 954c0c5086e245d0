"""A run: one parcel's passage through a test rig, real or simulated."""

from __future__ import annotations

import math
from dataclasses import dataclass

from parcelfit.errors import ParcelfitError, shown
from parcelfit.runs.trajectory import Trajectory

# the highest speed setting a test case may name (a rig has a handful; a bigger number is a
# mistake, and beyond 2^63 it could not even be stored)
MAX_SPEED_SETTING = 1000


@dataclass(frozen=True, order=True)
class TestCase:
    """A test case: rig (e.g. ``E3``), consignment type (e.g. ``KPBW``) and speed setting (1, 2, ...)."""

    __test__ = False  # not a pytest test class

    rig: str
    consignment: str
    speed_setting: int

    @property
    def label(self) -> str:
        """Short label such as ``E3/KPBW/1``."""
        return f"{self.rig}/{self.consignment}/{self.speed_setting}"

    @classmethod
    def parse(cls, text: str) -> TestCase:
        """Parse ``RIG/CONSIGNMENT/SETTING`` (e.g. ``E3/KPBW/1``)."""
        parts = text.split("/")
        setting = parts[2].strip() if len(parts) == 3 else ""
        if not (setting.isascii() and setting.isdigit()) or len(setting) > 9:
            raise ParcelfitError(
                f"cannot read test case {shown(text)}",
                fix="write it as RIG/CONSIGNMENT/SETTING, e.g. E3/KPBW/1",
            )
        if not 1 <= int(setting) <= MAX_SPEED_SETTING:
            raise ParcelfitError(
                f"test case {shown(text)} names speed setting {int(setting)}",
                fix=f"use a speed setting from 1 to {MAX_SPEED_SETTING}",
            )
        return cls(parts[0].strip(), parts[1].strip(), int(setting))


@dataclass(frozen=True, eq=False)
class Run:
    """One run of a test case: id, test case, trajectory and transit time [s] (None if unknown)."""

    id: str
    case: TestCase
    trajectory: Trajectory
    transit_time: float | None = None

    def __post_init__(self) -> None:
        if not self.id:
            raise ParcelfitError("a run needs a non-empty id")
        tt = self.transit_time
        if tt is not None and (not math.isfinite(tt) or tt <= 0):
            raise ParcelfitError(
                f"run {self.id!r}: transit time must be a positive number of seconds, got {tt}",
                fix="give the time between the two light barriers in seconds, or null if unknown",
            )
