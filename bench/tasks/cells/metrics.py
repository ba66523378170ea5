"""Cell-level detection metrics, per map and per summary cell (docs/architecture.md, 'Metrics').

Definitions (the HFSWR chapter's CFAR comparison made measurable):

* **Detection of a target**: its cell's statistic reaches the threshold
  (``statistic >= threshold``). Pd is counted per clutter region of the
  target's cell over *isolated* targets; targets placed as a close pair (the
  scene's ``target_paired``) are counted apart (``pd_paired``): the *masking*
  of a target by its neighbour is ``pd_paired`` against the isolated targets'
  Pd in the same (homogeneous) region at the same SNR.
* **False alarm**: a declared cell outside every target's *guard box* (the
  scene's ``guard_cells`` = (g_r, g_d): cells within g_r range cells and g_d
  Doppler cells of a target, the target cell included). The per-cell Pfa is
  false alarms over the cells outside the guard boxes ("clear cells"), per
  region and over the whole map; false alarms per map are the count.
* Intervals: Pd and Pfa are ratios over maps (hits over targets, false alarms
  over clear cells), and decisions within a map are correlated (neighbouring
  cells share reference cells; targets share the map's noise estimate), so
  their 95 % intervals are the ratio-estimator intervals clustered by map
  (:func:`bench.metrics.clustered_rate_interval`); false alarms per map carry
  a bootstrap interval over maps.
* **The ideal detector**: the known-noise detector thresholds z / N (N the
  cell's true noise-plus-clutter power) at τ = ln(1/Pfa), exactly Pfa for
  exponential noise. Its Pd in closed form: Swerling 1, Pd = Pfa^(1/(1+S));
  non-fluctuating, Pd = Q_1(√(2S), √(2τ)) (2z/N is non-central χ² with 2
  degrees of freedom and non-centrality 2S). **CFAR loss** (dB): the SNR at
  which the detector's Pd reaches 0.5 minus the SNR at which the ideal
  detector's does, at the same per-cell Pfa (the requested one).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import optimize, stats

from radarbench.bench.metrics import bootstrap_mean_interval, by_cell, clustered_rate_interval, mean_realised_snr

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

#: the clutter regions the task knows, in label order of the built-in scenario; the clutter
#: edge's band is one region, or its two sides (below the step / from it) when a scenario splits it
REGION_NAMES = ("homogeneous", "bragg", "interference", "clutter-edge", "clutter-edge-quiet", "clutter-edge-raised")
#: the target group of a closely spaced (paired) target, after the regions' indices
PAIRED_GROUP = len(REGION_NAMES)


def slug(region: str) -> str:
    """A region's name as a column suffix (``clutter-edge`` -> ``clutter_edge``)."""
    return region.replace("-", "_")


def _with_interval(name: str) -> tuple[str, str, str]:
    return name, f"{name}_low", f"{name}_high"


SUMMARY_COLUMNS = ("n_trials", *_with_interval("pd"), *_with_interval("pfa"), "threshold", "realised_snr_db",
                   "false_alarms_per_map", "false_alarms_per_map_low", "false_alarms_per_map_high",
                   *(c for r in REGION_NAMES for c in (*_with_interval(f"pd_{slug(r)}"),
                                                       *_with_interval(f"pfa_{slug(r)}"))),
                   *_with_interval("pd_paired"), "targets_per_map", "swerling")


def guard_mask(shape: tuple[int, int, int], target_cells: np.ndarray, guard_cells: tuple[int, int]) -> np.ndarray:
    """(n, R, D) bool: the cells within ``guard_cells`` (range, Doppler) of any target."""
    n, R, D = shape
    mask = np.zeros(shape, bool)
    if target_cells.shape[1] == 0:
        return mask
    trial = np.arange(n)[:, None]
    gr, gd = guard_cells
    for dr in range(-gr, gr + 1):        # loops over the box offsets, vectorised over maps and targets
        rows = np.clip(target_cells[..., 0] + dr, 0, R - 1)
        for dd in range(-gd, gd + 1):
            mask[trial, rows, np.clip(target_cells[..., 1] + dd, 0, D - 1)] = True
    return mask


def target_groups(region_labels: np.ndarray, region_names: tuple[str, ...], target_cells: np.ndarray,
                  target_paired: np.ndarray) -> np.ndarray:
    """(n, T) int: each target's group, the index in :data:`REGION_NAMES` of
    its cell's region, or :data:`PAIRED_GROUP` for a paired target."""
    vocab = np.array([REGION_NAMES.index(name) for name in region_names], np.int64)
    group = vocab[region_labels[target_cells[..., 0], target_cells[..., 1]]]
    return np.where(target_paired, PAIRED_GROUP, group)


def declared_cells(statistic: np.ndarray, threshold: float) -> np.ndarray:
    """``statistic >= threshold`` as the calibration reads it (in float64: the
    order statistics are float64), without a float64 copy of the maps: a
    float32 statistic is compared with the smallest float32 at or above the
    threshold (NumPy would otherwise round the threshold to float32, and a
    threshold just above a capped statistic would declare every capped cell)."""
    statistic = np.asarray(statistic)
    if statistic.dtype == np.float32 and np.isfinite(threshold):
        t = np.float32(threshold)
        if float(t) < threshold:
            t = np.nextafter(t, np.float32(np.inf))
        return statistic >= t
    return statistic >= threshold


def cell_trial_metrics(statistic: np.ndarray, threshold: float, *, region_labels: np.ndarray,
                       region_names: tuple[str, ...], target_cells: np.ndarray, target_paired: np.ndarray,
                       target_snr_db: np.ndarray, guard_cells: tuple[int, int],
                       swerling: int) -> dict[str, np.ndarray]:
    """Per-map counts (module docstring): ``hits``/``targets`` over every
    target, per region ``hits_<r>``/``targets_<r>`` over isolated targets,
    ``hits_paired``/``targets_paired``, ``false_alarms``/``clear_cells`` and
    per region ``false_alarms_<r>``/``clear_cells_<r>``; the series
    ``target_statistic`` and ``target_group`` (n, T) for ROC curves."""
    statistic = np.asarray(statistic)
    n = statistic.shape[0]
    declared = declared_cells(statistic, threshold)
    trial = np.arange(n)[:, None]
    tstat = statistic[trial, target_cells[..., 0], target_cells[..., 1]].astype(np.float64)
    hit = tstat >= threshold
    group = target_groups(region_labels, region_names, target_cells, target_paired)
    clear = ~guard_mask(statistic.shape, target_cells, guard_cells)
    false = declared & clear
    out = {"hits": hit.sum(axis=1), "targets": np.full(n, hit.shape[1]),
           "hit_fraction": hit.mean(axis=1) if hit.shape[1] else np.full(n, np.nan),
           "false_alarms": false.sum(axis=(1, 2)), "clear_cells": clear.sum(axis=(1, 2)),
           "swerling": np.full(n, int(swerling)),
           "target_snr_db": (target_snr_db.mean(axis=1) if target_snr_db.shape[1] else np.full(n, np.nan))}
    for g, region in enumerate(REGION_NAMES):
        in_group = group == g
        out[f"hits_{slug(region)}"] = (hit & in_group).sum(axis=1)
        out[f"targets_{slug(region)}"] = in_group.sum(axis=1)
        where = (np.asarray(region_names) == region)[region_labels] if region in region_names \
            else np.zeros(region_labels.shape, bool)
        out[f"false_alarms_{slug(region)}"] = (false & where).sum(axis=(1, 2))
        out[f"clear_cells_{slug(region)}"] = (clear & where).sum(axis=(1, 2))
    out["hits_paired"] = (hit & (group == PAIRED_GROUP)).sum(axis=1)
    out["targets_paired"] = (group == PAIRED_GROUP).sum(axis=1)
    out = {k: np.asarray(v) for k, v in out.items()}
    out["target_statistic"] = tstat
    out["target_group"] = group.astype(np.int64)
    return out


def ratio_with_interval(events: pd.Series, opportunities: pd.Series) -> tuple[float, float, float]:
    """A rate over maps with its map-clustered interval; NaN without opportunities."""
    e, o = events.to_numpy(float), opportunities.to_numpy(float)
    if o.sum() <= 0:
        return (np.nan, np.nan, np.nan)
    return (float(e.sum() / o.sum()), *clustered_rate_interval(e, o))


def summarise_cells(trials: pd.DataFrame, series: dict) -> pd.DataFrame:
    """One row per (scenario config, method config, SNR): Pd over every
    target and per region, Pd of paired targets, per-cell Pfa over the clear
    cells and per region, false alarms per map (module docstring)."""
    rows = []
    for keys, g in by_cell(trials):
        fa_lo, fa_hi = bootstrap_mean_interval(g["false_alarms"].to_numpy(float))
        row = {**keys, "n_trials": len(g)}
        row.update(zip(_with_interval("pd"), ratio_with_interval(g["hits"], g["targets"])))
        row.update(zip(_with_interval("pfa"), ratio_with_interval(g["false_alarms"], g["clear_cells"])))
        row.update({"threshold": float(g["threshold"].iloc[0]), "realised_snr_db": mean_realised_snr(g),
                    "false_alarms_per_map": float(g["false_alarms"].mean()), "false_alarms_per_map_low": fa_lo,
                    "false_alarms_per_map_high": fa_hi, "targets_per_map": float(g["targets"].mean()),
                    "swerling": int(g["swerling"].iloc[0])})
        for region in map(slug, REGION_NAMES):
            row.update(zip(_with_interval(f"pd_{region}"),
                           ratio_with_interval(g[f"hits_{region}"], g[f"targets_{region}"])))
            row.update(zip(_with_interval(f"pfa_{region}"),
                           ratio_with_interval(g[f"false_alarms_{region}"], g[f"clear_cells_{region}"])))
        row.update(zip(_with_interval("pd_paired"), ratio_with_interval(g["hits_paired"], g["targets_paired"])))
        rows.append(row)
    return pd.DataFrame(rows)


# ------------------------------------------------------------------ the ideal (known-noise) detector

def ideal_pd(snr_db, pfa: float, swerling: int) -> np.ndarray:
    """Pd of the known-noise detector (z / N >= ln(1/pfa)) at per-cell ``pfa``
    for a target of mean SNR ``snr_db`` (module docstring)."""
    s = 10.0 ** (np.asarray(snr_db, float) / 10.0)
    tau = -np.log(pfa)
    if swerling == 1:
        return np.exp(-tau / (1.0 + s))
    return stats.ncx2.sf(2.0 * tau, 2, 2.0 * s)


def ideal_snr_at_pd(pfa: float, swerling: int, pd: float = 0.5) -> float:
    """SNR (dB) at which the ideal detector reaches ``pd`` at per-cell ``pfa``."""
    if swerling == 1:     # pd = pfa^(1/(1+S))  =>  S = ln(pfa)/ln(pd) - 1
        return float(10.0 * np.log10(np.log(pfa) / np.log(pd) - 1.0))
    return float(optimize.brentq(lambda x: ideal_pd(x, pfa, 0) - pd, -30.0, 60.0, xtol=1e-10))
