"""CFAR noise estimates and significance over a batch of maps, one axis at a time: the
running sums of CA, GO and SO, the order statistic of OS, and their per-cell significance
(:mod:`models.cfar`; docs/architecture.md, 'Models')."""

from __future__ import annotations

import numba
import numpy as np

from radarbench.models.cfar.halves import HALVES, halves_log_survival, halves_mu, inverse_counts
from radarbench.models.cfar.order_statistic import _os_kth_axis1, _os_log_denominators, _os_log_survival, selection_networks
from radarbench.models.cfar.windows import (_LOG10, _ca_sig, _capped, _ratio, edge_rank, reference_counts,
                                           window_counts)


# ------------------------------------------------------------------ noise estimates

#: detector codes of the kernels (numba dispatches on an int, not a str)
CA, OS, GO, SO = 0, 1, 2, 3
DETECTOR_CODES = {"ca": CA, "os": OS, "go": GO, "so": SO}
#: the detectors whose noise estimate is a function of the reference cells' sums
SUM_DETECTORS = ("ca",) + HALVES


@numba.njit(cache=True, inline="always")
def _window_mean(detector, c_hi, c_lo, c_lhi, c_llo, inv, inv_l, inv_r):
    """mu of one cell from four prefix sums: the right half c_hi - c_lo, the left
    c_lhi - c_llo; CA their mean (the sum in this order, so the kernels agree bit
    for bit), GO/SO the larger/smaller half mean (:func:`models.cfar.halves.halves_mu`)."""
    if detector == CA:
        return (c_hi - c_lo + c_lhi - c_llo) * inv
    return halves_mu(c_lhi - c_llo, c_hi - c_lo, inv_l, inv_r, detector == GO)


@numba.njit(cache=True)
def _sum_mean_lines(x, L, g, detector, inv_count, inv_l, inv_r, c, mu):
    """CA's (or GO's, SO's) mu along axis 0 of one map x (A, B) float32, the B
    cells of a row at once: running sums, O(1) per cell.

    The prefix sums c[j] = sum_{a<j} x[a] (float64, in ``c`` (A + 1, B)) give
    each half's sum as one difference: right = c[min(i+g+L+1, A)] - c[min(i+g+1, A)],
    left = c[max(i-g, 0)] - c[max(i-g-L, 0)]; CA: mu = (left + right) / N'
    (``inv_count`` = 1 / N' per cell of the axis; ``inv_l``, ``inv_r`` = 1 / n
    of each half, 0 where it is empty).
    """
    A, B = x.shape
    for b in range(B):                           # element loops: a slice copy costs a call per row
        c[0, b] = 0.0
    for a in range(A):
        for b in range(B):
            c[a + 1, b] = c[a, b] + x[a, b]
    for i in range(A):
        _mean_of_rows(detector, c, i, L, g, A, inv_count[i], inv_l[i], inv_r[i], mu[i])


@numba.njit(cache=True, inline="always")
def _mean_of_rows(detector, c, i, L, g, A, inv, inv_l, inv_r, mu_row):
    """mu of row i of an axis of A rows from the prefix rows of ``c`` (any row
    of ``c`` is prefix row j mod its length: the streaming kernel's ring)."""
    n = c.shape[0]
    hi, lo = min(i + g + L + 1, A) % n, min(i + g + 1, A) % n
    lhi, llo = max(i - g, 0) % n, max(i - g - L, 0) % n
    if detector == CA:                           # the branch outside the loop: it vectorises
        for b in range(mu_row.shape[0]):
            mu_row[b] = (c[hi, b] - c[lo, b] + c[lhi, b] - c[llo, b]) * inv
    else:
        for b in range(mu_row.shape[0]):
            mu_row[b] = halves_mu(c[lhi, b] - c[llo, b], c[hi, b] - c[lo, b], inv_l, inv_r, detector == GO)


@numba.njit(cache=True)
def _sum_mean_axis1(x, L, g, detector, inv_count, inv_l, inv_r, mu):
    """:func:`_sum_mean_lines` along axis 1 of every map of x (P, A, B) float32."""
    c = np.empty((x.shape[1] + 1, x.shape[2]))
    for p in range(x.shape[0]):
        _sum_mean_lines(x[p], L, g, detector, inv_count, inv_l, inv_r, c, mu[p])


def sum_inverses(L: int, g: int, M: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(1/N', 1/n_left, 1/n_right) per cell of an axis of M cells (0 for an empty half)."""
    left, right = window_counts(M, L, g)
    return 1.0 / (left + right), inverse_counts(left), inverse_counts(right)


def window_noise(maps: np.ndarray, detector: str, L: int, g: int, k: int, axis: str) -> np.ndarray:
    """mu (n, R, D) float32 along ``axis`` ("range" or "doppler") of maps
    (n, R, D) float32: the mean of the N' reference cells (``detector``
    "ca"), their k'-th smallest ("os"), or the larger ("go") or smaller
    ("so") of the two half-windows' means. The kernels run along axis 1
    with the other axis as vector lanes, so along Doppler they run on the
    transposed maps (the readable composition; :func:`window_cfar` streams rows)."""
    lines = maps if axis == "range" else np.ascontiguousarray(maps.transpose(0, 2, 1))
    mu = np.empty_like(lines)
    if detector == "os":
        _os_kth_axis1(lines, L, g, k, *selection_networks(2 * L), mu)
    else:
        _sum_mean_axis1(lines, L, g, DETECTOR_CODES[detector], *sum_inverses(L, g, lines.shape[1]), mu)
    return mu if axis == "range" else np.ascontiguousarray(mu.transpose(0, 2, 1))


# ------------------------------------------------------------------ significance

@numba.njit(cache=True, inline="always")
def _window_sig(detector, t, N, k, log_den):
    """-log10 Pfa(t) of CA (N = N'), OS (:func:`models.cfar.order_statistic._os_log_survival`,
    N = N', k = k') or GO/SO (:func:`models.cfar.halves.halves_log_survival`,
    N, k = the halves' n_left, n_right)."""
    if detector == CA:
        return _ca_sig(t, N)
    if detector == OS:
        return _os_log_survival(t, N, k, log_den) / _LOG10
    return halves_log_survival(t, N, k, detector == GO) / _LOG10


#: t_a < t_b (1 - ORDER_MARGIN) orders CA's significances at t_a and t_b with margin to spare
#: (:func:`_combined_sig`): log1p's error (an ulp, 1e-16) is far below the gap it opens
ORDER_MARGIN = 1e-9


@numba.njit(cache=True, inline="always")
def _clearly_below(a: float, b: float) -> bool:
    """0 <= a < b (1 - ORDER_MARGIN) (False for a NaN)."""
    return 0.0 <= a < b * (1.0 - ORDER_MARGIN)


@numba.njit(cache=True, inline="always")
def _combined_sig(detector, t_r, n_r, k_r, t_d, n_d, k_d, both, log_den):
    """min (``both``) or max of the range and Doppler significances at ratios
    t_r, t_d. CA at equal N' (every cell away from the edges when the windows
    match): S = N' log10(1 + t/N') rises with t, so the smaller (larger) S is
    the one at the smaller (larger) t, and only that one is computed when the
    ratios differ by more than ORDER_MARGIN (far beyond the rounding of the
    log, so the value is the one both would give, bit for bit); otherwise both."""
    lo = t_r if t_r < t_d else t_d               # selects, not branches: the order is a coin toss
    hi = t_d if t_r < t_d else t_r
    if detector == CA and n_r == n_d and _clearly_below(lo, hi):
        return _ca_sig(lo if both else hi, n_r)
    s_r = _window_sig(detector, t_r, n_r, k_r, log_den)
    s_d = _window_sig(detector, t_d, n_d, k_d, log_den)
    return min(s_r, s_d) if both else max(s_r, s_d)


@numba.njit(cache=True)
def _row_significance(x, keep, mu_r, n_r, k_r, mu_d, n_d, k_d, use_r, use_d, both, detector, log_den,
                      kept, t_r, t_d, out):
    """out = the capped significance of the active dimensions combined ("both":
    the smaller, else the larger), at the cells of one row x (D,) where
    ``keep``; 0 elsewhere (so the logs are paid only at the local maxima of
    the peak detection). The row's range window is (n_r, k_r), its Doppler
    windows (n_d, k_d) (D,). The kept cells' indices (into ``kept``), their
    ratios t = x / mu (into ``t_r``, ``t_d``), then the logs in a loop of their own."""
    D = x.shape[0]
    n_kept = 0
    for d in range(D):                           # zeros, and the kept cells' indices, branch-free
        out[d] = 0.0
    for d in range(D):
        kept[n_kept] = d
        n_kept += keep[d]
    for j in range(n_kept):
        d = kept[j]
        if use_r:
            t_r[j] = _ratio(x[d], mu_r[d])
        if use_d:
            t_d[j] = _ratio(x[d], mu_d[d])
    for j in range(n_kept):
        d = kept[j]
        if use_r and use_d:
            s = _combined_sig(detector, t_r[j], n_r, k_r, t_d[j], n_d[d], k_d[d], both, log_den)
        elif use_r:
            s = _window_sig(detector, t_r[j], n_r, k_r, log_den)
        else:
            s = _window_sig(detector, t_d[j], n_d[d], k_d[d], log_den)
        out[d] = _capped(s)


@numba.njit(cache=True)
def _map_significance(x, keep, mu_r, n_r, k_r, mu_d, n_d, k_d, use_r, use_d, both, detector, log_den, out):
    """:func:`_row_significance` on every row of one map x (R, D) (n_r, k_r (R,))."""
    R, D = x.shape
    kept = np.empty(D, dtype=np.int64)
    t_r = np.zeros(D)
    t_d = np.zeros(D)
    for r in range(R):
        _row_significance(x[r], keep[r], mu_r[r], n_r[r] if use_r else 0, k_r[r] if use_r else 0, mu_d[r],
                          n_d, k_d, use_r, use_d, both, detector, log_den, kept, t_r, t_d, out[r])


@numba.njit(cache=True)
def _window_significance(x, keep, mu_r, n_r, k_r, mu_d, n_d, k_d, use_r, use_d, both, detector, log_den, out):
    """:func:`_map_significance` on every map of x (P, R, D)."""
    for p in range(x.shape[0]):
        _map_significance(x[p], keep[p], mu_r[p], n_r, k_r, mu_d[p], n_d, k_d, use_r, use_d, both, detector,
                          log_den, out[p])


def _axis_windows(detector: str, windows: dict, sizes: dict) -> tuple[dict, dict, np.ndarray]:
    """The two per-cell window arrays of each axis the closed forms take
    (:func:`_window_sig`): CA ({axis: N'}, {axis: N'}), OS ({axis: N'}, {axis: k'}),
    GO/SO ({axis: n_left}, {axis: n_right}), and the log-denominator table of
    :func:`models.cfar.order_statistic._os_log_survival`, of the windows
    ``{axis: (L, g, k)}`` on axes of ``sizes`` ``{axis: M}`` cells."""
    counts, ranks, full = {}, {}, 1
    for axis, (L, g, k) in windows.items():
        if detector in HALVES:
            counts[axis], ranks[axis] = (n.astype(np.int64) for n in window_counts(sizes[axis], L, g))
        else:
            counts[axis] = reference_counts(sizes[axis], L, g).astype(np.int64)
            ranks[axis] = (edge_rank(k, 2 * L, counts[axis]) if detector == "os" else counts[axis]).astype(np.int64)
        full = max(full, 2 * L)
    return counts, ranks, _os_log_denominators(full)


#: the per-cell array of an axis no active dimension uses (never read)
_UNUSED = np.zeros(1, dtype=np.int64)


def window_significance(maps: np.ndarray, detector: str, windows: dict, mus: dict, dimension: str,
                        keep: np.ndarray | None = None) -> np.ndarray:
    """S (n, R, D) float32 of CA, OS, GO or SO (``detector``) for the active
    dimensions combined (``dimension``), from their noise estimates ``mus``
    ``{axis: mu}`` and windows ``{axis: (L, g, k)}``, at each cell's own N'
    and k'; 0 where ``keep`` is False (None: every cell)."""
    n, R, D = maps.shape
    counts, ranks, log_den = _axis_windows(detector, windows, {"range": R, "doppler": D})
    some = next(iter(mus.values()))
    out = np.empty(maps.shape, dtype=np.float32)
    _window_significance(maps, np.ones(maps.shape, np.bool_) if keep is None else keep,
                         mus.get("range", some), counts.get("range", _UNUSED), ranks.get("range", _UNUSED),
                         mus.get("doppler", some), counts.get("doppler", _UNUSED), ranks.get("doppler", _UNUSED),
                         "range" in mus, "doppler" in mus, dimension == "both", DETECTOR_CODES[detector], log_den,
                         out)
    return out


def ca_cfar(maps: np.ndarray, L: int, g: int, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """CA-CFAR along ``axis`` of maps (n, R, D): (mu, S) both (n, R, D)
    float32, mu the mean of the N' reference cells, S the capped significance
    -log10 Pfa_CA(x / mu; N') of every cell."""
    maps = np.ascontiguousarray(maps, dtype=np.float32)
    mu = window_noise(maps, "ca", L, g, 0, axis)
    return mu, window_significance(maps, "ca", {axis: (L, g, 0)}, {axis: mu}, axis)


def halves_cfar(maps: np.ndarray, detector: str, L: int, g: int, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """GO- or SO-CFAR (``detector`` "go", "so") along ``axis`` of maps (n, R, D):
    (mu, S) (n, R, D) float32, mu the larger/smaller half-window mean, S =
    -log10 Pfa(x / mu; n_left, n_right) (:mod:`models.cfar.halves`)."""
    maps = np.ascontiguousarray(maps, dtype=np.float32)
    mu = window_noise(maps, detector, L, g, 0, axis)
    return mu, window_significance(maps, detector, {axis: (L, g, 0)}, {axis: mu}, axis)


def axis_cfar(maps: np.ndarray, detector: str, L: int, g: int, k: int, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """(mu, S) of ``detector`` ("ca", "os", "go", "so") along ``axis`` (k: OS's rank)."""
    if detector == "ca":
        return ca_cfar(maps, L, g, axis)
    return os_cfar(maps, L, g, k, axis) if detector == "os" else halves_cfar(maps, detector, L, g, axis)


def os_cfar(maps: np.ndarray, L: int, g: int, k: int, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """OS-CFAR along ``axis`` of maps (n, R, D): (mu, S) (n, R, D) float32, mu
    the k'-th smallest reference cell, S = -log10 Pfa_OS(x / mu; N', k')."""
    maps = np.ascontiguousarray(maps, dtype=np.float32)
    mu = window_noise(maps, "os", L, g, k, axis)
    return mu, window_significance(maps, "os", {axis: (L, g, k)}, {axis: mu}, axis)
