"""Metrics: the definitions of DESIGN.md section 7, per trial and per cell.

Per trial (maneuver detection), with alarm = statistic >= threshold:

* ``detected``: the first alarm at or after the onset falls within
  ``detect_window_steps`` steps of it;
* ``delay``: that alarm's step minus the onset (NaN when not detected);
* ``false_alarms``: alarms in the null region, the steps
  ``[max(warmup, valid_from), onset)``; ``null_steps`` is its length;
* ``peak_statistic``: the largest statistic in the detection window, so that a
  ROC curve (Pd at any threshold) can be computed later without re-running.

Per cell (scenario config, method config, SNR): Pd with a 95% Wilson interval
(``scipy.stats.binomtest``), per-step Pfa = false alarms / null steps with its
Wilson interval, mean delay with a percentile-bootstrap interval, median
delay. Alarms of window statistics are correlated over steps, so the Pfa
interval, which treats steps as independent, is too narrow for them; the
report says so.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

CONFIDENCE = 0.95
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 20040101


def detection_trial_metrics(statistic: np.ndarray, threshold: float, *, onset: int,
                            detect_window: int, null_start: int) -> dict[str, np.ndarray]:
    """Per-trial detection metrics for ``statistic`` (n, K) at ``threshold``."""
    n, K = statistic.shape
    alarms = statistic >= threshold
    null_start = min(null_start, onset)
    window = alarms[:, onset:min(onset + detect_window, K)]
    detected = window.any(axis=1)
    first = np.argmax(window, axis=1)
    delay = np.where(detected, first, np.nan).astype(float)
    in_window = statistic[:, onset:min(onset + detect_window, K)]
    peak = in_window.max(axis=1) if in_window.shape[1] else np.full(n, -np.inf)
    return {
        "detected": detected,
        "delay": delay,
        "false_alarms": alarms[:, null_start:onset].sum(axis=1).astype(np.int64),
        "null_steps": np.full(n, onset - null_start, dtype=np.int64),
        "peak_statistic": peak.astype(float),
    }


def binomial_interval(successes: int, trials: int, level: float = CONFIDENCE) -> tuple[float, float]:
    """Wilson score interval for a proportion (NaN when there are no trials)."""
    if trials <= 0:
        return (np.nan, np.nan)
    ci = stats.binomtest(int(successes), int(trials)).proportion_ci(level, method="wilson")
    return float(ci.low), float(ci.high)


def bootstrap_mean_interval(values: np.ndarray, level: float = CONFIDENCE,
                            resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean, with a fixed seed (reproducible)."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return (np.nan, np.nan)
    if values.size == 1 or np.all(values == values[0]):
        return (float(values[0]), float(values[0]))
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    idx = rng.integers(0, values.size, size=(resamples, values.size))
    means = values[idx].mean(axis=1)
    alpha = (1 - level) / 2
    return float(np.quantile(means, alpha)), float(np.quantile(means, 1 - alpha))


def summarise_detection(trials: pd.DataFrame) -> pd.DataFrame:
    """One row per (scenario, method, params, snr_db) from per-trial rows."""
    rows = []
    keys = ["scenario", "method", "config", "params", "snr_db"]
    for key, g in trials.groupby(keys, sort=False, dropna=False):
        n = len(g)
        hits = int(g["detected"].sum())
        fa, steps = int(g["false_alarms"].sum()), int(g["null_steps"].sum())
        delays = g.loc[g["detected"].astype(bool), "delay"].to_numpy(float)
        pd_low, pd_high = binomial_interval(hits, n)
        pfa_low, pfa_high = binomial_interval(fa, steps)
        d_low, d_high = bootstrap_mean_interval(delays)
        rows.append({
            **dict(zip(keys, key)),
            "n_trials": n,
            "pd": hits / n, "pd_low": pd_low, "pd_high": pd_high,
            "pfa": fa / steps if steps else np.nan, "pfa_low": pfa_low, "pfa_high": pfa_high,
            "delay_mean": float(delays.mean()) if delays.size else np.nan,
            "delay_low": d_low, "delay_high": d_high,
            "delay_median": float(np.median(delays)) if delays.size else np.nan,
            "rmse_mean": np.nan,
            "threshold": float(g["threshold"].iloc[0]),
            "realised_snr_db": float(np.nanmean(g["realised_snr_db"])) if g["realised_snr_db"].notna().any() else np.nan,
        })
    return pd.DataFrame(rows)


def roc_curve(null_values: np.ndarray, peaks: np.ndarray, points: int = 80) -> tuple[np.ndarray, np.ndarray]:
    """(per-step Pfa, Pd) over thresholds, from stored statistics only.

    Pfa(t) is the fraction of null-hypothesis statistic values >= t; Pd(t) the
    fraction of trials whose peak statistic in the detection window is >= t,
    which is exactly the detection rule at threshold t. Thresholds are the
    null quantiles at log-spaced Pfa from 1/N to 1.
    """
    null = np.sort(np.asarray(null_values, float))
    peaks = np.asarray(peaks, float)
    n = null.size
    levels = np.unique(np.concatenate([np.logspace(np.log10(1.0 / n), 0.0, points), [1.0]]))
    thresholds = null[np.clip(np.ceil(n * (1.0 - levels)).astype(int), 0, n - 1)]
    pfa = 1.0 - np.searchsorted(null, thresholds, side="left") / n
    pd = (peaks[None, :] >= thresholds[:, None]).mean(axis=1)
    return pfa, pd


def crossing(x: np.ndarray, y: np.ndarray, level: float = 0.5) -> float:
    """The first x at which the piecewise-linear y(x) reaches ``level`` from below.

    NaN when y never reaches it in the range (the crossing lies above it);
    ``-inf`` when y already starts at or above it (the crossing lies below).
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    order = np.argsort(x)
    x, y = x[order], y[order]
    above = np.nonzero(y >= level)[0]
    if above.size == 0:
        return float("nan")
    i = above[0]
    if i == 0:
        return float("-inf")
    x0, x1, y0, y1 = x[i - 1], x[i], y[i - 1], y[i]
    return float(x0 + (level - y0) * (x1 - x0) / (y1 - y0))


def snr_at_pd(snr_db, pd, pd_low, pd_high, level: float = 0.5) -> tuple[float, float, float]:
    """SNR at which Pd reaches ``level``, with an interval from the Pd bands.

    The upper band reaches the level first (lower SNR bound), the lower band
    last (upper bound). See :func:`crossing` for NaN and ``-inf``.
    """
    return crossing(snr_db, pd, level), crossing(snr_db, pd_high, level), crossing(snr_db, pd_low, level)
