"""The planar trajectory of one parcel: time, centre position and heading (SI units).

A `Trajectory` holds equal-length arrays ``t`` [s] (strictly increasing), ``x``, ``y`` [m] (the
parcel centre in the rig frame: x along the conveying direction, y across it) and ``theta``
[rad] (heading of the parcel's x axis, counter-clockwise from the rig's x axis, unwrapped, so
consecutive samples never jump by more than pi).

Optionally, per sample, ``source``: ``"detected"`` (measured in that frame by the tag detector),
``"fitted"`` (measured in that frame by the model fit of the motion-smeared tag, where the
detector missed it or the smear biases it) or ``"filled"`` (interpolated across a gap in the
measurements). Tracked runs carry it; simulated runs and files
without the column have ``source`` None, which means every sample was measured. Tracked runs may
also carry ``position_sd`` [m] and ``heading_sd`` [rad], a standard deviation per sample (NaN
where there is none, e.g. in filled frames); None when not known.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from parcelfit.errors import ParcelfitError

COLUMNS: tuple[str, ...] = ("t", "x", "y", "theta")
# optional per-sample columns: where each sample came from (see SOURCES) and its uncertainty
OPTIONAL_COLUMNS: tuple[str, ...] = ("source", "position_sd", "heading_sd")
UNCERTAINTY_COLUMNS: tuple[str, ...] = ("position_sd", "heading_sd")
SOURCES: tuple[str, ...] = ("detected", "fitted", "filled")
MIN_SAMPLES = 3
# `Trajectory.resample` keeps a grid point the run ends short of by at most this fraction of the
# grid's interval. It absorbs time stamps rounded in a file (9 significant digits in run files
# written before they kept every digit: up to 5e-9 s per second of time, 3e-4 of a 60 Hz
# interval at an hour) and floating-point error; the point, past the last sample, takes the
# last sample's value, off by at most this fraction of one interval's motion.
RESAMPLE_END_TOLERANCE = 1e-3


def unwrap_angle(theta: np.ndarray) -> np.ndarray:
    """Return ``theta`` [rad] unwrapped: 2*pi steps removed so consecutive samples differ < pi."""
    return np.unwrap(np.asarray(theta, dtype=float))


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Sampled planar motion of a parcel: t [s], x [m], y [m], theta [rad, unwrapped]; optionally
    ``source`` per sample ("detected", "fitted" or "filled"; None: all measured) and standard deviations
    ``position_sd`` [m], ``heading_sd`` [rad] (NaN where none; None: not known)."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    source: np.ndarray | None = None
    position_sd: np.ndarray | None = None
    heading_sd: np.ndarray | None = None

    def __post_init__(self) -> None:
        arrays = {}
        for name in COLUMNS:
            a = np.ascontiguousarray(np.asarray(getattr(self, name), dtype=float))
            if a.ndim != 1:
                raise ParcelfitError(
                    f"column {name!r} must be one-dimensional, got shape {a.shape}"
                )
            a.setflags(write=False)
            arrays[name] = a
            object.__setattr__(self, name, a)
        n = {len(a) for a in arrays.values()}
        if len(n) != 1:
            lengths = {k: len(v) for k, v in arrays.items()}
            raise ParcelfitError(
                f"columns differ in length: {lengths}", fix="give every column one value per sample"
            )
        if len(self.t) < MIN_SAMPLES:
            raise ParcelfitError(
                f"a trajectory needs at least {MIN_SAMPLES} samples, got {len(self.t)}",
                fix="record a longer run or check the file",
            )
        for name, a in arrays.items():
            bad = np.flatnonzero(~np.isfinite(a))
            if bad.size:
                raise ParcelfitError(
                    f"column {name!r} has a non-finite value (NaN or inf) at sample {bad[0]}",
                    fix="remove or interpolate the missing samples",
                )
        steps = np.diff(self.t)
        bad = np.flatnonzero(steps <= 0)
        if bad.size:
            raise ParcelfitError(
                f"time is not strictly increasing at sample {bad[0] + 1} "
                f"(t={self.t[bad[0]]:.6g} s then {self.t[bad[0] + 1]:.6g} s)",
                fix="sort the samples by time and drop duplicated time stamps",
            )
        jumps = np.flatnonzero(np.abs(np.diff(self.theta)) > np.pi)
        if jumps.size:
            raise ParcelfitError(
                f"theta jumps by more than pi at sample {jumps[0] + 1}: it is not unwrapped",
                fix="pass the heading through parcelfit.runs.unwrap_angle",
            )
        if self.source is not None:
            src = np.asarray(self.source, dtype=str)
            if src.shape != self.t.shape:
                raise ParcelfitError(
                    f"source has shape {src.shape}, the trajectory {self.t.shape}",
                    fix="give one source per sample",
                )
            bad = np.flatnonzero(~np.isin(src, SOURCES))
            if bad.size:
                raise ParcelfitError(
                    f"source of sample {bad[0]} is {str(src[bad[0]])!r}",
                    fix=f"use one of {', '.join(SOURCES)}",
                )
            src.setflags(write=False)
            object.__setattr__(self, "source", src)
        for name in UNCERTAINTY_COLUMNS:
            if getattr(self, name) is None:
                continue
            sd = np.array(getattr(self, name), dtype=float)
            if sd.shape != self.t.shape:
                raise ParcelfitError(
                    f"{name} has shape {sd.shape}, the trajectory {self.t.shape}",
                    fix="give one value per sample (NaN where there is none)",
                )
            bad = np.flatnonzero(np.isinf(sd) | (sd < 0))
            if bad.size:
                raise ParcelfitError(
                    f"{name} of sample {bad[0]} is {sd[bad[0]]}",
                    fix="a standard deviation is finite and >= 0 (NaN where there is none)",
                )
            sd.setflags(write=False)
            object.__setattr__(self, name, sd)

    @classmethod
    def from_arrays(
        cls,
        t: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
        theta: np.ndarray,
        source: np.ndarray | None = None,
        position_sd: np.ndarray | None = None,
        heading_sd: np.ndarray | None = None,
    ) -> Trajectory:
        """Build a trajectory, unwrapping ``theta`` [rad] first (t [s], x, y [m])."""
        return cls(
            t=t,
            x=x,
            y=y,
            theta=unwrap_angle(theta),
            source=source,
            position_sd=position_sd,
            heading_sd=heading_sd,
        )

    @classmethod
    def from_frame(cls, frame: pd.DataFrame) -> Trajectory:
        """Build from a table with columns t [s], x [m], y [m], theta [rad] (and, optionally,
        source, position_sd [m], heading_sd [rad])."""
        source = frame["source"].tolist() if "source" in frame else None
        sds = {c: frame[c].to_numpy(dtype=float) for c in UNCERTAINTY_COLUMNS if c in frame}
        return cls.from_arrays(
            *(frame[c].to_numpy(dtype=float) for c in COLUMNS), source=source, **sds
        )

    def to_frame(self) -> pd.DataFrame:
        """The trajectory as a table with columns t [s], x [m], y [m], theta [rad], and those of
        source, position_sd [m], heading_sd [rad] the trajectory has."""
        frame = pd.DataFrame({c: getattr(self, c) for c in COLUMNS})
        for c in OPTIONAL_COLUMNS:
            if getattr(self, c) is not None:
                frame[c] = getattr(self, c)
        return frame

    def _optional(self, mask: np.ndarray | None = None) -> dict[str, np.ndarray | None]:
        """The optional per-sample columns, restricted to ``mask`` when given."""
        out = {}
        for c in OPTIONAL_COLUMNS:
            a = getattr(self, c)
            out[c] = a if a is None or mask is None else a[mask]
        return out

    @property
    def filled(self) -> np.ndarray:
        """True where a sample was filled across a gap rather than measured (all False when the
        trajectory has no source)."""
        if self.source is None:
            return np.zeros(len(self.t), dtype=bool)
        return self.source == "filled"

    def __len__(self) -> int:
        return len(self.t)

    @property
    def xy(self) -> np.ndarray:
        """Centre positions as an (n, 2) array [m]."""
        return np.column_stack([self.x, self.y])

    @property
    def duration(self) -> float:
        """Time between first and last sample [s]."""
        return float(self.t[-1] - self.t[0])

    def relative(self) -> Trajectory:
        """Positions [m] and heading [rad] relative to the first sample (time unchanged).

        Position offsets are subtracted in the rig frame (the axes are not rotated), the initial
        heading is subtracted from theta.
        """
        return Trajectory(
            t=self.t,
            x=self.x - self.x[0],
            y=self.y - self.y[0],
            theta=self.theta - self.theta[0],
            **self._optional(),
        )

    def select(self, mask: np.ndarray) -> Trajectory:
        """The samples where ``mask`` is true (a boolean array of the trajectory's length)."""
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != self.t.shape:
            raise ParcelfitError(f"mask has shape {mask.shape}, trajectory has {self.t.shape}")
        if mask.sum() < MIN_SAMPLES:
            raise ParcelfitError(
                f"only {int(mask.sum())} samples remain after selection, {MIN_SAMPLES} needed",
                fix="widen the regions of interest or their margin (metres in the rig frame, "
                "as the runs' x and y)",
            )
        return Trajectory(
            t=self.t[mask],
            x=self.x[mask],
            y=self.y[mask],
            theta=self.theta[mask],
            **self._optional(mask),
        )

    def resample(
        self, rate: float, start: float | None = None, stop: float | None = None
    ) -> Trajectory:
        """Linearly interpolate onto a uniform grid of ``rate`` [Hz] between start and stop [s]
        (the new samples have no source and no standard deviations: they are not frames).

        The grid is ``t0 + k / rate`` up to the end; a grid point the end falls short of by no
        more than `RESAMPLE_END_TOLERANCE` of an interval (a rounded time stamp) is kept and
        takes the last sample's value."""
        if not np.isfinite(rate) or rate <= 0:
            raise ParcelfitError(f"resampling rate must be a positive number of Hz, got {rate}")
        t0 = self.t[0] if start is None else max(start, self.t[0])
        t1 = self.t[-1] if stop is None else min(stop, self.t[-1])
        # (t1 - t0) * rate counts intervals: the tolerance is a fraction of one interval
        n = int(np.floor((t1 - t0) * rate + RESAMPLE_END_TOLERANCE)) + 1
        t = t0 + np.arange(n) / rate
        return Trajectory(
            t=t,
            x=np.interp(t, self.t, self.x),
            y=np.interp(t, self.t, self.y),
            theta=np.interp(t, self.t, self.theta),
        )

    def sample_rate(self) -> float:
        """Median sampling rate [Hz]."""
        return float(1.0 / np.median(np.diff(self.t)))
