"""A simulated run's light-barrier crossings: the checks both simulator backends share.

Each backend times each beam on its own (the time [s] it broke, None if never, inf if the
parcel already straddled it at the start, where the time is not known). The transit time is
the second beam's time minus the first's where both are known. A second beam that breaks
before the first, or without it, means the rig file lists its light barriers in another order
than the parcel crosses them (its `light_barriers`): such a run fails with a message that says
so, where its transit time would otherwise be about zero or missing, silently. A run that ends
after fewer samples than a trajectory needs fails too, with why it ended.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from parcelfit.runs import Barrier


def barriers_out_of_order(crossed: Sequence[float | None]) -> bool:
    """Whether the second beam broke before the first, or without it (``crossed``: each beam's
    time [s], None if never broken, inf if already broken at the start)."""
    if len(crossed) < 2:
        return False
    first, second = crossed[0], crossed[1]
    if second is None or second == math.inf:
        return False
    return first is None or (first != math.inf and second < first)


def out_of_order_words(barriers: Sequence[Barrier]) -> str:
    """The message of a run whose light barriers broke out of order (`barriers_out_of_order`)."""
    a, b = barriers[0].name, barriers[1].name
    return (
        f"light barrier {b} broke before {a} (or without it): the rig file lists light_barriers "
        f"in another order than the parcel crosses them; list {b} first, or move the barriers"
    )


def too_short_words(message: str, samples: int) -> str:
    """The message of a run that ended (``message``: why) after fewer ``samples`` than a
    trajectory needs (3)."""
    return (
        f"{message} after {samples} sample{'s' if samples != 1 else ''}, too few for a "
        "trajectory (does the rig's end box hold the start, and end.duration the run?)"
    )
