"""MuJoCo's warnings, kept out of ``MUJOCO_LOG.TXT``.

Without a handler of its own, MuJoCo prints each warning and appends it to ``MUJOCO_LOG.TXT``
in the current folder. `install_default_handler` (called when `parcelfit.sim.mujoco` is
imported, unless a handler is already set) sends them to the ``parcelfit.sim.mujoco`` logger
instead; during a simulation `CountedWarnings` takes over and counts them into the run's
diagnostics (``mujoco_warnings``, ``first_mujoco_warning``).
"""

from __future__ import annotations

import logging

import mujoco

LOGGER = logging.getLogger("parcelfit.sim.mujoco")


def _log_warning(message: str) -> None:
    LOGGER.warning("MuJoCo: %s", str(message).strip())


def install_default_handler() -> None:
    """Send MuJoCo's warnings to the logger, unless some handler is already installed."""
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(_log_warning)


class CountedWarnings:
    """Count MuJoCo's warnings during a run instead of printing them (3-D flexes can warn about
    an ill-conditioned stiffness solve every step); the count goes into the diagnostics."""

    def __enter__(self) -> CountedWarnings:
        self.count = 0
        self.first = ""
        self._previous = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(self._handle)
        return self

    def _handle(self, message: str) -> None:
        self.count += 1
        if not self.first:
            self.first = str(message).strip()

    def __exit__(self, *exc: object) -> None:
        mujoco.set_mju_user_warning(self._previous)
