"""Metrics: their definitions, per trial and per cell.

Per trial (maneuver detection), with alarm = statistic >= threshold:

* ``detected``: the first alarm at or after the onset falls within
  ``detect_window_steps`` steps of it;
* ``delay``: that alarm's step minus the onset (NaN when not detected);
* ``false_alarms``: alarms in the null region, the steps
  ``[max(warmup, valid_from), onset)``; ``null_steps`` is its length;
* ``peak_statistic``: the largest statistic in the detection window, so that a
  ROC curve (Pd at any threshold) can be computed later without re-running;
* ``window_alarm_fraction``: the fraction of the detection window's steps that
  alarm (the per-step detection probability of the trial).

The onset may differ per trial (a scenario's onset jitter); every window and
null region above is then the trial's own.

Track-before-detect and tracking metrics follow (``tbd_trial_metrics``,
``tracking_trial_metrics``); per-trial arrays of shape (n, K) are *series*:
stored with the trial but kept out of trials.csv, they feed per-step RMSE.

Per cell (scenario config, method config, SNR): Pd with a 95% Wilson interval
(``scipy.stats.binomtest``); two further Pd definitions that favour no
detector (:func:`summarise_detection`): the per-step average Pd over the
detection window, and Pd at a threshold calibrated to the same chance Pd on
null trials (:func:`equal_chance_pd`); per-step Pfa = false alarms / null
steps with an interval over trials (``clustered_rate_interval``: alarms of
window statistics come in clusters, so steps are not independent), mean delay
with a percentile-bootstrap interval, median delay.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

CONFIDENCE = 0.95
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 20040101


def detection_trial_metrics(statistic: np.ndarray, threshold: float, *, onset,
                            detect_window: int, null_start: int) -> dict[str, np.ndarray]:
    """Per-trial detection metrics for ``statistic`` (n, K) at ``threshold``.

    ``onset``: the onset step, one for all trials or one per trial (n,).
    """
    n, K = statistic.shape
    alarms = statistic >= threshold
    onset = np.broadcast_to(np.asarray(onset, dtype=np.int64), (n,))
    null_start = np.minimum(null_start, onset)
    steps = np.arange(K)[None, :]
    window_steps = onset[:, None] + np.arange(detect_window)[None, :]      # (n, W)
    inside = window_steps < K
    idx = np.minimum(window_steps, K - 1)
    window = np.take_along_axis(alarms, idx, axis=1) & inside
    detected = window.any(axis=1)
    first = np.argmax(window, axis=1)
    delay = np.where(detected, first, np.nan).astype(float)
    in_window = np.where(inside, np.take_along_axis(statistic, idx, axis=1), -np.inf)
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
        pfa_low, pfa_high = clustered_rate_interval(g["false_alarms"], g["null_steps"])
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


# ------------------------------------------------------------------ track-before-detect

def cell_centres_m(cells: np.ndarray, grid: dict) -> np.ndarray:
    """(x, y) in metres of the centres of ``(row, col)`` cells (…, 2)."""
    cells = np.asarray(cells, float)
    x = grid["x_min_m"] + (cells[..., 1] + 0.5) * grid["cell_m"]
    y = grid["y_min_m"] + (cells[..., 0] + 0.5) * grid["cell_m"]
    return np.stack([x, y], axis=-1)


def tbd_trial_metrics(score: np.ndarray, track: np.ndarray, threshold: float, *, target_cells: np.ndarray,
                      truth_xy_m: np.ndarray, grid: dict, tolerance_cells: int,
                      min_hits: int = 2) -> dict[str, np.ndarray]:
    """Per-trial TBD metrics.

    A frame is a *hit* when the backtracked cell is within ``tolerance_cells``
    of the true cell in both row and column (Chebyshev distance). The trial is
    *detected* when ``score >= threshold`` and the track has at least
    ``min_hits`` hits. ``sq_err_m2`` (n, K) is the squared distance between
    the backtracked cell's centre and the true position, per frame: the
    per-frame RMSE over detected trials is computed from it.
    """
    score = np.asarray(score, float)
    off = np.abs(np.asarray(track, np.int64) - np.asarray(target_cells, np.int64)).max(axis=-1)
    hits = (off <= tolerance_cells).sum(axis=1)
    above = score >= threshold
    detected = above & (hits >= min_hits)
    sq_err = ((cell_centres_m(track, grid) - truth_xy_m) ** 2).sum(axis=-1)
    return {"detected": detected, "above_threshold": above, "hits": hits.astype(np.int64),
            "score": score, "rmse": np.sqrt(sq_err.mean(axis=1)), "sq_err_m2": sq_err}


def unit_innovation_snr_offset_db(ar_coefficients, autocovariance) -> float:
    """dB to add to our SNR (s² over the *stationary* noise variance) to get the
    SNR against a unit-variance *innovation* w_k ~ N(0, 1), the scale of an AR
    model v_k + a1 v_(k-1) + ... + aP v_(k-P) = w_k written with w ~ N(0, 1).

    Multiplying the model by v_k and taking expectations gives the first
    Yule-Walker equation σ_w² = γ(0) + Σ_i a_i γ(i), so at σ_w = 1 the
    stationary variance is γ(0) / σ_w² and the offset is 10 log10 of it.
    White noise (``ar_coefficients`` None): 0 dB."""
    if ar_coefficients is None:
        return 0.0
    a = np.asarray(ar_coefficients, float)
    gamma = np.asarray(autocovariance, float)
    innovation_var = gamma[0] + float(np.dot(a, gamma[1:len(a) + 1]))
    return float(10.0 * np.log10(gamma[0] / innovation_var))


def per_step_rmse(sq_err: np.ndarray) -> np.ndarray:
    """RMSE per step across trials, from squared errors (n, K)."""
    return np.sqrt(np.mean(sq_err, axis=0)) if len(sq_err) else np.full(sq_err.shape[1:], np.nan)


def time_averaged_rmse(sq_err: np.ndarray) -> float:
    """Mean over steps of the per-step RMSE across trials (the papers' "average RMSE")."""
    return float(np.mean(per_step_rmse(sq_err))) if len(sq_err) else float("nan")


def summarise_tbd(trials: pd.DataFrame, series: dict) -> pd.DataFrame:
    """One row per cell: Pd (Wilson) and the average per-frame RMSE (bootstrap
    interval over trials) twice: ``rmse_*`` over detected trials only, and
    ``rmse_all_*`` over every Monte Carlo run, detected or not, as Tonissen-type
    DP-TBD papers compute it: RMSE(k) = sqrt((1/MC) Σ_i ‖l̂_i(k) − l(k)‖²),
    averaged over k ("average RMSE")."""
    rows = []
    keys = ["scenario", "method", "config", "params", "snr_db"]
    for key, g in trials.groupby(keys, sort=False, dropna=False):
        n, hits = len(g), int(g["detected"].sum())
        lo, hi = binomial_interval(hits, n)
        sq_all = series[(key[0], key[2], key[4])]["sq_err_m2"]
        sq = sq_all[g["detected"].to_numpy(bool)]
        r_lo, r_hi = bootstrap_statistic_interval(sq, time_averaged_rmse, resamples=500)
        a_lo, a_hi = bootstrap_statistic_interval(sq_all, time_averaged_rmse, resamples=500)
        rows.append({**dict(zip(keys, key)), "n_trials": n, "pd": hits / n, "pd_low": lo, "pd_high": hi,
                     "rmse_mean": time_averaged_rmse(sq), "rmse_low": r_lo, "rmse_high": r_hi,
                     "rmse_all_mean": time_averaged_rmse(sq_all), "rmse_all_low": a_lo, "rmse_all_high": a_hi,
                     "snr_offset_unit_innovation_db": float(g["snr_offset_unit_innovation_db"].iloc[0])
                     if "snr_offset_unit_innovation_db" in g else np.nan,
                     "threshold": float(g["threshold"].iloc[0]),
                     "realised_snr_db": float(np.nanmean(g["realised_snr_db"]))
                     if g["realised_snr_db"].notna().any() else np.nan})
    return pd.DataFrame(rows)


# ------------------------------------------------------------------ tracking

def tracking_trial_metrics(estimate: np.ndarray, truth: np.ndarray, *, position_index, labels,
                           covariance: np.ndarray | None, divergence_bound_m: float,
                           derived=None) -> dict[str, np.ndarray]:
    """Per-trial tracking metrics.

    ``rmse``: the trial's position RMSE over time; ``final_error_m``;
    ``diverged``: the position error exceeded ``divergence_bound_m`` at some
    step; ``nees_mean``: the trial's mean normalised estimation error squared
    (NaN without a covariance). Series (n, K), kept for per-step statistics:
    ``sq_err_position``, ``sq_err_<component>``, ``est_<component>``,
    ``true_<component>`` and ``nees``; the same three per component of
    ``derived(states)`` (named functions of the state, e.g. range, bearing,
    elevation), when given.
    """
    err = np.asarray(estimate, float) - np.asarray(truth, float)
    pos_sq = (err[..., list(position_index)] ** 2).sum(axis=-1)
    pos_err = np.sqrt(pos_sq)
    out = {"rmse": np.sqrt(pos_sq.mean(axis=1)), "final_error_m": pos_err[:, -1],
           "diverged": (pos_err > divergence_bound_m).any(axis=1), "sq_err_position": pos_sq}
    if covariance is not None:
        nees = np.einsum("nki,nki->nk", err, np.linalg.solve(covariance, err[..., None])[..., 0])
        out["nees_mean"], out["nees"] = nees.mean(axis=1), nees
    else:
        out["nees_mean"] = np.full(len(err), np.nan)
    components = {label: (np.asarray(estimate, float)[..., j], np.asarray(truth, float)[..., j])
                  for j, label in enumerate(labels)}
    if derived is not None:
        est_d, true_d = derived(np.asarray(estimate, float)), derived(np.asarray(truth, float))
        components |= {name: (est_d[name], true_d[name]) for name in est_d}
    for label, (est, true) in components.items():
        out[f"sq_err_{label}"] = (est - true) ** 2
        out[f"est_{label}"] = est
        out[f"true_{label}"] = true
    return out


def summarise_tracking(trials: pd.DataFrame, series: dict) -> pd.DataFrame:
    """One row per cell: time-averaged position RMSE with a bootstrap interval
    over trials, divergence rate (Wilson), mean NEES."""
    rows = []
    keys = ["scenario", "method", "config", "params", "snr_db"]
    for key, g in trials.groupby(keys, sort=False, dropna=False):
        n, div = len(g), int(g["diverged"].sum())
        sq = series[(key[0], key[2], key[4])]["sq_err_position"]
        lo, hi = bootstrap_statistic_interval(sq, time_averaged_rmse, resamples=500)
        d_lo, d_hi = binomial_interval(div, n)
        rows.append({**dict(zip(keys, key)), "n_trials": n, "rmse_mean": time_averaged_rmse(sq),
                     "rmse_low": lo, "rmse_high": hi, "divergence_rate": div / n,
                     "divergence_low": d_lo, "divergence_high": d_hi,
                     "nees_mean": float(np.nanmean(g["nees_mean"])) if g["nees_mean"].notna().any() else np.nan,
                     "realised_snr_db": float(np.nanmean(g["realised_snr_db"]))
                     if g["realised_snr_db"].notna().any() else np.nan})
    return pd.DataFrame(rows)


def tracking_steps(series: dict, labels) -> pd.DataFrame:
    """Per step: position RMSE, RMSE and mean estimate vs truth per component."""
    cols = {"rmse_position": per_step_rmse(series["sq_err_position"])}
    for label in labels:
        cols[f"rmse_{label}"] = per_step_rmse(series[f"sq_err_{label}"])
        cols[f"mean_est_{label}"] = series[f"est_{label}"].mean(axis=0)
        cols[f"mean_true_{label}"] = series[f"true_{label}"].mean(axis=0)
    if "nees" in series:
        cols["nees"] = series["nees"].mean(axis=0)
    return pd.DataFrame(cols)


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
