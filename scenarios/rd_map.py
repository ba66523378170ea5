"""Scenario ``rd-map``: range-Doppler power maps of an HF surface-wave radar dwell.

The backgrounds the HFSWR chapter on target detection and tracking names for
its CFAR comparison (*CFAR detection*: CA-CFAR suits homogeneous noise but
"ground clutter, first-order sea clutter and ionospheric interference" inflate
its noise estimate; OS-CFAR copes with weak clutter; adaptive regression
with "ionospheric interference and low-speed clutter"), each a parameter:
first-order Bragg lines, a range-extended ionospheric interference band, a
clutter edge, and point targets, isolated in each background and in close
pairs. The chapter prints no map size, line strength or target SNR: every
number here is ours (bench/presets/cfar.md, "Paper vs ours").
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import Batch, Scenario
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_scenario
from radarbench.bench.tasks.cells import CELL_DETECTION, REGION_NAMES, MapScene
from radarbench.models.rd_map import (LAYOUT_BYTES_PER_CELL, RegionLevels, background_power, beside_lines, label_regions,
                                      place_targets, target_cell_power)

SNR_DEFINITION = (
    "SNR = 10 log10(S / N) per target: S its mean power in its cell (over the Swerling draw for Swerling 1), "
    "N the cell's mean noise-plus-clutter power (thermal noise 1 plus Bragg, interference or the raised "
    "level beyond the clutter edge), so each target's SNR is over its local background."
)


@register_scenario
class RdMap(Scenario):
    r"""HFSWR range-Doppler power maps: exponential noise, Bragg lines, ionospheric band, clutter edge, point targets.

    **Map** (``range_cells`` $R$ x ``doppler_cells`` $D$; zero Doppler at column
    $\lfloor D/2 \rfloor$): square-law detected power, one dwell, ``z`` (n, 1, R, D)
    float32. Every cell is exponential with mean $N(r, d)$, independent across
    cells: thermal noise of power 1 plus, each a parameter
    (:func:`models.rd_map.background_power`):

    * **Bragg lines** (``bragg``): first-order sea clutter at ±``bragg_offset_bins``
      from zero Doppler, Gaussian in Doppler with std ``bragg_spread_bins``,
      peak clutter-to-noise ratio ``bragg_cnr_db`` at the first range cell
      falling linearly in dB to ``bragg_cnr_far_db`` at the last (sea clutter
      weakens with range like the targets); the negative line
      ``bragg_asymmetry_db`` below the positive one. ``bragg_scale_db``
      scales both lines' power after the regions and targets are laid out
      at the strength above: the clutter's strength varies, its shape, the
      region labels and the target cells do not (the chapter's OS-CFAR
      "weak against strong clutter" with nothing else changed).
    * **Ionospheric interference** (``interference``): a band of
      ``interference_range_cells`` range cells from ``interference_range_start``,
      spread over Doppler as a Gaussian of std ``interference_doppler_bins``
      about zero Doppler with peak interference-to-noise ``interference_inr_db``.
    * **Clutter edge** (``clutter_edge``): the noise level steps up by
      ``edge_step_db`` from range cell ``edge_range_cell`` on.

    **Regions** (:func:`models.rd_map.label_regions`): a cell is ``bragg`` or
    ``interference`` where that component is at least
    :data:`models.rd_map.REGION_LEVEL_DB` relative to the thermal noise (the
    stronger wins), else ``clutter-edge`` within ``edge_band_cells`` range
    cells of the step, else ``homogeneous`` (the raised level beyond the edge
    included). With ``edge_sides`` the band is two regions,
    ``clutter-edge-quiet`` below the step (a range window reaching over it
    averages the raised level: the noise estimate is pulled up) and
    ``clutter-edge-raised`` from it (pulled down), each with its own targets,
    Pd and Pfa. ``region_names`` lists :data:`~bench.tasks.cells.REGION_NAMES`.

    **Targets** (fixed cells, the same in every map; :func:`models.rd_map.place_targets`):
    ``targets_per_region`` isolated point targets in each region present, at
    least ``target_spacing_cells`` apart (Chebyshev) and ``margin_cells`` from
    the map's border, chosen by a fixed-seed shuffle of each region's cells
    (``layout_seed``); with ``bragg_target_offsets_bins`` the Bragg region's
    targets only in the Doppler columns that many cells either side of a
    line's centre (0: on the line), where a CFAR window reaching over the
    line masks them (:func:`models.rd_map.beside_lines`; the shuffles are the
    same, so another region's target moves only where a moved Bragg target
    blocks its cell); then ``pairs`` close
    pairs in the homogeneous region,
    the second target ``pair_offset_cells`` = (range, Doppler) from the first
    (``target_paired``). Each target puts its power in one cell (no straddle):

    $$
    z = \left|\sqrt{S X}\, e^{j\theta} + \sqrt{N E}\right|^2
      = S X + N E + 2 \sqrt{S X N E} \cos\theta,
    $$

    with $E$ the cell's $\operatorname{Exp}(1)$ noise draw, $\theta$ uniform and $X = 1$
    (Swerling 0) or $\operatorname{Exp}(1)$ (Swerling 1; one dwell, so Swerling 1 and 2
    agree); this is the square-law output of a complex target plus complex Gaussian
    noise of power $N$. $S = N \cdot 10^{\text{SNR}/10}$ (:data:`SNR_DEFINITION`).

    **Null** (``snr_db = None``): the same maps without targets ($T = 0$).
    **Randomness**, per map, whatever the SNR: the R x D Exp(1) draws, then
    the phases $\theta$ and the Swerling draws $X$ of every target slot (drawn under
    the null too), so map i sees the same noise at every SNR level.

    **Scene** (:class:`~bench.tasks.cells.MapScene`): ``region_labels``,
    ``region_names``, ``noise_power`` (the same $N$ in every map), ``target_cells``,
    ``target_snr_db``, ``target_paired``, ``swerling``, ``guard_cells`` =
    (``fa_guard_cells``, ``fa_guard_cells``). ``truth`` (n, 1, 2) holds the
    first target's (range, Doppler) cell (zeros when there is none).
    """

    name = "rd-map"
    tasks = (CELL_DETECTION,)
    #: the parameters its random streams were first keyed by (Scenario.stream_params)
    stream_params = ("range_cells", "doppler_cells", "bragg", "bragg_offset_bins", "bragg_spread_bins",
                     "bragg_cnr_db", "bragg_cnr_far_db", "bragg_asymmetry_db", "bragg_scale_db", "interference",
                     "interference_inr_db", "interference_range_start", "interference_range_cells",
                     "interference_doppler_bins", "clutter_edge", "edge_step_db", "edge_range_cell",
                     "edge_band_cells", "edge_sides", "targets_per_region", "pairs", "pair_offset_cells",
                     "target_spacing_cells", "margin_cells", "swerling", "fa_guard_cells", "layout_seed")
    small_params = {"range_cells": 48, "doppler_cells": 96, "bragg_offset_bins": 14, "interference_range_start": 16,
                    "interference_range_cells": 8, "interference_doppler_bins": 20.0, "edge_range_cell": 34,
                    "edge_band_cells": 4, "target_spacing_cells": 10, "margin_cells": 6, "targets_per_region": 1,
                    "pairs": 1}
    #: "large": a long-range, fine-Doppler map (512 x 1024), where scratch no longer fits in cache
    perf_sizes = {"small": (small_params, 100), "default": ({}, 100),
                  "large": ({"range_cells": 512, "doppler_cells": 1024}, 4)}
    perf_snr_db = 15.0

    @dataclass(frozen=True)
    class Params:
        range_cells: int = param(96, "range cells R (rows of the map)", ge=16, le=4096,
                                 why="16 cells hold a CFAR window of 2 x 6 cells plus guards; 4096 is far beyond "
                                     "an HFSWR range axis (a unit's memory is checked)")
        doppler_cells: int = param(256, "Doppler cells D (columns; zero Doppler at D // 2)", ge=16, le=16384,
                                   why="16 cells hold a CFAR window; 16384 is beyond the longest HFSWR dwell's FFT")
        bragg: bool = param(True, "first-order Bragg lines on/off")
        bragg_offset_bins: int = param(28, "Doppler offset of each Bragg line from zero Doppler (cells)",
                                       ge=1, le=8191, why="at least one cell from zero Doppler; inside the map "
                                                          "(checked against doppler_cells)")
        bragg_spread_bins: float = param(1.5, "Gaussian std of a Bragg line in Doppler (cells)", ge=0.1, le=100.0,
                                         why="0.1 cell is a line in one cell; 100 cells spreads it over the map")
        bragg_cnr_db: float = param(30.0, "peak clutter-to-noise ratio of the positive line at the first range "
                                          "cell (dB)", ge=-30.0, le=80.0,
                                    why="-30 dB is invisible, 80 dB beyond a strong sea echo over noise")
        bragg_cnr_far_db: float = param(10.0, "the same at the last range cell (dB; linear in dB in between)",
                                        ge=-30.0, le=80.0, why="as bragg_cnr_db")
        bragg_asymmetry_db: float = param(6.0, "how much weaker the negative line is than the positive (dB)",
                                          ge=0.0, le=40.0, why="0 is symmetric; 40 dB removes the weaker line")
        bragg_scale_db: float = param(0.0, "scale of the Bragg lines' power (dB), applied after the regions and "
                                           "targets are laid out at bragg_cnr_db..bragg_cnr_far_db (the layout "
                                           "stays that of scale 0)", ge=-60.0, le=40.0,
                                      why="-60 dB removes any line; +40 dB puts even the far line far above "
                                          "the noise")
        interference: bool = param(True, "ionospheric interference band on/off")
        interference_inr_db: float = param(15.0, "peak interference-to-noise ratio of the band (dB)",
                                           ge=-30.0, le=80.0, why="as bragg_cnr_db")
        interference_range_start: int = param(40, "first range cell of the band", ge=0, le=4095,
                                              why="inside the map (checked against range_cells)")
        interference_range_cells: int = param(16, "range cells the band spans", ge=1, le=4096,
                                              why="one cell to the whole range axis (checked)")
        interference_doppler_bins: float = param(50.0, "Gaussian std of the band over Doppler about zero "
                                                       "Doppler (cells)", ge=0.5, le=1e5,
                                                 why="half a cell to flat over any map")
        clutter_edge: bool = param(True, "clutter edge (step in the noise level along range) on/off")
        edge_step_db: float = param(10.0, "the step of the noise level at the edge (dB)", ge=0.0, le=60.0,
                                    why="0 dB is no step, 60 dB beyond any receiver's dynamic range here")
        edge_range_cell: int = param(72, "first range cell of the raised level", ge=1, le=4095,
                                     why="one cell at least on each side (checked against range_cells)")
        edge_band_cells: int = param(6, "range cells each side of the step labelled clutter-edge", ge=1, le=2048,
                                     why="one cell to half the largest map")
        edge_sides: bool = param(False, "the clutter-edge band as two regions, its quiet side and its raised "
                                        "side, each with targets_per_region targets (Pd and Pfa per side)")
        targets_per_region: int = param(2, "isolated targets in each region present", ge=0, le=64,
                                        why="none to 64 a region (fewer when the region has no room, checked)")
        bragg_target_offsets_bins: tuple[int, ...] = param(
            (), "Doppler offsets (cells) from a Bragg line's centre, either side, at which the Bragg region's "
                "targets are placed (0: on the line); empty: anywhere in the region", ge=0, le=64, min_len=0,
            max_len=8, why="on the line to beyond any line's region (a region with no cell at the offsets is "
                           "refused, checked with the layout)")
        pairs: int = param(2, "close target pairs in the homogeneous region", ge=0, le=32,
                           why="none to 32 pairs (checked against the room)")
        pair_offset_cells: tuple[int, ...] = param((0, 4), "(range, Doppler) offset of a pair's second target "
                                                           "from its first (cells)", ge=-64, le=64,
                                                   min_len=2, max_len=2,
                                                   why="inside a CFAR reference window (not (0, 0), checked)")
        target_spacing_cells: int = param(20, "least Chebyshev distance between targets that are not a pair "
                                              "(cells)", ge=1, le=4096,
                                          why="1 cell allows neighbours; the room is checked")
        margin_cells: int = param(10, "least distance of a target from the map's border (cells)", ge=0, le=2047,
                                  why="0 allows border cells; less than half the largest map (checked "
                                      "against the map)")
        swerling: int = param(1, "target fluctuation: 0 (non-fluctuating) or 1 (Swerling 1)", ge=0, le=1,
                              why="the two cases the task's ideal detector has in closed form")
        fa_guard_cells: int = param(1, "false alarms are not counted within this many cells (range and "
                                       "Doppler) of a target", ge=0, le=64,
                                    why="0 excludes only the target cell; 64 a large box")
        layout_seed: int = param(13, "seed of the fixed target layout (the same cells in every map)",
                                 ge=0, le=2**32 - 1, why="numpy seeds")

        def validate(self) -> None:
            if self.bragg and self.bragg_offset_bins >= self.doppler_cells // 2:
                raise ConfigError("bragg_offset_bins", f"the lines must lie inside the map: < doppler_cells // 2 "
                                  f"= {self.doppler_cells // 2}, got {self.bragg_offset_bins}")
            if self.interference and self.interference_range_start + self.interference_range_cells > self.range_cells:
                raise ConfigError("interference_range_cells", "the band must end inside the map: "
                                  "interference_range_start + interference_range_cells <= range_cells = "
                                  f"{self.range_cells}")
            if self.clutter_edge and self.edge_range_cell >= self.range_cells:
                raise ConfigError("edge_range_cell", f"the edge must lie inside the map: < range_cells = "
                                  f"{self.range_cells}, got {self.edge_range_cell}")
            if self.bragg_target_offsets_bins and not self.bragg:
                raise ConfigError("bragg_target_offsets_bins", "places targets beside the Bragg lines: needs "
                                  "bragg = true")
            if tuple(self.pair_offset_cells) == (0, 0):
                raise ConfigError("pair_offset_cells", "a pair's targets must be in different cells, got (0, 0)")
            if 2 * self.margin_cells >= min(self.range_cells, self.doppler_cells):
                raise ConfigError("margin_cells", "the margins leave no cell for targets: 2 x margin_cells must be "
                                  f"< min(range_cells, doppler_cells) = {min(self.range_cells, self.doppler_cells)}")
    def check_config(self, params) -> None:
        """Every target has a cell: a search over the map's cells, run after the sweep's
        memory check (a map of 4096 x 16384 cells takes seconds and GBs)."""
        layout = scene_layout(params)
        if layout.shortfall:
            field = "bragg_target_offsets_bins" if params.bragg_target_offsets_bins and "'bragg'" in \
                layout.shortfall else "targets_per_region"
            raise ConfigError(field, f"no room for every target: {layout.shortfall}")

    def unit_memory_bytes(self, params, n: int) -> int:
        """The float64 draws and the float32 map and noise power: about 24 bytes a cell a map;
        and once, the layout's construction (:data:`models.rd_map.LAYOUT_BYTES_PER_CELL`)."""
        return (24 * n + LAYOUT_BYTES_PER_CELL) * params.range_cells * params.doppler_cells

    def generate(self, params, snr_db: float | None, n: int, rng) -> Batch:
        p = params
        R, D = p.range_cells, p.doppler_cells
        layout = scene_layout(p)
        if layout.shortfall:                # a config that skipped the sweep's check_config
            raise ConfigError("targets_per_region", f"no room for every target: {layout.shortfall}")
        T = len(layout.cells)
        # Draw first, in a fixed order, so every SNR level and the null share the noise.
        unit_noise = rng.exponential((R, D))                       # (n, R, D) Exp(1)
        phases = rng.uniform(T, 0.0, 2.0 * np.pi)                  # (n, T)
        fluctuation = rng.exponential(T)                           # (n, T) Swerling-1 power draws
        n_maps = unit_noise.shape[0]
        power = np.broadcast_to(layout.power, (n_maps, R, D))
        z = (unit_noise * layout.power).astype(np.float32)
        if snr_db is None or T == 0:
            cells = np.zeros((n_maps, 0, 2), np.int64)
            snr = np.zeros((n_maps, 0))
            paired = np.zeros((n_maps, 0), bool)
            realised = np.full(n_maps, np.nan)
        else:
            cells = np.broadcast_to(layout.cells, (n_maps, T, 2)).copy()
            snr = np.full((n_maps, T), float(snr_db))
            paired = np.broadcast_to(layout.paired, (n_maps, T)).copy()
            x = fluctuation if p.swerling == 1 else np.ones_like(fluctuation)
            rows, cols = layout.cells[:, 0], layout.cells[:, 1]
            noise_at = layout.power[rows, cols]                     # (T,)
            signal = noise_at * 10.0 ** (snr_db / 10.0) * x         # (n, T) S X
            z[:, rows, cols] = target_cell_power(signal, unit_noise[:, rows, cols] * noise_at, phases)
            realised = 10.0 * np.log10((signal / noise_at).mean(axis=1))
        truth = np.zeros((n_maps, 1, 2))
        if T:
            truth[:, 0, :] = layout.cells[0]
        scene = MapScene(region_labels=layout.labels, region_names=REGION_NAMES, noise_power=power,
                         target_cells=cells, target_snr_db=snr, target_paired=paired, swerling=int(p.swerling),
                         guard_cells=(int(p.fa_guard_cells), int(p.fa_guard_cells)),
                         snr_definition=SNR_DEFINITION, realised_snr_db=realised)
        return Batch(t=np.zeros(1), truth=truth, z=z[:, None], scene=scene, trials=np.asarray(rng.trials))


@dataclass(frozen=True, eq=False)
class Layout:
    """The fixed part of a config's maps: mean power, region labels, targets."""

    power: np.ndarray        # (R, D) float64 mean noise-plus-clutter power
    labels: np.ndarray       # (R, D) int8 index into REGION_NAMES
    cells: np.ndarray        # (T, 2) int64 target cells
    paired: np.ndarray       # (T,) bool
    shortfall: str           # why targets are missing ("" when every target has a cell)


@functools.lru_cache(maxsize=32)
def scene_layout(p) -> Layout:
    """Power, labels and target cells of a config (cached: the same in every map)."""
    R, D = p.range_cells, p.doppler_cells
    parts = background_power(
        (R, D), bragg=(p.bragg_offset_bins, p.bragg_spread_bins, p.bragg_cnr_db, p.bragg_cnr_far_db,
                       p.bragg_asymmetry_db) if p.bragg else None,
        interference=(p.interference_range_start, p.interference_range_cells, p.interference_doppler_bins,
                      p.interference_inr_db) if p.interference else None,
        edge=(p.edge_range_cell, p.edge_step_db) if p.clutter_edge else None)
    labels = label_regions(parts, REGION_NAMES, RegionLevels(edge_range_cell=p.edge_range_cell if p.clutter_edge
                                                             else None, edge_band_cells=p.edge_band_cells,
                                                             edge_sides=p.edge_sides))
    allowed = {REGION_NAMES.index("bragg"): beside_lines((R, D), p.bragg_offset_bins, tuple(p.bragg_target_offsets_bins))} \
        if p.bragg_target_offsets_bins else None
    cells, paired, shortfall = place_targets(labels, REGION_NAMES, per_region=p.targets_per_region, pairs=p.pairs,
                                             pair_offset=tuple(p.pair_offset_cells), spacing=p.target_spacing_cells,
                                             margin=p.margin_cells, seed=p.layout_seed, allowed=allowed)
    # the strength varies after the layout is fixed (bragg_scale_db)
    power = dataclasses.replace(parts, bragg=parts.bragg * 10.0 ** (p.bragg_scale_db / 10.0)).total
    for a in (power, labels, cells, paired):
        a.setflags(write=False)
    return Layout(power, labels, cells, paired, shortfall)
