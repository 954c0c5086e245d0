"""Design of experiments: two-level designs, effects, significance, Pareto charts, selection.

Knows nothing of simulators: it gets responses.
"""

from parcelfit.doe.designs import (
    Design,
    decode,
    fractional_factorial,
    full_factorial,
    latin_hypercube,
    with_centre_points,
)
from parcelfit.doe.effects import (
    EffectAnalysis,
    Selection,
    analyse_effects,
    lenth,
    pareto_chart,
    select_parameters,
)

__all__ = [
    "Design",
    "EffectAnalysis",
    "Selection",
    "analyse_effects",
    "decode",
    "fractional_factorial",
    "full_factorial",
    "latin_hypercube",
    "lenth",
    "pareto_chart",
    "select_parameters",
    "with_centre_points",
]
