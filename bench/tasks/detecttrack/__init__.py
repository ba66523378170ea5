"""Detect and track: range-Doppler maps per scan in, tracks out, scored on the
tracks and on the detector's cells (docs/architecture.md, 'Tasks').

The whole chain of the HFSWR chapter ("目标检测与跟踪方法, 海洋遥感技术应用":
CFAR along range and Doppler with peak detection, plots, then M/N initiation
and JPDA-UKF; tracking "the last and most complex link, responsible for
reducing false alarms and forming tracks"). A method gets a scan's maps and
returns the tracks of a :class:`bench.tasks.multitarget.MultiTargetOutput`
plus the cells it declared and the plots it made of them
(:class:`DetectTrackOutput`). The confirmed tracks are scored by the
multi-target task's metrics (GOSPA and its parts, OSPA, initiation delay —
the time to confirm, in scans —, false tracks per hour, breaks, identity
switches, purity: :mod:`bench.tasks.multitarget.metrics`), the declared cells
by the detector's cell Pd and Pfa per scan (:mod:`bench.tasks.detecttrack.metrics`),
so one run shows how detection quality maps to tracking quality.

The batch of a detect-and-track scenario::

    z      (n, K, R, D)  float32 square-law power of scan k's range-Doppler map
    truth  (n, K, T, 4)  [x, vx, y, vy] of target T at scan k, NaN while it is absent

and a :class:`DetectTrackScene`: the maps' axes, a direction of arrival per
cell, the clutter regions, each target's cell per scan, the sensor and what
the trackers may assume of the targets (docs/architecture.md, 'Scenes').
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from radarbench.bench.core import Batch, Scene, has_shape, require
from radarbench.bench.metrics import CELL_KEYS
from radarbench.bench.recording.record import MethodTrace
from radarbench.bench.tasks.base import OutputError, RecordedScene, ReportContext, time_series
from radarbench.bench.tasks.cells.metrics import REGION_NAMES
from radarbench.bench.tasks.detecttrack.metrics import cell_metrics, summarise_cells
from radarbench.bench.tasks.multitarget import (MultiTargetOutput, MultiTargetTask, _number, _plots_xy,
                                                check_multitarget_output)
from radarbench.bench.tasks.multitarget.metrics import multitarget_trial_metrics

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

__all__ = ["DETECT_TRACK", "DetectTrackOutput", "DetectTrackScene", "DetectTrackTask"]

DETECT_TRACK = "detect-track"


@dataclass(frozen=True, kw_only=True, eq=False)
class DetectTrackScene(Scene):
    """What a detect-and-track scenario tells the chains and the harness
    (docs/architecture.md, 'Scenes'). Cell (r, d) of a map covers range
    ``range_start_m + [r, r + 1) range_cell_m`` and radial velocity
    ``velocity_start_m_s + [d, d + 1) velocity_cell_m_s``."""

    #: first range cell's lower edge (m) and the range cell size (m)
    range_start_m: float
    range_cell_m: float
    #: first Doppler cell's lower edge as a radial velocity (m/s, positive receding) and the cell size (m/s)
    velocity_start_m_s: float
    velocity_cell_m_s: float
    #: (n, K, R, D) float32: the direction of arrival (azimuth, rad clockwise from north) a detection
    #: in that cell would report
    azimuth_rad: np.ndarray
    #: the std (rad) of a target cell's direction of arrival about the target's true azimuth
    azimuth_std_rad: float
    #: (R, D) int: the clutter-region label of every cell, an index into ``region_names``
    region_labels: np.ndarray
    region_names: tuple[str, ...]
    #: (R, D) float: the mean noise-plus-clutter power of every cell (thermal noise 1)
    noise_power: np.ndarray
    #: (n, K, T, 2) int: the (range, Doppler) cell of each target's echo peak, -1 where absent or outside the map
    target_cells: np.ndarray
    #: (range, Doppler) half-size of the box about a target's cell where a detection is the target's (cells)
    guard_cells: tuple[int, int]
    scan_period_s: float
    sensor_xy: np.ndarray
    #: (3, 2) min / max of range (m), azimuth (rad), radial velocity (m/s): the maps' extent and the DOA's
    surveillance_region: np.ndarray
    speed_bounds_m_s: tuple[float, float]
    accel_std_m_s2: float
    gospa_cutoff_m: float = 5000.0
    gospa_order: float = 2.0
    position_index: tuple[int, ...] = (0, 2)

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("range_start_m", "range_cell_m", "velocity_cell_m_s", "azimuth_std_rad", "scan_period_s",
                     "gospa_cutoff_m", "gospa_order"):
            require(self, name, _number(getattr(self, name)) and getattr(self, name) > 0, "a number > 0")
        require(self, "velocity_start_m_s", _number(self.velocity_start_m_s), "a finite number")
        require(self, "accel_std_m_s2", _number(self.accel_std_m_s2) and self.accel_std_m_s2 >= 0, "a number >= 0")
        require(self, "azimuth_rad", has_shape(self.azimuth_rad, (None, None, None, None), "f"),
                "an (n, K, R, D) float array")
        require(self, "region_labels", has_shape(self.region_labels, (None, None), "iu"), "an (R, D) int array")
        require(self, "region_names", isinstance(self.region_names, tuple)
                and all(name in REGION_NAMES for name in self.region_names), f"names from {REGION_NAMES}")
        require(self, "noise_power", has_shape(self.noise_power, self.region_labels.shape, "f")
                and bool(np.all(self.noise_power > 0)), "an (R, D) float array of powers > 0")
        require(self, "target_cells", has_shape(self.target_cells, (None, None, None, 2), "i"),
                "an (n, K, T, 2) int array")
        require(self, "guard_cells", isinstance(self.guard_cells, tuple) and len(self.guard_cells) == 2
                and all(isinstance(g, int) and g >= 0 for g in self.guard_cells), "a pair of ints >= 0")
        require(self, "surveillance_region", has_shape(self.surveillance_region, (3, 2), "f")
                and bool(np.all(self.surveillance_region[:, 1] > self.surveillance_region[:, 0])),
                "(3, 2) with max > min on every row")
        b = self.speed_bounds_m_s
        require(self, "speed_bounds_m_s", isinstance(b, tuple) and len(b) == 2 and all(_number(v) for v in b)
                and 0 <= b[0] < b[1], "(min, max) speeds with 0 <= min < max (m/s)")

    @property
    def shape(self) -> tuple[int, int]:
        """(R, D): range cells by Doppler cells."""
        return tuple(self.region_labels.shape)

    def check(self, batch: Batch) -> None:
        super().check(batch)
        n, K, (R, D) = batch.n, batch.steps, self.shape
        require(self, "region_labels", batch.z.shape == (n, K, R, D), f"the maps' shape: z is {batch.z.shape}, "
                f"expected ({n}, {K}, {R}, {D})")
        require(self, "azimuth_rad", self.azimuth_rad.shape == (n, K, R, D), f"shape ({n}, {K}, {R}, {D})")
        T = batch.truth.shape[2]
        cells = self.target_cells
        require(self, "target_cells", cells.shape == (n, K, T, 2) and bool(np.all(cells[..., 0] < R))
                and bool(np.all(cells[..., 1] < D)) and bool(np.all((cells[..., 0] >= 0) == (cells[..., 1] >= 0))),
                f"shape ({n}, {K}, {T}, 2), cells inside the {R} x {D} map or -1 in both")


@dataclass
class DetectTrackOutput(MultiTargetOutput):
    """A chain's output: its tracks (the :class:`MultiTargetOutput` fields) and what it detected.

    plot_cells : (n, K, P, 2) int64 — the (range, Doppler) cell of each plot of
        the scan, -1 padded: the cells the detector declared (after its peak
        detection), one plot each.
    plots : (n, K, P, 3) float — the plots [range m, azimuth rad, radial
        velocity m/s] the tracker was given, NaN where ``plot_cells`` is -1.
    """

    plot_cells: np.ndarray | None = None
    plots: np.ndarray | None = None


def check_detect_track_output(out, batch: Batch) -> DetectTrackOutput:
    """``out`` if it is a well-formed :class:`DetectTrackOutput` for ``batch``, else OutputError."""
    if not isinstance(out, DetectTrackOutput):
        raise OutputError(f"expected a DetectTrackOutput, got {type(out).__name__}")
    check_multitarget_output(out, batch)
    cells, plots = np.asarray(out.plot_cells), np.asarray(out.plots, float)
    n, K, (R, D) = batch.n, batch.steps, batch.scene.shape
    if cells.ndim != 4 or cells.shape[:2] != (n, K) or cells.shape[3] != 2 or cells.dtype.kind not in "iu":
        raise OutputError(f"plot_cells has shape {cells.shape} ({cells.dtype}), expected ({n}, {K}, P, 2) int")
    if plots.shape != (*cells.shape[:3], 3):
        raise OutputError(f"plots has shape {plots.shape}, expected {(*cells.shape[:3], 3)}")
    used = cells[..., 0] >= 0
    if np.any(used != (cells[..., 1] >= 0)) or np.any(cells[..., 0] >= R) or np.any(cells[..., 1] >= D):
        raise OutputError(f"plot_cells: cells must lie inside the {R} x {D} map, or be -1 in both")
    if np.any(~np.isfinite(plots[used])) or np.any(np.isfinite(plots[~used])):
        raise OutputError("plots are finite exactly where plot_cells holds a cell")
    return out


class DetectTrackTask(MultiTargetTask):
    """Detect and track: CFAR on range-Doppler maps, plots, tracks; scored with GOSPA, track metrics and cell Pd/Pfa."""

    name = DETECT_TRACK
    scene_type = DetectTrackScene
    noun = "detect-and-track chains"
    short_noun = "chains"
    recording_text = ("the range-Doppler map of each scan with the cells each chain declared over it, the true "
                      "tracks, every plot the chain made (green near a target's cell, grey elsewhere) and its "
                      "tentative, confirmed and terminated tracks with their 3-sigma gates, scan by scan, and its "
                      "GOSPA per scan")
    summary_columns = (*MultiTargetTask.summary_columns,
                       *(f"{rate}_{s}" for rate in ("cell_pd", "cell_pfa") for s in ("mean", "low", "high")))
    headline_columns = (*MultiTargetTask.headline_columns, "cell_pd_mean", "cell_pfa_mean")
    scene_entities = ("truths", "maps")                   # the plots are each chain's own
    method_entities = ("plots", "detections", *MultiTargetTask.method_entities)

    def check_output(self, out, batch: Batch) -> DetectTrackOutput:
        return check_detect_track_output(out, batch)

    def trial_metrics(self, batch: Batch, out: DetectTrackOutput, threshold: float) -> dict[str, np.ndarray]:
        sc = batch.scene
        tracks = multitarget_trial_metrics(batch.truth, np.asarray(out.state, float), np.asarray(out.track_id),
                                           np.asarray(out.status), position_index=sc.position_index,
                                           cutoff=sc.gospa_cutoff_m, order=sc.gospa_order,
                                           scan_period_s=sc.scan_period_s)
        cells = cell_metrics(sc.target_cells, np.asarray(out.plot_cells), sc.shape, sc.guard_cells)
        return tracks | cells | time_series(batch) | {
            name: np.full(batch.n, float(value)) for name, value in self.scene_columns(sc).items()}

    @staticmethod
    def scene_columns(sc: DetectTrackScene) -> dict[str, float]:
        """The GOSPA settings (Pd and clutter are the detector's doing here: its cell Pd and Pfa)."""
        return {"gospa_cutoff_m": sc.gospa_cutoff_m, "gospa_order": sc.gospa_order}

    def recorded_scene(self, batch: Batch, i: int) -> RecordedScene:
        from radarbench.bench.tasks.detecttrack.draw import MAPS, map_db
        pos = list(batch.scene.position_index)[:2]
        return RecordedScene(arrays={"truths_xy": batch.truth[i][..., pos]}, images={MAPS: map_db(batch.z[i])})

    def recorded_method(self, batch: Batch, out: DetectTrackOutput, i: int, threshold: float) -> MethodTrace:
        trace = super().recorded_method(batch, out, i, threshold)
        sc = batch.scene
        cells = np.asarray(out.plot_cells)[i:i + 1]
        near = np.abs(cells[:, :, :, None, :] - sc.target_cells[i:i + 1, :, None, :, :])
        on_target = ((near[..., 0] <= sc.guard_cells[0]) & (near[..., 1] <= sc.guard_cells[1])
                     & (sc.target_cells[i:i + 1, :, None, :, 0] >= 0)).any(axis=3)[0]
        origin = np.where(cells[0, ..., 0] < 0, -2, np.where(on_target, 0, -1)).astype(np.int64)
        trace.arrays |= {"plots_xy": _plots_xy(np.asarray(out.plots, float)[i], sc.sensor_xy), "plot_origin": origin,
                         "plot_cells": cells[0].astype(np.int32)}
        return trace

    def log_trial(self, stream, layout, rec) -> None:
        from radarbench.bench.tasks.detecttrack import draw
        draw.log_trial(self, stream, layout, rec)

    def views(self, layout, rec):
        from radarbench.bench.tasks.detecttrack import draw
        return draw.views(self, layout, rec)

    def summarise(self, trials: pd.DataFrame, series: dict) -> pd.DataFrame:
        tracks = super().summarise(trials, series)
        return tracks.merge(summarise_cells(trials), on=CELL_KEYS, how="left")

    def report_sections(self, ctx: ReportContext) -> list[str]:
        from radarbench.bench.tasks.detecttrack import report
        return report.sections(ctx)
