"""Small rigs for physics tests, built from dicts; a scene stepped by hand under the per-contact
friction law."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import mujoco
import numpy as np

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator
from parcelfit.sim.mujoco.friction import ContactFriction, Stepper
from parcelfit.sim.mujoco.mjlog import CountedWarnings
from parcelfit.sim.mujoco.rig import Rig, parse_rig
from parcelfit.sim.mujoco.simulator import _set_velocity


@contextmanager
def contact_law_scene(
    case: TestCase, placement: int | None = None
) -> Iterator[tuple[mujoco.MjModel, mujoco.MjData, ContactFriction]]:
    """The default scene of ``case`` (at seeded ``placement``, else the nominal start) at its
    start velocity, with its per-contact friction law, for stepping by hand (``mj_step1``,
    ``apply``, ``mj_step2``, ``record``); MuJoCo's warnings counted, not printed."""
    sim = MujocoSimulator()
    if placement is not None:
        sim = sim.with_placement(placement)
    scene = sim.scene({}, case)
    with CountedWarnings():
        model = scene.model()
        data = mujoco.MjData(model)
        _set_velocity(model, data, np.asarray(scene.start_velocity))
        params = sim.consignment(case.consignment).parameter_values()
        stepper = Stepper(model, data, scene, params, sim.options.scene)
        assert stepper.contact is not None
        yield model, data, stepper.contact


def flat_belt(
    speed: float = 1.0,
    length: float = 4.0,
    barriers: tuple[float, float] = (0.5, 1.0),
    duration: float = 1.0,
    start_x: float = 0.0,
    heading: float = 0.0,
) -> Rig:
    """One belt along x from -1 m, moving at ``speed``; the parcel starts at ``start_x``."""
    return parse_rig(
        {
            "name": "flat",
            "speeds": {1: {"belt": speed}},
            "surfaces": [
                {
                    "name": "belt",
                    "type": "belt",
                    "material": "belt",
                    "centre": [length / 2 - 1, 0],
                    "length": length,
                    "width": 1.0,
                    "heading": 0,
                    "top": 0.0,
                    "drive": "belt",
                }
            ],
            "start": {"position": [start_x, 0], "heading": heading, "surface": "belt"},
            "light_barriers": [
                {"name": "LS1", "from": [barriers[0], -0.5], "to": [barriers[0], 0.5]},
                {"name": "LS2", "from": [barriers[1], -0.5], "to": [barriers[1], 0.5]},
            ],
            "end": {
                "x": [-2, length],
                "y": [-1, 1],
                "duration": duration,
                "after_last_barrier": 0.0,
            },
        },
        "<test rig>",
    )
