"""Cell metrics of the detect-and-track task: the detector's per-scan Pd and
Pfa on the range-Doppler maps a chain tracks from (docs/architecture.md,
'Metrics'); the track metrics are the multi-target task's
(:mod:`bench.tasks.multitarget.metrics`), called, not repeated.

**Cell Pd**: over the (scan, target) pairs whose target lies in the map, the
fraction with a detected cell within ``guard_cells`` (range, Doppler) of the
target's true cell (an echo spread over neighbouring cells peaks within one
cell of it). **Cell Pfa**: detected cells farther than the guard from every
target in the map, over the cells so left (per scan: R D minus the union of
the targets' guard boxes). Both are ratios counted within trials, so their
intervals are :func:`bench.metrics.clustered_rate_interval`'s (clustered by
trial).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from radarbench.bench.metrics import by_cell, clustered_rate_interval

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

#: per-trial (events, opportunities) columns -> the summary rate they give
RATES = {"cell_pd": ("cell_hits", "cell_targets"), "cell_pfa": ("cell_false", "cell_free")}


def guard_boxes(target_cells: np.ndarray, shape: tuple[int, int], guard: tuple[int, int]) -> np.ndarray:
    """(n, K, R, D) bool: the cells within ``guard`` of a target's cell (targets at -1 are absent)."""
    n, K, T, _ = target_cells.shape
    R, D = shape
    box = np.zeros((n, K, R + 2 * guard[0] + 1, D + 2 * guard[1] + 1), bool)
    present = target_cells[..., 0] >= 0
    i, k, t = np.nonzero(present)
    r, d = target_cells[i, k, t, 0], target_cells[i, k, t, 1]
    for dr in range(2 * guard[0] + 1):               # a few shifts: the box, cell by cell
        for dd in range(2 * guard[1] + 1):
            box[i, k, r + dr, d + dd] = True
    return box[:, :, guard[0]:guard[0] + R, guard[1]:guard[1] + D]


def cell_metrics(target_cells: np.ndarray, detected: np.ndarray, shape: tuple[int, int],
                 guard: tuple[int, int]) -> dict[str, np.ndarray]:
    """Per-scan series (n, K) of hits, targets in the map, false cells and free cells,
    and per-trial sums (n,) of each plus the trial's cell Pd and Pfa.

    ``target_cells`` (n, K, T, 2) true (range, Doppler) cells, -1 where absent;
    ``detected`` (n, K, Q, 2) the declared cells, -1 padded."""
    present = target_cells[..., 0] >= 0                                           # (n, K, T)
    valid = detected[..., 0] >= 0                                                 # (n, K, Q)
    gap = np.abs(target_cells[:, :, :, None, :] - detected[:, :, None, :, :])     # (n, K, T, Q, 2)
    near = (gap[..., 0] <= guard[0]) & (gap[..., 1] <= guard[1]) & present[..., None] & valid[:, :, None, :]
    hits = near.any(axis=3).sum(axis=2)
    false = (valid & ~near.any(axis=2)).sum(axis=2)
    free = shape[0] * shape[1] - guard_boxes(target_cells, shape, guard).sum(axis=(2, 3))
    series = {"cell_hits_scan": hits.astype(float), "cell_targets_scan": present.sum(axis=2).astype(float),
              "cell_false_scan": false.astype(float), "cell_free_scan": free.astype(float)}
    sums = {name.removesuffix("_scan"): s.sum(axis=1) for name, s in series.items()}
    rates = {rate: sums[e] / np.where(sums[o] > 0, sums[o], np.nan) for rate, (e, o) in RATES.items()}
    return series | sums | rates


def summarise_cells(trials: pd.DataFrame) -> pd.DataFrame:
    """Per cell of the summary (scenario config, method config, SNR): the pooled cell Pd
    and Pfa with intervals clustered by trial."""
    rows = []
    for keys, g in by_cell(trials):
        row = dict(keys)
        for rate, (e, o) in RATES.items():
            events, opportunities = g[e].to_numpy(float), g[o].to_numpy(float)
            total = opportunities.sum()
            row[f"{rate}_mean"] = float(events.sum() / total) if total > 0 else np.nan
            row[f"{rate}_low"], row[f"{rate}_high"] = clustered_rate_interval(events, opportunities)
        rows.append(row)
    return pd.DataFrame(rows)
