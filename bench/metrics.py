"""Generic statistics of the harness: intervals, bootstrap, RMSE, crossings.

Every task's metrics (bench/tasks/*_metrics.py) are built from these; the
definitions are in docs/architecture.md, 'Metrics'.

* proportions: Wilson score intervals (``scipy.stats.binomtest``);
* rates counted over steps that are correlated within a trial (per-step Pfa
  of a window statistic): a ratio-estimator interval over trials
  (:func:`clustered_rate_interval`);
* means and other statistics over trials: percentile bootstrap with a fixed
  seed (reproducible);
* RMSE per step across trials and its time average (the papers' "average RMSE");
* the SNR at which a Pd curve reaches 0.5, with an interval from its bands.

A *cell* is one (scenario config, method config, SNR) of a sweep: summaries
have one row per cell (:func:`by_cell`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

CONFIDENCE = 0.95
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 20040101
#: The columns that identify a cell in trials.csv and summary.csv.
CELL_KEYS = ["scenario", "method", "config", "params", "snr_db"]


def by_cell(trials: pd.DataFrame):
    """``(keys, rows)`` per cell, in the order of ``trials``: ``keys`` maps
    :data:`CELL_KEYS` to the cell's values."""
    for key, g in trials.groupby(CELL_KEYS, sort=False, dropna=False):
        yield dict(zip(CELL_KEYS, key)), g


def series_key(keys: dict) -> tuple:
    """The key of a cell's series: (scenario, config, snr_db)."""
    return keys["scenario"], keys["config"], keys["snr_db"]


def mean_realised_snr(g: pd.DataFrame) -> float:
    """Mean realised SNR of a cell's trials (NaN when the scenario gives none)."""
    return float(np.nanmean(g["realised_snr_db"])) if g["realised_snr_db"].notna().any() else np.nan


def binomial_interval(successes: int, trials: int, level: float = CONFIDENCE) -> tuple[float, float]:
    """Wilson score interval for a proportion (NaN when there are no trials)."""
    if trials <= 0:
        return (np.nan, np.nan)
    ci = stats.binomtest(int(successes), int(trials)).proportion_ci(level, method="wilson")
    return float(ci.low), float(ci.high)


def clustered_rate_interval(events: np.ndarray, opportunities: np.ndarray,
                            level: float = CONFIDENCE) -> tuple[float, float]:
    """Interval of a rate counted over steps (or cells) that are correlated
    within a trial, e.g. the per-step false-alarm rate of a window statistic.

    ``events[i]`` and ``opportunities[i]`` are trial *i*'s count of alarms and
    of steps. The rate R = sum(events) / sum(opportunities) is a ratio
    estimator over independent trials; its linearised variance
    ``n/(n-1) * sum((e_i - R o_i)^2) / (sum o_i)^2`` (Cochran, *Sampling
    Techniques*, eq. 6.13) counts the clustering of alarms. The interval is
    Wilson's on the *effective* number of steps ``sum(o) / deff``, where the
    design effect ``deff`` is that variance over the binomial one (at least 1,
    so never narrower than the independent-steps interval), with Student's
    quantile in place of the normal one (Korn & Graubard, "Confidence
    intervals for proportions with small expected number of positive counts
    estimated from survey data", Survey Methodology 24, 1998). Its degrees of
    freedom are the trials that alarmed (at most n - 1): with rare clustered
    alarms the variance rests on those trials alone; in simulation (window
    sums of 16-32 chi-square values) this keeps coverage at or above 95 %
    where the normal quantile falls to 0.88 with few alarming trials.

    Chosen over a cluster bootstrap, whose percentile interval collapses to
    [0, 0] without alarms and under-covers with few alarming trials. Limits:
    every trial one step (independent Bernoulli trials): Wilson's interval;
    at most one trial alarmed, or one trial in all (no between-trial
    variance): the assumption-free bracket [q_low / max(o), q_high] from
    Wilson's interval of q, the fraction of trials with an alarm, because a
    stationary per-step rate p satisfies q / o <= p <= q.
    """
    e = np.asarray(events, float)
    o = np.asarray(opportunities, float)
    total_o = float(o.sum())
    if total_o <= 0:
        return (np.nan, np.nan)
    if np.all(o == 1):
        return binomial_interval(int(e.sum()), e.size, level)
    rate = float(e.sum()) / total_o
    n, alarmed = e.size, int(np.count_nonzero(e > 0))
    if n < 2 or alarmed < 2:
        q_low, q_high = binomial_interval(alarmed, n, level)
        return q_low / float(o.max()), q_high
    var_binomial = rate * (1 - rate) / total_o
    var_ratio = n / (n - 1) * float(((e - rate * o) ** 2).sum()) / total_o ** 2
    deff = max(1.0, var_ratio / var_binomial) if var_binomial > 0 else 1.0
    return wilson_interval(rate, total_o / deff, level, df=min(n - 1, alarmed))


def wilson_interval(proportion: float, n: float, level: float = CONFIDENCE,
                    df: float = np.inf) -> tuple[float, float]:
    """Wilson score interval for a proportion observed on ``n`` (possibly
    effective, non-integer) independent Bernoulli trials; with finite ``df``
    Student's quantile replaces the normal one."""
    if n <= 0:
        return (np.nan, np.nan)
    z = float(stats.norm.isf((1 - level) / 2) if np.isinf(df) else stats.t.isf((1 - level) / 2, df))
    denom = 1 + z * z / n
    centre = (proportion + z * z / (2 * n)) / denom
    half = z * np.sqrt(proportion * (1 - proportion) / n + z * z / (4 * n * n)) / denom
    return float(max(0.0, centre - half)), float(min(1.0, centre + half))


def _bootstrap_interval(n: int, estimate, level: float, resamples: int) -> tuple[float, float]:
    """Percentile bootstrap interval: ``estimate(idx)`` maps a (resamples, n)
    array of resampled indices to one statistic per resample; fixed seed."""
    idx = np.random.default_rng(BOOTSTRAP_SEED).integers(0, n, size=(resamples, n))
    values = estimate(idx)
    alpha = (1 - level) / 2
    return float(np.quantile(values, alpha)), float(np.quantile(values, 1 - alpha))


def bootstrap_mean_interval(values: np.ndarray, level: float = CONFIDENCE,
                            resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean, with a fixed seed (reproducible)."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return (np.nan, np.nan)
    if values.size == 1 or np.all(values == values[0]):
        return (float(values[0]), float(values[0]))
    return _bootstrap_interval(values.size, lambda idx: values[idx].mean(axis=1), level, resamples)


def bootstrap_statistic_interval(samples: np.ndarray, statistic, level: float = CONFIDENCE,
                                 resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float]:
    """Percentile bootstrap interval of ``statistic(samples[idx])``, resampling
    trials (the first axis), with a fixed seed."""
    samples = np.asarray(samples, float)
    if len(samples) < 2:
        value = statistic(samples) if len(samples) else np.nan
        return (float(value), float(value))
    return _bootstrap_interval(len(samples), lambda idx: np.array([statistic(samples[i]) for i in idx]),
                               level, resamples)


def per_step_rmse(sq_err: np.ndarray) -> np.ndarray:
    """RMSE per step across trials, from squared errors (n, K)."""
    return np.sqrt(np.mean(sq_err, axis=0)) if len(sq_err) else np.full(sq_err.shape[1:], np.nan)


def time_averaged_rmse(sq_err: np.ndarray) -> float:
    """Mean over steps of the per-step RMSE across trials (the papers' "average RMSE")."""
    return float(np.mean(per_step_rmse(sq_err))) if len(sq_err) else float("nan")


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
