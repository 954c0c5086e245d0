"""Dynamic time warping with the symmetric2 step pattern (the dtw-python package's default).

For series a (n samples) and b (m samples), each sample a point in R^k, the local distance is
Euclidean, d(i, j) = ||a_i - b_j||_2 (for k = 1 the absolute difference), and the cumulative
cost g obeys

    g(0, 0) = d(0, 0)
    g(i, j) = min( g(i-1, j-1) + 2 d(i, j),  g(i, j-1) + d(i, j),  g(i-1, j) + d(i, j) )

The DTW distance is g(n-1, m-1) (dtw-python's ``distance``); the normalised distance divides by
n + m (its ``normalizedDistance``). An optional Sakoe-Chiba band admits only cells with
|i - j| <= w, exactly as dtw-python's ``sakoechiba`` window (no slope correction).

Written by hand with numba because dtw-python builds the full n x m cost matrix per pair in a
scalar C loop and cannot compute many pairs in parallel; this kernel sweeps anti-diagonals in
SIMD, keeps three diagonals (O(n) memory), releases the GIL, and `pairwise_dtw` spreads pairs
over all cores.
"""

from __future__ import annotations

from collections.abc import Sequence

import numba
import numpy as np

from parcelfit.errors import ParcelfitError

_NO_WINDOW = -1


@numba.njit(cache=True, nogil=True)
def _dtw_kernel(a: np.ndarray, b: np.ndarray, window: int) -> float:
    # Anti-diagonal (wavefront) order: the cells (i, j) with i + j = s depend only on the
    # diagonals s - 1 and s - 2, so each diagonal is one loop without a dependency chain that
    # LLVM vectorises (4 cells per AVX2 instruction). Three diagonal buffers indexed by i + 1
    # (slot 0 is the i = -1 border), +inf sentinels just outside each computed range, b stored
    # reversed so that b[s - i] runs forward with i, and loops over slices from 0 so numba
    # needs no negative-index handling. Sums and minima are the same floating-point operations
    # as dtw-python's, so results are bit-identical.
    n, m, k = a.shape[0], b.shape[0], a.shape[1]
    br = np.ascontiguousarray(b[::-1].T)  # (k, m)
    at = np.ascontiguousarray(a.T)  # (k, n)
    buf = np.full((3, n + 2), np.inf)
    dist = np.empty(n)
    r0, r1, r2 = 0, 1, 2  # rows of buf holding diagonals s, s - 1, s - 2
    for s in range(n + m - 1):
        ilo = max(0, s - m + 1)
        ihi = min(n - 1, s)
        if window >= 0:
            ilo = max(ilo, (s - window + 1) // 2)
            ihi = min(ihi, (s + window) // 2)
        if ilo > ihi:  # the band misses this diagonal (every odd one for window 0)
            buf[r0, :] = np.inf
            r0, r1, r2 = r2, r0, r1
            continue
        size = ihi - ilo + 1
        off = m - 1 - s + ilo
        ds = dist[:size]
        ds[:] = 0.0
        for c in range(k):
            ac = at[c, ilo : ihi + 1]
            bc = br[c, off : off + size]
            for t in range(size):
                diff = ac[t] - bc[t]
                ds[t] += diff * diff
        out = buf[r0, ilo + 1 : ihi + 2]
        if s == 0:
            out[0] = np.sqrt(ds[0])
        else:
            diag = buf[r2, ilo : ihi + 1]  # (i - 1, j - 1)
            left = buf[r1, ilo + 1 : ihi + 2]  # (i, j - 1)
            up = buf[r1, ilo : ihi + 1]  # (i - 1, j)
            for t in range(size):
                d = np.sqrt(ds[t])
                v = min(diag[t] + 2.0 * d, left[t] + d)
                out[t] = min(v, up[t] + d)
        buf[r0, ilo] = np.inf
        buf[r0, ihi + 2] = np.inf
        r0, r1, r2 = r2, r0, r1
    return buf[r1, n]


@numba.njit(cache=True, parallel=True)
def _pairs_kernel(
    data: np.ndarray,
    offsets: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    window: int,
    out: np.ndarray,
) -> None:
    for p in numba.prange(left.shape[0]):
        i, j = left[p], right[p]
        out[p] = _dtw_kernel(
            data[offsets[i] : offsets[i + 1]], data[offsets[j] : offsets[j + 1]], window
        )


def _as_series(x: np.ndarray | Sequence[float], name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ParcelfitError(
            f"{name} must be a non-empty 1-D series or an (n, k) array, got shape {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise ParcelfitError(
            f"{name} contains NaN or inf", fix="remove or interpolate those samples"
        )
    return np.ascontiguousarray(a)


def _window(window: int | None) -> int:
    if window is None:
        return _NO_WINDOW
    if isinstance(window, bool) or int(window) != window or window < 0:
        raise ParcelfitError(
            f"the Sakoe-Chiba window must be a whole number of samples >= 0, got {window}"
        )
    return int(window)


def _no_path(n: int, m: int, w: int) -> ParcelfitError:
    return ParcelfitError(
        f"no warping path fits a Sakoe-Chiba window of {w} samples for lengths {n} and {m}",
        fix=f"use a window of at least |n - m| = {abs(n - m)} samples, or none",
    )


def dtw_distance(
    a: np.ndarray | Sequence[float],
    b: np.ndarray | Sequence[float],
    window: int | None = None,
    normalized: bool = False,
) -> float:
    """DTW distance between two series (symmetric2, Euclidean local distance; units of the data).

    ``a`` and ``b`` are 1-D series or (n, k) arrays with the same k. ``window`` is the Sakoe-Chiba
    half-width in samples (None: unconstrained). ``normalized`` divides by n + m.
    """
    A, B = _as_series(a, "a"), _as_series(b, "b")
    if A.shape[1] != B.shape[1]:
        raise ParcelfitError(f"series have different dimensions: {A.shape[1]} and {B.shape[1]}")
    w = _window(window)
    d = float(_dtw_kernel(A, B, w))
    if not np.isfinite(d):
        raise _no_path(len(A), len(B), w)
    return d / (len(A) + len(B)) if normalized else d


def _pack(series: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    arrays = [_as_series(s, f"series {i}") for i, s in enumerate(series)]
    dims = {a.shape[1] for a in arrays}
    if len(dims) > 1:
        raise ParcelfitError(f"series have different dimensions: {sorted(dims)}")
    offsets = np.zeros(len(arrays) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(a) for a in arrays])
    return np.ascontiguousarray(np.concatenate(arrays)), offsets


def pairwise_dtw(series: Sequence[np.ndarray], window: int | None = None) -> np.ndarray:
    """Symmetric matrix of DTW distances between all series (zero diagonal), on all cores."""
    n = len(series)
    out = np.zeros((n, n))
    if n < 2:
        return out
    data, offsets = _pack(series)
    left, right = np.triu_indices(n, k=1)
    vals = np.empty(len(left))
    w = _window(window)
    _pairs_kernel(data, offsets, left.astype(np.int64), right.astype(np.int64), w, vals)
    if not np.all(np.isfinite(vals)):
        p = int(np.flatnonzero(~np.isfinite(vals))[0])
        lens = np.diff(offsets)
        raise _no_path(int(lens[left[p]]), int(lens[right[p]]), w)
    out[left, right] = vals
    out[right, left] = vals
    return out


def cross_dtw(
    rows: Sequence[np.ndarray], cols: Sequence[np.ndarray], window: int | None = None
) -> np.ndarray:
    """Matrix of DTW distances between every series in ``rows`` and every one in ``cols``."""
    if not rows or not cols:
        return np.zeros((len(rows), len(cols)))
    data, offsets = _pack([*rows, *cols])
    r, c = np.meshgrid(np.arange(len(rows)), np.arange(len(cols)) + len(rows), indexing="ij")
    vals = np.empty(r.size)
    w = _window(window)
    _pairs_kernel(data, offsets, r.ravel().astype(np.int64), c.ravel().astype(np.int64), w, vals)
    if not np.all(np.isfinite(vals)):
        p = int(np.flatnonzero(~np.isfinite(vals))[0])
        lens = np.diff(offsets)
        raise _no_path(int(lens[r.ravel()[p]]), int(lens[c.ravel()[p]]), w)
    return vals.reshape(len(rows), len(cols))
