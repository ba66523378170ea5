"""Tracking metrics, per trial and per cell (docs/architecture.md, 'Metrics').

Per trial: the time-averaged position RMSE, the final error, divergence (the
position error left a bound) and the mean NEES (normalised estimation error
squared; Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, 2001, section 5.4), plus per-step series. Per cell:
the papers' time-averaged RMSE (mean over steps of the per-step RMSE across
trials) with a bootstrap interval, the divergence rate (Wilson), the mean NEES.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from bench.metrics import (binomial_interval, bootstrap_statistic_interval, by_cell, mean_realised_snr,
                           per_step_rmse, series_key, time_averaged_rmse)


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
    for keys, g in by_cell(trials):
        n, div = len(g), int(g["diverged"].sum())
        sq = series[series_key(keys)]["sq_err_position"]
        lo, hi = bootstrap_statistic_interval(sq, time_averaged_rmse, resamples=500)
        d_lo, d_hi = binomial_interval(div, n)
        rows.append({**keys, "n_trials": n, "rmse_mean": time_averaged_rmse(sq),
                     "rmse_low": lo, "rmse_high": hi, "divergence_rate": div / n,
                     "divergence_low": d_lo, "divergence_high": d_hi,
                     "nees_mean": float(np.nanmean(g["nees_mean"])) if g["nees_mean"].notna().any() else np.nan,
                     "realised_snr_db": mean_realised_snr(g)})
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
