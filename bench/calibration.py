"""Threshold calibration. One routine, used everywhere.

* ``nominal``: the method's own analytic threshold (e.g. a chi-square
  quantile), taken as is.
* ``empirical``: the smallest threshold whose exceedance fraction on the
  null-hypothesis statistic values does not exceed the requested Pfa
  (per step for detectors, per scene for TBD).
* ``gumbel``: for scene maxima (TBD), a Gumbel law fitted by maximum
  likelihood to the null scene scores, and the threshold its (1 − Pfa)
  quantile: extreme-value theory for the maximum over many cells (Johnston &
  Krishnamurthy, IEEE TAES 38(1), 2002), which reaches Pfa = 1e-3 with a few
  thousand null scenes where the empirical quantile would need ~1e5.
* ``pot`` (peaks over threshold): for scene scores whose tail is not Gumbel's
  (a particle filter's existence log-odds has a heavier one), a generalized
  Pareto law fitted by maximum likelihood to the excesses of the largest
  :data:`POT_TAIL_FRACTION` of the null scores over the next one, u, and the
  threshold where the fitted tail reaches the Pfa (Pickands, "Statistical
  inference using extreme order statistics", Ann. Statist. 3(1), 1975; as a
  detection threshold: Broadwater & Chellappa, "Adaptive threshold estimation
  via extreme value theory", IEEE Trans. Signal Process. 58(2), 2010):

      P(X > t) = q (1 + xi (t - u) / sigma)^(-1/xi),   t >= u,

  with q the fraction of null scores above u. The Gumbel law is the xi = 0
  limit of the laws this tail approximates, so ``pot`` also holds on Gumbel
  scores, at the cost of a third parameter.

Whatever the mode, the nominal threshold's *measured* Pfa on the same null
values is reported with its binomial interval: a miscalibrated nominal
threshold is a finding to show.

Detectors are also given a *window* threshold: the empirical
(1 − ``chance_pd``) quantile of the null trials' peak statistic within
the detection window. At it every detector has the same chance Pd (a per-trial
false-alarm probability), which is the fair basis for comparing a single-step
test with window statistics whose alarms cluster (``pd_equal_chance`` in
summary.csv); ``chance_pd`` is the sweep's ``[calibration] chance_pd``
(default ``EQUAL_CHANCE_PD``).

Scene statistics (TBD) are thresholded per scene, but a threshold on a value
map can also be read per cell (the DP-TBD literature's "candidate end cells"
whose merit exceeds V_T). For those tasks each null scene keeps the order
statistics of its value map at a fixed set of ranks
(:func:`cell_order_statistics`), from which the per-cell Pfa of the threshold
used, and the threshold whose per-cell Pfa is the requested one, are computed
exactly or within a stated bracket (:func:`cell_exceedances`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from radarbench.bench.metrics import binomial_interval, clustered_rate_interval

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

#: the default chance Pd (fraction of null trials with an alarm in the detection
#: window) that every detector is calibrated to for ``pd_equal_chance``
EQUAL_CHANCE_PD = 0.05
#: ranks 1..EXACT_CELL_RANKS of a value map are kept exactly; beyond them ranks grow
#: geometrically by CELL_RANK_RATIO up to the number of cells
EXACT_CELL_RANKS = 64
CELL_RANK_RATIO = 1.25
#: ``pot``: the fraction q of the null values whose excesses are fitted (the largest tenth:
#: the rest of the sample says nothing about a Pfa far below q)
POT_TAIL_FRACTION = 0.1
#: ``pot`` fits at least this many excesses: fewer leave the shape xi to noise
POT_MIN_TAIL = 30


def empirical_threshold(null_values: np.ndarray, pfa: float) -> float:
    """Smallest t with mean(null_values >= t) <= pfa.

    With the values sorted in decreasing order v_0 >= v_1 >= ..., and
    k = floor(pfa * N), any t just above v_k is exceeded by at most k values.
    """
    v = np.asarray(null_values, dtype=float)
    if v.size == 0:
        raise ValueError("no null values to calibrate on")
    k = int(np.floor(pfa * v.size))
    if k >= v.size:
        return float(v.min())
    kth_largest = -np.partition(-v, k)[k]
    return float(np.nextafter(kth_largest, np.inf))


def gumbel_fit(null_values: np.ndarray) -> tuple[float, float]:
    """Maximum-likelihood Gumbel (max) location and scale of the null scene scores."""
    loc, scale = stats.gumbel_r.fit(np.asarray(null_values, float))
    return float(loc), float(scale)


def pot_tail_count(n: int) -> int:
    """How many of ``n`` null values the ``pot`` tail holds: round(n q), q = :data:`POT_TAIL_FRACTION`."""
    return int(round(n * POT_TAIL_FRACTION))


def pot_fit(null_values: np.ndarray) -> tuple[float, float, float]:
    """(u, sigma, xi): the tail's start u, the (k + 1)-th largest null value for the k of
    :func:`pot_tail_count`, and the maximum-likelihood generalized Pareto scale and shape
    of the k excesses over it (the module docstring's tail law, with q = k / n)."""
    v = np.sort(np.asarray(null_values, float))
    k = pot_tail_count(v.size)
    if k < POT_MIN_TAIL or k >= v.size:
        raise ValueError(f"'pot' needs at least {POT_MIN_TAIL} values in its tail, got {k} of {v.size}")
    u = float(v[-k - 1])
    xi, _, sigma = stats.genpareto.fit(v[-k:] - u, floc=0.0)
    return u, float(sigma), float(xi)


def pot_threshold(fit: tuple[float, float, float], pfa: float, n: int) -> float:
    """The t where the fitted tail q (1 + xi (t - u) / sigma)^(-1/xi) equals ``pfa``, q = k / n."""
    u, sigma, xi = fit
    q = pot_tail_count(n) / n
    return u + float(stats.genpareto.isf(pfa / q, xi, 0.0, sigma)) if pfa < q else u


def fitted_survival(c: "CalibrationResult", grid: np.ndarray) -> np.ndarray:
    """P(score >= x) at ``grid`` under the law calibration ``c`` fitted (``gumbel``: the
    whole law; ``pot``: its tail, NaN below the tail's start)."""
    if c.mode == "pot":
        q = pot_tail_count(c.null_values) / c.null_values
        sf = q * stats.genpareto.sf(grid - c.fit_loc, c.fit_shape, 0.0, c.fit_scale)
        return np.where(grid >= c.fit_loc, sf, np.nan)
    return stats.gumbel_r.sf(grid, c.fit_loc, c.fit_scale)


@dataclass(frozen=True)
class CalibrationResult:
    """The calibration of one method config on one scenario config."""

    scenario: str
    method: str
    mode: str
    pfa: float
    nominal: float
    used: float
    null_values: int            # how many null statistic values were used
    nominal_exceedances: int
    nominal_pfa: float          # measured Pfa of the nominal threshold
    nominal_pfa_low: float
    nominal_pfa_high: float
    chance_pd: float = float("nan")   # Pd under the null at the threshold used
    chance_pd_low: float = float("nan")
    chance_pd_high: float = float("nan")
    used_exceedances: int = 0          # null values at or above the threshold used
    used_pfa: float = float("nan")     # their fraction: the measured Pfa of the threshold used
    used_pfa_low: float = float("nan")
    used_pfa_high: float = float("nan")
    fit_loc: float = float("nan")      # the fit: gumbel's location, pot's tail start u
    fit_scale: float = float("nan")    # gumbel's scale, pot's sigma
    fit_shape: float = float("nan")    # pot's xi (gumbel: 0)
    equal_chance_threshold: float = float("nan")   # window threshold for the sweep's chance Pd
    cell_pfa: float = float("nan")          # per-cell Pfa of the threshold used (value maps)
    cell_pfa_low: float = float("nan")
    cell_pfa_high: float = float("nan")
    cell_threshold: float = float("nan")    # threshold whose per-cell Pfa is the requested pfa
    cell_threshold_scene_pfa: float = float("nan")   # fraction of null scenes whose score reaches it

    def as_row(self) -> dict:
        return asdict(self)


def exceedance_interval(values: np.ndarray, threshold: float,
                        trial_lengths: np.ndarray | None = None) -> tuple[float, float]:
    """Interval of the fraction of null values at or above ``threshold``,
    counted over trials (``trial_lengths``: values per null trial, in order),
    since a window statistic's exceedances cluster within a trial; one value per
    trial (or no lengths given) is Wilson's interval."""
    hits = values >= threshold
    if trial_lengths is None or len(trial_lengths) == 0 or int(np.sum(trial_lengths)) != values.size:
        return binomial_interval(int(np.count_nonzero(hits)), values.size)
    starts = np.concatenate([[0], np.cumsum(trial_lengths)[:-1]])
    return clustered_rate_interval(np.add.reduceat(hits.astype(np.int64), starts), trial_lengths)


def cell_ranks(cells: int) -> np.ndarray:
    """1-based ranks kept of a value map of ``cells`` cells: 1..EXACT_CELL_RANKS,
    then geometric steps of CELL_RANK_RATIO, always ending at ``cells``."""
    ranks = list(range(1, min(EXACT_CELL_RANKS, cells) + 1))
    r = float(ranks[-1])
    while r < cells:
        r = max(r * CELL_RANK_RATIO, r + 1)
        ranks.append(min(int(r), cells))
    return np.unique(np.asarray(ranks, np.int64))


def cell_order_statistics(values: np.ndarray) -> np.ndarray:
    """(n, 2, R) float64: per trial, the ranks of :func:`cell_ranks` (row 0) and
    the value map's values at those ranks in decreasing order (row 1), from
    ``values`` (n, ...) (each trial's cells flattened)."""
    v = np.asarray(values, float).reshape(len(values), -1)
    ranks = cell_ranks(v.shape[1])
    top = -np.partition(-v, ranks - 1, axis=1)[:, ranks - 1]
    return np.stack([np.broadcast_to(ranks.astype(float), top.shape), top], axis=1)


def cell_exceedances(order_stats: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Per trial, bounds (low, high) on the number of cells at or above
    ``threshold``: with v_j the value at rank r_j, the count is r_j for the
    last j with v_j >= threshold, up to r_(j+1) - 1 (exact where the kept
    ranks are consecutive, i.e. for fewer than EXACT_CELL_RANKS cells)."""
    ranks, vals = order_stats[:, 0], order_stats[:, 1]
    above = vals >= threshold
    j = above.sum(axis=1)                       # values are decreasing: the first j are above
    idx = np.maximum(j - 1, 0)
    low = np.where(j > 0, np.take_along_axis(ranks, idx[:, None], axis=1)[:, 0], 0.0)
    nxt = np.minimum(j, ranks.shape[1] - 1)
    high = np.where(j >= ranks.shape[1], ranks[:, -1],
                    np.take_along_axis(ranks, nxt[:, None], axis=1)[:, 0] - 1.0)
    return low, np.maximum(high, low)


def cell_calibration(order_stats: np.ndarray, scores: np.ndarray, used: float,
                     pfa: float) -> tuple[float, float, float, float, float]:
    """Per-cell Pfa of the threshold ``used`` (point, low, high) and the
    threshold whose pooled per-cell Pfa is ``pfa`` with the fraction of null
    scene ``scores`` reaching it.

    The point estimate takes the middle of each trial's count bracket
    (:func:`cell_exceedances`); the interval is the trial-clustered interval of
    the lower counts' rate at its low end and of the upper counts' at its high
    end. The per-cell threshold solves mean(count(t)) / cells = pfa by
    bisection on the bracket midpoints."""
    cells = order_stats[:, 0, -1]
    low, high = cell_exceedances(order_stats, used)
    point = float(((low + high) / 2).sum() / cells.sum())
    lo_int = clustered_rate_interval(low, cells)[0]
    hi_int = clustered_rate_interval(high, cells)[1]

    def rate(t: float) -> float:
        lo, hi = cell_exceedances(order_stats, t)
        return float(((lo + hi) / 2).sum() / cells.sum())

    a, b = float(order_stats[:, 1].min()), float(order_stats[:, 1].max()) + 1.0
    for _ in range(80):
        mid = (a + b) / 2
        a, b = (mid, b) if rate(mid) > pfa else (a, mid)
    scene = float(np.mean(np.asarray(scores, float) >= b))
    return point, float(lo_int), float(hi_int), b, scene


def calibrate(scenario: str, method: str, null_values: np.ndarray, nominal: float,
              pfa: float, mode: str, null_peaks: np.ndarray | None = None,
              trial_lengths: np.ndarray | None = None, chance_pd: float = EQUAL_CHANCE_PD,
              null_cells: np.ndarray | None = None, per_cell: bool = False) -> CalibrationResult:
    """Choose the threshold; measure the nominal one's Pfa and, given the null
    trials' window peaks, the chance detection rate at the threshold used (and the
    window threshold whose chance Pd is ``chance_pd``); given the null trials'
    cell order statistics, the per-cell Pfa (:func:`cell_calibration`).
    Measured Pfa intervals are counted over trials (:func:`exceedance_interval`).

    ``per_cell`` (tasks whose Pfa is per cell of a map, e.g. CFAR on
    range-Doppler maps): the requested Pfa is per cell, so the *empirical*
    threshold is the one whose pooled per-cell exceedance rate over the null
    maps is ``pfa`` (:func:`cell_calibration` on ``null_cells``), and the
    measured Pfa of the nominal and of the used threshold are per-cell rates
    with intervals counted over maps; ``null_values`` (one value per map, its
    peak) then only counts the maps."""
    if per_cell and null_cells is not None and len(null_cells):
        return _calibrate_per_cell(scenario, method, null_values, nominal, pfa, mode, null_peaks, null_cells)
    values = np.asarray(null_values, dtype=float)
    fit = (np.nan, np.nan, np.nan)
    if mode == "empirical":
        used = empirical_threshold(values, pfa)
    elif mode == "gumbel":
        fit = (*gumbel_fit(values), 0.0)
        used = float(stats.gumbel_r.isf(pfa, *fit[:2]))
    elif mode == "pot":
        fit = pot_fit(values)
        used = pot_threshold(fit, pfa, values.size)
    else:
        used = float(nominal)
    if np.isfinite(nominal):
        exceed = int(np.count_nonzero(values >= nominal))
        measured = (exceed / values.size, *exceedance_interval(values, nominal, trial_lengths))
    else:   # the method has no analytic threshold
        exceed, measured = 0, (np.nan, np.nan, np.nan)
    chance, window_threshold = (np.nan, np.nan, np.nan), np.nan
    if null_peaks is not None and len(null_peaks):
        hits = int(np.count_nonzero(np.asarray(null_peaks) >= used))
        chance = (hits / len(null_peaks), *binomial_interval(hits, len(null_peaks)))
        window_threshold = empirical_threshold(null_peaks, chance_pd)
    used_exceed = int(np.count_nonzero(values >= used))
    per_cell = (cell_calibration(null_cells, values, used, pfa) if null_cells is not None and len(null_cells)
                and np.isfinite(used) else (np.nan,) * 5)
    return CalibrationResult(scenario, method, mode, pfa, float(nominal), used, int(values.size),
                             exceed, *measured, *chance, used_exceed, used_exceed / values.size,
                             *exceedance_interval(values, used, trial_lengths), *fit, window_threshold,
                             *per_cell)


def _calibrate_per_cell(scenario: str, method: str, null_values: np.ndarray, nominal: float, pfa: float,
                        mode: str, null_peaks: np.ndarray | None, null_cells: np.ndarray) -> CalibrationResult:
    """:func:`calibrate` for a per-cell Pfa: thresholds and measured rates from
    the null maps' order statistics; the chance Pd is the fraction of null maps
    whose peak reaches the threshold used."""
    peaks = np.asarray(null_values, dtype=float)
    at_pfa = cell_calibration(null_cells, peaks, float(nominal) if np.isfinite(nominal) else 0.0, pfa)
    used = at_pfa[3] if mode == "empirical" else float(nominal)
    measured_nominal = at_pfa[:3] if np.isfinite(nominal) else (np.nan, np.nan, np.nan)
    measured_used = cell_calibration(null_cells, peaks, used, pfa)[:3] if np.isfinite(used) else (np.nan,) * 3
    chance = (np.nan, np.nan, np.nan)
    if null_peaks is not None and len(null_peaks) and np.isfinite(used):
        hits = int(np.count_nonzero(np.asarray(null_peaks) >= used))
        chance = (hits / len(null_peaks), *binomial_interval(hits, len(null_peaks)))
    count = lambda t: int(round(float(np.sum(np.add(*cell_exceedances(null_cells, t)) / 2))))  # noqa: E731
    return CalibrationResult(scenario, method, mode, pfa, float(nominal), float(used), int(peaks.size),
                             count(nominal) if np.isfinite(nominal) else 0, *measured_nominal, *chance,
                             count(used) if np.isfinite(used) else 0, *measured_used,
                             cell_pfa=measured_used[0], cell_pfa_low=measured_used[1],
                             cell_pfa_high=measured_used[2], cell_threshold=at_pfa[3],
                             cell_threshold_scene_pfa=at_pfa[4])
