"""Simulation: the `Simulator` protocol, the parameter catalogue and the backends.

Backends: `parcelfit.sim.mujoco.MujocoSimulator` (rigs and consignments from data files),
`parcelfit.sim.rigidbox.RigidBoxSimulator` (the rigid-box reference on the same files) and
`parcelfit.sim.external.ExternalSimulator` (any solver run as a command), built from a
configuration by `parcelfit.sim.factory.make_simulator`; `parcelfit.sim.executors` runs
simulations in this process, in local processes or on Dask.
"""

from parcelfit.sim.params import (
    CATALOGUE,
    ParameterSpec,
    defaults_si,
    parameter,
    parameters_for,
    resolve,
)
from parcelfit.sim.protocol import SimResult, SimStatus, Simulator

__all__ = [
    "CATALOGUE",
    "ParameterSpec",
    "SimResult",
    "SimStatus",
    "Simulator",
    "defaults_si",
    "parameter",
    "parameters_for",
    "resolve",
]
