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

All kernels take a batch of maps with a leading trial axis and run along
axis 1 of a (P, A, B) array: the range axis of (n, R, D) maps directly, the
Doppler axis as (n R, D, 1). Single-threaded and free of shared state
(parallelism comes from the harness's worker processes).
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
import scipy.ndimage
import scipy.optimize

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
def _os_sig(t: float, N: int, k: int, log_den) -> float:
    """-log10 of prod_{i<k} (N - i)/(N - i + t) = [sum_i log(N - i + t) - sum_i log(N - i)] / ln 10:
    the numerator as a running product (folded into a log whenever it grows
    large: one log per cell in practice), the denominator from the table
    ``log_den[N, k]`` (:func:`_os_log_denominators`); no division in the loop."""
    total = 0.0
    prod = 1.0
    for i in range(k):
        prod *= N - i + t
        if prod > 1e200:
            total += math.log(prod)
            prod = 1.0
    return (total + math.log(prod) - log_den[N, k]) / _LOG10


@numba.njit(cache=True)
def _os_log_denominators(N: int):
    """log_den[n, k] = sum_{i<k} log(n - i) for 0 <= k <= n <= N."""
    log_den = np.zeros((N + 1, N + 1))
    for n in range(1, N + 1):
        for k in range(1, n + 1):
            log_den[n, k] = log_den[n, k - 1] + math.log(n - k + 1)
    return log_den


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
def _ca_mean_axis1(x, L, g, inv_count, mu):
    """CA-CFAR's mu along axis 1 of x (P, A, B) float32, the B cells of a row
    at once: running sums, O(1) per cell.

    The prefix sums c[j] = sum_{a<j} x[a] (float64) give each window sum as
    two differences: right = c[min(i+g+L+1, A)] - c[min(i+g+1, A)],
    left = c[max(i-g, 0)] - c[max(i-g-L, 0)]; mu = (left + right) / N'
    (``inv_count`` = 1 / N' per cell of the axis).
    """
    P, A, B = x.shape
    c = np.empty((A + 1, B))
    for p in range(P):
        c[0, :] = 0.0
        for a in range(A):
            for b in range(B):
                c[a + 1, b] = c[a, b] + x[p, a, b]
        for i in range(A):
            hi, lo = min(i + g + L + 1, A), min(i + g + 1, A)
            lhi, llo = max(i - g, 0), max(i - g - L, 0)
            for b in range(B):
                mu[p, i, b] = (c[hi, b] - c[lo, b] + c[lhi, b] - c[llo, b]) * inv_count[i]


def _batcher_network(n: int) -> list[tuple[int, int]]:
    """Batcher's odd-even merge sorting network on n = 2^m wires: the
    comparators (i, j), i < j, in order; after them wire w holds the w-th
    smallest value."""
    def merge(lo: int, hi: int, r: int):
        step = 2 * r
        if step < hi - lo:
            yield from merge(lo, hi, step)
            yield from merge(lo + r, hi, step)
            yield from ((i, i + r) for i in range(lo + r, hi - r, step))
        else:
            yield (lo, lo + r)

    def sort(lo: int, hi: int):
        if hi - lo >= 1:
            mid = lo + (hi - lo) // 2
            yield from sort(lo, mid)
            yield from sort(mid + 1, hi)
            yield from merge(lo, hi, 1)

    return list(sort(0, n - 1))


#: networks on at most this many wires are pruned per k (beyond, one full sorting network serves every k)
PRUNED_WIRES = 64


@functools.lru_cache(maxsize=16)
def selection_networks(N: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Comparator lists that put the k-th smallest of N values on wire k - 1:
    Batcher's network on the next power of two (the spare wires hold +inf),
    pruned for each k = 1..N to the comparators wire k - 1 depends on (up to
    PRUNED_WIRES wires; beyond, the whole network for every k). Returns
    (comparators (lists, C, 2) int64, counts (lists,), list of each k (N + 1,), wires)."""
    wires = 1 << max(0, (N - 1).bit_length())
    network = _batcher_network(wires) if wires > 1 else []
    if wires > PRUNED_WIRES:
        lists, of_k = [network], np.zeros(N + 1, dtype=np.int64)
    else:
        lists, of_k = [], np.arange(N + 1, dtype=np.int64)
        for k in range(N + 1):
            needed, kept = {k - 1}, []
            for i, j in reversed(network):
                if i in needed or j in needed:
                    kept.append((i, j))
                    needed |= {i, j}
            lists.append(kept[::-1] if k >= 1 else [])
    comps = np.zeros((len(lists), max(1, max(len(c) for c in lists)), 2), dtype=np.int64)
    for index, kept in enumerate(lists):
        if kept:
            comps[index, :len(kept)] = kept
    return comps, np.array([len(c) for c in lists], dtype=np.int64), of_k, wires


@numba.njit(cache=True)
def _os_kth_axis1(x, L, g, k, comps, n_comps, of_k, wires, mu):
    """OS-CFAR's mu along axis 1 of x (P, A, B) float32, B cells at once: for
    the cells i of a row, their reference rows (the +-L cells beyond the
    guards, those inside the map) are copied into a (wires, B) buffer padded
    with +inf, and a selection network (:func:`selection_networks`) of
    element-wise min/max across the B lanes leaves the k'-th smallest,
    k' = ceil(k N' / 2L), on wire k' - 1: branch-free and vectorised, O(N log^2 N)
    comparisons per cell."""
    P, A, B = x.shape
    N = 2 * L
    buf = np.empty((wires, B), dtype=np.float32)
    for p in range(P):
        for i in range(A):
            n_ref = 0
            for a in range(max(i - g - L, 0), max(i - g, 0)):
                buf[n_ref, :] = x[p, a, :]
                n_ref += 1
            for a in range(min(i + g + 1, A), min(i + g + L + 1, A)):
                buf[n_ref, :] = x[p, a, :]
                n_ref += 1
            for w in range(n_ref, wires):
                buf[w, :] = np.inf
            kk = (k * n_ref + N - 1) // N
            net = of_k[kk]
            for c in range(n_comps[net]):
                u, v = comps[net, c, 0], comps[net, c, 1]
                for b in range(B):
                    lo = min(buf[u, b], buf[v, b])
                    buf[v, b] = max(buf[u, b], buf[v, b])
                    buf[u, b] = lo
            mu[p, i, :] = buf[kk - 1, :]


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
    return _os_sig(t, N, k, log_den) if is_os else _ca_sig(t, N)


@numba.njit(cache=True)
def _window_significance(x, keep, mu_r, n_r, k_r, mu_d, n_d, k_d, use_r, use_d, both, is_os, log_den, out):
    """out = the capped significance of the active dimensions combined ("both":
    the smaller, else the larger), at the cells where ``keep``; 0 elsewhere
    (so the logs are paid only at the local maxima of the peak detection)."""
    P, R, D = x.shape
    for p in range(P):
        for r in range(R):
            for d in range(D):
                if not keep[p, r, d]:
                    out[p, r, d] = 0.0
                    continue
                v = x[p, r, d]
                s_r = _window_sig(is_os, _ratio(v, mu_r[p, r, d]), n_r[r], k_r[r], log_den) if use_r else 0.0
                s_d = _window_sig(is_os, _ratio(v, mu_d[p, r, d]), n_d[d], k_d[d], log_den) if use_d else 0.0
                if use_r and use_d:
                    s = min(s_r, s_d) if both else max(s_r, s_d)
                else:
                    s = s_r if use_r else s_d
                out[p, r, d] = _capped(s)


def window_significance(maps: np.ndarray, detector: str, windows: dict, mus: dict, dimension: str,
                        keep: np.ndarray | None = None) -> np.ndarray:
    """S (n, R, D) float32 of CA or OS (``detector``) for the active
    dimensions combined (``dimension``), from their noise estimates ``mus``
    ``{axis: mu}`` and windows ``{axis: (L, g, k)}``, at each cell's own N'
    and k'; 0 where ``keep`` is False (None: every cell)."""
    n, R, D = maps.shape
    sizes = {"range": R, "doppler": D}
    counts, ranks, full = {}, {}, 1
    for axis, (L, g, k) in windows.items():
        counts[axis] = reference_counts(sizes[axis], L, g).astype(np.int64)
        ranks[axis] = (edge_rank(k, 2 * L, counts[axis]) if detector == "os" else counts[axis]).astype(np.int64)
        full = max(full, 2 * L)
    some = next(iter(mus.values()))
    dummy = np.zeros(1, dtype=np.int64)
    out = np.empty(maps.shape, dtype=np.float32)
    _window_significance(maps, np.ones(maps.shape, np.bool_) if keep is None else keep,
                         mus.get("range", some), counts.get("range", dummy), ranks.get("range", dummy),
                         mus.get("doppler", some), counts.get("doppler", dummy), ranks.get("doppler", dummy),
                         "range" in mus, "doppler" in mus, dimension == "both", detector == "os",
                         _os_log_denominators(full), out)
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


def window_cfar(maps: np.ndarray, detector: str, windows: dict, dimension: str, half_range: int,
                half_doppler: int) -> tuple[np.ndarray, np.ndarray]:
    """(statistic, noise estimate) (n, R, D) float32 of CA or OS over the
    active dimensions ``windows`` ``{axis: (L, g, k)}``, combined
    (``dimension``, :func:`combine`), with the peak detection folded in; the
    significance computed at the local maxima only."""
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


def with_peaks(maps: np.ndarray, sig: np.ndarray, half_range: int, half_doppler: int,
               peaks=None) -> np.ndarray:
    """The statistic (n, R, D) float32: the significance where the cell is a
    local maximum of the power (``peaks``, default :func:`local_maxima`), 0 elsewhere."""
    keep = (peaks or local_maxima)(maps, half_range, half_doppler)
    return np.where(keep, sig, np.float32(0.0)).astype(np.float32, copy=False)


def fold(maps: np.ndarray, per_axis: dict, dimension: str, half_range: int,
         half_doppler: int, peaks=None) -> tuple[np.ndarray, np.ndarray]:
    """(statistic, noise estimate) (n, R, D) float32 of a CFAR method: its
    dimensions combined (:func:`combine`), then the peak detection folded in."""
    sig, mu = combine(per_axis, dimension)
    return with_peaks(maps, sig, half_range, half_doppler, peaks), np.asarray(mu, dtype=np.float32)


@numba.njit(cache=True)
def _local_maxima(x, half_range, half_doppler, keep):
    """keep[p, r, d] = x[p, r, d] >= the box maximum: separable, first along
    Doppler (per row), then along range over the row maxima, each as a running
    maximum over the box's offsets, vectorised along the row; the box cut at
    the map's edges."""
    P, R, D = x.shape
    row_max = np.empty((R, D), dtype=x.dtype)
    box_max = np.empty(D, dtype=x.dtype)
    for p in range(P):
        for r in range(R):
            row_max[r, :] = x[p, r, :]
            for e in range(1, half_doppler + 1):
                for d in range(D - e):
                    row_max[r, d] = max(row_max[r, d], x[p, r, d + e])
                for d in range(e, D):
                    row_max[r, d] = max(row_max[r, d], x[p, r, d - e])
        for r in range(R):
            box_max[:] = row_max[r, :]
            for q in range(max(r - half_range, 0), min(r + half_range + 1, R)):
                for d in range(D):
                    box_max[d] = max(box_max[d], row_max[q, d])
            for d in range(D):
                keep[p, r, d] = x[p, r, d] >= box_max[d]


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
