"""Statistics on real runs: transit-time comparisons between consignment types."""

from parcelfit.stats.plots import transit_time_boxplots
from parcelfit.stats.transit import (
    compare_transit_times,
    significance_stars,
    transit_time_table,
)

__all__ = [
    "compare_transit_times",
    "significance_stars",
    "transit_time_boxplots",
    "transit_time_table",
]
