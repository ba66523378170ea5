"""Maneuver-detection metrics, per trial and per cell (docs/architecture.md, 'Metrics').

Per trial, with alarm = statistic >= threshold at a step where the statistic is
formed (from ``valid_from`` on: an alarm of a partial window is no alarm):

* ``detected``: the first alarm at or after the onset falls within
  ``detect_window_steps`` steps of it;
* ``delay``: that alarm's step minus the onset (NaN when not detected);
* ``false_alarms``: alarms in the null region, the steps
  ``[max(warmup, valid_from), onset)``; ``null_steps`` is its length;
* ``peak_statistic``: the largest formed statistic in the detection window, so that a
  ROC curve (Pd at any threshold) can be computed later without re-running;
* ``window_alarm_fraction``: the fraction of the detection window's steps that
  alarm (the per-step detection probability of the trial).

The onset may differ per trial (a scenario's onset jitter); every window and
null region above is then the trial's own.

Per cell: Pd with a 95% Wilson interval; two further Pd definitions that
favour no detector: the per-step average Pd over the detection window
(:func:`step_average_pd`, the cumulant paper's "average detection
probability", Song, Ji & Gao 2004), and Pd at a threshold calibrated to the
same chance Pd on null trials (:func:`equal_chance_pd`); per-step Pfa = false
alarms / null steps with an interval over trials
(:func:`bench.metrics.clustered_rate_interval`: alarms of window statistics
come in clusters, so steps are not independent), mean delay with a
percentile-bootstrap interval, median delay.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from radarbench.bench.metrics import (binomial_interval, bootstrap_mean_interval, by_cell, clustered_rate_interval,
                           mean_realised_snr)

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True


def detection_trial_metrics(statistic: np.ndarray, threshold: float, *, onset,
                            detect_window: int, null_start: int, valid_from: int = 0) -> dict[str, np.ndarray]:
    """Per-trial detection metrics for ``statistic`` (n, K) at ``threshold``.

    ``onset``: the onset step, one for all trials or one per trial (n,);
    ``valid_from``: the first step the statistic is formed, before which nothing alarms.
    """
    n, K = statistic.shape
    steps = np.arange(K)[None, :]
    alarms = (statistic >= threshold) & (steps >= valid_from)
    onset = np.broadcast_to(np.asarray(onset, dtype=np.int64), (n,))
    null_start = np.minimum(null_start, onset)
    window_steps = onset[:, None] + np.arange(detect_window)[None, :]      # (n, W)
    inside = window_steps < K
    idx = np.minimum(window_steps, K - 1)
    window = np.take_along_axis(alarms, idx, axis=1) & inside
    detected = window.any(axis=1)
    first = np.argmax(window, axis=1)
    delay = np.where(detected, first, np.nan).astype(float)
    in_window = np.where(inside & (window_steps >= valid_from), np.take_along_axis(statistic, idx, axis=1), -np.inf)
    peak = in_window.max(axis=1) if detect_window else np.full(n, -np.inf)
    null_region = (steps >= null_start[:, None]) & (steps < onset[:, None])
    return {
        "detected": detected,
        "delay": delay,
        "false_alarms": (alarms & null_region).sum(axis=1).astype(np.int64),
        "null_steps": (onset - null_start).astype(np.int64),
        "peak_statistic": peak.astype(float),
        # the paper's per-step ("average") detection probability of one trial
        "window_alarm_fraction": (window.sum(axis=1) / np.maximum(inside.sum(axis=1), 1)).astype(float),
    }


def summarise_detection(trials: pd.DataFrame) -> pd.DataFrame:
    """One row per (scenario, method, params, snr_db) from per-trial rows."""
    rows = []
    for keys, g in by_cell(trials):
        n = len(g)
        hits = int(g["detected"].sum())
        fa, steps = int(g["false_alarms"].sum()), int(g["null_steps"].sum())
        delays = g.loc[g["detected"].astype(bool), "delay"].to_numpy(float)
        pd_low, pd_high = binomial_interval(hits, n)
        pfa_low, pfa_high = clustered_rate_interval(g["false_alarms"], g["null_steps"])
        d_low, d_high = bootstrap_mean_interval(delays)
        rows.append({
            **keys,
            "n_trials": n,
            "pd": hits / n, "pd_low": pd_low, "pd_high": pd_high,
            "pfa": fa / steps if steps else np.nan, "pfa_low": pfa_low, "pfa_high": pfa_high,
            "delay_mean": float(delays.mean()) if delays.size else np.nan,
            "delay_low": d_low, "delay_high": d_high,
            "delay_median": float(np.median(delays)) if delays.size else np.nan,
            "rmse_mean": np.nan,
            "threshold": float(g["threshold"].iloc[0]),
            "realised_snr_db": mean_realised_snr(g),
            **step_average_pd(g),
        })
    return pd.DataFrame(rows)


def step_average_pd(g: pd.DataFrame) -> dict[str, float]:
    """Pd averaged over the steps of the detection window and over trials:
    mean of the alarm indicator, i.e. the mean over trials of each trial's
    ``window_alarm_fraction``. Its interval is a bootstrap over trials (the
    independent units; a trial's steps are correlated)."""
    if "window_alarm_fraction" not in g:
        return {"pd_step": np.nan, "pd_step_low": np.nan, "pd_step_high": np.nan}
    f = g["window_alarm_fraction"].to_numpy(float)
    low, high = bootstrap_mean_interval(f)
    return {"pd_step": float(f.mean()) if f.size else np.nan, "pd_step_low": low, "pd_step_high": high}


def equal_chance_pd(peaks: np.ndarray, threshold: float) -> dict[str, float]:
    """Pd at a window threshold: the fraction of trials whose peak statistic in
    the detection window reaches it, with its Wilson interval."""
    peaks = np.asarray(peaks, float)
    if not np.isfinite(threshold) or peaks.size == 0:
        return {"pd_equal_chance": np.nan, "pd_equal_chance_low": np.nan, "pd_equal_chance_high": np.nan}
    hits = int(np.count_nonzero(peaks >= threshold))
    low, high = binomial_interval(hits, peaks.size)
    return {"pd_equal_chance": hits / peaks.size, "pd_equal_chance_low": low, "pd_equal_chance_high": high}


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
