"""What the harness does with each task's outputs.

A task handler knows, for one task of DESIGN.md section 3, how to check a
method's output, which statistic values under the null hypothesis feed the
calibration, how to turn an output and a threshold into per-trial metrics,
what to record of a trial, and how to summarise trials into cells. The runner
and the report look handlers up by the method's ``task``; they never look at a
method by name.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from bench.core import MANEUVER_DETECTION, Batch, DetectionOutput
from bench.metrics import detection_trial_metrics, summarise_detection
from bench.recording import MethodTrace


class OutputError(RuntimeError):
    """A method returned something malformed; recorded as that method's failure."""


class DetectionTask:
    task = MANEUVER_DETECTION
    #: per-trial columns of trials.csv, in order
    trial_columns = ("detected", "delay", "false_alarms", "null_steps", "peak_statistic")

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
        window = out.statistic[:, onset:onset + int(batch.meta["detect_window_steps"])]
        return window.max(axis=1)

    def trial_metrics(self, batch: Batch, out: DetectionOutput, threshold: float) -> dict[str, np.ndarray]:
        return detection_trial_metrics(out.statistic, threshold, onset=int(batch.meta["onset_step"]),
                                       detect_window=int(batch.meta["detect_window_steps"]),
                                       null_start=self.null_start(batch, out))

    def trace(self, out: DetectionOutput, i: int, threshold: float) -> MethodTrace:
        stat = out.statistic[i]
        return MethodTrace(statistic=stat, threshold=float(threshold), alarms=stat >= threshold,
                           traces={k: v[i] for k, v in out.traces.items()})

    def summarise(self, trials: pd.DataFrame) -> pd.DataFrame:
        return summarise_detection(trials)


HANDLERS = {MANEUVER_DETECTION: DetectionTask()}


def handler(task: str):
    try:
        return HANDLERS[task]
    except KeyError:
        raise OutputError(f"the harness has no handler for task {task!r}") from None
