"""Scenario ``hfswr-rd-scans``: a range-Doppler map per scan of an HF surface-wave
radar watching the ship targets of ``hfswr-targets``, over the sea-clutter Bragg
lines, ionospheric band and clutter edge of ``rd-map``: the input of the HFSWR
chapter's whole detect-and-track chain (task ``detect-track``)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from radarbench.bench.core import Batch, Scenario
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_scenario
from radarbench.bench.tasks.cells import REGION_NAMES
from radarbench.bench.tasks.detecttrack import DETECT_TRACK, DetectTrackScene
from radarbench.models.hfswr import POSITION_INDEX, measure
from radarbench.models.rd_map import RegionLevels, background_power, label_regions, target_cell_power
# the multi-target suite's HFSWR scene: its targets' draws and trajectories, reused as they are
from radarbench.scenarios.hfswr_targets import _draw_targets as draw_targets
from radarbench.scenarios.hfswr_targets import _trajectories as trajectories

#: m/s^2, and the speed of light (m/s), for the Bragg lines' radial velocity
GRAVITY, LIGHT = 9.81, 299_792_458.0
#: the half-width of the box of cells a target's echo is spread over (cells; 3 x 3)
ECHO_BOX = 1
#: bytes a map cell costs in a unit, per trial and scan: the Exp(1) and uniform draws (float64), the
#: map and its direction of arrival (float32), the signal power and its phases (float64, scattered)
BYTES_PER_CELL = 40

SNR_DEFINITION = (
    "snr_db is the peak signal-to-noise ratio of a target's echo over the thermal noise (power 1) in the "
    "range-Doppler cell it is centred on (less when it straddles cells), averaged over its Swerling-1 "
    "fluctuation from scan to scan; the Bragg lines, the ionospheric band and the raised level beyond the "
    "clutter edge add to the noise, so a target on them has a lower SNR over its local background; "
    "snr_db = None: the maps without targets."
)


def bragg_velocity_m_s(frequency_mhz: float) -> float:
    """Radial velocity of first-order sea clutter, v_B = sqrt(g lambda / (4 pi)) at radar wavelength lambda."""
    wavelength = LIGHT / (frequency_mhz * 1e6)
    return math.sqrt(GRAVITY * wavelength / (4.0 * math.pi))


@register_scenario
class HfswrRdScans(Scenario):
    r"""Range-Doppler maps scan by scan: moving ships' spread echoes over Bragg lines, an ionospheric band and a clutter edge, with a direction of arrival per cell.

    **Targets** are those of ``hfswr-targets`` (the multi-target suite's HFSWR
    scene; its ``_draw_targets`` and ``_trajectories`` are called with this
    scenario's parameters of the same names): ``targets`` ships, CV with small
    accelerations, appearing, disappearing, ``crossing_targets`` of them
    crossing at the middle scan; present while inside the surveillance region,
    which here is the maps' extent in range and radial velocity and
    ``azimuth_bounds_deg`` in azimuth.

    **Maps** ($R$ = ``range_cells`` x $D$ = ``doppler_cells``; cell $(r, d)$ covers
    range $\rho_0 + [r, r + 1)\, \Delta\rho$ and is centred on radial velocity
    $(d - \lfloor D/2 \rfloor)\, \Delta v$; $\rho_0$, $\Delta\rho$, $\Delta v$: ``range_start_m``,
    ``range_cell_m``, ``velocity_cell_m_s``): square-law power, every cell
    exponential about its mean noise-plus-clutter power $N$ (thermal noise 1,
    :func:`models.rd_map.background_power`, the ``rd-map`` scene's components):
    first-order Bragg lines at $\pm v_B = \pm\sqrt{g \lambda / 4\pi}$ (``radar_frequency_mhz``:
    7.1 m/s at 4.7 MHz, where ships sail), their CNR falling linearly in dB
    with range; an ionospheric band of ``interference_range_cells`` range
    cells spread over Doppler; the noise raised by ``edge_step_db`` beyond
    ``edge_range_cell``. Clutter regions as ``rd-map`` labels them
    (:func:`models.rd_map.label_regions`). The clutter is independent from
    scan to scan (a new dwell), its mean the same.

    **Echoes** (ours: the chapter prints no waveform): a target at range $\rho$
    and radial velocity $\nu$ (in cell units) puts power $S w$ in each cell of the
    3 x 3 box about its nearest cell,

    $$
    w = \exp\left(-\frac{(r - \rho)^2}{2 s_r^2} - \frac{(d - \nu)^2}{2 s_d^2}\right),
    $$

    (``echo_spread_cells`` $= (s_r, s_d)$, the range and Doppler windows' main lobes),
    so $w = 1$ at a cell centre and the straddle loss is real;
    $S = 10^{\text{SNR}/10} X$, $X \sim \operatorname{Exp}(1)$ per target and scan (Swerling 1).
    A cell's power is $|\sqrt{S w}\, e^{j\theta} + \text{noise}|^2$
    (:func:`models.rd_map.target_cell_power`, $\theta$ uniform); where echoes
    overlap their powers add and the first target's phase is used.

    **Direction of arrival** (the chapter's plots carry an azimuth, it says not
    how: our modelling choice, stated here): ``scene.azimuth_rad`` gives the
    DOA a detection in a cell would report. Where a target's echo power $S w$
    exceeds the cell's mean noise-plus-clutter power, the target's azimuth
    plus $\mathcal{N}(0, \sigma_{az}^2)$ (``sigma_azimuth_deg``, one draw per target and scan,
    shared by its cells); elsewhere (noise, Bragg, ionospheric cells) a
    uniform draw over ``azimuth_bounds_deg``, independent per cell and scan:
    clutter arrives from everywhere the array looks.

    **Scene** (:class:`~bench.tasks.detecttrack.DetectTrackScene`): the axes,
    the DOA map, $\sigma_{az}$, the region labels, the mean power $N$, each target's
    nearest cell per scan (-1 absent) for the cell Pd/Pfa, ``guard_cells``,
    the sensor at the origin, the speed bounds and process noise the trackers
    may assume, the GOSPA settings. ``snr_db = None``: the same maps without
    echoes (truths NaN).

    **Random draws** per trial, in this order whatever the SNR: the targets'
    (``hfswr-targets``' order), then the maps' Exp(1) draws (K, R, D), the DOA
    uniforms (K, R, D), the Swerling draws (K, T), the phases (K, T, 3, 3) and
    the DOA noise (K, T).

    **Memory per unit**: about 40 bytes per cell, scan and trial
    (:data:`BYTES_PER_CELL`): 13 MB a trial at the defaults (64 x 128 cells,
    40 scans); ``unit_memory_bytes`` states it to the harness.
    """

    name = "hfswr-rd-scans"
    tasks = (DETECT_TRACK,)
    small_params: ClassVar[dict] = {"targets": 3, "scans": 12, "range_cells": 32, "doppler_cells": 64,
                                    "range_cell_m": 3000.0, "velocity_cell_m_s": 0.625,
                                    "interference_range_start": 12, "interference_range_cells": 6,
                                    "edge_range_cell": 24}
    perf_sizes: ClassVar[dict] = {"default": ({}, 4)}
    perf_snr_db: ClassVar[float] = 20.0

    @dataclass(frozen=True)
    class Params:
        targets: int = param(6, "number of ship targets T", ge=1, le=50,
                             why="one target at least; 50 ships crowd a 64 x 128 map")
        scans: int = param(40, "number of scans K (maps per trial; duration K times scan_period_s)", ge=6, le=500,
                           why="the M/N logic needs a few scans; 500 maps a trial bound a unit's memory")
        scan_period_s: float = param(60.0, "time between scans (s): the coherent integration of one map",
                                     ge=1.0, le=600.0, why="HFSWR revisit times, a second to ten minutes")
        range_cells: int = param(64, "range cells R of a map", ge=16, le=1024,
                                 why="16 cells hold a CFAR window; 1024 bounds a unit's memory")
        doppler_cells: int = param(128, "Doppler cells D of a map (zero radial velocity at D // 2)", ge=16,
                                   le=4096, why="16 cells hold a CFAR window; 4096 bounds a unit's memory")
        range_start_m: float = param(50e3, "lower edge of the first range cell (m)", ge=1e3, le=1e6,
                                     why="1 km to 1000 km, HFSWR ranges")
        range_cell_m: float = param(1500.0, "range cell size (m; 1.5 km: a 100 kHz sweep)", ge=10.0, le=2e4,
                                    why="10 m to 20 km, HFSWR range resolutions")
        velocity_cell_m_s: float = param(0.3125, "Doppler cell size as radial velocity (m/s; 128 cells span "
                                                 "+-20 m/s)", ge=0.01, le=5.0,
                                         why="a few minutes' integration at 5 MHz to a short dwell")
        azimuth_bounds_deg: tuple[float, ...] = param((-30.0, 30.0), "[min, max] azimuth the array looks at (deg, "
                                                      "clockwise from north)", ge=-90.0, le=90.0, min_len=2,
                                                      max_len=2, why="the half-plane a shore array sees")
        sigma_azimuth_deg: float = param(1.0, "std of a target cell's direction of arrival (deg; ours)",
                                         ge=0.01, le=10.0,
                                         why="a hundredth of a degree to 10 deg, beyond which the trackers' "
                                             "linearisation breaks")
        echo_spread_cells: tuple[float, ...] = param((0.6, 0.8), "(range, Doppler) Gaussian std of an echo's "
                                                     "spread over neighbouring cells (cells; ours)", ge=0.1, le=2.0,
                                                     min_len=2, max_len=2,
                                                     why="a tenth of a cell is a point echo; 2 cells fill the "
                                                         "3 x 3 box")
        radar_frequency_mhz: float = param(4.7, "radar frequency (MHz): the Bragg lines' radial velocity",
                                           ge=2.0, le=30.0, why="the HF band")
        bragg: bool = param(True, "first-order Bragg lines on/off")
        bragg_spread_bins: float = param(1.5, "Gaussian std of a Bragg line in Doppler (cells)", ge=0.1,
                                         le=50.0, why="a line in one cell to a smeared sea")
        bragg_cnr_db: float = param(30.0, "peak CNR of the positive Bragg line at the first range cell (dB)",
                                    ge=-30.0, le=80.0, why="invisible to far above the noise")
        bragg_cnr_far_db: float = param(10.0, "the same at the last range cell (dB; linear in dB between)",
                                        ge=-30.0, le=80.0, why="as bragg_cnr_db")
        bragg_asymmetry_db: float = param(6.0, "how much weaker the negative Bragg line is (dB)", ge=0.0, le=40.0,
                                          why="0 is symmetric; 40 dB removes the weaker line")
        interference: bool = param(True, "ionospheric interference band on/off")
        interference_inr_db: float = param(15.0, "peak interference-to-noise ratio of the band (dB)", ge=-30.0,
                                           le=80.0, why="invisible to far above the noise")
        interference_range_start: int = param(24, "first range cell of the band", ge=0, le=1023,
                                              why="inside the map (checked)")
        interference_range_cells: int = param(10, "range cells the band spans", ge=1, le=1024,
                                              why="one cell to the whole range axis (checked)")
        interference_doppler_bins: float = param(30.0, "Gaussian std of the band over Doppler (cells)", ge=0.5,
                                                 le=1e5, why="half a cell to flat")
        clutter_edge: bool = param(True, "clutter edge (a step of the noise level along range) on/off")
        edge_step_db: float = param(10.0, "the step of the noise level at the edge (dB)", ge=0.0, le=60.0,
                                    why="no step to beyond a receiver's dynamic range")
        edge_range_cell: int = param(48, "first range cell of the raised level", ge=1, le=1023,
                                     why="one cell at least on each side (checked)")
        edge_band_cells: int = param(4, "range cells each side of the step labelled clutter-edge", ge=1, le=512,
                                     why="one cell to half the largest map")
        guard_cells: int = param(1, "a detection within this many cells (range and Doppler) of a target's cell "
                                    "is the target's (cell Pd; left out of the cell Pfa)", ge=0, le=8,
                                 why="the echo box's half-width and a little more")
        speed_bounds_m_s: tuple[float, ...] = param((1.0, 15.0), "[min, max] target speed (m/s)", ge=0.0,
                                                    le=100.0, min_len=2, max_len=2, why="a drifting buoy to a fast boat")
        accel_std_m_s2: float = param(0.002, "std of the white acceleration per axis, held over a scan (m/s^2)",
                                      ge=0.0, le=1.0, why="0 is straight lines; 0.1 g is far beyond a ship")
        crossing: bool = param(True, "make crossing_targets targets cross at the middle scan")
        crossing_targets: int = param(2, "how many targets cross (the first ones)", ge=2, le=50,
                                      why="a crossing takes two; at most every target")
        crossing_angle_deg: float = param(20.0, "spread of the crossing targets' headings (deg)", ge=1.0,
                                          le=179.0, why="crossing, neither parallel nor head-on")
        gospa_cutoff_m: float = param(5000.0, "GOSPA / OSPA cut-off c (m)", ge=1.0, le=1e6,
                                      why="a metre to beyond the region")
        gospa_order: float = param(2.0, "GOSPA / OSPA order p", ge=1.0, le=10.0,
                                   why="p >= 1 for a metric; beyond 10 it is the maximum error")

        def validate(self) -> None:
            for name in ("azimuth_bounds_deg", "speed_bounds_m_s"):
                lo, hi = getattr(self, name)
                if not lo < hi:
                    raise ConfigError(name, f"expected [min, max] with min < max, got {[lo, hi]}")
            if self.interference and self.interference_range_start + self.interference_range_cells > self.range_cells:
                raise ConfigError("interference_range_cells", "the band must end inside the map: "
                                  f"interference_range_start + interference_range_cells <= {self.range_cells}")
            if self.clutter_edge and self.edge_range_cell >= self.range_cells:
                raise ConfigError("edge_range_cell", f"the edge must lie inside the map: < {self.range_cells}")
            if self.crossing and self.crossing_targets > self.targets:
                raise ConfigError("crossing_targets", f"{self.crossing_targets} crossing targets, but targets = "
                                  f"{self.targets}")

        @property
        def velocity_start_m_s(self) -> float:
            """Lower edge of the first Doppler cell (m/s): cell D // 2 is centred on 0."""
            return -(self.doppler_cells // 2 + 0.5) * self.velocity_cell_m_s

        def region(self) -> np.ndarray:
            """(3, 2) min / max of range (m), azimuth (rad), radial velocity (m/s): the maps' extent."""
            v0 = self.velocity_start_m_s
            return np.array([[self.range_start_m, self.range_start_m + self.range_cells * self.range_cell_m],
                             np.radians(self.azimuth_bounds_deg),
                             [v0, v0 + self.doppler_cells * self.velocity_cell_m_s]], float)

    def unit_memory_bytes(self, params, n: int) -> int:
        """:data:`BYTES_PER_CELL` per cell, scan and trial."""
        return BYTES_PER_CELL * n * params.scans * params.range_cells * params.doppler_cells

    def generate(self, params, snr_db: float | None, n: int, rng) -> Batch:
        p = params
        K, T, (R, D) = p.scans, p.targets, (p.range_cells, p.doppler_cells)
        region = p.region()
        truth = trajectories(p, draw_targets(p, rng, n), region)
        unit_noise = rng.exponential((K, R, D))
        doa = rng.uniform((K, R, D), *region[1])
        swerling = rng.exponential((K, T))
        phases = rng.uniform((K, T, 2 * ECHO_BOX + 1, 2 * ECHO_BOX + 1), 0.0, 2.0 * np.pi)
        doa_noise = rng.standard_normal((K, T))
        if snr_db is None:
            truth[:] = np.nan
        power, labels = background(p)
        z = (unit_noise * power).astype(np.float32)
        azimuth = doa.astype(np.float32)
        zt = measure(np.where(np.isfinite(truth), truth, 1.0), np.zeros(2))          # (n, K, T, 3)
        fractional = np.stack([(zt[..., 0] - p.range_start_m) / p.range_cell_m - 0.5,
                               (zt[..., 2] - p.velocity_start_m_s) / p.velocity_cell_m_s - 0.5], axis=-1)
        cell = np.clip(np.rint(fractional), 0, [R - 1, D - 1]).astype(np.int64)
        present = np.isfinite(truth[..., 0])
        cells = np.where(present[..., None], cell, -1)
        if snr_db is not None:
            signal = 10.0 ** (snr_db / 10.0) * swerling
            target_azimuth = zt[..., 1] + math.radians(p.sigma_azimuth_deg) * doa_noise
            add_echoes(z, azimuth, power, unit_noise, cells, fractional, signal, phases, target_azimuth,
                       p.echo_spread_cells)
        scene = DetectTrackScene(
            snr_definition=SNR_DEFINITION, realised_snr_db=np.full(n, np.nan if snr_db is None else float(snr_db)),
            position_index=POSITION_INDEX, range_start_m=float(p.range_start_m), range_cell_m=float(p.range_cell_m),
            velocity_start_m_s=float(p.velocity_start_m_s), velocity_cell_m_s=float(p.velocity_cell_m_s),
            azimuth_rad=azimuth, azimuth_std_rad=math.radians(p.sigma_azimuth_deg), region_labels=labels,
            region_names=REGION_NAMES, noise_power=power, target_cells=cells, guard_cells=(p.guard_cells,) * 2,
            scan_period_s=float(p.scan_period_s), sensor_xy=np.zeros(2), surveillance_region=region,
            speed_bounds_m_s=tuple(map(float, p.speed_bounds_m_s)), accel_std_m_s2=float(p.accel_std_m_s2),
            gospa_cutoff_m=float(p.gospa_cutoff_m), gospa_order=float(p.gospa_order))
        return Batch(t=np.arange(K) * p.scan_period_s, truth=truth, z=z, scene=scene, trials=np.asarray(rng.trials))


@functools.lru_cache(maxsize=16)
def background(p) -> tuple[np.ndarray, np.ndarray]:
    """(R, D) mean noise-plus-clutter power and clutter-region labels of a config (the same every scan)."""
    R, D = p.range_cells, p.doppler_cells
    offset = bragg_velocity_m_s(p.radar_frequency_mhz) / p.velocity_cell_m_s
    parts = background_power(
        (R, D), bragg=(offset, p.bragg_spread_bins, p.bragg_cnr_db, p.bragg_cnr_far_db, p.bragg_asymmetry_db)
        if p.bragg else None,
        interference=(p.interference_range_start, p.interference_range_cells, p.interference_doppler_bins,
                      p.interference_inr_db) if p.interference else None,
        edge=(p.edge_range_cell, p.edge_step_db) if p.clutter_edge else None)
    labels = label_regions(parts, REGION_NAMES, RegionLevels(edge_range_cell=p.edge_range_cell if p.clutter_edge
                                                             else None, edge_band_cells=p.edge_band_cells))
    power = parts.total
    for a in (power, labels):
        a.setflags(write=False)
    return power, labels


def add_echoes(z, azimuth, power, unit_noise, cells, fractional, signal, phases, target_azimuth, spread) -> None:
    """The targets' echoes into the maps ``z`` (n, K, R, D) and their direction of arrival into
    ``azimuth``, in place (the class docstring's *Echoes* and *Direction of arrival*).

    ``cells`` (n, K, T, 2) nearest cells (-1 absent), ``fractional`` (n, K, T, 2) positions in
    cell units, ``signal`` (n, K, T) S, ``phases`` (n, K, T, 3, 3), ``target_azimuth`` (n, K, T)."""
    n, K, R, D = z.shape
    box = np.arange(-ECHO_BOX, ECHO_BOX + 1)
    rows = cells[..., 0, None, None] + box[:, None]                                   # (n, K, T, 3, 1)
    cols = cells[..., 1, None, None] + box[None, :]                                   # (n, K, T, 1, 3)
    rows, cols = np.broadcast_arrays(rows, cols)
    w = np.exp(-0.5 * (((rows - fractional[..., 0, None, None]) / spread[0]) ** 2
                       + ((cols - fractional[..., 1, None, None]) / spread[1]) ** 2))
    inside = (cells[..., 0, None, None] >= 0) & (rows >= 0) & (rows < R) & (cols >= 0) & (cols < D)
    trial, scan = (np.broadcast_to(a, rows.shape) for a in np.ix_(np.arange(n), np.arange(K), [0], [0], [0])[:2])
    flat = ((trial * K + scan) * R + rows) * D + cols
    echo = signal[..., None, None] * w
    idx, first = np.unique(flat[inside], return_index=True)                           # first target wins a cell
    total = np.zeros(idx.size)
    np.add.at(total, np.searchsorted(idx, flat[inside]), echo[inside])               # overlapping echoes add
    cell_rc = np.unravel_index(idx, (n * K, R, D))
    noise = unit_noise.reshape(n * K, R, D)[cell_rc] * power[cell_rc[1], cell_rc[2]]
    z.reshape(n * K, R, D)[cell_rc] = target_cell_power(total, noise, phases[inside][first])
    dominant = echo[inside][first] > power[cell_rc[1], cell_rc[2]]
    doa = np.broadcast_to(target_azimuth[..., None, None], rows.shape)[inside][first]
    az = azimuth.reshape(n * K, R, D)
    az[tuple(c[dominant] for c in cell_rc)] = doa[dominant]
