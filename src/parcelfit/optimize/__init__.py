"""Optimisation: batch Bayesian optimisation (ask/tell), the other samplers and the search space.

Knows nothing of physics or studies: it gets parameters and costs. It imports nothing from
`parcelfit.sim` or `parcelfit.study` (a test checks).
"""

from typing import Any

from parcelfit.optimize.bo import BatchBO, BOSettings
from parcelfit.optimize.space import Dimension, Space

__all__ = ["BOSettings", "BatchBO", "Dimension", "Space"]


def __getattr__(name: str) -> Any:
    """Backwards compatibility: the study layer (``Calibration``, ``load_study``,
    ``study_status``, ``Store``, ``load_screen``, ...) moved to `parcelfit.study`; its names
    still resolve here, imported only when asked for."""
    import parcelfit.study

    if name in parcelfit.study.__all__:
        return getattr(parcelfit.study, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
