"""Building a simulator from the ``simulator`` section of a study or screen file.

The section's ``backend`` chooses: ``mujoco`` (a bundled or user rig and consignment, optional
``timestep`` [s], ``spacing`` [m] and ``wall_limit`` [s]), ``external`` (a solver description
file run as a command) or ``python`` (``factory: package.module:callable``, imported and called:
such a file runs code). The section has been checked by `SimulatorSection` (`parcelfit.optimize.study`).
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from parcelfit.errors import ParcelfitError
from parcelfit.sim.protocol import Simulator


def make_simulator(sim: Mapping[str, Any], folder: Path) -> Simulator:
    """The simulator a study's or screen's ``simulator`` section describes (``folder``: the file's)."""
    backend = sim["backend"]
    if backend == "mujoco":
        from parcelfit.sim.mujoco import (
            MujocoSimulator,
            SceneOptions,
            SimOptions,
            load_consignment,
            load_rig,
        )

        rig = load_rig(sim["rig"])
        cons = load_consignment(sim["consignment"])
        scene = SceneOptions(**{k: float(sim[k]) for k in ("timestep", "spacing") if k in sim})
        options = SimOptions(scene=scene, wall_limit=float(sim.get("wall_limit", 600.0)))
        return MujocoSimulator(options, rigs={rig.name: rig}, consignments={cons.name: cons})
    if backend == "external":
        from parcelfit.sim.external import ExternalSimulator, load_external_solver

        return ExternalSimulator(
            load_external_solver(sim["external"]), workroot=folder / ".external-runs"
        )
    module, _, attr = str(sim["factory"]).partition(":")
    try:
        factory = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ParcelfitError(
            f"cannot import the simulator factory {sim['factory']!r} ({exc})",
            fix="give it as package.module:callable, importable from here",
        ) from exc
    return factory()


__all__ = ["make_simulator"]
