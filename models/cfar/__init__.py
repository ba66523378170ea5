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
a window: :mod:`models.cfar.regression`.

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

GO and SO (the larger or smaller of the two half-windows' means, our
baselines beside the chapter's detectors) share CA's windows and running
sums; their maths is in :mod:`models.cfar.halves`.

All kernels take a batch of maps with a leading trial axis; the per-axis
ones run along axis 1 of a (P, A, B) array (the Doppler axis on the
transposed maps), and :func:`window_cfar` runs a detector in one fused pass
per map (CA, GO, SO streamed row by row, :func:`_sum_cfar_rows`; OS,
:func:`_os_cfar_fused`), bit-identical to its composed steps
(:func:`window_cfar_composed`, the readable oracle). The order-statistic
machinery is in :mod:`models.cfar.order_statistic`, the peak detection in
:mod:`models.cfar.peaks` (re-exported here). Single-threaded and free of
shared state (parallelism comes from the harness's worker processes; ``bench
perf`` measures one core).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.optimize

from radarbench.models.cfar.peaks import _local_maxima_row, local_maxima, local_maxima_scipy, with_peaks  # noqa: F401
from radarbench.models.cfar.halves import HALVES, halves_log_survival, halves_mu, inverse_counts
from radarbench.models.cfar.order_statistic import (_os_kth_axis1, _os_kth_lines, _os_log_denominators, _os_log_survival,
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
