r"""The peak detection of the CFAR methods (:mod:`models.cfar`; docs/architecture.md,
'Models'): a cell survives if its power is the largest of a box around it.

The HFSWR detection chain (hfswr-cfar-mn-jpda-ukf in the shared papers,
sec. 1 "CFAR检测") combines the CFAR result "with the result of a peak
detection" (结合峰值检测的结果) and prints no neighbourhood: the box of
$\pm$ ``half_range`` range and $\pm$ ``half_doppler`` Doppler cells is our parameter
(:mod:`methods.cfar.detectors`).
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.ndimage


@numba.njit(cache=True, inline="always")
def _larger(a, b):
    """max(a, b) as Python's ``max`` decides it (b only if b > a), as a select the loops vectorise."""
    return b if b > a else a


@numba.njit(cache=True)
def _local_maxima_row(x, r, half_range, half_doppler, col_max, keep_row):
    """keep_row[d] = x[r, d] >= the box maximum, for row r of one map x (R, D),
    by row views: the column maxima of rows r - half_range .. r + half_range
    (``col_max`` (D,), whole contiguous rows at a time), then x[r, d] compared
    with each of col_max[d - half_doppler .. d + half_doppler]; the box cut at
    the map's edges. x >= the maximum of a set is x >= each of its members, so
    the mask is the box maximum's (maps hold no NaN)."""
    R, D = x.shape
    for d in range(D):                           # element loops: a slice copy costs a call per row
        col_max[d] = x[r, d]
    for q in range(max(r - half_range, 0), min(r + half_range + 1, R)):
        for d in range(D):
            col_max[d] = _larger(col_max[d], x[q, d])
    for d in range(D):
        keep_row[d] = x[r, d] >= col_max[d]
    x_r = x[r]
    for e in range(1, min(half_doppler, D - 1) + 1):
        # views offset by e, so every index is a loop counter (no negative-index checks: it vectorises)
        keep_lo, x_lo, col_hi = keep_row[:D - e], x_r[:D - e], col_max[e:]
        for d in range(D - e):
            keep_lo[d] = keep_lo[d] & (x_lo[d] >= col_hi[d])
        keep_hi, x_hi, col_lo = keep_row[e:], x_r[e:], col_max[:D - e]
        for d in range(D - e):
            keep_hi[d] = keep_hi[d] & (x_hi[d] >= col_lo[d])


@numba.njit(cache=True)
def _local_maxima_map(x, half_range, half_doppler, col_max, keep):
    """:func:`_local_maxima_row` for every row of one map x (R, D)."""
    for r in range(x.shape[0]):
        _local_maxima_row(x, r, half_range, half_doppler, col_max, keep[r])


@numba.njit(cache=True)
def _local_maxima(x, half_range, half_doppler, keep):
    """:func:`_local_maxima_map` on every map of x (P, R, D)."""
    col_max = np.empty(x.shape[2], dtype=x.dtype)
    for p in range(x.shape[0]):
        _local_maxima_map(x[p], half_range, half_doppler, col_max, keep[p])


def local_maxima(maps: np.ndarray, half_range: int, half_doppler: int) -> np.ndarray:
    """(n, R, D) bool: cells whose power is the largest of the box of
    +-half_range range and +-half_doppler Doppler cells around them (the box
    cut at the map's edges; ties keep every tied cell). All True when both
    half-widths are 0 (no peak detection)."""
    if half_range == 0 and half_doppler == 0:
        return np.ones(maps.shape, dtype=bool)
    maps = np.ascontiguousarray(maps, dtype=np.float32)
    keep = np.empty(maps.shape, dtype=np.bool_)
    _local_maxima(maps, half_range, half_doppler, keep)
    return keep


def local_maxima_scipy(maps: np.ndarray, half_range: int, half_doppler: int) -> np.ndarray:
    """:func:`local_maxima` by ``scipy.ndimage.maximum_filter`` (the straightforward
    implementation; mode "nearest" repeats the edge cells, which cannot change a maximum)."""
    if half_range == 0 and half_doppler == 0:
        return np.ones(maps.shape, dtype=bool)
    box = scipy.ndimage.maximum_filter(maps, size=(1, 2 * half_range + 1, 2 * half_doppler + 1), mode="nearest")
    return maps >= box


def with_peaks(maps: np.ndarray, sig: np.ndarray, half_range: int, half_doppler: int,
               peaks=None) -> np.ndarray:
    """The statistic (n, R, D) float32: the significance where the cell is a
    local maximum of the power (``peaks``, default :func:`local_maxima`), 0 elsewhere."""
    keep = (peaks or local_maxima)(maps, half_range, half_doppler)
    return np.where(keep, sig, np.float32(0.0)).astype(np.float32, copy=False)
