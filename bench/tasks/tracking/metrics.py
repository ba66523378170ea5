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

from radarbench.bench.batched import inner
from radarbench.bench.metrics import (binomial_interval, bootstrap_mean_interval, bootstrap_statistic_interval, by_cell,
                           clustered_rate_interval, mean_over_present, mean_realised_snr, per_step_rmse,
                           series_key, time_averaged_rmse)

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True


def tracking_trial_metrics(estimate: np.ndarray, truth: np.ndarray, *, position_index, labels,
                           covariance: np.ndarray | None, divergence_bound_m: float,
                           derived=None, valid: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per-trial tracking metrics.

    ``rmse``: the trial's position RMSE over time; ``final_error_m``;
    ``diverged``: the position error exceeded ``divergence_bound_m`` at some
    step; ``nees_mean``: the trial's mean normalised estimation error squared
    (NaN without a covariance). Series (n, K), kept for per-step statistics:
    ``sq_err_position``, ``sq_err_<component>``, ``est_<component>``,
    ``true_<component>`` and ``nees``; the same three per component of
    ``derived(states)`` (named functions of the state, e.g. range, bearing,
    elevation), when given.

    ``valid`` (n, K) bool: the steps each trial has (a ragged batch; None: all).
    Every metric is over a trial's valid steps only (``final_error_m`` at its last
    one) and every series is NaN at the others, so per-step statistics count a step
    over the trials that have it (:func:`bench.metrics.mean_over_present`).
    """
    estimate, truth = np.asarray(estimate, float), np.asarray(truth, float)
    if valid is not None:                    # a missing step: no estimate, no truth (NaN throughout)
        estimate = np.where(valid[..., None], estimate, np.nan)
        truth = np.where(valid[..., None], truth, np.nan)
    err = estimate - truth
    pos_sq = (err[..., list(position_index)] ** 2).sum(axis=-1)
    pos_err = np.sqrt(pos_sq)
    n, K = pos_sq.shape
    last = np.full(n, K - 1) if valid is None else K - 1 - np.argmax(valid[:, ::-1], axis=1)
    out = {"rmse": np.sqrt(mean_over_present(pos_sq, axis=1)), "final_error_m": pos_err[np.arange(n), last],
           "diverged": (pos_err > divergence_bound_m).any(axis=1), "sq_err_position": pos_sq}
    if covariance is not None:
        nees = inner(err, np.linalg.solve(covariance, np.nan_to_num(err)[..., None])[..., 0])
        out["nees_mean"], out["nees"] = mean_over_present(nees, axis=1), nees
    else:
        out["nees_mean"] = np.full(len(err), np.nan)
    components = {label: (estimate[..., j], truth[..., j]) for j, label in enumerate(labels)}
    if derived is not None:
        est_d, true_d = derived(estimate), derived(truth)
        components |= {name: (est_d[name], true_d[name]) for name in est_d}
    for label, (est, true) in components.items():
        out[f"sq_err_{label}"] = (est - true) ** 2
        out[f"est_{label}"] = est
        out[f"true_{label}"] = true
    return out


def bound_series(bound: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
    """The scene's position bound (n, K) as a series, NaN at the steps a trial does not have."""
    bound = np.asarray(bound, float)
    return bound if valid is None else np.where(valid, bound, np.nan)


def summarise_bound(rmse: float, cell_series: dict) -> dict:
    """``pcrb_rmse``: the posterior Cramér-Rao bound time-averaged as the RMSE is (mean over
    steps of the root of its mean over trials); ``efficiency``: pcrb_rmse / RMSE (1 at the
    bound); empty without a bound."""
    if "pcrb_position" not in cell_series:
        return {}
    bound = time_averaged_rmse(cell_series["pcrb_position"])
    return {"pcrb_rmse": bound, "efficiency": bound / rmse if rmse > 0 else np.nan}


def summarise_tracking(trials: pd.DataFrame, series: dict) -> pd.DataFrame:
    """One row per cell: time-averaged position RMSE with a bootstrap interval
    over trials, divergence rate (Wilson), mean NEES; the bound and the efficiency
    where the scene has a bound (:func:`summarise_bound`)."""
    rows = []
    for keys, g in by_cell(trials):
        n, div = len(g), int(g["diverged"].sum())
        sq = series[series_key(keys)]["sq_err_position"]
        lo, hi = bootstrap_statistic_interval(sq, time_averaged_rmse, resamples=500)
        d_lo, d_hi = binomial_interval(div, n)
        rmse = time_averaged_rmse(sq)
        rows.append({**keys, "n_trials": n, "rmse_mean": rmse,
                     "rmse_low": lo, "rmse_high": hi, "divergence_rate": div / n,
                     "divergence_low": d_lo, "divergence_high": d_hi,
                     "nees_mean": float(np.nanmean(g["nees_mean"])) if g["nees_mean"].notna().any() else np.nan,
                     "realised_snr_db": mean_realised_snr(g)} | summarise_maneuvers(g, series[series_key(keys)])
                    | summarise_bound(rmse, series[series_key(keys)]))
    return pd.DataFrame(rows)


def tracking_steps(series: dict, labels) -> pd.DataFrame:
    """Per step: position RMSE, RMSE and mean estimate vs truth per component."""
    cols = {"rmse_position": per_step_rmse(series["sq_err_position"])}
    for label in labels:
        cols[f"rmse_{label}"] = per_step_rmse(series[f"sq_err_{label}"])
        cols[f"mean_est_{label}"] = mean_over_present(series[f"est_{label}"], axis=0)
        cols[f"mean_true_{label}"] = mean_over_present(series[f"true_{label}"], axis=0)
    if "nees" in series:
        cols["nees"] = mean_over_present(series["nees"], axis=0)
    if "pcrb_position" in series:                   # the bound per step, on the RMSE's scale
        cols["pcrb_position"] = per_step_rmse(series["pcrb_position"])
    return pd.DataFrame(cols | maneuver_steps(series))


# ------------------------------------------------ maneuvering targets (scenes with a maneuver mask)
#
# A scenario that marks its maneuvers (TrackingScene.maneuver_mask, maneuver_onset_steps)
# gets the position RMSE split into quiet and maneuvering steps; a tracker that reports
# its model switches (traces ``switch`` and ``mode``: 1.0 where a chi-square test chose
# the maneuver model, where it is in use) gets its switch times scored against the true
# onsets. Scenes without the fields (glint) get none of these columns.

#: the traces of a switching tracker kept as series (per-step means in steps.csv)
SWITCH_TRACES = ("mode", "switch", "q_k")
#: steps from the true onset over which ``rmse_onset_m`` is taken: the detection delay
#: of a chi-square switch plus the transient of the model change (a re-initialisation)
ONSET_WINDOW_STEPS = 10


def segment_rms(sq: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per trial, the root mean of ``sq`` (n, K) over the steps where ``mask`` (n, K); NaN without any."""
    count = mask.sum(axis=1)
    total = np.where(mask, sq, 0.0).sum(axis=1)
    return np.sqrt(np.divide(total, count, out=np.full(len(sq), np.nan), where=count > 0))


def maneuver_trial_metrics(pos_sq: np.ndarray, mask: np.ndarray, onsets: np.ndarray | None,
                           traces: dict, valid: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per-trial metrics against the true maneuvers.

    ``rmse_quiet_m`` / ``rmse_maneuver_m``: the trial's position RMS error over
    its quiet / maneuvering steps (``mask`` (n, K) bool); ``rmse_onset_m``: over
    the first :data:`ONSET_WINDOW_STEPS` steps from the first onset, where a
    switching tracker detects and changes its model (NaN without an onset); series
    ``maneuvering`` and ``onset_window`` (the masks, for the per-step splits). With a ``switch``
    trace: ``switch_detected`` (a switch at or after the first onset, before
    the maneuver's last step; NaN without an onset), ``switch_delay_steps``
    (its step minus the onset), ``false_switches`` (switches before the first
    onset, or anywhere without one) over ``quiet_steps`` (those steps). With
    a ``q_k`` trace: its mean over quiet and maneuvering steps. ``valid`` (n, K)
    bool: the steps each trial has (a ragged batch; None: all): every segment is
    cut to them, and the series are NaN (``maneuvering``, the traces) or 0
    (``onset_window``) at the others.
    """
    mask = np.asarray(mask, bool)
    n, K = mask.shape
    present = np.ones((n, K), bool) if valid is None else np.asarray(valid, bool)
    quiet, maneuver = ~mask & present, mask & present
    out = {"rmse_quiet_m": segment_rms(pos_sq, quiet), "rmse_maneuver_m": segment_rms(pos_sq, maneuver),
           "maneuvering": np.where(present, mask.astype(float), np.nan)}
    steps = np.arange(K)
    first = np.full(n, K) if onsets is None or onsets.shape[1] == 0 else np.asarray(onsets)[:, 0]
    before = (steps[None, :] < first[:, None]) & present
    onset_window = (steps[None, :] >= first[:, None]) & (steps[None, :] < first[:, None] + ONSET_WINDOW_STEPS) \
        & present
    out["rmse_onset_m"] = segment_rms(pos_sq, onset_window)
    out["onset_window"] = onset_window.astype(float)
    if "switch" in traces:
        switch = np.asarray(traces["switch"]) > 0.5
        last = np.where(mask.any(axis=1), K - 1 - np.argmax(mask[:, ::-1], axis=1), -1)
        window = (steps[None, :] >= first[:, None]) & (steps[None, :] <= last[:, None])
        hit = (switch & window).any(axis=1)
        has_onset = first < K
        out["switch_detected"] = np.where(has_onset, hit.astype(float), np.nan)
        out["switch_delay_steps"] = np.where(hit, np.argmax(switch & window, axis=1) - first, np.nan)
        out["false_switches"] = (switch & before).sum(axis=1).astype(float)
        out["quiet_steps"] = before.sum(axis=1).astype(float)
    for name in SWITCH_TRACES:
        if name in traces:
            out[name] = np.where(present, np.asarray(traces[name], float), np.nan)
    if "q_k" in traces:
        q = np.asarray(traces["q_k"], float)
        out["q_quiet_mean"] = _segment_mean(q, quiet)
        out["q_maneuver_mean"] = _segment_mean(q, maneuver)
    return out


def _segment_mean(x: np.ndarray, mask: np.ndarray) -> np.ndarray:
    count = mask.sum(axis=1)
    return np.divide(np.where(mask, x, 0.0).sum(axis=1), count, out=np.full(len(x), np.nan), where=count > 0)


def segment_time_averaged_rmse(stacked: np.ndarray):
    """Time-averaged RMSE over a segment: ``stacked`` (n, K, 2) holds squared
    errors and a 0/1 segment mask; per step, the RMSE over the trials in the
    segment at that step, averaged over the steps where any trial is. Of a stack
    (r, n, K, 2) (bootstrap resamples), one value per data set (r,)."""
    sq, mask = stacked[..., 0], stacked[..., 1] > 0.5
    count = mask.sum(axis=-2)
    total = np.where(mask, sq, 0.0).sum(axis=-2)
    with np.errstate(invalid="ignore", divide="ignore"):
        per_step = np.where(count > 0, np.sqrt(total / np.maximum(count, 1)), np.nan)
        seen = (count > 0).sum(axis=-1)
        value = np.where(seen > 0, np.nansum(per_step, axis=-1) / np.maximum(seen, 1), np.nan)
    return float(value) if np.ndim(value) == 0 else value


def summarise_maneuvers(g: pd.DataFrame, cell_series: dict) -> dict:
    """A cell's quiet / maneuvering / onset-window split (time-averaged RMSE, bootstrap intervals over trials),
    switch detection (Wilson), delay (bootstrap) and false-switch rate per quiet step
    (ratio-estimator interval over trials); empty without a maneuver mask."""
    if "maneuvering" not in cell_series:
        return {}
    sq, mask = cell_series["sq_err_position"], cell_series["maneuvering"]
    row = {}
    segments = (("rmse_quiet", 1.0 - mask), ("rmse_maneuver", mask), ("rmse_onset", cell_series["onset_window"]))
    for name, seg in segments:
        stacked = np.stack([sq, seg], axis=-1)
        row[name] = segment_time_averaged_rmse(stacked)
        row[f"{name}_low"], row[f"{name}_high"] = bootstrap_statistic_interval(
            stacked, segment_time_averaged_rmse, resamples=500) if np.any(seg) else (np.nan, np.nan)
    if "switch_detected" in g:
        det = g["switch_detected"].dropna()
        row["switch_pd"] = float(det.mean()) if len(det) else np.nan
        row["switch_pd_low"], row["switch_pd_high"] = binomial_interval(int(det.sum()), len(det))
        delay = g["switch_delay_steps"].to_numpy(float)
        row["switch_delay_mean"] = float(np.nanmean(delay)) if np.isfinite(delay).any() else np.nan
        row["switch_delay_low"], row["switch_delay_high"] = bootstrap_mean_interval(delay)
        fs, qs = g["false_switches"].to_numpy(float), g["quiet_steps"].to_numpy(float)
        row["false_switch_rate"] = float(fs.sum() / qs.sum()) if qs.sum() > 0 else np.nan
        row["false_switch_low"], row["false_switch_high"] = clustered_rate_interval(fs, qs)
    if "q_maneuver_mean" in g:
        row["q_quiet_mean"] = float(np.nanmean(g["q_quiet_mean"])) if g["q_quiet_mean"].notna().any() else np.nan
        row["q_maneuver_mean"] = float(np.nanmean(g["q_maneuver_mean"])) \
            if g["q_maneuver_mean"].notna().any() else np.nan
        row["q_maneuver_low"], row["q_maneuver_high"] = bootstrap_mean_interval(g["q_maneuver_mean"].to_numpy(float))
    return row


def maneuver_steps(series: dict) -> dict[str, np.ndarray]:
    """Per-step columns of a maneuvering cell: the fraction of trials maneuvering, and the
    mean of each switching trace (fraction in the maneuver model, switch rate, mean Q_k)."""
    cols = {}
    if "maneuvering" in series:
        cols["maneuver_fraction"] = mean_over_present(series["maneuvering"], axis=0)
    for name in SWITCH_TRACES:
        if name in series:
            cols[f"{name}_mean"] = mean_over_present(series[name], axis=0)
    return cols
