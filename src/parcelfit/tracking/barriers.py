"""Transit times: virtual light barriers crossed by the parcel, or a real sensor log.

A barrier is a segment a -> b in the rig frame. With unit normal n (a's left-hand side turned
to the right: n = (d_y, -d_x) / |d| for d = b - a, flipped so the parcel starts on its negative
side), the parcel's outline (a length x width rectangle about its centre, heading theta; or its
centre point without an outline) breaks the beam when its leading extent

    e(t) = max over the outline's corners c of n . (c - a)

first becomes >= 0 while the outline overlaps the segment's extent along d. The crossing time is
interpolated linearly between the two samples around the sign change (sub-frame). Transit time =
crossing of the last barrier - crossing of the first. A beam already broken at the first sample
was crossed before the trajectory began: its crossing time is not known (None), and neither is
the transit time. So was a beam the outline lies wholly beyond at the first sample and never
breaks (`passed_at_start`; beyond: the side of the last barrier, for the last the side away
from the first).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from parcelfit.errors import ParcelfitError
from parcelfit.runs import Barrier, Trajectory


def outline_corners(
    x: np.ndarray, y: np.ndarray, theta: np.ndarray, outline: tuple[float, float] | None
) -> np.ndarray:
    """Corners (n, 4, 2) [m] of the parcel's outline per sample (the centre, repeated, if None)."""
    n = len(x)
    if outline is None:
        return np.repeat(np.column_stack([x, y])[:, None, :], 4, axis=1)
    half_l, half_w = outline[0] / 2, outline[1] / 2
    local = np.array([[half_l, half_w], [half_l, -half_w], [-half_l, -half_w], [-half_l, half_w]])
    c, s = np.cos(theta), np.sin(theta)
    out = np.empty((n, 4, 2))
    out[..., 0] = x[:, None] + c[:, None] * local[:, 0] - s[:, None] * local[:, 1]
    out[..., 1] = y[:, None] + s[:, None] * local[:, 0] + c[:, None] * local[:, 1]
    return out


def _breaks(
    traj: Trajectory, barrier: Barrier, outline: tuple[float, float] | None
) -> tuple[np.ndarray, np.ndarray]:
    """Per sample, whether the outline breaks the barrier, and its leading extent e(t) [m]
    (module docstring)."""
    a, b = np.asarray(barrier.start), np.asarray(barrier.end)
    d = b - a
    length = float(np.hypot(*d))
    if length == 0:
        raise ParcelfitError(f"light barrier {barrier.name!r} has zero length")
    u = d / length
    n = np.array([u[1], -u[0]])
    corners = outline_corners(traj.x, traj.y, traj.theta, outline)
    rel = corners - a
    lead = (rel @ n).max(axis=1)
    if (rel[0] @ n).min() > 0:  # the parcel starts on the positive side: flip
        n = -n
        lead = (rel @ n).max(axis=1)
    along = rel @ u
    overlap = (along.max(axis=1) >= 0) & (along.min(axis=1) <= length)
    return (lead >= 0) & overlap, lead


def broken_at_start(
    traj: Trajectory, barrier: Barrier, outline: tuple[float, float] | None
) -> bool:
    """Whether the outline already breaks the barrier at the trajectory's first sample (it
    crossed before the trajectory began)."""
    return bool(len(traj.t)) and bool(_breaks(traj, barrier, outline)[0][0])


def passed_at_start(
    traj: Trajectory, barriers: Sequence[Barrier], outline: tuple[float, float] | None
) -> list[str]:
    """Names of the barriers the outline lies wholly beyond at the first sample, beside the
    beam's segment, and never breaks (it passed them before the trajectory began). Beyond a
    barrier is the side of the last barrier's midpoint, and beyond the last barrier the side
    away from the first's; with fewer than two barriers no side is known and none is named."""
    if len(barriers) < 2 or not len(traj.t):
        return []
    corners0 = outline_corners(traj.x[:1], traj.y[:1], traj.theta[:1], outline)[0]
    out = []
    for k, barrier in enumerate(barriers):
        a, b = np.asarray(barrier.start, float), np.asarray(barrier.end, float)
        d = b - a
        n = np.array([d[1], -d[0]])
        if k < len(barriers) - 1:
            other, beyond = barriers[-1], 1.0  # beyond: the last barrier's side
        else:
            other, beyond = barriers[0], -1.0  # beyond the last: away from the first
        mid = (np.asarray(other.start, float) + np.asarray(other.end, float)) / 2
        side = float(n @ (mid - a))
        if side == 0:
            continue
        n = n * beyond * math.copysign(1.0, side)
        rel = corners0 - a
        wholly_beyond = float((rel @ n).min()) > 0
        # and beside the beam's segment, not beyond its line only (a curved layout's line
        # passes elsewhere)
        along = rel @ (d / float(np.hypot(*d)))
        beside = along.max() >= 0 and along.min() <= float(np.hypot(*d))
        if wholly_beyond and beside and crossing_time(traj, barrier, outline) is None:
            out.append(barrier.name)
    return out


OUT_OF_ORDER_WORDS = (
    "the last light barrier broke before the first: the tag map lists light_barriers in another "
    "order than the parcel crosses them, so the transit time is left out (list them in order)"
)
"""What the tracking commands say when the last barrier broke before the first."""


def late_start_words(names: Sequence[str]) -> str:
    """What the tracking commands say of barriers already broken or passed at the first sample
    (`broken_at_start`, `passed_at_start`)."""
    return (
        f"{', '.join(names)} already broken or passed in the first frame with the tag: crossed "
        "before the video shows it, so its time is not known and the transit time is left out "
        "(start the video earlier)"
    )


def crossing_time(
    traj: Trajectory, barrier: Barrier, outline: tuple[float, float] | None
) -> float | None:
    """First time [s] the outline breaks the barrier (None if it never does, or if it breaks it
    already at the first sample: it crossed before the trajectory began, at a time not seen, and
    a transit time from it would be too short; `broken_at_start` tells the two apart)."""
    broken, lead = _breaks(traj, barrier, outline)
    hit = np.flatnonzero(broken)
    if len(hit) == 0:
        return None
    k = int(hit[0])
    if k == 0:
        return None
    e0, e1 = lead[k - 1], lead[k]
    frac = 0.0 if e1 == e0 else float(np.clip(-e0 / (e1 - e0), 0, 1))
    return float(traj.t[k - 1] + frac * (traj.t[k] - traj.t[k - 1]))


def barrier_times(
    traj: Trajectory, barriers: Sequence[Barrier], outline: tuple[float, float] | None
) -> dict[str, float | None]:
    """Crossing time [s] of every barrier by id."""
    return {b.name: crossing_time(traj, b, outline) for b in barriers}


def read_sensor_log(path: str | Path, start: str, end: str) -> float:
    """Transit time [s] from a light-barrier log CSV with columns ``timestamp`` [s] and
    ``sensor``: the first ``end`` event after the first ``start`` event."""
    path = Path(path)
    if not path.is_file():
        raise ParcelfitError("sensor log not found", file=path, fix="check the path")
    table = pd.read_csv(path)
    missing = {"timestamp", "sensor"} - set(table.columns)
    if missing:
        raise ParcelfitError(
            f"missing column(s) {', '.join(sorted(missing))}",
            file=path,
            fix="write a header line: timestamp,sensor (timestamp in seconds)",
        )
    table["sensor"] = table["sensor"].astype(str)
    starts = table.loc[table["sensor"] == start, "timestamp"].astype(float)
    if starts.empty:
        raise ParcelfitError(f"no event of sensor {start!r}", file=path, fix="check the sensor ids")
    t0 = float(starts.min())
    ends = table.loc[(table["sensor"] == end) & (table["timestamp"] >= t0), "timestamp"]
    if ends.empty:
        raise ParcelfitError(
            f"no event of sensor {end!r} after {start!r}", file=path, fix="check the sensor ids"
        )
    value = float(ends.min()) - t0
    if not math.isfinite(value) or value <= 0:
        raise ParcelfitError(f"transit time {value} s is not positive", file=path)
    return value
