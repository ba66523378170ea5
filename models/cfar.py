"""CFAR detector maths on range-Doppler power maps: reference windows, the
CA and OS noise estimates over a whole batch of maps, their closed-form
false-alarm probabilities, and the nominal significance every CFAR method
of the ``cell-detection`` task reports (docs/architecture.md, 'Models').

The detectors are the three of the HFSWR detection chain ("目标检测与跟踪方法
-海洋遥感技术应用", sec. 1 "CFAR检测", in the shared papers as
hfswr-cfar-mn-jpda-ukf): CFAR "done along range and along Doppler
separately, then the two results combined, with the result of a peak
detection" (地波雷达的CFAR检测处理通常在距离向和多普勒向分别进行 ... 再综合距离向、
多普勒向检测结果,结合峰值检测的结果). Per dimension a cell under test x_D is
compared with U0 = K mu:

* CA: "mu = the mean of the N reference cells around the cell under test,
  U0 = K mu" (对被检测单元周围N个参考单元求均值,其结果便为噪声估计μ,检测门限U0=Kμ);
* OS: "the N (N = 2L) reference cells, L on each side of x_D, are sorted and
  the k-th smallest x_k is the noise estimate mu; U0 = K mu"
  (将参考单元中N(N=2L)个信号的值排序,取出其中第k个最小值xk,xk即为噪声估计值μ).

The third detector, the adaptive regression CFAR, fits a curve instead of
a window: :mod:`models.cfar_regression`.

The CA text says the register holds N = 2L + 1 cells and averages "the N
reference cells"; the register of 2L + 1 includes the cell under test, so
both detectors here use N = 2L reference cells, L per side, as the OS text
prints. The document prints no guard cells: ``guard`` cells per side
between the cell under test and its reference cells are our parameter
(guard = 0 is the printed structure).

**Windows and map edges.** Along an axis of M cells, the cell i has its
reference cells at i - g - L .. i - g - 1 and i + g + 1 .. i + g + L; those
outside the map are dropped (one-sided windows at the edges), so the cell's
N' = N_left + N_right <= 2L, and its closed form uses that N'. OS keeps its
quantile at the edges: k' = ceil(k N' / N) (:func:`edge_rank`).

**Nominal significance.** For square-law detected (exponential) noise of
any level, the false-alarm probability of "x > K mu" is (Rohling's closed
forms, as issue 13 quotes them)

    CA:  Pfa(K) = (1 + K/N)^(-N)
    OS:  Pfa(K) = prod_{i=0}^{k-1} (N - i) / (N - i + K),

and each method reports, per cell, S = -log10 Pfa(t) at the observed ratio
t = x / mu (:func:`ca_significance`, :func:`os_significance`): a monotone
transform of t, so "S > -log10(pfa)" is exactly "t > K(pfa)" and one
threshold serves every detector, window and dimension. S is capped at
:data:`MAX_SIGNIFICANCE` (Pfa = 1e-300, the smallest the calibration takes).

All kernels take a batch of maps with a leading trial axis; the per-axis
ones run along axis 1 of a (P, A, B) array (the Doppler axis on the
transposed maps), and :func:`window_cfar` runs CA or OS in one fused pass
per map (:func:`_window_cfar_fused`), bit-identical to its composed steps
(:func:`window_cfar_composed`, the readable oracle). The order-statistic
machinery is in :mod:`models.order_statistic`, the peak detection in
:mod:`models.cfar_peaks` (re-exported here). Single-threaded and free of
shared state (parallelism comes from the harness's worker processes; ``bench
perf`` measures one core).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.optimize

from models.cfar_peaks import _local_maxima_map, local_maxima, local_maxima_scipy, with_peaks  # noqa: F401
from models.order_statistic import (_os_kth_axis1, _os_kth_lines, _os_log_denominators, _os_log_survival,
                                    selection_networks)

#: the cap of the significance -log10 Pfa: Pfa = 1e-300, the smallest the calibration accepts
MAX_SIGNIFICANCE = 300.0
_LOG10 = math.log(10.0)


# ------------------------------------------------------------------ windows

def window_counts(M: int, L: int, g: int) -> tuple[np.ndarray, np.ndarray]:
    """(N_left, N_right) per cell of an axis of M cells: reference cells
    i - g - L .. i - g - 1 and i + g + 1 .. i + g + L inside 0 .. M - 1."""
    i = np.arange(M)
    left = np.clip(i - g, 0, L)
    right = np.clip(M - 1 - i - g, 0, L)
    return left, right


def reference_counts(M: int, L: int, g: int) -> np.ndarray:
    """N' per cell: the reference cells inside the map (:func:`window_counts`)."""
    left, right = window_counts(M, L, g)
    return left + right


def edge_rank(k: int, n_full: int, n_cells: np.ndarray | int) -> np.ndarray | int:
    """k' = ceil(k N' / N): the OS rank of a cell with N' of the N reference
    cells (the same quantile of its window; k' = k where the window is whole)."""
    return (k * n_cells + n_full - 1) // n_full


def axis_problem(M: int, L: int, g: int, axis_name: str) -> str | None:
    """Why a window of L reference and g guard cells per side cannot run on an
    axis of M cells (its middle cell would have no reference cell), or None."""
    if reference_counts(M, L, g).min() < 1:
        return (f"{axis_name}: {g} guard cells per side leave no reference cell for some of the "
                f"{M} cells (the axis needs at least {2 * g + 2} cells)")
    return None


# ------------------------------------------------------------------ closed forms

def ca_pfa(K, N):
    """CA-CFAR: Pfa = (1 + K/N)^(-N) for N exponential reference cells."""
    return (1.0 + np.asarray(K, dtype=float) / N) ** (-np.asarray(N, dtype=float))


def os_pfa(K, N: int, k: int):
    """OS-CFAR: Pfa = prod_{i=0}^{k-1} (N - i) / (N - i + K)."""
    K = np.asarray(K, dtype=float)
    i = np.arange(k).reshape((k,) + (1,) * K.ndim)
    return np.prod((N - i) / (N - i + K), axis=0)


def ca_threshold_factor(pfa: float, N: int) -> float:
    """K of CA-CFAR for ``pfa``: K = N (pfa^(-1/N) - 1), the inverse of :func:`ca_pfa`
    (by expm1, exact down to the smallest pfa; 0 for pfa >= 1)."""
    return float(N * math.expm1(-math.log(min(pfa, 1.0)) / N))


def os_threshold_factor(pfa: float, N: int, k: int) -> float:
    """K of OS-CFAR for ``pfa``: the root of sum_i log(1 + K/(N - i)) = -log(pfa)
    (:func:`os_pfa`), solved for log K between the bounds the smallest and the
    largest of the k terms give: (N - k + 1) expm1(-log(pfa)/k) <= K <= N expm1(-log(pfa))."""
    if pfa >= 1.0:                               # every cell passes: no threshold above the noise estimate
        return 0.0
    target = -math.log(pfa)
    terms = N - np.arange(k, dtype=float)

    def excess(log_K: float) -> float:
        return float(np.log1p(math.exp(log_K) / terms).sum()) - target

    lo = math.log((N - k + 1) * math.expm1(target / k))
    hi = math.log(N * math.expm1(target))
    if hi - lo < 1e-12:
        return float(math.exp(hi))
    return float(math.exp(scipy.optimize.brentq(excess, lo, hi, xtol=1e-13, rtol=1e-15, maxiter=500)))


@numba.njit(cache=True, inline="always")
def _ca_sig(t: float, N: int) -> float:
    """-log10 of (1 + t/N)^(-N)."""
    return N * math.log1p(t / N) / _LOG10


@numba.njit(cache=True, inline="always")
def _ratio(x: float, mu: float) -> float:
    """t = x / mu; an empty estimate (mu = 0) makes any power infinitely significant."""
    if mu > 0.0:
        return x / mu
    return math.inf if x > 0.0 else 0.0


@numba.njit(cache=True, inline="always")
def _capped(s: float) -> float:
    return s if s < MAX_SIGNIFICANCE else MAX_SIGNIFICANCE


def ca_significance(t, N):
    """S = -log10 Pfa_CA(t) = N log10(1 + t/N), capped (NumPy form, any shapes)."""
    N = np.asarray(N, dtype=float)
    return np.minimum(N * np.log1p(np.asarray(t, dtype=float) / N) / _LOG10, MAX_SIGNIFICANCE)


def os_significance(t, N, k):
    """S = -log10 Pfa_OS(t) = sum_{i<k} log10(1 + t/(N - i)), capped (NumPy
    form: N, k broadcast with t; the straightforward sum of k logs)."""
    t = np.asarray(t, dtype=float)
    N = np.broadcast_to(np.asarray(N, dtype=float), t.shape)
    k = np.broadcast_to(np.asarray(k), t.shape)
    total = np.zeros(t.shape)
    for i in range(int(k.max())):
        total += np.where(i < k, np.log1p(t / np.maximum(N - i, 1.0)), 0.0)
    return np.minimum(total / _LOG10, MAX_SIGNIFICANCE)


# ------------------------------------------------------------------ noise estimates

@numba.njit(cache=True)
def _ca_mean_lines(x, L, g, inv_count, c, mu):
    """CA-CFAR's mu along axis 0 of one map x (A, B) float32, the B cells of a
    row at once: running sums, O(1) per cell.

    The prefix sums c[j] = sum_{a<j} x[a] (float64, in ``c`` (A + 1, B)) give
    each window sum as two differences: right = c[min(i+g+L+1, A)] - c[min(i+g+1, A)],
    left = c[max(i-g, 0)] - c[max(i-g-L, 0)]; mu = (left + right) / N'
    (``inv_count`` = 1 / N' per cell of the axis).
    """
    A, B = x.shape
    for b in range(B):                           # element loops: a slice copy costs a call per row
        c[0, b] = 0.0
    for a in range(A):
        for b in range(B):
            c[a + 1, b] = c[a, b] + x[a, b]
    for i in range(A):
        hi, lo = min(i + g + L + 1, A), min(i + g + 1, A)
        lhi, llo = max(i - g, 0), max(i - g - L, 0)
        for b in range(B):
            mu[i, b] = (c[hi, b] - c[lo, b] + c[lhi, b] - c[llo, b]) * inv_count[i]


@numba.njit(cache=True)
def _ca_mean_axis1(x, L, g, inv_count, mu):
    """:func:`_ca_mean_lines` along axis 1 of every map of x (P, A, B) float32."""
    c = np.empty((x.shape[1] + 1, x.shape[2]))
    for p in range(x.shape[0]):
        _ca_mean_lines(x[p], L, g, inv_count, c, mu[p])


def window_noise(maps: np.ndarray, detector: str, L: int, g: int, k: int, axis: str) -> np.ndarray:
    """mu (n, R, D) float32 along ``axis`` ("range" or "doppler") of maps
    (n, R, D) float32: the mean of the N' reference cells (``detector``
    "ca") or their k'-th smallest ("os"). Both kernels run along axis 1
    with the other axis as vector lanes, so along Doppler they run on the
    transposed maps (a transpose costs less than a scalar pass along each line)."""
    lines = maps if axis == "range" else np.ascontiguousarray(maps.transpose(0, 2, 1))
    mu = np.empty_like(lines)
    if detector == "ca":
        _ca_mean_axis1(lines, L, g, 1.0 / reference_counts(lines.shape[1], L, g), mu)
    else:
        _os_kth_axis1(lines, L, g, k, *selection_networks(2 * L), mu)
    return mu if axis == "range" else np.ascontiguousarray(mu.transpose(0, 2, 1))


# ------------------------------------------------------------------ significance

@numba.njit(cache=True, inline="always")
def _window_sig(is_os, t, N, k, log_den):
    """-log10 Pfa(t) of OS (:func:`models.order_statistic._os_log_survival`) or CA."""
    return _os_log_survival(t, N, k, log_den) / _LOG10 if is_os else _ca_sig(t, N)


#: t_a < t_b (1 - ORDER_MARGIN) orders CA's significances at t_a and t_b with margin to spare
#: (:func:`_combined_sig`): log1p's error (an ulp, 1e-16) is far below the gap it opens
ORDER_MARGIN = 1e-9


@numba.njit(cache=True, inline="always")
def _clearly_below(a: float, b: float) -> bool:
    """0 <= a < b (1 - ORDER_MARGIN) (False for a NaN)."""
    return 0.0 <= a < b * (1.0 - ORDER_MARGIN)


@numba.njit(cache=True, inline="always")
def _combined_sig(is_os, t_r, n_r, k_r, t_d, n_d, k_d, both, log_den):
    """min (``both``) or max of the range and Doppler significances at ratios
    t_r, t_d. CA at equal N' (every cell away from the edges when the windows
    match): S = N' log10(1 + t/N') rises with t, so the smaller (larger) S is
    the one at the smaller (larger) t, and only that one is computed when the
    ratios differ by more than ORDER_MARGIN (far beyond the rounding of the
    log, so the value is the one both would give, bit for bit); otherwise both."""
    lo = t_r if t_r < t_d else t_d               # selects, not branches: the order is a coin toss
    hi = t_d if t_r < t_d else t_r
    if not is_os and n_r == n_d and _clearly_below(lo, hi):
        return _ca_sig(lo if both else hi, n_r)
    s_r = _window_sig(is_os, t_r, n_r, k_r, log_den)
    s_d = _window_sig(is_os, t_d, n_d, k_d, log_den)
    return min(s_r, s_d) if both else max(s_r, s_d)


@numba.njit(cache=True)
def _map_significance(x, keep, mu_r, n_r, k_r, mu_d, n_d, k_d, use_r, use_d, both, is_os, log_den, out):
    """out = the capped significance of the active dimensions combined ("both":
    the smaller, else the larger), at the cells of one map x (R, D) where
    ``keep``; 0 elsewhere (so the logs are paid only at the local maxima of
    the peak detection). Per row: the kept cells' indices, their ratios
    t = x / mu, then the logs in a loop of their own."""
    R, D = x.shape
    kept = np.empty(D, dtype=np.int64)
    t_r = np.zeros(D)
    t_d = np.zeros(D)
    for r in range(R):
        n_kept = 0
        for d in range(D):                       # zeros, and the kept cells' indices, branch-free
            out[r, d] = 0.0
        for d in range(D):
            kept[n_kept] = d
            n_kept += keep[r, d]
        for j in range(n_kept):
            d = kept[j]
            if use_r:
                t_r[j] = _ratio(x[r, d], mu_r[r, d])
            if use_d:
                t_d[j] = _ratio(x[r, d], mu_d[r, d])
        for j in range(n_kept):
            d = kept[j]
            if use_r and use_d:
                s = _combined_sig(is_os, t_r[j], n_r[r], k_r[r], t_d[j], n_d[d], k_d[d], both, log_den)
            elif use_r:
                s = _window_sig(is_os, t_r[j], n_r[r], k_r[r], log_den)
            else:
                s = _window_sig(is_os, t_d[j], n_d[d], k_d[d], log_den)
            out[r, d] = _capped(s)


@numba.njit(cache=True)
def _window_significance(x, keep, mu_r, n_r, k_r, mu_d, n_d, k_d, use_r, use_d, both, is_os, log_den, out):
    """:func:`_map_significance` on every map of x (P, R, D)."""
    for p in range(x.shape[0]):
        _map_significance(x[p], keep[p], mu_r[p], n_r, k_r, mu_d[p], n_d, k_d, use_r, use_d, both, is_os,
                          log_den, out[p])


def _axis_windows(detector: str, windows: dict, sizes: dict) -> tuple[dict, dict, np.ndarray]:
    """({axis: N' per cell}, {axis: k' per cell (CA: N')}, the log-denominator
    table of :func:`models.order_statistic._os_log_survival`) of the windows
    ``{axis: (L, g, k)}`` on axes of ``sizes`` ``{axis: M}`` cells."""
    counts, ranks, full = {}, {}, 1
    for axis, (L, g, k) in windows.items():
        counts[axis] = reference_counts(sizes[axis], L, g).astype(np.int64)
        ranks[axis] = (edge_rank(k, 2 * L, counts[axis]) if detector == "os" else counts[axis]).astype(np.int64)
        full = max(full, 2 * L)
    return counts, ranks, _os_log_denominators(full)


#: the per-cell array of an axis no active dimension uses (never read)
_UNUSED = np.zeros(1, dtype=np.int64)


def window_significance(maps: np.ndarray, detector: str, windows: dict, mus: dict, dimension: str,
                        keep: np.ndarray | None = None) -> np.ndarray:
    """S (n, R, D) float32 of CA or OS (``detector``) for the active
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
                         "range" in mus, "doppler" in mus, dimension == "both", detector == "os", log_den, out)
    return out


def ca_cfar(maps: np.ndarray, L: int, g: int, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """CA-CFAR along ``axis`` of maps (n, R, D): (mu, S) both (n, R, D)
    float32, mu the mean of the N' reference cells, S the capped significance
    -log10 Pfa_CA(x / mu; N') of every cell."""
    maps = np.ascontiguousarray(maps, dtype=np.float32)
    mu = window_noise(maps, "ca", L, g, 0, axis)
    return mu, window_significance(maps, "ca", {axis: (L, g, 0)}, {axis: mu}, axis)


def os_cfar(maps: np.ndarray, L: int, g: int, k: int, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """OS-CFAR along ``axis`` of maps (n, R, D): (mu, S) (n, R, D) float32, mu
    the k'-th smallest reference cell, S = -log10 Pfa_OS(x / mu; N', k')."""
    maps = np.ascontiguousarray(maps, dtype=np.float32)
    mu = window_noise(maps, "os", L, g, k, axis)
    return mu, window_significance(maps, "os", {axis: (L, g, k)}, {axis: mu}, axis)


# ------------------------------------------------------------------ window CFAR, fused

@numba.njit(cache=True, inline="always")
def _noise_lines(is_os, x, window, c, buf, mu):
    """mu along axis 0 of one map x (A, B): :func:`_ca_mean_lines` or
    :func:`models.order_statistic._os_kth_lines`, ``window`` = (L, g, k, 1/N'
    per cell, the selection networks of N = 2L)."""
    L, g, k, inv_count, comps, n_comps, of_k, wires = window
    if is_os:
        _os_kth_lines(x, L, g, k, comps, n_comps, of_k, wires, buf, mu)
    else:
        _ca_mean_lines(x, L, g, inv_count, c, mu)


@numba.njit(cache=True)
def _transpose_into(src, dst):
    """dst (B, A) = src (A, B).T: contiguous reads, strided writes (a map's
    columns of dst stay in cache; measured faster than tiles at these sizes)."""
    A, B = src.shape
    for a in range(A):
        for b in range(B):
            dst[b, a] = src[a, b]


@numba.njit(cache=True)
def _window_cfar_fused(x, is_os, use_r, use_d, both, window_r, window_d, n_r, k_r, n_d, k_d, log_den,
                       half_range, half_doppler, statistic, noise):
    """:func:`window_cfar_composed` in one pass per map x[p] (R, D), its
    scratch (a few maps' worth) reused from map to map while it sits in cache:
    the range noise estimate along axis 0 of the map, the Doppler one along
    axis 0 of its transpose (vector lanes either way), the local maxima, the
    significance at the kept cells only, and the noise estimates combined
    ("both": the larger, "either": the smaller); the same kernels on the same
    values as the composition, so the result is bit-identical."""
    P, R, D = x.shape
    mu_r = np.empty((R, D), dtype=np.float32)
    x_t = np.empty((D, R), dtype=np.float32)
    mu_t = np.empty((D, R), dtype=np.float32)
    mu_d = mu_t.T                                # read in place: a transposing copy back would thrash the cache
    c_r = np.empty((R + 1, D))
    c_d = np.empty((D + 1, R))
    buf_r = np.empty((window_r[7], D), dtype=np.float32)
    buf_d = np.empty((window_d[7], R), dtype=np.float32)
    keep = np.ones((R, D), dtype=np.bool_)
    row_max = np.empty((R, D), dtype=np.float32)
    box_max = np.empty(D, dtype=np.float32)
    peaks = half_range > 0 or half_doppler > 0
    for p in range(P):
        if use_r:
            _noise_lines(is_os, x[p], window_r, c_r, buf_r, mu_r)
        if use_d:
            _transpose_into(x[p], x_t)
            _noise_lines(is_os, x_t, window_d, c_d, buf_d, mu_t)
        if peaks:
            _local_maxima_map(x[p], half_range, half_doppler, row_max, box_max, keep)
        _map_significance(x[p], keep, mu_r, n_r, k_r, mu_d, n_d, k_d, use_r, use_d, both, is_os, log_den,
                          statistic[p])
        if use_r and use_d:
            for r in range(R):                   # np.maximum / np.minimum, cell by cell along the row
                for d in range(D):
                    noise[p, r, d] = np.maximum(mu_r[r, d], mu_d[r, d]) if both else np.minimum(mu_r[r, d],
                                                                                                mu_d[r, d])
        else:
            noise[p] = mu_r if use_r else mu_d


def _fused_window(detector: str, window: tuple[int, int, int] | None, M: int) -> tuple:
    """The ``window`` argument of :func:`_noise_lines` for an axis of M cells
    (a placeholder of the same types where the axis is not active)."""
    L, g, k = window or (1, 0, 1)
    inv_count = 1.0 / reference_counts(M, L, g)
    comps, n_comps, of_k, wires = selection_networks(2 * L) if detector == "os" and window else selection_networks(1)
    return L, g, k, inv_count, comps, n_comps, of_k, wires


def window_cfar(maps: np.ndarray, detector: str, windows: dict, dimension: str, half_range: int,
                half_doppler: int) -> tuple[np.ndarray, np.ndarray]:
    """(statistic, noise estimate) (n, R, D) float32 of CA or OS over the
    active dimensions ``windows`` ``{axis: (L, g, k)}``, combined
    (``dimension``, :func:`combine`), with the peak detection folded in; the
    significance computed at the local maxima only. One pass per map
    (:func:`_window_cfar_fused`), bit-identical to :func:`window_cfar_composed`."""
    maps = np.ascontiguousarray(maps, dtype=np.float32)
    n, R, D = maps.shape
    counts, ranks, log_den = _axis_windows(detector, windows, {"range": R, "doppler": D})
    statistic = np.empty(maps.shape, dtype=np.float32)
    noise = np.empty(maps.shape, dtype=np.float32)
    _window_cfar_fused(maps, detector == "os", "range" in windows, "doppler" in windows, dimension == "both",
                       _fused_window(detector, windows.get("range"), R),
                       _fused_window(detector, windows.get("doppler"), D),
                       counts.get("range", _UNUSED), ranks.get("range", _UNUSED),
                       counts.get("doppler", _UNUSED), ranks.get("doppler", _UNUSED), log_den,
                       half_range, half_doppler, statistic, noise)
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


# ------------------------------------------------------------------ threshold factors along an axis

def ca_factor_along(pfa: float, M: int, L: int, g: int) -> np.ndarray:
    """(M,) K of CA-CFAR per cell of an axis at its own N' (:func:`reference_counts`)."""
    N = reference_counts(M, L, g).astype(float)
    return N * np.expm1(-math.log(min(pfa, 1.0)) / N)


def os_factor_along(pfa: float, M: int, L: int, g: int, k: int) -> np.ndarray:
    """(M,) K of OS-CFAR per cell of an axis at its own (N', k')."""
    N = reference_counts(M, L, g)
    ks = edge_rank(k, 2 * L, N)
    factors = {pair: os_threshold_factor(pfa, *pair) for pair in set(zip(N.tolist(), ks.tolist()))}
    return np.array([factors[pair] for pair in zip(N.tolist(), ks.tolist())])


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
