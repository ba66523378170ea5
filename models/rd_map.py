"""Range-Doppler map backgrounds of an HF surface-wave radar: mean power, clutter regions, targets.

The backgrounds the HFSWR chapter on target detection and tracking names for
CFAR detection (first-order sea clutter, ionospheric interference, a clutter
edge) as mean-power maps over (range, Doppler) cells, the clutter-region
label of every cell, a fixed target layout, and the square-law power of a
target cell. Used by the ``rd-map`` scenario (scenarios/rd_map.py); the
shapes are ours, the chapter prints none (bench/presets/cfar.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: a clutter component labels a cell when its mean power is at least this far
#: from the thermal noise power (dB): a tenth of the noise already biases a
#: CA-CFAR estimate by 10 %
REGION_LEVEL_DB = -10.0


@dataclass(frozen=True, eq=False)
class BackgroundParts:
    """The components of the mean power map, each (R, D), thermal noise = 1."""

    bragg: np.ndarray
    interference: np.ndarray
    level: np.ndarray          # thermal noise times the clutter-edge step

    @property
    def total(self) -> np.ndarray:
        return self.level + self.bragg + self.interference


def background_power(shape: tuple[int, int], *, bragg=None, interference=None, edge=None) -> BackgroundParts:
    """Mean power of every cell, by component (thermal noise power 1).

    ``bragg`` = (offset_bins, spread_bins, cnr_near_db, cnr_far_db,
    asymmetry_db): two Gaussian lines in Doppler at D//2 ± offset, std
    spread, the positive line's peak CNR linear in dB from the first range
    cell (near) to the last (far), the negative line asymmetry_db weaker.
    ``interference`` = (range_start, range_cells, doppler_std_bins, inr_db):
    a band over those range cells, Gaussian in Doppler about D//2.
    ``edge`` = (range_cell, step_db): the noise level times 10^(step/10)
    from that range cell on. None: the component is absent (zeros).
    """
    R, D = shape
    doppler = np.arange(D, dtype=float) - D // 2
    zeros = np.zeros(shape)
    bragg_power = zeros
    if bragg is not None:
        offset, spread, near_db, far_db, asym_db = bragg
        cnr_db = np.linspace(near_db, far_db, R)[:, None]
        line = lambda centre: np.exp(-0.5 * ((doppler - centre) / spread) ** 2)[None, :]  # noqa: E731
        bragg_power = 10.0 ** (cnr_db / 10.0) * (line(offset) + 10.0 ** (-asym_db / 10.0) * line(-offset))
    interference_power = zeros
    if interference is not None:
        start, cells, std, inr_db = interference
        band = np.zeros((R, 1))
        band[start:start + cells] = 1.0
        interference_power = band * 10.0 ** (inr_db / 10.0) * np.exp(-0.5 * (doppler / std) ** 2)[None, :]
    level = np.ones(shape)
    if edge is not None:
        range_cell, step_db = edge
        level[range_cell:] = 10.0 ** (step_db / 10.0)
    return BackgroundParts(bragg=bragg_power, interference=interference_power, level=level)


@dataclass(frozen=True)
class RegionLevels:
    """Where the clutter-edge region lies: range cells within ``edge_band_cells``
    of ``edge_range_cell`` (None: no edge); ``edge_sides``: label its two
    sides as two regions, "clutter-edge-quiet" below the step and
    "clutter-edge-raised" from it, so that each gets its own targets."""

    edge_range_cell: int | None = None
    edge_band_cells: int = 6
    edge_sides: bool = False


def label_regions(parts: BackgroundParts, names: tuple[str, ...], edge: RegionLevels) -> np.ndarray:
    """(R, D) int8 region labels, indices into ``names`` (which holds
    "homogeneous", "bragg", "interference", "clutter-edge", and with
    ``edge.edge_sides`` "clutter-edge-quiet", "clutter-edge-raised"): Bragg or
    interference where that component is at least :data:`REGION_LEVEL_DB`
    over the thermal noise (the stronger wins), else clutter-edge within the
    band around the step (or its side of the step), else homogeneous."""
    R, D = parts.level.shape
    floor = 10.0 ** (REGION_LEVEL_DB / 10.0)
    labels = np.full((R, D), names.index("homogeneous"), np.int8)
    if edge.edge_range_cell is not None:
        step = edge.edge_range_cell
        lo, hi = max(step - edge.edge_band_cells, 0), step + edge.edge_band_cells
        if edge.edge_sides:
            labels[lo:step] = names.index("clutter-edge-quiet")
            labels[step:hi] = names.index("clutter-edge-raised")
        else:
            labels[lo:hi] = names.index("clutter-edge")
    bragg = (parts.bragg >= floor) & (parts.bragg >= parts.interference)
    interference = (parts.interference >= floor) & ~bragg
    labels[bragg] = names.index("bragg")
    labels[interference] = names.index("interference")
    return labels


def _far_enough(cell: np.ndarray, placed: list, spacing: int) -> bool:
    return not placed or int(np.abs(np.asarray(placed) - cell).max(axis=1).min()) >= spacing


def place_targets(labels: np.ndarray, names: tuple[str, ...], *, per_region: int, pairs: int,
                  pair_offset: tuple[int, int], spacing: int, margin: int,
                  seed: int) -> tuple[np.ndarray, np.ndarray, str]:
    """A fixed target layout: ``per_region`` isolated targets in each region
    present (smallest region first), then ``pairs`` pairs in the homogeneous
    region (second target at ``pair_offset`` from the first, also
    homogeneous). Targets that are not partners are at least ``spacing``
    apart (Chebyshev), every target at least ``margin`` from the border.
    Candidates are each region's cells in a shuffle of ``seed``. Returns the
    (T, 2) cells, the (T,) paired flags and what could not be placed ("" if
    nothing)."""
    R, D = labels.shape
    rng = np.random.default_rng(seed)
    inside = np.zeros(labels.shape, bool)
    inside[margin:R - margin, margin:D - margin] = True
    placed: list = []
    paired: list = []
    missing = []
    present = [k for k in range(len(names)) if np.any(labels == k)]
    for k in sorted(present, key=lambda k: int(np.count_nonzero(labels == k))):
        candidates = np.argwhere((labels == k) & inside)
        got = 0
        for cell in candidates[rng.permutation(len(candidates))]:
            if got == per_region:
                break
            if _far_enough(cell, placed, spacing):
                placed.append(cell)
                paired.append(False)
                got += 1
        if got < per_region:
            missing.append(f"{per_region - got} of {per_region} targets in region {names[k]!r}")
    home = names.index("homogeneous")
    offset = np.asarray(pair_offset, np.int64)
    candidates = np.argwhere((labels == home) & inside)
    got = 0
    for cell in candidates[rng.permutation(len(candidates))]:
        if got == pairs:
            break
        mate = cell + offset
        if not (margin <= mate[0] < R - margin and margin <= mate[1] < D - margin) or labels[tuple(mate)] != home:
            continue
        if _far_enough(cell, placed, spacing) and _far_enough(mate, placed, spacing):
            placed += [cell, mate]
            paired += [True, True]
            got += 1
    if got < pairs:
        missing.append(f"{pairs - got} of {pairs} pairs in region 'homogeneous'")
    cells = np.asarray(placed, np.int64).reshape(-1, 2)
    return cells, np.asarray(paired, bool), "; ".join(missing)


def target_cell_power(signal_power: np.ndarray, noise_power: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """Square-law output |√S e^(jθ) + √N_c|² = S + N_c + 2√(S N_c) cos θ of a
    target of power S over a noise sample of power N_c (the cell's noise-only
    output) at relative phase θ uniform: the Rician (Swerling 0) or, with S
    exponential, exponential (Swerling 1) law of a target in complex Gaussian noise."""
    return signal_power + noise_power + 2.0 * np.sqrt(signal_power * noise_power) * np.cos(phase)
