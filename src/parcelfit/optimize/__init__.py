"""Calibration: batch Bayesian optimisation (ask/tell) and its search space.

Knows nothing of physics: it gets parameters and costs.
"""

from parcelfit.optimize.bo import BatchBO, BOSettings
from parcelfit.optimize.space import Dimension, Space

__all__ = ["BOSettings", "BatchBO", "Dimension", "Space"]
