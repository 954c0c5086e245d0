"""Optimisation: batch Bayesian optimisation (ask/tell), the other samplers and the search space.

Knows nothing of physics or studies: it gets parameters and costs. It imports nothing from
`parcelfit.sim` or `parcelfit.study` (a test checks).
"""

from parcelfit.optimize.bo import BatchBO, BOSettings
from parcelfit.optimize.space import Dimension, Space

__all__ = ["BOSettings", "BatchBO", "Dimension", "Space"]
