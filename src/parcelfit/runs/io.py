"""Reading and writing trajectory files (CSV or Parquet, columns t, x, y, theta in SI units).

Schema: one row per sample; ``t`` [s] strictly increasing, ``x``, ``y`` [m] parcel centre in the
rig frame, ``theta`` [rad] heading (wrapped or unwrapped; it is unwrapped on load). Optional:
``source``, ``detected``, ``fitted`` or ``filled`` per sample (tracked runs; a file without it was measured
in every sample), and ``position_sd`` [m], ``heading_sd`` [rad] per sample (empty where there is
none). Nothing else.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pandas as pd

from parcelfit.errors import ParcelfitError, one_line, shown
from parcelfit.runs.trajectory import (
    COLUMNS,
    MIN_SAMPLES,
    OPTIONAL_COLUMNS,
    SOURCES,
    UNCERTAINTY_COLUMNS,
    Trajectory,
    unwrap_angle,
)

SUFFIXES = (".csv", ".parquet")
# Plausibility limits for spotting unit mistakes; a test rig is a few metres long, a run lasts
# seconds and a parcel turns at most a few times.
MAX_POSITION_SPAN_M = 100.0
MAX_TIME_SPAN_S = 3600.0
# a camera or a simulation samples a run at 2 Hz to 100 kHz; milliseconds read as seconds give
# samples about 17 "s" apart
MIN_SAMPLE_INTERVAL_S = 1e-5
MAX_SAMPLE_INTERVAL_S = 0.5
MAX_HEADING_RAD = 4 * np.pi


def read_table(path: Path) -> pd.DataFrame:
    """Read a CSV (UTF-8, a byte-order mark allowed) or Parquet file into a table; a file that
    cannot be read says why (missing, empty, not UTF-8 at byte N, malformed CSV, not Parquet)
    and the fix."""
    path = Path(path)
    if not path.is_file():
        raise ParcelfitError("file not found", file=path, fix="check the path in dataset.yaml")
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise ParcelfitError(
            f"unknown file type {path.suffix!r}", file=path, fix="use a .csv or .parquet file"
        )
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ParcelfitError(
            f"cannot read the file ({exc.strerror or exc})",
            file=path,
            fix="check that it is a readable file",
        ) from None
    if not data.strip():
        raise ParcelfitError(
            f"the file is empty ({len(data)} bytes{', all white space' if data else ''})",
            file=path,
            fix="write the run's samples into it (columns t,x,y,theta), or name the right file",
        )
    if suffix == ".parquet":
        try:
            return pd.read_parquet(io.BytesIO(data))
        except Exception as exc:  # pyarrow's errors have no common base class
            raise ParcelfitError(
                f"not a readable Parquet file ({one_line(str(exc))[:120]})",
                file=path,
                fix="write the run again as .parquet (parcelfit does), or as a .csv file",
            ) from None
    try:
        text = data.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as exc:
        raise ParcelfitError(
            f"not UTF-8 text (byte {exc.start}: {data[exc.start : exc.start + 1]!r})",
            file=path,
            fix="save the file as UTF-8 (CSV UTF-8)",
        ) from None
    try:
        return pd.read_csv(io.StringIO(text))
    except (pd.errors.ParserError, pd.errors.EmptyDataError, ValueError) as exc:
        raise ParcelfitError(
            f"malformed CSV ({one_line(str(exc).strip())[:120]})",
            file=path,
            fix="write a header line t,x,y,theta and one line of numbers per sample",
        ) from None


def check_trajectory_table(frame: pd.DataFrame, file: str | Path) -> Trajectory:
    """Check a table against the trajectory schema and return it as a `Trajectory`.

    Errors name the file, the column or data row (1-based, header excluded) and the fix.
    """
    cols = [str(c) for c in frame.columns]
    missing = [c for c in COLUMNS if c not in cols]
    extra = [c for c in cols if c not in COLUMNS + OPTIONAL_COLUMNS]
    if missing:
        raise ParcelfitError(
            f"missing column(s) {missing}; found {cols}",
            file=file,
            fix="name the columns exactly t,x,y,theta (seconds, metres, radians)",
        )
    if extra:
        raise ParcelfitError(
            f"unexpected column(s) {extra}",
            file=file,
            fix="keep only the columns t,x,y,theta (seconds, metres, radians) and optionally "
            + ",".join(OPTIONAL_COLUMNS),
        )
    if len(frame) < MIN_SAMPLES:
        raise ParcelfitError(
            f"{len(frame)} samples, at least {MIN_SAMPLES} needed",
            file=file,
            fix="record a longer run",
        )
    values = {}
    for c in COLUMNS:
        a = pd.to_numeric(frame[c], errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise ParcelfitError(
                f"column {c!r} has a missing, non-numeric or infinite value ({shown(frame[c].iloc[bad[0]])})",
                file=file,
                where=f"data row {bad[0] + 1}",
                fix="remove or interpolate that sample",
            )
        values[c] = a
    t = values["t"]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise ParcelfitError(
            f"time does not increase (t={t[bad[0]]:.6g} then {t[bad[0] + 1]:.6g})",
            file=file,
            where=f"data row {bad[0] + 2}",
            fix="sort by t and drop duplicated time stamps",
        )
    if t[-1] - t[0] > MAX_TIME_SPAN_S:
        raise ParcelfitError(
            f"the run spans {t[-1] - t[0]:.4g} s, more than {MAX_TIME_SPAN_S:.0f} s",
            file=file,
            where="column 't'",
            fix="t must be in seconds; if it is in milliseconds, divide by 1000",
        )
    step = float(np.median(np.diff(t)))
    if not MIN_SAMPLE_INTERVAL_S <= step <= MAX_SAMPLE_INTERVAL_S:
        raise ParcelfitError(
            f"samples are {step:.4g} s apart ({1 / step:.4g} Hz), outside the plausible "
            f"[{MIN_SAMPLE_INTERVAL_S:g}, {MAX_SAMPLE_INTERVAL_S:g}] s of a tracked run",
            file=file,
            where="column 't'",
            fix="t must be in seconds; if it is in milliseconds, divide by 1000",
        )
    for c in ("x", "y"):
        span = np.ptp(values[c])
        if span > MAX_POSITION_SPAN_M:
            raise ParcelfitError(
                f"{c} spans {span:.4g} m, more than any test rig ({MAX_POSITION_SPAN_M:.0f} m)",
                file=file,
                where=f"column {c!r}",
                fix="positions must be in metres; if they are in millimetres, divide by 1000",
            )
    theta = unwrap_angle(values["theta"])
    if np.max(np.abs(theta)) > MAX_HEADING_RAD or np.ptp(theta) > MAX_HEADING_RAD:
        raise ParcelfitError(
            f"theta reaches {np.max(np.abs(theta)):.4g} rad (more than two turns)",
            file=file,
            where="column 'theta'",
            fix="theta must be in radians; if it is in degrees, convert with numpy.radians",
        )
    source = None
    if "source" in cols:
        raw = frame["source"]
        text = np.array([v.strip() if isinstance(v, str) else "" for v in raw.tolist()])
        bad = np.flatnonzero(~np.isin(text, SOURCES))
        if bad.size:
            raise ParcelfitError(
                f"column 'source' has {shown(raw.iloc[bad[0]])}",
                file=file,
                where=f"data row {bad[0] + 1}",
                fix=f"write {', '.join(SOURCES[:-1])} or {SOURCES[-1]} in every row, or drop the column",
            )
        source = text
    sds = {}
    for c in UNCERTAINTY_COLUMNS:
        if c not in cols:
            continue
        a = pd.to_numeric(frame[c], errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero((np.isnan(a) & frame[c].notna().to_numpy()) | np.isinf(a) | (a < 0))
        if bad.size:
            raise ParcelfitError(
                f"column {c!r} has {shown(frame[c].iloc[bad[0]])}",
                file=file,
                where=f"data row {bad[0] + 1}",
                fix="a standard deviation is a number >= 0 (SI units), or empty where there is none",
            )
        sds[c] = a
    return Trajectory(t=t, x=values["x"], y=values["y"], theta=theta, source=source, **sds)


def read_trajectory(path: str | Path) -> Trajectory:
    """Read and check a trajectory file (.csv or .parquet; t [s], x [m], y [m], theta [rad],
    optionally source, position_sd [m], heading_sd [rad])."""
    path = Path(path)
    return check_trajectory_table(read_table(path), path)


def check_trajectory_path(path: str | Path) -> None:
    """Refuse a trajectory file name whose suffix is not .csv or .parquet (before any work)."""
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise ParcelfitError(
            f"unknown file type {path.suffix!r}", file=path, fix="use .csv or .parquet"
        )


def write_trajectory(trajectory: Trajectory, path: str | Path) -> Path:
    """Write a trajectory to .csv or .parquet (by suffix); returns the path written. Numbers keep
    every digit (a CSV holds each as its shortest text that reads back to the same float). The
    optional columns (source, position_sd, heading_sd) are written only when the trajectory has
    them (tracked runs, not simulated ones)."""
    path = Path(path)
    check_trajectory_path(path)
    suffix = path.suffix.lower()
    path.parent.mkdir(parents=True, exist_ok=True)
    frame = trajectory.to_frame()
    tmp = path.with_name(path.name + ".tmp")
    try:
        if suffix == ".csv":
            # no float_format: every number as its shortest round-trip text (Python's repr), so
            # a run read back is the run written, to the last bit (files written earlier kept 9
            # significant digits; Trajectory.resample tolerates their rounded time stamps)
            frame.to_csv(tmp, index=False)
        else:
            frame.to_parquet(tmp, index=False)
        tmp.replace(path)  # atomic: a crash never leaves half a file under the final name
    except OSError as exc:  # a full disk: nothing half-written stays, the error names the file
        tmp.unlink(missing_ok=True)
        if exc.filename is None or exc.filename == str(tmp):
            exc.filename = str(path)
        raise
    return path
