"""Threshold calibration (DESIGN.md section 6). One routine, used everywhere.

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

Whatever the mode, the nominal threshold's *measured* Pfa on the same null
values is reported with its binomial interval: a miscalibrated nominal
threshold is a finding to show.

Detectors are also given a *window* threshold: the empirical
(1 − ``EQUAL_CHANCE_PD``) quantile of the null trials' peak statistic within
the detection window. At it every detector has the same chance Pd (a per-trial
false-alarm probability), which is the fair basis for comparing a single-step
test with window statistics whose alarms cluster (``pd_equal_chance`` in
summary.csv).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from bench.metrics import binomial_interval, clustered_rate_interval

#: the chance Pd (fraction of null trials with an alarm in the detection
#: window) that every detector is calibrated to for ``pd_equal_chance``
EQUAL_CHANCE_PD = 0.05


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
    gumbel_loc: float = float("nan")   # the fit, in gumbel mode
    gumbel_scale: float = float("nan")
    equal_chance_threshold: float = float("nan")   # window threshold for chance Pd = EQUAL_CHANCE_PD

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


def calibrate(scenario: str, method: str, null_values: np.ndarray, nominal: float,
              pfa: float, mode: str, null_peaks: np.ndarray | None = None,
              trial_lengths: np.ndarray | None = None) -> CalibrationResult:
    """Choose the threshold; measure the nominal one's Pfa and, given the null
    trials' window peaks, the chance detection rate at the threshold used.
    Measured Pfa intervals are counted over trials (:func:`exceedance_interval`)."""
    values = np.asarray(null_values, dtype=float)
    fit = (np.nan, np.nan)
    if mode == "empirical":
        used = empirical_threshold(values, pfa)
    elif mode == "gumbel":
        fit = gumbel_fit(values)
        used = float(stats.gumbel_r.isf(pfa, *fit))
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
        window_threshold = empirical_threshold(null_peaks, EQUAL_CHANCE_PD)
    used_exceed = int(np.count_nonzero(values >= used))
    return CalibrationResult(scenario, method, mode, pfa, float(nominal), used, int(values.size),
                             exceed, *measured, *chance, used_exceed, used_exceed / values.size,
                             *exceedance_interval(values, used, trial_lengths), *fit, window_threshold)
