"""A stand-in for your own Python model of a rig (`backend: python` in a study file).

parcelfit calls ``make()`` to build the model and sends the object to its worker processes
(so it must be picklable, as a plain class is), which call ``run(params, case)`` per
simulation.
This toy model carries the parcel along x at the belt's speed and turns it towards the belt's
direction at a rate that grows with the belt friction; replace its body with your model.
"""

from __future__ import annotations

import time
from collections.abc import Mapping

import numpy as np

from parcelfit.runs import Run, TestCase, Trajectory
from parcelfit.sim.protocol import SimResult, SimStatus

BELT_SPEED = {1: 0.62, 2: 1.00}  # m/s per speed setting (this toy rig's)
BARRIERS = (0.3, 1.3)  # x [m] of the two light barriers


class ToyModel:
    """A simulator: ``run`` takes SI parameters named as in the catalogue (``parcelfit
    params``; missing ones take your defaults) and a test case, and returns a `SimResult`."""

    def with_placement(self, seed: int | None) -> ToyModel:
        """Optional: the same model with placement ``seed`` (None: the nominal start), so that
        parcelfit can compare ensembles of placed runs. A seed is any integer (up to 2^31 in
        magnitude); -s is the mirror image of s. Here: the start heading off by a normal draw
        of sd 1 degree seeded by |s|, its sign flipped for -s."""
        placed = ToyModel()
        if seed is not None:
            draw = np.random.default_rng(abs(seed)).normal(0.0, np.radians(1.0))
            placed.offset = float(draw if seed >= 0 else -draw)
        return placed

    offset = 0.0

    def run(self, params: Mapping[str, float], case: TestCase) -> SimResult:
        """Simulate ``case`` with ``params`` (SI units); trajectory t [s], x, y [m], theta [rad]
        sampled at 50 Hz, the transit time [s] between the two barriers."""
        t0 = time.perf_counter()
        speed = BELT_SPEED.get(case.speed_setting)
        if speed is None:
            return SimResult(None, SimStatus.FAILED, 0.0, {"message": "unknown speed setting"})
        mu = float(params.get("mu_d_BePa", 0.45))
        t = np.arange(0.0, 2.5, 0.02)
        x = speed * t
        theta = (np.radians(30.0) + self.offset) * np.exp(-4.0 * mu * t)
        y = 0.02 * (1.0 - np.exp(-t))
        crossed = (BARRIERS[1] - BARRIERS[0]) / speed if x[-1] > BARRIERS[1] else None
        run = Run(
            id=f"toy-{case.label}",
            case=case,
            trajectory=Trajectory.from_arrays(t, x, y, theta),
            transit_time=crossed,
        )
        return SimResult(run, SimStatus.OK, time.perf_counter() - t0)


def make() -> ToyModel:
    """The factory a study file names: ``factory: toy_model:make``."""
    return ToyModel()
