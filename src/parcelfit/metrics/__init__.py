"""Metrics: DTW, distance matrices, reference-run selection, calibration cost, validation.

Knows nothing of where runs come from. Formulas are stated in each module's docstring.
"""

from parcelfit.metrics.comparison import Comparison
from parcelfit.metrics.cost import Cost, calibration_cost, real_run_costs
from parcelfit.metrics.dtw import cross_dtw, dtw_distance, pairwise_dtw
from parcelfit.metrics.reference import ReferenceSelection, normalise, select_reference
from parcelfit.metrics.validation import (
    MeanDistanceCheck,
    TransitTimeCheck,
    Validation,
    mean_distance_check,
    transit_time_check,
    validate,
)

__all__ = [
    "Comparison",
    "Cost",
    "MeanDistanceCheck",
    "ReferenceSelection",
    "TransitTimeCheck",
    "Validation",
    "calibration_cost",
    "cross_dtw",
    "dtw_distance",
    "mean_distance_check",
    "normalise",
    "pairwise_dtw",
    "real_run_costs",
    "select_reference",
    "transit_time_check",
    "validate",
]
