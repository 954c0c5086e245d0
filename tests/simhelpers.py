"""Small rigs for physics tests, built from dicts."""

from __future__ import annotations

from parcelfit.sim.mujoco.rig import Rig, parse_rig


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
