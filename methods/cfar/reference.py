"""The straightforward implementations of the CFAR methods (:mod:`methods.cfar.detectors`),
which ``bench perf`` times them against and the tests use as oracles
(docs/architecture.md, 'Performance').

Same windows, edges, closed forms and peak detection as :mod:`models.cfar`,
by SciPy filters over the whole batch. CA, GO and SO take their window sums from
SciPy's running sums (``scipy.ndimage.uniform_filter1d``, O(1) per cell, zeros
beyond the map, so edges are one-sided exactly as in the kernel): CA's window is
the block of 2(g + L) + 1 cells centred on the cell less the 2g + 1 guard block,
a GO/SO half the g + L + 1 cells ending (leading) or starting (lagging) at the
cell less the g + 1 nearest; the in-map counts are
:func:`models.cfar.window_counts`; GO and SO's closed forms by
``scipy.special.betainc``. OS by ``scipy.ndimage.rank_filter`` with the window's
footprint (ones on the reference cells, zeros on the guard cells and the cell
under test) where the window is whole and ``np.partition`` of the gathered
window at the edges (where k' = ceil(k N'/N) changes). The regression by a
per-line ``numpy.linalg.lstsq`` loop with its explicit hat matrix: the tests'
oracle only (``regression-cfar``'s fit is itself vectorised NumPy, so ``bench
perf`` has no plain peer to time it against).
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage

from radarbench.bench.tasks.cells import CellDetectionOutput
from radarbench.models import cfar
from radarbench.models.cfar import halves as cfar_halves
from radarbench.models.cfar import regression as cfar_regression

AXIS = {"range": 1, "doppler": 2}


def footprint(L: int, g: int) -> np.ndarray:
    """(2(g + L) + 1,) weights: 1 on the reference cells, 0 on the guard cells and the cell under test."""
    w = np.ones(2 * (g + L) + 1)
    w[L:L + 2 * g + 1] = 0.0
    return w


def _axes(dimension: str) -> tuple[str, ...]:
    return (dimension,) if dimension in ("range", "doppler") else ("range", "doppler")


def _along(values: np.ndarray, axis: str) -> np.ndarray:
    """(M,) per-position values broadcast along ``axis`` of (n, R, D) maps."""
    return values.reshape((1, -1, 1) if axis == "range" else (1, 1, -1))


def _finish(maps, per_axis, params) -> CellDetectionOutput:
    return CellDetectionOutput(*cfar.fold(maps, per_axis, params.dimension, params.peak_range, params.peak_doppler,
                                          peaks=cfar.local_maxima_scipy))


#: where a block of cells lies against the cell it is summed for, and the origin
#: ``scipy.ndimage.uniform_filter1d`` takes for it (a block of ``size`` cells)
ALIGNMENTS = {"centre": lambda size: 0, "end": lambda size: (size - 1) // 2, "start": lambda size: -(size // 2)}


def block_sums(maps: np.ndarray, axis: str, size: int, align: str) -> np.ndarray:
    """Per cell, in float64, the sum of the ``size`` cells along ``axis`` centred on it (``size``
    odd), ending at it or starting at it (:data:`ALIGNMENTS`), zero beyond the map: SciPy's
    running mean times ``size``."""
    mean = scipy.ndimage.uniform_filter1d(maps, size, axis=AXIS[axis], output=np.float64, mode="constant",
                                          cval=0.0, origin=ALIGNMENTS[align](size))
    return mean * size


def ca_axis(maps: np.ndarray, L: int, g: int, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """(mu, S) of CA-CFAR along ``axis``: the window's sum by running sums, the whole block
    less the guard block (module docstring)."""
    sums = block_sums(maps, axis, 2 * (g + L) + 1, "centre") - block_sums(maps, axis, 2 * g + 1, "centre")
    counts = _along(cfar.reference_counts(maps.shape[AXIS[axis]], L, g).astype(np.float64), axis)
    mu = sums / counts
    return mu, cfar.ca_significance(maps / mu, counts)


def os_axis(maps: np.ndarray, L: int, g: int, k: int, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """(mu, S) of OS-CFAR along ``axis``: rank filter inside, partition at the edges."""
    ax = AXIS[axis]
    M = maps.shape[ax]
    shape = [1, 1, 1]
    shape[ax] = 2 * (g + L) + 1
    fp = footprint(L, g).astype(bool).reshape(shape)
    mu = scipy.ndimage.rank_filter(maps, k - 1, footprint=fp, mode="constant", cval=np.inf).astype(np.float64)
    n_ref = cfar.reference_counts(M, L, g)
    ranks = cfar.edge_rank(k, 2 * L, n_ref)
    for i in np.flatnonzero(n_ref < 2 * L):                      # edge cells: their own window and rank
        idx = [a for a in range(i - g - L, i - g) if a >= 0] + [a for a in range(i + g + 1, i + g + L + 1) if a < M]
        window = np.take(maps, idx, axis=ax)
        kth = np.partition(window, ranks[i] - 1, axis=ax).take(ranks[i] - 1, axis=ax)
        if ax == 1:
            mu[:, i, :] = kth
        else:
            mu[:, :, i] = kth
    return mu, cfar.os_significance(maps / mu, _along(n_ref, axis), _along(ranks, axis))


def halves_axis(maps: np.ndarray, L: int, g: int, axis: str, detector: str) -> tuple[np.ndarray, np.ndarray]:
    """(mu, S) of GO- or SO-CFAR along ``axis``: each half's sum by running sums (module
    docstring) over its in-map count, the larger/smaller mean (an empty half: the
    other's), the closed form by ``scipy.special.betainc`` (:func:`models.cfar.halves.halves_pfa`)."""
    means, counts = [], []
    for side, n in zip(("end", "start"), cfar.window_counts(maps.shape[AXIS[axis]], L, g)):   # leading, lagging
        sums = block_sums(maps, axis, g + L + 1, side) - block_sums(maps, axis, g + 1, side)
        n = _along(n.astype(np.float64), axis)
        means.append(np.where(n > 0, sums / np.maximum(n, 1.0), np.nan))
        counts.append(n)
    pick = np.fmax if detector == "go" else np.fmin                # NaN (an empty half): the other
    mu = pick(*means)
    pfa = cfar_halves.halves_pfa(maps / mu, *counts, greatest=detector == "go")
    with np.errstate(divide="ignore"):
        return mu, np.minimum(-np.log10(pfa), cfar.MAX_SIGNIFICANCE)


def regression_axis(maps: np.ndarray, params, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """(noise level, S) of the regression CFAR along ``axis``, one line at a time by lstsq."""
    curve = cfar_regression.Curve(params.family, params.order, params.iterations, params.exclusion_factor)
    lines = maps.astype(np.float64) if axis == "doppler" else maps.astype(np.float64).transpose(0, 2, 1)
    flat = lines.reshape(-1, lines.shape[-1])
    M, Q = flat.shape[1], params.order + 1
    phi = cfar_regression.legendre_basis(M, params.order)
    level = np.empty_like(flat)
    leverage = np.empty_like(flat)
    included = np.ones(flat.shape, dtype=bool)
    for p, x in enumerate(flat):
        y = cfar_regression.fitted_variable(x, curve)
        use = np.ones(M, dtype=bool)
        for it in range(params.iterations + 1):
            m = cfar_regression.noise_moments(curve, censored=it > 0)[0]
            fitted = phi @ np.linalg.lstsq(phi[use], y[use], rcond=None)[0]
            level[p] = cfar_regression.noise_level(fitted, curve, m)
            if it == params.iterations:
                break
            keep = x <= params.exclusion_factor * level[p]
            if keep.sum() >= 2 * Q:
                use = keep
        included[p] = use
        leverage[p] = np.einsum("mq,qr,mr->m", phi, np.linalg.inv(phi[use].T @ phi[use]), phi)
    sig = cfar_regression.significance(flat, level, included, leverage, curve)
    level, sig = level.reshape(lines.shape), sig.reshape(lines.shape)
    if axis == "range":
        level, sig = level.transpose(0, 2, 1), sig.transpose(0, 2, 1)
    return level, sig


def ca(maps: np.ndarray, params):
    return _finish(maps, {axis: ca_axis(maps, getattr(params, f"reference_{axis}"), getattr(params, f"guard_{axis}"),
                                        axis) for axis in _axes(params.dimension)}, params)


def os(maps: np.ndarray, params):
    return _finish(maps, {axis: os_axis(maps, getattr(params, f"reference_{axis}"), getattr(params, f"guard_{axis}"),
                                        getattr(params, f"k_{axis}"), axis) for axis in _axes(params.dimension)},
                   params)


def halves(maps: np.ndarray, params, detector: str):
    return _finish(maps, {axis: halves_axis(maps, getattr(params, f"reference_{axis}"),
                                            getattr(params, f"guard_{axis}"), axis, detector)
                          for axis in _axes(params.dimension)}, params)


def regression(maps: np.ndarray, params):
    return _finish(maps, {axis: regression_axis(maps, params, axis) for axis in _axes(params.dimension)}, params)
