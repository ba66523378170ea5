"""What the harness does with each task's outputs.

A task handler knows, for one task (:data:`bench.core.TASKS`), how to check a
method's output, which statistic values under the null hypothesis feed the
calibration, how to turn an output and a threshold into per-trial metrics,
what to record of a trial, and how to summarise trials into cells. The runner
and the report look handlers up by the method's ``task``; they never look at a
method by name.

Per-trial metrics are 1-D columns (``trials.csv``) or 2-D *series* (n, K)
(per-step errors: kept in the store, summarised per step, never in
``trials.csv``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from bench.core import (
    MANEUVER_DETECTION,
    TBD,
    TRACKING,
    Batch,
    DetectionOutput,
    TBDOutput,
    TrackingOutput,
)
from bench.calibration import cell_order_statistics
from bench.metrics import (
    detection_trial_metrics,
    summarise_detection,
    summarise_tbd,
    summarise_tracking,
    tbd_trial_metrics,
    tracking_trial_metrics,
    unit_innovation_snr_offset_db,
)
from bench.recording import MethodTrace


class OutputError(RuntimeError):
    """A method returned something malformed; recorded as that method's failure."""


def _check_finite(name: str, a: np.ndarray, shape: tuple) -> None:
    if a.shape != shape:
        raise OutputError(f"{name} has shape {a.shape}, expected {shape}")
    bad = int(np.count_nonzero(~np.isfinite(a)))
    if bad:
        raise OutputError(f"{name} has {bad} non-finite values")


def _time_series(batch: Batch) -> dict[str, np.ndarray]:
    """The step times as a series, so per-step tables carry time in seconds."""
    return {"t_s": np.broadcast_to(np.asarray(batch.t, float), (batch.n, batch.steps))}


class DetectionTask:
    task = MANEUVER_DETECTION
    #: whether a threshold is calibrated on null trials for this task
    calibrated = True
    calibration_modes = ("nominal", "empirical")
    #: what the requested Pfa is counted over
    pfa_unit = "per step"

    def check_output(self, out, batch: Batch) -> DetectionOutput:
        if not isinstance(out, DetectionOutput):
            raise OutputError(f"expected a DetectionOutput, got {type(out).__name__}")
        shape = (batch.n, batch.steps)
        if out.statistic.shape != shape:
            raise OutputError(f"statistic has shape {out.statistic.shape}, expected {shape}")
        bad = int(np.count_nonzero(~np.isfinite(out.statistic)))
        if bad:
            raise OutputError(f"statistic has {bad} non-finite values")
        return out

    def null_start(self, batch: Batch, out: DetectionOutput) -> int:
        return max(int(batch.meta.get("warmup_steps", 0)), int(out.valid_from))

    def null_values(self, batch: Batch, out: DetectionOutput) -> np.ndarray:
        """Per-step statistic values of a null batch, after warm-up: the calibration sample."""
        return out.statistic[:, self.null_start(batch, out):].ravel()

    def null_peaks(self, batch: Batch, out: DetectionOutput) -> np.ndarray | None:
        """Per null trial, the largest statistic in the detection window placed
        where the maneuver would start: ``mean(peaks >= threshold)`` is the
        chance detection rate, the floor Pd falls to as SNR goes down."""
        onset = batch.meta.get("null_onset_step")
        if onset is None:
            return None
        steps = np.asarray(onset)[..., None] + np.arange(int(batch.meta["detect_window_steps"]))
        steps = np.broadcast_to(steps, (batch.n, steps.shape[-1]))   # per-trial onsets (jitter)
        return np.take_along_axis(out.statistic, np.minimum(steps, batch.steps - 1), axis=1).max(axis=1)

    def null_cells(self, batch: Batch, out: DetectionOutput) -> None:
        return None

    def trial_metrics(self, batch: Batch, out: DetectionOutput, threshold: float) -> dict[str, np.ndarray]:
        return detection_trial_metrics(out.statistic, threshold, onset=np.asarray(batch.meta["onset_step"]),
                                       detect_window=int(batch.meta["detect_window_steps"]),
                                       null_start=self.null_start(batch, out))

    def trace(self, batch: Batch, out: DetectionOutput, i: int, threshold: float) -> MethodTrace:
        stat = out.statistic[i]
        return MethodTrace(statistic=stat, threshold=float(threshold), alarms=stat >= threshold,
                           traces={k: v[i] for k, v in out.traces.items()})

    def summarise(self, trials: pd.DataFrame, series: dict) -> pd.DataFrame:
        return summarise_detection(trials)


class TBDTask:
    """Track-before-detect: a scene score thresholded at a per-scene Pfa, and a
    backtracked track scored against the true cells (:func:`bench.metrics.tbd_trial_metrics`)."""

    task = TBD
    calibrated = True
    calibration_modes = ("nominal", "empirical", "gumbel")
    pfa_unit = "per scene"

    def check_output(self, out, batch: Batch) -> TBDOutput:
        if not isinstance(out, TBDOutput):
            raise OutputError(f"expected a TBDOutput, got {type(out).__name__}")
        _check_finite("score", np.asarray(out.score, float), (batch.n,))
        track = np.asarray(out.track)
        if track.shape != (batch.n, batch.steps, 2) or not np.issubdtype(track.dtype, np.integer):
            raise OutputError(f"track has shape {track.shape} ({track.dtype}), expected integer cells "
                              f"{(batch.n, batch.steps, 2)}")
        grid = batch.meta["grid"]
        if track.min() < 0 or (track[..., 0] >= grid["rows"]).any() or (track[..., 1] >= grid["cols"]).any():
            raise OutputError("track leaves the grid")
        return out

    def null_values(self, batch: Batch, out: TBDOutput) -> np.ndarray:
        """One scene score per null trial: the calibration sample."""
        return np.asarray(out.score, float)

    def null_peaks(self, batch: Batch, out: TBDOutput) -> None:
        return None

    def null_cells(self, batch: Batch, out: TBDOutput) -> np.ndarray | None:
        """Order statistics of each null scene's value map (the final merit per
        cell), for the per-cell Pfa (:func:`bench.calibration.cell_calibration`)."""
        return None if out.value is None else cell_order_statistics(out.value)

    def trial_metrics(self, batch: Batch, out: TBDOutput, threshold: float) -> dict[str, np.ndarray]:
        meta = batch.meta
        if meta.get("target_cells") is None:
            raise OutputError("an evaluation batch has no target (target_cells is None)")
        offset = (unit_innovation_snr_offset_db(meta["ar_coefficients"], meta["noise_autocovariance"])
                  if "noise_autocovariance" in meta else np.nan)
        return (tbd_trial_metrics(out.score, out.track, threshold, target_cells=meta["target_cells"],
                                  truth_xy_m=batch.truth[..., :2], grid=meta["grid"],
                                  tolerance_cells=int(meta.get("hit_tolerance_cells", 1)))
                | {"snr_offset_unit_innovation_db": np.full(batch.n, offset)} | _time_series(batch))

    def trace(self, batch: Batch, out: TBDOutput, i: int, threshold: float) -> MethodTrace:
        return MethodTrace(statistic=None, threshold=float(threshold), alarms=None,
                           track_cells=np.asarray(out.track[i]),
                           value=None if out.value is None else np.asarray(out.value[i]),
                           score=float(out.score[i]))

    def summarise(self, trials: pd.DataFrame, series: dict) -> pd.DataFrame:
        return summarise_tbd(trials, series)


class TrackingTask:
    """Tracking: state estimates scored against the truth; no threshold."""

    task = TRACKING
    calibrated = False
    calibration_modes = ("nominal", "empirical", "gumbel")   # none applies; any mode is accepted
    pfa_unit = ""

    def check_output(self, out, batch: Batch) -> TrackingOutput:
        if not isinstance(out, TrackingOutput):
            raise OutputError(f"expected a TrackingOutput, got {type(out).__name__}")
        _check_finite("estimate", np.asarray(out.estimate, float), batch.truth.shape)
        if out.covariance is not None:
            d = batch.truth.shape[-1]
            _check_finite("covariance", np.asarray(out.covariance, float), (*batch.truth.shape[:2], d, d))
        return out

    def labels(self, batch: Batch) -> list[str]:
        d = batch.truth.shape[-1]
        return list(batch.meta.get("state_labels", [f"x{j}" for j in range(d)]))

    def trial_metrics(self, batch: Batch, out: TrackingOutput, threshold: float) -> dict[str, np.ndarray]:
        return tracking_trial_metrics(out.estimate, batch.truth,
                                      position_index=batch.meta.get("position_index", (0, 1)),
                                      labels=self.labels(batch), covariance=out.covariance,
                                      divergence_bound_m=float(batch.meta.get("divergence_bound_m", np.inf)),
                                      derived=batch.meta.get("derived_components")) \
            | _time_series(batch)

    def trace(self, batch: Batch, out: TrackingOutput, i: int, threshold: float) -> MethodTrace:
        pos = list(batch.meta.get("position_index", (0, 1)))
        err = out.estimate[i] - batch.truth[i]
        return MethodTrace(statistic=None, threshold=None, alarms=None, estimate_xy=out.estimate[i][:, pos[:2]],
                           traces={f"error_{label}": err[:, j] for j, label in enumerate(self.labels(batch))})

    def summarise(self, trials: pd.DataFrame, series: dict) -> pd.DataFrame:
        return summarise_tracking(trials, series)


HANDLERS = {MANEUVER_DETECTION: DetectionTask(), TBD: TBDTask(), TRACKING: TrackingTask()}


def handler(task: str):
    try:
        return HANDLERS[task]
    except KeyError:
        raise OutputError(f"the harness has no handler for task {task!r}") from None
