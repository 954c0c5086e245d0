"""The MuJoCo backend: rigs and consignments from YAML, flexible packaging shells, observation
like the camera's. See README.md in this folder for the model and its parameter mapping."""

from parcelfit.sim.mujoco.consignment import (
    Consignment,
    bundled_consignment_names,
    load_consignment,
)
from parcelfit.sim.mujoco.mjlog import install_default_handler
from parcelfit.sim.mujoco.options import SceneOptions
from parcelfit.sim.mujoco.rig import Rig, bundled_rig_names, load_rig, load_rig_files
from parcelfit.sim.mujoco.scene import build_scene
from parcelfit.sim.mujoco.simulator import Frames, MujocoSimulator, SimOptions

install_default_handler()  # MuJoCo's warnings go to logging, never into MUJOCO_LOG.TXT

__all__ = [
    "Consignment",
    "Frames",
    "MujocoSimulator",
    "Rig",
    "SceneOptions",
    "SimOptions",
    "build_scene",
    "bundled_consignment_names",
    "bundled_rig_names",
    "load_consignment",
    "load_rig",
    "load_rig_files",
]
