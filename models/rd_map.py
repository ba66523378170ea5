"""Range-Doppler map backgrounds of an HF surface-wave radar: mean power, clutter regions, targets.

The backgrounds the HFSWR chapter on target detection and tracking names for
CFAR detection (first-order sea clutter, ionospheric interference, a clutter
edge) as mean-power maps over (range, Doppler) cells, the clutter-region
label of every cell, a fixed target layout, and the square-law power of a
target cell. Used by the ``rd-map`` scenario (scenarios/rd_map.py) and by ``hfswr-rd-scans``
(scenarios/hfswr_rd_scans.py, a map per scan); the
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


#: bytes a cell of the map costs while its layout is built (:func:`background_power`'s
#: float64 components and their sum, the labels, :func:`place_targets`' candidate indices
#: and their shuffle): the scenario adds it to a unit's memory estimate
LAYOUT_BYTES_PER_CELL = 72

#: candidates examined at once by :func:`place_targets` (grown while none is free)
_SCAN_CHUNK = 4096
_SCAN_CHUNK_MAX = 1 << 20


def _block(blocked: np.ndarray, cell: int, spacing: int) -> None:
    """Mark every cell closer than ``spacing`` (Chebyshev) to the flat ``cell``."""
    r, d = divmod(int(cell), blocked.shape[1])
    blocked[max(r - spacing + 1, 0):r + spacing, max(d - spacing + 1, 0):d + spacing] = True


def _take_free(candidates: np.ndarray, order: np.ndarray, want: int, blocked: np.ndarray, spacing: int,
               any_free, mate_of=None) -> list[tuple[int, ...]]:
    """Walk ``candidates[order]`` (flat cells) and take, in that order, each cell that is
    not ``blocked`` (nor its mate, ``mate_of(cells) -> (mates, usable)``), blocking around
    what it takes, until ``want`` are taken: the first-fit of a Python loop over the
    candidates with a distance test against every placed target, vectorised over chunks
    of candidates. After a long run of blocked candidates it asks ``any_free()`` (one
    sequential pass over the map) whether any is left and stops if none is (a candidate
    passed over was blocked and stays so): a map with no room costs a pass, not minutes."""
    flat = blocked.reshape(-1)
    taken: list[tuple[int, ...]] = []
    start, chunk, asked = 0, _SCAN_CHUNK, False
    while len(taken) < want and start < len(order):
        if chunk == _SCAN_CHUNK_MAX and not asked:
            asked = True
            if not any_free():
                break
        cells = candidates[order[start:start + chunk]]
        free = ~flat[cells]
        mates = None
        if mate_of is not None:
            mates, usable = mate_of(cells)
            free &= usable & ~flat[mates]
        hit = np.flatnonzero(free)
        if hit.size == 0:
            start += len(cells)
            chunk = min(2 * chunk, _SCAN_CHUNK_MAX)
            continue
        first = int(hit[0])
        pick = (int(cells[first]),) if mates is None else (int(cells[first]), int(mates[first]))
        for cell in pick:
            _block(blocked, cell, spacing)
        taken.append(pick)
        start, chunk, asked = start + first + 1, _SCAN_CHUNK, False
    return taken


def _shifted(mask: np.ndarray, dr: int, dd: int) -> np.ndarray:
    """out[r, d] = mask[r + dr, d + dd], False outside the map."""
    R, D = mask.shape
    out = np.zeros_like(mask)
    out[max(-dr, 0):R - max(dr, 0), max(-dd, 0):D - max(dd, 0)] = \
        mask[max(dr, 0):R - max(-dr, 0), max(dd, 0):D - max(-dd, 0)]
    return out


def place_targets(labels: np.ndarray, names: tuple[str, ...], *, per_region: int, pairs: int,
                  pair_offset: tuple[int, int], spacing: int, margin: int,
                  seed: int, allowed: dict[int, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray, str]:
    """A fixed target layout: ``per_region`` isolated targets in each region
    present (smallest region first), then ``pairs`` pairs in the homogeneous
    region (second target at ``pair_offset`` from the first, also
    homogeneous). Targets that are not partners are at least ``spacing``
    apart (Chebyshev), every target at least ``margin`` from the border.
    Candidates are each region's cells in a shuffle of ``seed``, taken first
    fit (:func:`_take_free`); ``allowed`` (region index -> (R, D) bool) keeps a
    region's isolated targets to those of its cells (e.g. :func:`beside_lines`):
    the region's shuffle is drawn as without it and only walked over the allowed
    cells, so every other region's shuffle stays that of the unrestricted layout
    (its picks move only where a moved target blocks one). Returns the (T, 2) cells, the (T,) paired flags and what could not
    be placed ("" if nothing)."""
    R, D = labels.shape
    rng = np.random.default_rng(seed)
    inside = np.zeros(labels.shape, bool)
    inside[margin:R - margin, margin:D - margin] = True
    blocked = np.zeros(labels.shape, bool)
    placed: list = []
    paired: list = []
    missing = []
    present = [k for k in range(len(names)) if np.any(labels == k)]
    allowed = allowed or {}
    for k in sorted(present, key=lambda k: int(np.count_nonzero(labels == k))):
        region = (labels == k) & inside
        candidates = np.flatnonzero(region)
        order = rng.permutation(len(candidates))
        if k in allowed:
            order = order[allowed[k].reshape(-1)[candidates[order]]]
            region = region & allowed[k]
        got = _take_free(candidates, order, per_region, blocked, spacing, lambda: bool((region & ~blocked).any()))
        placed += [cell for cell, in got]
        paired += [False] * len(got)
        if len(got) < per_region:
            missing.append(f"{per_region - len(got)} of {per_region} targets in region {names[k]!r}")
    home = names.index("homogeneous")
    dr, dd = (int(x) for x in pair_offset)

    def mate_of(cells):
        r, d = np.divmod(cells, D)
        r, d = r + dr, d + dd
        usable = (margin <= r) & (r < R - margin) & (margin <= d) & (d < D - margin)
        mates = np.where(usable, r * D + d, cells)
        usable &= labels.reshape(-1)[mates] == home
        return mates, usable

    region = (labels == home) & inside
    candidates = np.flatnonzero(region)
    got = _take_free(candidates, rng.permutation(len(candidates)), pairs, blocked, spacing,
                     lambda: bool((region & ~blocked & _shifted(region & ~blocked, dr, dd)).any()), mate_of)
    placed += [cell for pair in got for cell in pair]
    paired += [True] * (2 * len(got))
    if len(got) < pairs:
        missing.append(f"{pairs - len(got)} of {pairs} pairs in region 'homogeneous'")
    cells = np.stack(np.divmod(np.asarray(placed, np.int64), D), axis=-1).reshape(-1, 2)
    return cells, np.asarray(paired, bool), "; ".join(missing)


def beside_lines(shape: tuple[int, int], line_offset: int, offsets: tuple[int, ...]) -> np.ndarray:
    """(R, D) bool: the Doppler columns ``offsets`` cells either side of each Bragg
    line's centre (D//2 ± ``line_offset``, as :func:`background_power` places them);
    offset 0 is the line's own column. Columns outside the map are left out."""
    R, D = shape
    columns = {D // 2 + sign * line_offset + side * k for sign in (1, -1) for side in (1, -1) for k in offsets}
    mask = np.zeros(shape, bool)
    mask[:, sorted(c for c in columns if 0 <= c < D)] = True
    return mask


def target_cell_power(signal_power: np.ndarray, noise_power: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """Square-law output |√S e^(jθ) + √N_c|² = S + N_c + 2√(S N_c) cos θ of a
    target of power S over a noise sample of power N_c (the cell's noise-only
    output) at relative phase θ uniform: the Rician (Swerling 0) or, with S
    exponential, exponential (Swerling 1) law of a target in complex Gaussian noise."""
    return signal_power + noise_power + 2.0 * np.sqrt(signal_power * noise_power) * np.cos(phase)
