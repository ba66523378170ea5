r"""CFAR reference windows along an axis, their one-sided edges, and the closed forms of
CA and OS: false-alarm probability, threshold factor, the nominal significance $S = -\log_{10} P_{fa}$
(:mod:`models.cfar`, whose docstring states the maths; docs/architecture.md, 'Models')."""

from __future__ import annotations

import math

import numba
import numpy as np
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
