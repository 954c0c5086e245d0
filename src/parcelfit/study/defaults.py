"""The default run counts of `predict` and `design`, in a module of their own so that the
command line's options read them without loading the study modules (counts, no unit)."""

from __future__ import annotations

PREDICT_PLACEMENTS = 10  # seeded placements per set (1 where the simulator cannot place runs)
DESIGN_PLACEMENTS = 5  # seeded placements per set and candidate (1 where runs cannot be placed)
SCATTER_RUNS = 10  # runs of the recommended parameters per fitted and validation case (run_scatter)
NUMERICAL_RUNS = 6  # placements at which the model and the refined model are compared
