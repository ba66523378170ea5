"""A window CFAR in one pass per map (CA, GO and SO streamed row by row, OS fused),
bit-identical to its composed per-axis steps (:func:`window_cfar_composed`, the readable
oracle); the per-axis results combined and the peak detection folded in
(:mod:`models.cfar`; docs/architecture.md, 'Models')."""

from __future__ import annotations

import numba
import numpy as np

from radarbench.models.cfar.estimates import (CA, DETECTOR_CODES, OS, _UNUSED, _axis_windows, _mean_of_rows,
                                             _row_significance, _window_mean, sum_inverses, window_noise,
                                             window_significance)
from radarbench.models.cfar.order_statistic import _os_kth_lines, selection_networks
from radarbench.models.cfar.peaks import _local_maxima_row, local_maxima, with_peaks


# ------------------------------------------------------------------ window CFAR, fused

@numba.njit(cache=True)
def _transpose_into(src, dst):
    """dst (B, A) = src (A, B).T: contiguous reads, strided writes (a map's
    columns of dst stay in cache; measured faster than tiles at these sizes)."""
    A, B = src.shape
    for a in range(A):
        for b in range(B):
            dst[b, a] = src[a, b]


@numba.njit(cache=True, inline="always")
def _combine_row(mu_r, mu_d, use_r, use_d, both, out):
    """One row of the noise estimate: the larger ("both") or smaller of the two
    dimensions' estimates (np.maximum / np.minimum, cell by cell), or the one active."""
    for d in range(out.shape[0]):
        if use_r and use_d:
            out[d] = np.maximum(mu_r[d], mu_d[d]) if both else np.minimum(mu_r[d], mu_d[d])
        else:
            out[d] = mu_r[d] if use_r else mu_d[d]


@numba.njit(cache=True)
def _row_scratch(D):
    """The per-row scratch of :func:`_finish_row`: (keep, col_max, kept, t_r, t_d) for rows of D cells."""
    return (np.ones(D, dtype=np.bool_), np.empty(D, dtype=np.float32), np.empty(D, dtype=np.int64), np.zeros(D),
            np.zeros(D))


@numba.njit(cache=True, inline="always")
def _finish_row(x, i, scratch, half_range, half_doppler, mu_r, n_r, k_r, mu_d, n_d, k_d, use_r, use_d, both,
                detector, log_den, statistic, noise):
    """Row i of a map x (R, D) once its noise estimates ``mu_r``, ``mu_d`` (D,)
    are known: its local maxima by row views (:func:`models.cfar.peaks._local_maxima_row`;
    none when both half-widths are 0), the significance at the kept cells
    (:func:`_row_significance`, the range window (n_r, k_r) of row i), the
    estimates combined (:func:`_combine_row`), into the rows ``statistic``, ``noise``."""
    keep, col_max, kept, t_r, t_d = scratch
    if half_range > 0 or half_doppler > 0:
        _local_maxima_row(x, i, half_range, half_doppler, col_max, keep)
    _row_significance(x[i], keep, mu_r, n_r[i] if use_r else 0, k_r[i] if use_r else 0, mu_d, n_d, k_d,
                      use_r, use_d, both, detector, log_den, kept, t_r, t_d, statistic)
    _combine_row(mu_r, mu_d, use_r, use_d, both, noise)


@numba.njit(cache=True)
def _os_cfar_fused(x, use_r, use_d, both, window_r, window_d, n_r, k_r, n_d, k_d, log_den,
                   half_range, half_doppler, statistic, noise):
    """:func:`window_cfar_composed` of OS in one pass per map x[p] (R, D), its
    scratch (a few maps' worth) reused from map to map while it sits in cache:
    the range noise estimate along axis 0 of the map, the Doppler one along
    axis 0 of its transpose (the selection network's vector lanes either way),
    then row by row the local maxima, the significance at the kept cells only
    and the noise estimates combined ("both": the larger, "either": the
    smaller); the same kernels on the same values as the composition, so the
    result is bit-identical. ``window`` = (L, g, k, the selection networks of N = 2L)."""
    P, R, D = x.shape
    mu_r = np.empty((R, D), dtype=np.float32)
    x_t = np.empty((D, R), dtype=np.float32)
    mu_t = np.empty((D, R), dtype=np.float32)
    mu_d = mu_t.T                                # read in place: a transposing copy back would thrash the cache
    buf_r = np.empty((window_r[6], D), dtype=np.float32)
    buf_d = np.empty((window_d[6], R), dtype=np.float32)
    scratch = _row_scratch(D)
    for p in range(P):
        if use_r:
            _os_kth_lines(x[p], *window_r, buf_r, mu_r)
        if use_d:
            _transpose_into(x[p], x_t)
            _os_kth_lines(x_t, *window_d, buf_d, mu_t)
        for r in range(R):
            _finish_row(x[p], r, scratch, half_range, half_doppler, mu_r[r], n_r, k_r, mu_d[r], n_d, k_d,
                        use_r, use_d, both, OS, log_den, statistic[p, r], noise[p, r])


#: rows whose Doppler prefix sums run side by side (independent chains of additions overlap)
ROW_BLOCK = 4


@numba.njit(cache=True)
def _doppler_means(detector, x, i0, i1, window, c, mu):
    """mu along Doppler (axis 1) of rows i0 .. i1 - 1 of one map x (R, D), into
    rows 0 .. i1 - i0 of ``mu``: each row's prefix sums c[j, d] = sum_{e<d} x[i0 + j, e]
    (float64, the rows' additions interleaved), then the window means
    (:func:`_window_mean`, the same sums as :func:`_sum_mean_lines` along the
    transposed map), the interior cells with fixed offsets (they vectorise).
    ``window`` = (L, g, 1/N', 1/n_left, 1/n_right per cell)."""
    L, g, inv, inv_l, inv_r = window
    D = x.shape[1]
    rows = i1 - i0
    if rows == 4:                                # four chains in registers (the sums in the same order)
        _prefix_rows4(x, i0, c)
    else:
        for j in range(rows):
            c[j, 0] = 0.0
        for d in range(D):
            for j in range(rows):
                c[j, d + 1] = c[j, d] + x[i0 + j, d]
    lo = min(g + L, D)
    hi = max(D - g - L, lo)                      # interior lo .. hi - 1: every offset inside the row
    for j in range(rows):
        cj, out = c[j], mu[j]
        # the interior through views offset so every index is a loop counter (no negative-index checks)
        c_hi, c_lo, c_lhi, c_llo = cj[lo + g + L + 1:], cj[lo + g + 1:], cj[lo - g:], cj[lo - g - L:]
        inv_k, out_k = inv[lo:], out[lo:]
        if detector == CA:                       # the branch outside the loop: it vectorises
            for k in range(hi - lo):
                out_k[k] = (c_hi[k] - c_lo[k] + c_lhi[k] - c_llo[k]) * inv_k[k]
        else:
            inv_lk, inv_rk = inv_l[lo:], inv_r[lo:]
            for k in range(hi - lo):
                out_k[k] = _window_mean(detector, c_hi[k], c_lo[k], c_lhi[k], c_llo[k], inv_k[k], inv_lk[k],
                                        inv_rk[k])
        for d in range(lo):
            out[d] = _clipped_mean(detector, cj, d, L, g, inv[d], inv_l[d], inv_r[d])
        for d in range(hi, D):
            out[d] = _clipped_mean(detector, cj, d, L, g, inv[d], inv_l[d], inv_r[d])


@numba.njit(cache=True)
def _prefix_rows4(x, i0, c):
    """c[j, d] = sum_{e<d} x[i0 + j, e] for the four rows j = 0..3 (float64, in order along each row)."""
    a0 = a1 = a2 = a3 = 0.0
    c[0, 0] = c[1, 0] = c[2, 0] = c[3, 0] = 0.0
    for d in range(x.shape[1]):
        a0 += x[i0, d]
        a1 += x[i0 + 1, d]
        a2 += x[i0 + 2, d]
        a3 += x[i0 + 3, d]
        c[0, d + 1] = a0
        c[1, d + 1] = a1
        c[2, d + 1] = a2
        c[3, d + 1] = a3


@numba.njit(cache=True, inline="always")
def _clipped_mean(detector, c, d, L, g, inv, inv_l, inv_r):
    """:func:`_window_mean` of cell d from the prefix sums ``c`` (D + 1,), its window cut at the ends."""
    D = c.shape[0] - 1
    return _window_mean(detector, c[min(d + g + L + 1, D)], c[min(d + g + 1, D)], c[max(d - g, 0)],
                        c[max(d - g - L, 0)], inv, inv_l, inv_r)


@numba.njit(cache=True)
def _sum_cfar_rows(x, detector, use_r, use_d, both, window_r, window_d, n_r, k_r, n_d, k_d, log_den,
                   half_range, half_doppler, statistic, noise):
    """:func:`window_cfar_composed` of CA, GO or SO streamed row by row over
    each map x[p] (R, D): x is read in row order once, the two outputs written
    once, every scratch a few rows long (in cache at any map size; no
    transposed reads). Per row i: the range prefix sums advanced to row
    i + g + L + 1 in a ring of 2(g + L) + 2 rows (row j of the prefix in ring
    row j mod its length), row i's range estimate from four of them; the row's
    own Doppler prefix sums and its Doppler estimate; its local maxima by row
    views (:func:`models.cfar.peaks._local_maxima_row`); the significance at
    the kept cells; the estimates combined. The same sums in the same order as
    the composition (:func:`_sum_mean_lines` along each axis), so the result is
    bit-identical. ``window`` = (L, g, 1/N', 1/n_left, 1/n_right per cell)."""
    P, R, D = x.shape
    L_r, g_r, inv_r, inv_rl, inv_rr = window_r
    ring = np.empty((2 * (g_r + L_r) + 2, D))
    c_d = np.empty((ROW_BLOCK, D + 1))
    mu_r = np.zeros(D, dtype=np.float32)
    mu_d = np.zeros((ROW_BLOCK, D), dtype=np.float32)
    scratch = _row_scratch(D)
    for p in range(P):
        xp = x[p]
        for b in range(D):
            ring[0, b] = 0.0
        filled = 0                               # prefix rows 0 .. filled are in the ring
        for i in range(R):
            if use_r:
                while filled < min(i + g_r + L_r + 1, R):
                    src, dst = ring[filled % ring.shape[0]], ring[(filled + 1) % ring.shape[0]]
                    for b in range(D):
                        dst[b] = src[b] + xp[filled, b]
                    filled += 1
                _mean_of_rows(detector, ring, i, L_r, g_r, R, inv_r[i], inv_rl[i], inv_rr[i], mu_r)
            if use_d and i % ROW_BLOCK == 0:
                _doppler_means(detector, xp, i, min(i + ROW_BLOCK, R), window_d, c_d, mu_d)
            _finish_row(xp, i, scratch, half_range, half_doppler, mu_r, n_r, k_r, mu_d[i % ROW_BLOCK], n_d, k_d,
                        use_r, use_d, both, detector, log_den, statistic[p, i], noise[p, i])


def _os_window(window: tuple[int, int, int] | None) -> tuple:
    """The ``window`` argument of :func:`_os_cfar_fused` for an axis (a
    placeholder of the same types where the axis is not active)."""
    L, g, k = window or (1, 0, 1)
    return (L, g, k, *selection_networks(2 * L if window else 1))


def _sum_window(window: tuple[int, int, int] | None, M: int) -> tuple:
    """The ``window`` argument of :func:`_sum_cfar_rows` for an axis of M cells
    (a placeholder of the same types where the axis is not active)."""
    L, g, _ = window or (1, 0, 1)
    return (L, g, *sum_inverses(L, g, M))


def window_cfar(maps: np.ndarray, detector: str, windows: dict, dimension: str, half_range: int,
                half_doppler: int) -> tuple[np.ndarray, np.ndarray]:
    """(statistic, noise estimate) (n, R, D) float32 of CA, OS, GO or SO over
    the active dimensions ``windows`` ``{axis: (L, g, k)}``, combined
    (``dimension``, :func:`combine`), with the peak detection folded in; the
    significance computed at the local maxima only. One pass per map
    (:func:`_sum_cfar_rows`, :func:`_os_cfar_fused`), bit-identical to
    :func:`window_cfar_composed`."""
    maps = np.ascontiguousarray(maps, dtype=np.float32)
    n, R, D = maps.shape
    counts, ranks, log_den = _axis_windows(detector, windows, {"range": R, "doppler": D})
    statistic = np.empty(maps.shape, dtype=np.float32)
    noise = np.empty(maps.shape, dtype=np.float32)
    use = ("range" in windows, "doppler" in windows, dimension == "both")
    arrays = (counts.get("range", _UNUSED), ranks.get("range", _UNUSED), counts.get("doppler", _UNUSED),
              ranks.get("doppler", _UNUSED), log_den, half_range, half_doppler, statistic, noise)
    if detector == "os":
        _os_cfar_fused(maps, *use, _os_window(windows.get("range")), _os_window(windows.get("doppler")), *arrays)
    else:
        _sum_cfar_rows(maps, DETECTOR_CODES[detector], *use, _sum_window(windows.get("range"), R),
                       _sum_window(windows.get("doppler"), D), *arrays)
    return statistic, noise


def window_cfar_composed(maps: np.ndarray, detector: str, windows: dict, dimension: str, half_range: int,
                         half_doppler: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`window_cfar` composed of its steps over the whole batch (the
    readable oracle of the fused kernel): the noise estimate per active
    axis (:func:`window_noise`), the local maxima, the significance at them
    (:func:`window_significance`), the noise estimates combined."""
    maps = np.ascontiguousarray(maps, dtype=np.float32)
    mus = {axis: window_noise(maps, detector, L, g, k, axis) for axis, (L, g, k) in windows.items()}
    keep = local_maxima(maps, half_range, half_doppler)
    statistic = window_significance(maps, detector, windows, mus, dimension, keep)
    if len(mus) == 1:
        return statistic, next(iter(mus.values()))
    pick = np.maximum if dimension == "both" else np.minimum
    return statistic, pick(mus["range"], mus["doppler"])


# ------------------------------------------------------------------ combination and peaks

def combine(per_axis: dict, dimension: str) -> tuple[np.ndarray, np.ndarray]:
    """(significance, noise estimate) of the per-axis results ``{axis: (mu, S)}``
    as one: "both" (a cell must pass along range and along Doppler: the
    smaller significance; the larger noise estimate), "either" (the larger
    significance; the smaller estimate), or the one dimension computed."""
    if dimension in ("range", "doppler"):
        mu, sig = per_axis[dimension]
        return sig, mu
    (mu_r, sig_r), (mu_d, sig_d) = per_axis["range"], per_axis["doppler"]
    if dimension == "both":
        return np.minimum(sig_r, sig_d), np.maximum(mu_r, mu_d)
    return np.maximum(sig_r, sig_d), np.minimum(mu_r, mu_d)


def fold(maps: np.ndarray, per_axis: dict, dimension: str, half_range: int,
         half_doppler: int, peaks=None) -> tuple[np.ndarray, np.ndarray]:
    """(statistic, noise estimate) (n, R, D) float32 of a CFAR method: its
    dimensions combined (:func:`combine`), then the peak detection folded in."""
    sig, mu = combine(per_axis, dimension)
    return with_peaks(maps, sig, half_range, half_doppler, peaks), np.asarray(mu, dtype=np.float32)
