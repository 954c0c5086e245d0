"""An independent reference for the MuJoCo parcel model: the parcel as one rigid box with
area-weighted penalty contacts and velocity-dependent friction per contact point, integrated by
a small symplectic Newton-Euler integrator (numba). See README.md in this folder."""

from parcelfit.sim.rigidbox.engine import Motion, World
from parcelfit.sim.rigidbox.geometry import Body, Primitives, parcel_body, rig_primitives
from parcelfit.sim.rigidbox.simulator import RigidBoxOptions, RigidBoxSimulator

__all__ = [
    "Body",
    "Motion",
    "Primitives",
    "RigidBoxOptions",
    "RigidBoxSimulator",
    "World",
    "parcel_body",
    "rig_primitives",
]
