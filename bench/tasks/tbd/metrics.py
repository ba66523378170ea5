"""Track-before-detect metrics, per trial and per cell (docs/architecture.md, 'Metrics').

A scene is a *track detection* when its score reaches the threshold and the
backtracked track lies on the true cells in at least two frames; the position
error is the distance from the backtracked cell's centre to the true position.
Per cell: Pd (Wilson) and the average per-frame RMSE over detected trials and,
as the multi-frame DP-TBD paper (and Tonissen & Evans, IEEE TAES 32(4), 1996)
compute it, over every Monte Carlo run, with bootstrap intervals; and the
offset between our SNR axis and one scaled by a unit-variance AR innovation.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from radarbench.bench.metrics import (binomial_interval, bootstrap_statistic_interval, by_cell, mean_realised_snr,
                           series_key, time_averaged_rmse)

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True


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


def summarise_tbd(trials: pd.DataFrame, series: dict) -> pd.DataFrame:
    """One row per cell: Pd (Wilson) and the average per-frame RMSE (bootstrap
    interval over trials) twice: ``rmse_*`` over detected trials only, and
    ``rmse_all_*`` over every Monte Carlo run, detected or not, as Tonissen-type
    DP-TBD papers compute it: RMSE(k) = sqrt((1/MC) Σ_i ‖l̂_i(k) − l(k)‖²),
    averaged over k ("average RMSE")."""
    rows = []
    for keys, g in by_cell(trials):
        n, hits = len(g), int(g["detected"].sum())
        lo, hi = binomial_interval(hits, n)
        sq_all = series[series_key(keys)]["sq_err_m2"]
        sq = sq_all[g["detected"].to_numpy(bool)]
        r_lo, r_hi = bootstrap_statistic_interval(sq, time_averaged_rmse, resamples=500)
        a_lo, a_hi = bootstrap_statistic_interval(sq_all, time_averaged_rmse, resamples=500)
        rows.append({**keys, "n_trials": n, "pd": hits / n, "pd_low": lo, "pd_high": hi,
                     "rmse_mean": time_averaged_rmse(sq), "rmse_low": r_lo, "rmse_high": r_hi,
                     "rmse_all_mean": time_averaged_rmse(sq_all), "rmse_all_low": a_lo, "rmse_all_high": a_hi,
                     "snr_offset_unit_innovation_db": float(g["snr_offset_unit_innovation_db"].iloc[0])
                     if "snr_offset_unit_innovation_db" in g else np.nan,
                     "threshold": float(g["threshold"].iloc[0]),
                     "realised_snr_db": mean_realised_snr(g)})
    return pd.DataFrame(rows)
