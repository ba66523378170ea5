"""Cell-level detection on maps: a per-cell statistic thresholded at a per-cell Pfa.

The task of CFAR detection on the range-Doppler (RD) spectrum of an HF
surface-wave radar (the HFSWR chapter on target detection and tracking, *CFAR
detection*: "CFAR along range and along Doppler, the two combined, then peak
detection"). A method returns a :class:`CellDetectionOutput`: per cell of
each map a test statistic on the scale of *nominal significance*, so a cell
is declared where ``statistic >= threshold`` and every detector's nominal
threshold is ``-log10(pfa)``. The harness calibrates that threshold per cell
(``nominal``: as is; ``empirical``: the threshold whose pooled per-cell
exceedance rate on null maps is the requested Pfa, from the null maps' order
statistics, :func:`bench.calibration.cell_calibration`), then scores targets
and false alarms per clutter region (:mod:`bench.tasks.cells.metrics`;
docs/architecture.md, 'Tasks' and 'Metrics').

Its scenarios put a :class:`MapScene` on the batch: the clutter-region label
of every cell, the true mean noise-plus-clutter power of every cell (for the
ideal known-noise detector and the CFAR loss), the target cells and their
SNR (docs/architecture.md, 'Scenes'). The batch's ``z`` is (n, 1, R, D)
float32 linear power (square-law detected, one dwell: K = 1 step), ``t`` (1,).

A recorded map keeps the RD map and the region labels (quantised images), the
true noise power and the target cells; per method its statistic, its
threshold map (``noise_estimate`` times the threshold factor that gives the
threshold in force, when the method gives its noise estimate) and its
detections. Entities::

    .../map                     DepthImage: the RD map in dB (range down, Doppler across)
    .../map/targets             Points2D: the true target cells
    .../regions                 SegmentationImage: the clutter-region label of every cell
    .../{method}/statistic      DepthImage: the method's statistic (nominal significance)
    .../{method}/threshold_map  DepthImage: the method's threshold map in dB (when given)
    .../{method}/detections     Points2D: the declared cells
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from radarbench.bench.calibration import cell_order_statistics
from radarbench.bench.core import Batch, Scene, has_shape, require
from radarbench.bench.recording.record import MethodTrace
from radarbench.bench.tasks.base import OutputError, RecordedScene, ReportContext, Task, check_finite, check_range
from radarbench.bench.tasks.cells.metrics import REGION_NAMES, SUMMARY_COLUMNS, cell_trial_metrics, summarise_cells

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

__all__ = ["CELL_DETECTION", "REGION_NAMES", "CellDetectionOutput", "CellDetectionTask", "MapScene"]

CELL_DETECTION = "cell-detection"


def _count(x) -> bool:
    return isinstance(x, (int, np.integer)) and not isinstance(x, bool)


@dataclass(frozen=True, kw_only=True, eq=False)
class MapScene(Scene):
    """What a map scenario tells the detectors and the harness
    (docs/architecture.md, 'Scenes'), besides :class:`~bench.core.Scene`'s
    fields. Maps are R range cells by D Doppler cells; cell ``(r, d)`` is
    ``z[:, 0, r, d]``.
    """

    #: (R, D) int8: the clutter-region label of every cell, an index into ``region_names``
    region_labels: np.ndarray
    #: the name of each label, from :data:`REGION_NAMES` (the vocabulary the task's metrics know)
    region_names: tuple[str, ...]
    #: (n, R, D) float: the true mean noise-plus-clutter power of every cell (no target), linear
    noise_power: np.ndarray
    #: (n, T, 2) int (range, Doppler) cell of each target; T may be 0 (the null: no target)
    target_cells: np.ndarray
    #: (n, T) float: each target's mean SNR over the noise-plus-clutter power of its cell (dB)
    target_snr_db: np.ndarray
    #: (n, T) bool: whether the target has a close neighbour by design (the masking pairs)
    target_paired: np.ndarray
    #: the targets' fluctuation: 0 (non-fluctuating) or 1 (Swerling 1: exponential power over dwells)
    swerling: int = 0
    #: (range, Doppler) half-size of the box around each target left out of the false-alarm count (cells)
    guard_cells: tuple[int, int] = (2, 2)

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self, "region_labels", has_shape(self.region_labels, (None, None), "iu"), "an (R, D) integer array")
        require(self, "region_names", isinstance(self.region_names, tuple) and len(self.region_names) >= 1
                and all(name in REGION_NAMES for name in self.region_names),
                f"a non-empty tuple of names from {REGION_NAMES}")
        require(self, "region_labels", int(self.region_labels.min()) >= 0
                and int(self.region_labels.max()) < len(self.region_names),
                f"labels in 0..{len(self.region_names) - 1} (indices into region_names)")
        require(self, "noise_power", has_shape(self.noise_power, (None, None, None), "f")
                and bool(np.all(self.noise_power > 0)), "an (n, R, D) float array of powers > 0")
        require(self, "target_cells", has_shape(self.target_cells, (None, None, 2), "iu"),
                "an (n, T, 2) integer array")
        require(self, "target_snr_db", has_shape(self.target_snr_db, (None, None), "f"), "an (n, T) float array")
        require(self, "target_paired", has_shape(self.target_paired, (None, None), "b"), "an (n, T) bool array")
        require(self, "swerling", _count(self.swerling) and self.swerling in (0, 1), "0 or 1")
        require(self, "guard_cells", isinstance(self.guard_cells, tuple) and len(self.guard_cells) == 2
                and all(_count(g) and g >= 0 for g in self.guard_cells), "a (range, Doppler) pair of ints >= 0")

    @property
    def shape(self) -> tuple[int, int]:
        """(R, D): range cells by Doppler cells."""
        return tuple(self.region_labels.shape)

    def check(self, batch: Batch) -> None:
        super().check(batch)
        n, (R, D) = batch.n, self.shape
        require(self, "region_labels", batch.z.shape == (n, 1, R, D),
                f"the maps' shape: z is {batch.z.shape}, expected ({n}, 1, {R}, {D})")
        require(self, "noise_power", self.noise_power.shape == (n, R, D), f"shape ({n}, {R}, {D})")
        T = self.target_cells.shape[1]
        require(self, "target_cells", self.target_cells.shape[0] == n and (T == 0 or (
            int(self.target_cells.min()) >= 0 and bool(np.all(self.target_cells[..., 0] < R))
            and bool(np.all(self.target_cells[..., 1] < D)))), f"({n}, T, 2) cells inside the {R} x {D} map")
        for name in ("target_snr_db", "target_paired"):
            require(self, name, getattr(self, name).shape == (n, T), f"shape ({n}, {T})")


@dataclass
class CellDetectionOutput:
    """Output of a cell-level detector (a CFAR).

    statistic : (n, R, D) float32 — per cell the test statistic on the scale
        of nominal significance: -log10 of the detector's nominal per-cell
        false-alarm probability at the observed ratio (cell power over noise
        estimate), a monotone transform of that ratio. A cell is declared
        where ``statistic >= threshold``; the nominal threshold is
        ``-log10(pfa)``. The range/Doppler combination and the peak detection
        are folded in (cells removed by the peak detection hold 0).
    noise_estimate : (n, R, D) float32 or None — the detector's noise
        estimate μ per cell (its threshold map is μ·K), for recordings.
    threshold_factor : callable or None — K as a function of the nominal
        per-cell Pfa (the method's ``threshold_factor`` bound to its params;
        a float, or an (R, D) array when K differs by cell, e.g. per region),
        so a recording can draw the threshold map μ·K at the threshold in force.
    """

    statistic: np.ndarray
    noise_estimate: np.ndarray | None = None
    threshold_factor: Callable[[float], float | np.ndarray] | None = None


class CellDetectionTask(Task):
    """Cell-level detection on range-Doppler maps: a per-cell statistic at a calibrated per-cell Pfa."""

    name = CELL_DETECTION
    scene_type = MapScene
    calibrated = True
    calibration_modes = ("nominal", "empirical")
    pfa_unit = "per cell"
    pfa_per_cell = True
    evaluation_pfa = True
    noun, short_noun = "CFAR detectors", "CFAR"
    null_sample = "every cell of every null map (kept as order statistics), and each map's peak"
    calibration_text = ("For CFAR detectors the Pfa is per cell: the measured Pfa is the pooled fraction of "
                        "null-map cells at or above the threshold, with an interval counted over maps (decisions "
                        "of neighbouring cells share reference cells), and *chance Pd* is the fraction of null "
                        "maps with at least one false alarm.")
    recording_text = ("per CFAR detector the statistic, the threshold map and the detections over the RD map, "
                      "with the true targets and the clutter-region labels")
    scene_entities = ("map", "noise_power", "regions")
    method_entities = ("statistic", "threshold_map", "detections")
    ranking_metric = "hit_fraction"
    ranking_higher_is_better = True
    ranking_label = "fraction of a map's targets detected"
    ranking_undefined = "no targets"
    ranking_column = "pd"
    curves = (("pd", "Pd (fraction of the targets detected)"),)
    recording_charts = (("pd", "Pd"), ("false_alarms_per_map", "false alarms per map"))
    informative_column = "pd"

    summary_columns = SUMMARY_COLUMNS
    headline_columns = ("pd", "pd_low", "pd_high", "pfa", "pfa_low", "pfa_high", "false_alarms_per_map")

    # -------------------------------------------------------------- worker side

    def check_output(self, out, batch: Batch) -> CellDetectionOutput:
        if not isinstance(out, CellDetectionOutput):
            raise OutputError(f"expected a CellDetectionOutput, got {type(out).__name__}")
        shape = (batch.n, *batch.scene.shape)
        check_finite("statistic", np.asarray(out.statistic), shape)
        # -log10 of a probability is >= 0; a probability of 1 may round to 1 + 1e-16
        check_range("statistic", out.statistic, -1e-12, what="-log10 of a false-alarm probability")
        if out.noise_estimate is not None:
            check_finite("noise_estimate", np.asarray(out.noise_estimate), shape)
        return out

    def null_values(self, batch: Batch, out: CellDetectionOutput) -> np.ndarray:
        """Each null map's largest statistic: the chance of any false alarm in
        a map (the per-cell calibration reads :meth:`null_cells`)."""
        return np.asarray(out.statistic, float).reshape(batch.n, -1).max(axis=1)

    def null_peaks(self, batch: Batch, out: CellDetectionOutput) -> np.ndarray:
        """The same map peaks: the chance Pd is the fraction of null maps with a false alarm."""
        return self.null_values(batch, out)

    def null_cells(self, batch: Batch, out: CellDetectionOutput) -> np.ndarray:
        """Order statistics of each null map's statistic, for the per-cell Pfa
        (:func:`bench.calibration.cell_calibration`)."""
        return cell_order_statistics(np.asarray(out.statistic))

    def trial_metrics(self, batch: Batch, out: CellDetectionOutput, threshold: float) -> dict[str, np.ndarray]:
        sc = batch.scene
        return cell_trial_metrics(np.asarray(out.statistic), threshold, region_labels=sc.region_labels,
                                  region_names=sc.region_names, target_cells=sc.target_cells,
                                  target_paired=sc.target_paired, target_snr_db=sc.target_snr_db,
                                  guard_cells=sc.guard_cells, swerling=sc.swerling)

    def recorded_scene(self, batch: Batch, i: int) -> RecordedScene:
        from radarbench.bench.tasks.cells.draw import recorded_scene
        return recorded_scene(batch, i)

    def recorded_method(self, batch: Batch, out: CellDetectionOutput, i: int, threshold: float) -> MethodTrace:
        from radarbench.bench.tasks.cells.draw import recorded_method
        return recorded_method(batch, out, i, threshold)

    # -------------------------------------------------------------- driver side

    def summarise(self, trials: pd.DataFrame, series: dict) -> pd.DataFrame:
        return summarise_cells(trials, series)

    def log_trial(self, stream, layout, rec) -> None:
        from radarbench.bench.tasks.cells.draw import log_trial
        log_trial(self, stream, layout, rec)

    def views(self, layout, rec):
        from radarbench.bench.tasks.cells.draw import views
        return views(self, layout, rec)

    def report_sections(self, ctx: ReportContext) -> list[str]:
        from radarbench.bench.tasks.cells import report
        return report.sections(ctx)
