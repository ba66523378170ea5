"""Plot extraction: the cells a CFAR declared, each made a plot in range, azimuth and radial velocity.

The HFSWR chapter goes from "the final detection result" of CFAR and peak
detection to the plots (点迹) its tracker takes, and says no more. Ours: the
peak detection already leaves one declared cell per local maximum, so every
declared cell is one plot; its range and radial velocity are the cell's
centre moved by the power-weighted centroid of the three cells about it along
that axis (x_c = x + (p[x+1] - p[x-1]) / (p[x-1] + p[x] + p[x+1]), a cell
beyond the map's edge weighing 0), its azimuth the direction of arrival the
scene gives for that cell (the scenario's DOA model). Plots are in the cells'
row-major order per scan.
"""

from __future__ import annotations

import numpy as np


def _centroid_shift(maps: np.ndarray, at: tuple[np.ndarray, ...], axis: int) -> np.ndarray:
    """(m,) the power-weighted centroid's offset from each cell ``at`` = (i, k, r, d) along ``axis`` (2 or 3)."""
    size = maps.shape[axis]
    centre = maps[at].astype(float)

    def neighbour(step: int) -> np.ndarray:
        where = list(at)
        where[axis] = at[axis] + step
        inside = (where[axis] >= 0) & (where[axis] < size)
        where[axis] = np.clip(where[axis], 0, size - 1)
        return np.where(inside, maps[tuple(where)], 0.0)

    below, above = neighbour(-1), neighbour(1)
    return (above - below) / (below + centre + above)


def extract_plots(maps: np.ndarray, detected: np.ndarray, azimuth: np.ndarray, range_start_m: float,
                  range_cell_m: float, velocity_start_m_s: float,
                  velocity_cell_m_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per scan the plots of the declared cells (module docstring).

    ``maps``, ``detected`` (bool) and ``azimuth`` (n, K, R, D). Returns
    ``cells`` (n, K, P, 2) int64 (-1 padded), ``plots`` (n, K, P, 3) [range m,
    azimuth rad, radial velocity m/s] (NaN padded) and ``counts`` (n, K); P is the
    most plots of a scan in the batch, at least 1."""
    n, K = maps.shape[:2]
    at = np.nonzero(detected)                                  # row-major: by trial, scan, range, Doppler
    counts = detected.sum(axis=(2, 3))
    P = max(1, int(counts.max(initial=0)))
    scan = at[0] * K + at[1]
    slot = np.arange(scan.size) - np.repeat(np.cumsum(counts.ravel()) - counts.ravel(), counts.ravel())
    cells = np.full((n, K, P, 2), -1, np.int64)
    plots = np.full((n, K, P, 3), np.nan)
    cells[at[0], at[1], slot] = np.stack([at[2], at[3]], axis=1)
    plots[at[0], at[1], slot] = np.stack([
        range_start_m + (at[2] + 0.5 + _centroid_shift(maps, at, 2)) * range_cell_m,
        azimuth[at],
        velocity_start_m_s + (at[3] + 0.5 + _centroid_shift(maps, at, 3)) * velocity_cell_m_s], axis=1)
    return cells, plots, counts
