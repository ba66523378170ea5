"""The straightforward implementations of the CFAR methods (:mod:`methods.cfar.detectors`),
which ``bench perf`` times them against and the tests use as oracles
(docs/architecture.md, 'Performance').

Same windows, edges, closed forms and peak detection as :mod:`models.cfar`,
by SciPy filters over the whole batch: CA by ``scipy.ndimage.correlate1d``
with the window's footprint (ones on the reference cells, zeros on the
guard cells and the cell under test; the count of in-map reference cells by
the same correlation of ones, so edges are one-sided exactly as in the
kernel), OS by ``scipy.ndimage.rank_filter`` with that footprint where the
window is whole and ``np.partition`` of the gathered window at the edges
(where k' = ceil(k N'/N) changes), GO and SO by one correlation per
half-window and ``scipy.special.betainc`` for their closed forms, the regression by a per-line
``numpy.linalg.lstsq`` loop with its explicit hat matrix.
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


def ca_axis(maps: np.ndarray, L: int, g: int, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """(mu, S) of CA-CFAR along ``axis`` by correlation with the footprint."""
    w = footprint(L, g)
    sums = scipy.ndimage.correlate1d(maps.astype(np.float64), w, axis=AXIS[axis], mode="constant", cval=0.0)
    M = maps.shape[AXIS[axis]]
    counts = _along(scipy.ndimage.correlate1d(np.ones(M), w, mode="constant", cval=0.0), axis)
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
    """(mu, S) of GO- or SO-CFAR along ``axis``: each half's sum and in-map count by
    correlation with its own footprint, the larger/smaller mean (an empty half:
    the other's), the closed form by ``scipy.special.betainc`` (:func:`models.cfar.halves.halves_pfa`)."""
    means, counts = [], []
    M = maps.shape[AXIS[axis]]
    for side in (slice(0, L), slice(L + 2 * g + 1, None)):     # leading half, lagging half
        w = np.zeros(2 * (g + L) + 1)
        w[side] = 1.0
        n = scipy.ndimage.correlate1d(np.ones(M), w, mode="constant", cval=0.0)
        sums = scipy.ndimage.correlate1d(maps.astype(np.float64), w, axis=AXIS[axis], mode="constant", cval=0.0)
        means.append(np.where(_along(n, axis) > 0, sums / _along(np.maximum(n, 1.0), axis), np.nan))
        counts.append(_along(n, axis))
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
