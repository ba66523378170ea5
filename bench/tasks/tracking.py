"""Tracking: state estimates scored against the truth; no threshold.

A tracker returns a :class:`~bench.core.TrackingOutput`; the harness scores
position RMSE, divergence and NEES per trial and per step
(:mod:`bench.tasks.tracking_metrics`; docs/architecture.md, 'Tasks'), as the
glint paper (Viterbi vs EKF under glint noise) compares its trackers.

A recorded trial keeps, per tracker, the position estimate (drawn as a track
under ``.../{method}/estimate``, north up) and its error per state component
(traces ``error_<component>``); of the scene, the steps whose measurement had
a glint outlier (``meta["glint_outlier"]``), drawn in red under
``.../measurements/glint``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from bench.core import TRACKING, Batch, TrackingOutput
from bench.recording.blueprint import Views
from bench.recording.draw import log_static_points, log_track, north_up
from bench.recording.layout import TrialLayout
from bench.recording.record import MethodTrace, TrialRecord, check_shape
from bench.tasks.base import OutputError, ReportContext, Scene, Task, check_finite, time_series
from bench.tasks.tracking_metrics import summarise_tracking, tracking_steps, tracking_trial_metrics

__all__ = ["TrackingTask", "method_trace", "scene"]

_GLINT_COLOR = (255, 40, 90)


def method_trace(estimate_xy, traces: dict | None = None) -> MethodTrace:
    """What a recorded trial keeps of a tracker: its position estimate (K, 2) in
    metres and its error traces."""
    estimate_xy = np.asarray(estimate_xy)
    check_shape(estimate_xy, (None, 2), "estimate_xy")
    return MethodTrace(threshold=None, traces=traces or {}, arrays={"estimate_xy": estimate_xy})


def scene(measurement_flags=None) -> Scene:
    """What a recorded trial keeps of a tracking scene: the (K,) steps whose
    measurement had a glint outlier, if the scenario flags them."""
    if measurement_flags is None:
        return Scene()
    flags = np.asarray(measurement_flags, dtype=bool)
    check_shape(flags, (None,), "measurement_flags")
    return Scene(arrays={"measurement_flags": flags})


class TrackingTask(Task):
    """Tracking: state estimates scored against the truth (RMSE, divergence, NEES)."""

    name = TRACKING
    noun = short_noun = "trackers"
    recording_text = ("per tracker the estimated trajectory and its error per state component, with "
                      "glint-corrupted measurements marked")
    summary_columns = ("n_trials", "rmse_mean", "rmse_low", "rmse_high", "realised_snr_db", "divergence_rate",
                       "divergence_low", "divergence_high", "nees_mean")
    headline_columns = ("rmse_mean", "rmse_low", "rmse_high", "divergence_rate", "nees_mean")
    method_entities = ("estimate",)

    # -------------------------------------------------------------- worker side

    def check_output(self, out, batch: Batch) -> TrackingOutput:
        if not isinstance(out, TrackingOutput):
            raise OutputError(f"expected a TrackingOutput, got {type(out).__name__}")
        check_finite("estimate", np.asarray(out.estimate, float), batch.truth.shape)
        if out.covariance is not None:
            d = batch.truth.shape[-1]
            check_finite("covariance", np.asarray(out.covariance, float), (*batch.truth.shape[:2], d, d))
        return out

    def labels(self, batch: Batch) -> list[str]:
        """Names of the state components (``meta["state_labels"]``, else x0, x1, ...)."""
        d = batch.truth.shape[-1]
        return list(batch.meta.get("state_labels", [f"x{j}" for j in range(d)]))

    def trial_metrics(self, batch: Batch, out: TrackingOutput, threshold: float) -> dict[str, np.ndarray]:
        return tracking_trial_metrics(out.estimate, batch.truth,
                                      position_index=batch.meta.get("position_index", (0, 1)),
                                      labels=self.labels(batch), covariance=out.covariance,
                                      divergence_bound_m=float(batch.meta.get("divergence_bound_m", np.inf)),
                                      derived=batch.meta.get("derived_components")) \
            | time_series(batch)

    def recorded_scene(self, batch: Batch, i: int) -> Scene:
        flags = batch.meta.get("glint_outlier")
        return scene(None if flags is None else np.asarray(flags[i]).reshape(batch.steps, -1).any(axis=1))

    def recorded_method(self, batch: Batch, out: TrackingOutput, i: int, threshold: float) -> MethodTrace:
        pos = list(batch.meta.get("position_index", (0, 1)))
        err = out.estimate[i] - batch.truth[i]
        return method_trace(out.estimate[i][:, pos[:2]],
                            {f"error_{label}": err[:, j] for j, label in enumerate(self.labels(batch))})

    # -------------------------------------------------------------- driver side

    def summarise(self, trials: pd.DataFrame, series: dict) -> pd.DataFrame:
        return summarise_tracking(trials, series)

    def steps(self, trials: pd.DataFrame, series: dict[str, np.ndarray]) -> pd.DataFrame:
        labels = [k[len("est_"):] for k in series if k.startswith("est_")]
        return tracking_steps(series, labels).assign(n_trials=len(trials))

    def log_trial(self, stream, layout: TrialLayout, rec: TrialRecord) -> None:
        t = np.asarray(rec.t, dtype=np.float64)
        flags = rec.arrays.get("measurement_flags")
        if flags is not None and rec.measurements_xy is not None:
            pos = north_up(rec.measurements_xy)
            glint = np.intersect1d(np.flatnonzero(np.isfinite(pos).all(axis=1)), np.flatnonzero(flags))
            if glint.size:
                log_static_points(stream, layout.path("measurements/glint"), pos[glint], _GLINT_COLOR, 4.5)
        for m in layout.methods_of(self):
            estimate = rec.methods[m.label].arrays.get("estimate_xy")
            if estimate is not None:
                log_track(stream, m.path("estimate"), t, north_up(estimate), m.color)

    def views(self, layout: TrialLayout, rec: TrialRecord) -> Views:
        return Views(has_xy=any("estimate_xy" in rec.methods[m.label].arrays for m in layout.methods_of(self)))

    def report_sections(self, ctx: ReportContext) -> list[str]:
        from bench.tasks import tracking_report
        return tracking_report.sections(ctx)

