"""The peak detection of the CFAR methods (:mod:`models.cfar`; docs/architecture.md,
'Models'): a cell survives if its power is the largest of a box around it.

The HFSWR detection chain (hfswr-cfar-mn-jpda-ukf in the shared papers,
sec. 1 "CFAR检测") combines the CFAR result "with the result of a peak
detection" (结合峰值检测的结果) and prints no neighbourhood: the box of
+-half_range range and +-half_doppler Doppler cells is our parameter
(:mod:`methods.cfar`).
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
def _local_maxima_map(x, half_range, half_doppler, row_max, box_max, keep):
    """keep[r, d] = x[r, d] >= the box maximum, on one map x (R, D): separable,
    first along Doppler (per row, into ``row_max`` (R, D)), then along range
    over the row maxima (``box_max`` (D,)), each as a running maximum over the
    box's offsets, vectorised along the row; the box cut at the map's edges."""
    R, D = x.shape
    for r in range(R):
        for d in range(D):                       # element loops: a slice copy costs a call per row
            row_max[r, d] = x[r, d]
        for e in range(1, half_doppler + 1):
            for d in range(D - e):
                row_max[r, d] = _larger(row_max[r, d], x[r, d + e])
            for d in range(e, D):
                row_max[r, d] = _larger(row_max[r, d], x[r, d - e])
    for r in range(R):
        for d in range(D):
            box_max[d] = row_max[r, d]
        for q in range(max(r - half_range, 0), min(r + half_range + 1, R)):
            for d in range(D):
                box_max[d] = _larger(box_max[d], row_max[q, d])
        for d in range(D):
            keep[r, d] = x[r, d] >= box_max[d]


@numba.njit(cache=True)
def _local_maxima(x, half_range, half_doppler, keep):
    """:func:`_local_maxima_map` on every map of x (P, R, D)."""
    P, R, D = x.shape
    row_max = np.empty((R, D), dtype=x.dtype)
    box_max = np.empty(D, dtype=x.dtype)
    for p in range(P):
        _local_maxima_map(x[p], half_range, half_doppler, row_max, box_max, keep[p])


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
