"""A simulated run's light-barrier crossings: what both simulator backends make of them.

Each backend times each beam on its own (the time [s] it broke; None if never; inf if the
parcel already straddled it at the start, where the time is not known). `judge_crossings`
then gives:

* the **transit time**: the second beam's time minus the first's where both are known and the
  second broke after the first;
* **out of order**: the second beam broke before the first (or with it): the rig file lists its
  light barriers in another order than the parcel crosses them (its `light_barriers`), or two
  barriers lie on one line. Such a run fails with a message that says so, where its transit
  time would otherwise be about zero (the second beam was timed only after the first), or
  negative;
* **why there is no transit time** otherwise (`Crossings.note`): a beam already broken at the
  start (the start lies across it), the first beam never broken while the second was (the
  start may lie past it, or the parcel passed beside it), or a beam not reached.

A run that ends after fewer samples than a trajectory needs fails too, with why it ended.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from parcelfit.runs import Barrier


@dataclass(frozen=True)
class Crossings:
    """What a run's beam times say: ``times`` [s] (None where not known), ``transit`` [s] (None
    where not known), the beams broken at the start, whether they broke out of order, and
    ``note``: why there is no transit time (None where there is one)."""

    times: tuple[float | None, ...]
    transit: float | None
    at_start: tuple[str, ...]
    out_of_order: bool
    note: str | None


def judge_crossings(crossed: Sequence[float | None], barriers: Sequence[Barrier]) -> Crossings:
    """`Crossings` of the beam times ``crossed`` [s] (None: never broken; inf: broken at the
    start) of the rig's ``barriers`` (module docstring)."""
    n = min(len(crossed), len(barriers))
    raw = list(crossed[:n])
    names = [b.name for b in barriers[:n]]
    times = tuple(None if t is None or t == math.inf else float(t) for t in raw)
    at_start = tuple(name for name, t in zip(names, raw, strict=True) if t == math.inf)
    if n < 2:
        return Crossings(times, None, at_start, False, "the rig has fewer than two light barriers")
    (a, b), (first, second) = names, times
    out_of_order = first is not None and second is not None and second <= first
    transit = None if out_of_order or first is None or second is None else second - first
    note = None
    if out_of_order and second == first:
        note = f"light barriers {a} and {b} broke together: the rig file puts them on one line"
    elif out_of_order:
        note = (
            f"light barrier {b} broke before {a}: the rig file lists light_barriers in another "
            f"order than the parcel crosses them (list {b} first)"
        )
    elif transit is None:
        if at_start:
            note = (
                f"{', '.join(at_start)} already broken at the start, the parcel's start lying "
                "across it: move the rig file's start.position back"
            )
        elif first is None and second is not None:
            note = (
                f"{a} was never broken, {b} was: the start may lie past {a}, the parcel passed "
                f"beside it, or the rig file lists its light barriers out of order"
            )
        else:
            note = f"light barrier {a if first is None else b} was not reached"
    return Crossings(times, transit, at_start, out_of_order, note)


def crossing_diagnostics(judged: Crossings) -> dict[str, object]:
    """A run's diagnostics from its `Crossings`: ``barrier_times`` [s], the beams broken at the
    start, whether they broke out of order, and why there is no transit time."""
    return {
        "barrier_times": judged.times,
        "barriers_broken_at_start": judged.at_start,
        "barriers_out_of_order": judged.out_of_order,
        "transit_note": judged.note,
    }


def too_short_words(message: str, samples: int) -> str:
    """The message of a run that ended (``message``: why) after fewer ``samples`` than a
    trajectory needs (3)."""
    return (
        f"{message} after {samples} sample{'s' if samples != 1 else ''}, too few for a "
        "trajectory (does the rig's end box hold the start, and end.duration the run?)"
    )
