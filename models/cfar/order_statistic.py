r"""The order-statistic machinery of OS-CFAR (:mod:`models.cfar`; docs/architecture.md,
'Models'): selection networks that leave the $k$-th smallest of the $N = 2L$
reference cells on one wire, the numba kernel that runs them over the lines
of a batch of maps, and the closed-form log survival it is judged by.

OS-CFAR after the HFSWR detection chain (hfswr-cfar-mn-jpda-ukf in the
shared papers, sec. 1 "CFAR检测"): "the $N$ ($N = 2L$) reference cells, $L$ on
each side of $x_D$, are sorted and the $k$-th smallest $x_k$ is the noise
estimate $\mu$" (将参考单元中N(N=2L)个信号的值排序,取出其中第k个最小值xk,xk即为噪声估计值μ).
No sort is needed for one order statistic: a selection network (Batcher's
odd-even merge sort pruned to the comparators the $k$-th wire depends on)
finds it branch-free, as element-wise min/max across the cells of a row.
Under exponential noise its false-alarm probability is
$P_{fa}(t) = \prod_{i<k} (N - i)/(N - i + t)$ (the closed form), whose
negative natural log :func:`_os_log_survival` computes per cell.
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np

#: networks on at most this many wires are pruned per k (beyond, one full sorting network serves every k)
PRUNED_WIRES = 64


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
def _os_kth_lines(x, L, g, k, comps, n_comps, of_k, wires, buf, mu):
    """OS-CFAR's mu along axis 0 of one map x (A, B) float32, the B cells of a
    row at once: for the cells i of a row, their reference rows (the +-L cells
    beyond the guards, those inside the map) are copied into ``buf`` (wires, B)
    padded with +inf, and a selection network (:func:`selection_networks`) of
    element-wise min/max across the B lanes leaves the k'-th smallest,
    k' = ceil(k N' / 2L), on wire k' - 1: branch-free and vectorised,
    O(N log^2 N) comparisons per cell."""
    A, B = x.shape
    N = 2 * L
    for i in range(A):
        n_ref = 0
        for a in range(max(i - g - L, 0), max(i - g, 0)):
            for b in range(B):                   # element loops: a slice copy costs a call per row
                buf[n_ref, b] = x[a, b]
            n_ref += 1
        for a in range(min(i + g + 1, A), min(i + g + L + 1, A)):
            for b in range(B):
                buf[n_ref, b] = x[a, b]
            n_ref += 1
        for w in range(n_ref, wires):
            for b in range(B):
                buf[w, b] = np.inf
        kk = (k * n_ref + N - 1) // N
        net = of_k[kk]
        for c in range(n_comps[net]):
            u, v = comps[net, c, 0], comps[net, c, 1]
            for b in range(B):
                lo = min(buf[u, b], buf[v, b])
                buf[v, b] = max(buf[u, b], buf[v, b])
                buf[u, b] = lo
        for b in range(B):
            mu[i, b] = buf[kk - 1, b]


@numba.njit(cache=True)
def _os_kth_axis1(x, L, g, k, comps, n_comps, of_k, wires, mu):
    """:func:`_os_kth_lines` along axis 1 of every map of x (P, A, B) float32."""
    buf = np.empty((wires, x.shape[2]), dtype=np.float32)
    for p in range(x.shape[0]):
        _os_kth_lines(x[p], L, g, k, comps, n_comps, of_k, wires, buf, mu[p])


@numba.njit(cache=True, inline="always")
def _os_log_survival(t: float, N: int, k: int, log_den) -> float:
    """-ln of prod_{i<k} (N - i)/(N - i + t) = sum_i log(N - i + t) - sum_i log(N - i):
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
    return total + math.log(prod) - log_den[N, k]


@numba.njit(cache=True)
def _os_log_denominators(N: int):
    """log_den[n, k] = sum_{i<k} log(n - i) for 0 <= k <= n <= N."""
    log_den = np.zeros((N + 1, N + 1))
    for n in range(1, N + 1):
        for k in range(1, n + 1):
            log_den[n, k] = log_den[n, k - 1] + math.log(n - k + 1)
    return log_den
