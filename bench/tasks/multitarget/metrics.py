"""Multi-target tracking metrics, per scan, per trial and per cell
(docs/architecture.md, 'Metrics').

**GOSPA** (Rahmathullah, García-Fernández & Svensson, "Generalized optimal
sub-pattern assignment metric", FUSION 2017) with alpha = 2, cut-off c and
order p, between the true positions X and the confirmed tracks' positions Y
of a scan::

    d(X, Y)^p = min over assignments gamma of
                sum_{(i, j) in gamma} d(x_i, y_j)^p  +  c^p / 2 (|X| - |gamma|)  +  c^p / 2 (|Y| - |gamma|)

over partial assignments whose pairs are closer than c; it is found by
``scipy.optimize.linear_sum_assignment`` on the costs min(d, c)^p (a pair at
c or beyond costs exactly a miss plus a false track, c^p, so it is counted as
one). Its *decomposition*: the localisation term (sum over pairs of d^p), the
number of missed targets and of false tracks (each costing c^p / 2).

**OSPA** (Schuhmacher, Vo & Vo, "A consistent metric for performance evaluation
of multi-object filters", IEEE TSP 2008) from the same assignment (it
minimises the same costs): d = ((sum min(d, c)^p + c^p | |X| - |Y| |) / max(|X|, |Y|))^(1/p),
0 when both are empty.

**Time averages** per trial: GOSPA as (mean over scans of d_k^p)^(1/p) (so
the squares of the localisation, missed and false parts add up to it at
p = 2), OSPA as the mean over scans. Only confirmed tracks (status 2) are
scored; a scan's pairs with d < c *assign* a track to a target, and the
track-level metrics read that assignment:

* **initiation delay** of a target: scans from its first presence to the
  first scan a confirmed track is assigned to it (never: not initiated);
* **false track**: a confirmed track (an identity) never assigned to a
  target; the **false-track rate** is their number per hour of the run;
* **track break**: a scan at which a target present at it and at the
  previous scan, assigned at the previous scan, has no track assigned;
* **identity switch**: a scan at which a target is assigned a track whose
  identity differs from the last one assigned to it;
* **purity** of a non-false track: the fraction of its confirmed scans on
  which it is assigned to the target it is most often assigned to; a trial's
  purity is the mean over its non-false tracks.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.optimize import linear_sum_assignment

from radarbench.bench.metrics import bootstrap_mean_interval, bootstrap_statistic_interval, by_cell, mean_realised_snr

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

CONFIRMED = 2

#: per-cell columns of summary.csv: (column, per-trial column it averages)
MEANS = {"gospa": "gospa_m", "gospa_loc": "gospa_loc_m", "gospa_missed": "missed_per_scan",
         "gospa_false": "false_per_scan", "ospa": "ospa_m", "false_track_rate": "false_track_rate_per_h",
         "track_breaks": "track_breaks", "id_switches": "id_switches", "purity": "purity"}


#: per-trial columns that repeat the scene (constant within a cell), carried to summary.csv
SCENE_COLUMNS = ("scene_pd", "clutter_per_scan", "gospa_cutoff_m", "gospa_order")


def pairwise_distances(truth_xy: np.ndarray, track_xy: np.ndarray) -> np.ndarray:
    """(n, K, T, J) Euclidean distances between targets (n, K, T, 2) and
    tracks (n, K, J, 2) (NaN where either is absent)."""
    return np.linalg.norm(truth_xy[:, :, :, None, :] - track_xy[:, :, None, :, :], axis=-1)


def gospa_assignment(dist: np.ndarray, truth_on: np.ndarray, track_on: np.ndarray, cutoff: float,
                     order: float) -> dict[str, np.ndarray]:
    """Per scan GOSPA (alpha = 2) and OSPA with the assignment behind them.

    ``dist`` (n, K, T, J); ``truth_on`` (n, K, T) and ``track_on`` (n, K, J)
    say which targets and tracks exist. Returns (n, K) series ``gospa`` (m),
    ``gospa_loc`` (the localisation term, sum of d^p over pairs closer than
    c), ``gospa_missed`` and ``gospa_false`` (counts), ``ospa`` (m),
    ``n_truth``, ``n_tracks``, and ``assigned`` (n, K, T): the track slot
    assigned to each target (-1: none).
    """
    n, K, T, J = dist.shape
    c_p = float(cutoff) ** order
    loc = np.zeros((n, K))
    pairs = np.zeros((n, K), np.int64)
    assigned = np.full((n, K, T), -1, np.int64)
    cost = np.minimum(np.nan_to_num(dist, nan=np.inf), cutoff) ** order
    both = np.nonzero(truth_on.any(axis=2) & track_on.any(axis=2))
    for i, k in zip(*both):                  # one small assignment problem per scan (scipy)
        rows, cols = np.flatnonzero(truth_on[i, k]), np.flatnonzero(track_on[i, k])
        r, c = linear_sum_assignment(cost[i, k][np.ix_(rows, cols)])
        d = dist[i, k, rows[r], cols[c]]
        close = d < cutoff
        loc[i, k] = float(np.sum(d[close] ** order))
        pairs[i, k] = int(close.sum())
        assigned[i, k, rows[r[close]]] = cols[c[close]]
    m, j = truth_on.sum(axis=2), track_on.sum(axis=2)
    missed, false = m - pairs, j - pairs
    gospa = (loc + c_p / 2.0 * (missed + false)) ** (1.0 / order)
    # OSPA: the pairs at c or beyond cost c^p each, the cardinality mismatch c^p each
    far = np.minimum(m, j) - pairs
    big = np.maximum(m, j)
    ospa = np.where(big > 0, ((loc + c_p * (far + np.abs(m - j))) / np.maximum(big, 1)) ** (1.0 / order), 0.0)
    return {"gospa": gospa, "gospa_loc": loc, "gospa_missed": missed.astype(float),
            "gospa_false": false.astype(float), "ospa": ospa, "n_truth": m.astype(float),
            "n_tracks": j.astype(float), "assigned": assigned}


def _forward_fill(ids: np.ndarray) -> np.ndarray:
    """(n, K, T) the last identity >= 0 at or before each scan (-1: none yet)."""
    K = ids.shape[1]
    where = np.where(ids >= 0, np.arange(K)[None, :, None], -1)
    last = np.maximum.accumulate(where, axis=1)
    filled = np.take_along_axis(ids, np.maximum(last, 0), axis=1)
    return np.where(last >= 0, filled, -1)


def initiation(truth_on: np.ndarray, assigned_id: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, T) initiation delay (scans; NaN: never initiated or never present)
    and (n, T) whether the target is ever present."""
    K = truth_on.shape[1]
    scans = np.arange(K)[None, :, None]
    seen = truth_on.any(axis=1)
    first = np.argmax(truth_on, axis=1)
    hit = (assigned_id >= 0) & (scans >= first[:, None, :])
    found = hit.any(axis=1)
    delay = np.where(seen & found, np.argmax(hit, axis=1) - first, np.nan)
    return delay, seen


def breaks_and_switches(truth_on: np.ndarray, assigned_id: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n,) track breaks and identity switches per trial (module docstring)."""
    tracked = assigned_id >= 0
    breaks = truth_on[:, 1:] & truth_on[:, :-1] & tracked[:, :-1] & ~tracked[:, 1:]
    last = _forward_fill(assigned_id)
    switches = tracked[:, 1:] & (last[:, :-1] >= 0) & (assigned_id[:, 1:] != last[:, :-1])
    return breaks.sum(axis=(1, 2)), switches.sum(axis=(1, 2))


def track_identities(track_id: np.ndarray, confirmed: np.ndarray, assigned_id: np.ndarray,
                     truth_index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per trial: (n,) confirmed identities, false tracks among them, and mean
    purity of the others (NaN when none). ``assigned_id`` (n, K, T) is the
    identity assigned to each target, ``truth_index`` its target index (n, K, T)."""
    n = track_id.shape[0]
    trial = np.broadcast_to(np.arange(n)[:, None, None], track_id.shape)
    conf_keys, conf_scans = np.unique(np.stack([trial[confirmed], track_id[confirmed]], 1), axis=0,
                                      return_counts=True)
    hit = assigned_id >= 0
    atrial = np.broadcast_to(np.arange(n)[:, None, None], assigned_id.shape)[hit]
    triples, counts = np.unique(np.stack([atrial, assigned_id[hit], truth_index[hit]], 1), axis=0,
                                return_counts=True)
    # per (trial, id): its scans on its most frequent target
    pairs, inverse = np.unique(triples[:, :2], axis=0, return_inverse=True)
    best = np.zeros(len(pairs), np.int64)
    np.maximum.at(best, inverse.ravel(), counts)
    n_conf = np.bincount(conf_keys[:, 0], minlength=n) if len(conf_keys) else np.zeros(n, np.int64)
    if len(conf_keys) == 0:
        return n_conf, n_conf, np.full(n, np.nan)
    pos = _rows_in(conf_keys, pairs)
    real = pos >= 0
    false = np.bincount(conf_keys[~real, 0], minlength=n)
    purity = np.full(len(conf_keys), np.nan)
    purity[real] = best[pos[real]] / conf_scans[real]
    sums = np.bincount(conf_keys[real, 0], weights=purity[real], minlength=n)
    num = np.bincount(conf_keys[real, 0], minlength=n)
    return n_conf, false, np.where(num > 0, sums / np.maximum(num, 1), np.nan)


def _rows_in(keys: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Index in ``table`` (sorted unique rows of two ints) of each row of ``keys``; -1 if absent."""
    if len(table) == 0:
        return np.full(len(keys), -1)
    width = int(max(keys[:, 1].max(initial=0), table[:, 1].max(initial=0))) + 1
    flat_t, flat_k = table[:, 0] * width + table[:, 1], keys[:, 0] * width + keys[:, 1]
    at = np.clip(np.searchsorted(flat_t, flat_k), 0, len(flat_t) - 1)
    return np.where(flat_t[at] == flat_k, at, -1)


def multitarget_trial_metrics(truth: np.ndarray, state: np.ndarray, track_id: np.ndarray, status: np.ndarray,
                              *, position_index, cutoff: float, order: float,
                              scan_period_s: float) -> dict[str, np.ndarray]:
    """Per-trial columns (n,) and per-scan series (n, K) of a multi-target
    tracker's output against the truths (module docstring).

    ``truth`` (n, K, T, d) NaN where absent; ``state`` (n, K, J, d),
    ``track_id`` and ``status`` (n, K, J) as in
    :class:`bench.tasks.multitarget.MultiTargetOutput`.
    """
    pos = list(position_index)[:2]
    truth_xy, track_xy = truth[..., pos], state[..., pos]
    truth_on = np.isfinite(truth_xy).all(axis=-1)
    confirmed = (status == CONFIRMED) & np.isfinite(track_xy).all(axis=-1)
    scan = gospa_assignment(pairwise_distances(truth_xy, track_xy), truth_on, confirmed, cutoff, order)
    slot = scan.pop("assigned")
    assigned_id = np.where(slot >= 0, np.take_along_axis(track_id, np.maximum(slot, 0), axis=2), -1)
    delay, seen = initiation(truth_on, assigned_id)
    breaks, switches = breaks_and_switches(truth_on, assigned_id)
    truth_index = np.broadcast_to(np.arange(truth.shape[2]), assigned_id.shape)
    n_conf, false, purity = track_identities(track_id, confirmed, assigned_id, truth_index)
    hours = truth.shape[1] * scan_period_s / 3600.0
    p = float(order)
    return {
        "gospa_m": np.mean(scan["gospa"] ** p, axis=1) ** (1 / p),
        "gospa_loc_m": np.mean(scan["gospa_loc"], axis=1) ** (1 / p),
        "missed_per_scan": scan["gospa_missed"].mean(axis=1),
        "false_per_scan": scan["gospa_false"].mean(axis=1),
        "ospa_m": scan["ospa"].mean(axis=1),
        "targets": seen.sum(axis=1), "targets_initiated": np.isfinite(delay).sum(axis=1),
        "init_delay_sum": np.nansum(delay, axis=1),
        "init_delay_scans": np.where(np.isfinite(delay).any(axis=1),
                                     np.nansum(delay, axis=1) / np.maximum(np.isfinite(delay).sum(axis=1), 1),
                                     np.nan),
        "confirmed_tracks": n_conf, "false_tracks": false, "false_track_rate_per_h": false / hours,
        "track_breaks": breaks, "id_switches": switches, "purity": purity,
    } | scan


def _ratio(sums: np.ndarray, counts: np.ndarray) -> float:
    total = counts.sum(axis=-1)
    return sums.sum(axis=-1) / np.where(total > 0, total, np.nan)


def summarise_multitarget(trials: pd.DataFrame, series: dict) -> pd.DataFrame:
    """One row per cell: the mean over trials of each per-trial metric
    (:data:`MEANS`) with a 95 % bootstrap interval over trials; the
    initiation delay pooled over the initiated targets of all trials (its
    interval by resampling trials), the fraction of targets initiated."""
    rows = []
    for keys, g in by_cell(trials):
        row = {**keys, "n_trials": len(g), "realised_snr_db": mean_realised_snr(g)}
        row |= {c: float(g[c].iloc[0]) for c in SCENE_COLUMNS if c in g}
        for name, col in MEANS.items():
            v = g[col].to_numpy(float)
            v = v[np.isfinite(v)]
            row[f"{name}_mean"] = float(v.mean()) if len(v) else np.nan
            row[f"{name}_low"], row[f"{name}_high"] = bootstrap_mean_interval(v) if len(v) else (np.nan, np.nan)
        both = np.stack([g.init_delay_sum.to_numpy(float), g.targets_initiated.to_numpy(float)], axis=1)
        row["init_delay_mean"] = float(_ratio(both[:, 0], both[:, 1]))
        row["init_delay_low"], row["init_delay_high"] = bootstrap_statistic_interval(
            both, lambda s: _ratio(s[..., 0], s[..., 1]), resamples=500)
        row["initiated_fraction"] = float(g.targets_initiated.sum() / max(g.targets.sum(), 1))
        rows.append(row)
    return pd.DataFrame(rows)


def multitarget_steps(series: dict) -> pd.DataFrame:
    """Per scan, across trials: mean GOSPA, its parts (localisation as the p-th
    root of the mean term), OSPA, targets and confirmed tracks."""
    cols = {name: series[name].mean(axis=0) for name in ("gospa", "gospa_missed", "gospa_false", "ospa",
                                                         "n_truth", "n_tracks")}
    return pd.DataFrame(cols)
