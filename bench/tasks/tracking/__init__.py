"""Tracking: state estimates scored against the truth; no threshold.

A tracker returns a :class:`~bench.core.TrackingOutput`; the harness scores
position RMSE, divergence and NEES per trial and per step
(:mod:`bench.tasks.tracking.metrics`; docs/architecture.md, 'Tasks'), as the
glint paper (Viterbi vs EKF under glint noise) compares its trackers.

A recorded trial keeps, per tracker, the position estimate (drawn as a track
under ``.../{method}/estimate``, north up) and its error per state component
(traces ``error_<component>``; a scene with a single position component, a
range, draws it against time, x = t in s); of the scene, the steps whose measurement had
a glint outlier (:attr:`TrackingScene.outlier_flags`), drawn in red under
``.../measurements/glint``.

Its scenarios put a :class:`TrackingScene` on the batch: the state labels,
the divergence bound, the outlier flags, the true maneuvers (mask and onset
steps, where the scenario has them) and the model the trackers run on
(docs/architecture.md, 'Scenes').
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from radarbench.bench.core import TRACKING, Batch, Scene, TrackingOutput, has_shape, require
from radarbench.bench.recording.blueprint import Views
from radarbench.bench.recording.draw import log_static_points, log_track, north_up
from radarbench.bench.recording.layout import TrialLayout
from radarbench.bench.recording.record import MethodTrace, TrialRecord, check_shape
from radarbench.bench.tasks.base import (OutputError, RecordedScene, ReportContext, Task, check_covariance, check_estimate,
                              check_finite, check_range, check_traces, time_series)
from radarbench.bench.tasks.tracking.metrics import (bound_series, maneuver_trial_metrics, summarise_tracking,
                                          tracking_steps, tracking_trial_metrics)

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

__all__ = ["TrackingScene", "TrackingTask", "method_trace", "scene"]

_GLINT_COLOR = (255, 40, 90)

#: The traces the metrics score (:data:`~bench.tasks.tracking.metrics.SWITCH_TRACES`) and the
#: values they can take: a value outside is an impossible output, the method's failure.
SCORED_TRACES = {"mode": (0.0, 1.0, "the maneuver mode's probability, or 1 where it is in use"),
                 "switch": (0.0, 1.0, "a switch decision, 0 or 1"),
                 "q_k": (0.0, np.inf, "a noise variance")}
#: The series a recorded trial keeps of a tracker besides its own traces (every one of which
#: is recorded): its error and estimate per state component, named by these prefixes.
RECORDED_PREFIXES = ("error_", "estimate_")


def _labels(value) -> bool:
    return isinstance(value, tuple) and all(isinstance(x, str) for x in value)


@dataclass(frozen=True, kw_only=True, eq=False)
class TrackingScene(Scene):
    """What a tracking scenario tells the trackers and the harness
    (docs/architecture.md, 'Scenes'), besides :class:`~bench.core.Scene`'s
    fields (``position_index``: the components the position RMSE is over).
    """

    #: the state-space model the trackers run on, e.g. a :class:`models.glint.GlintModel`
    #: (dynamics, known control, prior, spherical measurement under glint noise); None:
    #: none. Typed Any here because the harness never imports models; the methods check it.
    model: Any = None
    #: names of the state components, in order (d of them); None: x0, x1, ...
    state_labels: tuple[str, ...] | None = None
    #: names of the measured components, in order (m of them); None: not named
    measurement_labels: tuple[str, ...] | None = None
    #: a trial has diverged when its position error exceeds this bound (m) at some step
    divergence_bound_m: float = math.inf
    #: a picklable function of states (..., d) returning named (...) arrays (e.g. range,
    #: bearing, elevation), scored per step like the state components; None: none
    derived_components: Callable[[np.ndarray], dict[str, np.ndarray]] | None = None
    #: (n, K, m) bool: which measured components are outliers (glint); drawn in recordings
    outlier_flags: np.ndarray | None = None
    #: (n, K) bool: the steps inside a true maneuver (for RMSE split into quiet and
    #: maneuvering steps); None: the scenario defines no maneuvers
    maneuver_mask: np.ndarray | None = None
    #: (n, O) int: the step of each true maneuver onset per trial (O may be 0: none), for
    #: switch delays and false switches; None: the scenario defines no maneuvers
    maneuver_onset_steps: np.ndarray | None = None
    #: (n, K) float: the posterior Cramér-Rao bound on the position's mean square error (m^2)
    #: per trial and step, computed by the scenario from its truth and its own dynamics and
    #: noise (drawn under the RMSE curves; the trackers' efficiency is bound / RMSE); None: none
    position_bound: np.ndarray | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("state_labels", "measurement_labels"):
            require(self, name, getattr(self, name) is None or _labels(getattr(self, name)), "None or a tuple of str")
        require(self, "divergence_bound_m", isinstance(self.divergence_bound_m, (int, float))
                and self.divergence_bound_m > 0, "a number > 0 (m)")
        require(self, "derived_components", self.derived_components is None or callable(self.derived_components),
                "None or a function of states")
        flags = self.outlier_flags
        require(self, "outlier_flags", flags is None or (isinstance(flags, np.ndarray) and flags.dtype == bool
                                                         and flags.ndim == 3), "None or an (n, K, m) bool array")
        mask = self.maneuver_mask
        require(self, "maneuver_mask", mask is None or (isinstance(mask, np.ndarray) and mask.dtype == bool
                                                        and mask.ndim == 2), "None or an (n, K) bool array")
        onsets = self.maneuver_onset_steps
        require(self, "maneuver_onset_steps", onsets is None or (has_shape(onsets, (None, None), "iu")
                                                                 and bool((onsets >= 0).all())),
                "None or an (n, O) array of step indices >= 0")
        bound = self.position_bound
        require(self, "position_bound", bound is None or (has_shape(bound, (None, None), "f")
                                                          and bool((np.nan_to_num(bound) >= 0).all())),
                "None or an (n, K) float array of mean square errors >= 0 (m^2)")

    def check(self, batch: Batch) -> None:
        super().check(batch)
        n, K, d = batch.n, batch.steps, batch.truth.shape[-1]
        m = batch.z.shape[-1]
        require(self, "state_labels", self.state_labels is None or len(self.state_labels) == d, f"{d} labels")
        require(self, "measurement_labels", self.measurement_labels is None or len(self.measurement_labels) == m,
                f"{m} labels")
        require(self, "outlier_flags", self.outlier_flags is None or self.outlier_flags.shape == (n, K, m),
                f"shape ({n}, {K}, {m})")
        require(self, "maneuver_mask", self.maneuver_mask is None or self.maneuver_mask.shape == (n, K),
                f"shape ({n}, {K})")
        onsets = self.maneuver_onset_steps
        require(self, "maneuver_onset_steps", onsets is None or (onsets.shape[0] == n and bool((onsets < K).all())),
                f"{n} rows of steps < {K}")
        require(self, "position_bound", self.position_bound is None or self.position_bound.shape == (n, K),
                f"shape ({n}, {K})")


def method_trace(estimate_xy, traces: dict | None = None) -> MethodTrace:
    """What a recorded trial keeps of a tracker: its position estimate (K, 2) in
    metres and its error traces."""
    estimate_xy = np.asarray(estimate_xy)
    check_shape(estimate_xy, (None, 2), "estimate_xy")
    return MethodTrace(threshold=None, traces=traces or {}, arrays={"estimate_xy": estimate_xy})


def scene(measurement_flags=None) -> RecordedScene:
    """What a recorded trial keeps of a tracking scene: the (K,) steps whose
    measurement had a glint outlier, if the scenario flags them."""
    if measurement_flags is None:
        return RecordedScene()
    flags = np.asarray(measurement_flags, dtype=bool)
    check_shape(flags, (None,), "measurement_flags")
    return RecordedScene(arrays={"measurement_flags": flags})


def _log_maneuver(stream, layout: TrialLayout, t: np.ndarray, rec: TrialRecord) -> None:
    """A maneuvering scene's truth per component over time (``truth/<component>``) and
    the true maneuver (``truth/maneuvering``, 1 inside it; its first step the onset)."""
    import rerun as rr

    from radarbench.bench.recording.draw import log_series

    every = np.arange(t.shape[0])
    for name, values in rec.arrays.items():
        if name.startswith("truth_") or name == "maneuvering":
            label = name[len("truth_"):] if name.startswith("truth_") else name
            log_series(stream, layout.path(f"truth/{label}"), t, every, np.asarray(values, float),
                       rr.SeriesLines(names=f"truth {label}", colors=[(235, 235, 235)], widths=[1.5]))


class TrackingTask(Task):
    """Tracking: state estimates scored against the truth (RMSE, divergence, NEES)."""

    name = TRACKING
    scene_type = TrackingScene
    noun = short_noun = "trackers"
    recording_text = ("per tracker the estimated trajectory and its error per state component, with "
                      "glint-corrupted measurements marked")
    summary_columns = ("n_trials", "rmse_mean", "rmse_low", "rmse_high", "realised_snr_db", "divergence_rate",
                       "divergence_low", "divergence_high", "nees_mean",
                       # scenes with a maneuver mask (empty otherwise): the quiet / maneuvering split and,
                       # for trackers with a ``switch`` trace, the switches against the true onsets
                       "rmse_quiet", "rmse_quiet_low", "rmse_quiet_high", "rmse_maneuver", "rmse_maneuver_low",
                       "rmse_maneuver_high", "rmse_onset", "rmse_onset_low", "rmse_onset_high", "switch_pd",
                       "switch_pd_low", "switch_pd_high", "switch_delay_mean",
                       "switch_delay_low", "switch_delay_high", "false_switch_rate", "false_switch_low",
                       "false_switch_high", "q_quiet_mean", "q_maneuver_mean", "q_maneuver_low",
                       "q_maneuver_high",
                       # scenes with a position bound (empty otherwise): the posterior Cramér-Rao
                       # bound, time-averaged like the RMSE, and the tracker's efficiency bound / RMSE
                       "pcrb_rmse", "efficiency")
    headline_columns = ("rmse_mean", "rmse_low", "rmse_high", "divergence_rate", "nees_mean")
    ranking_metric = "rmse"
    ranking_higher_is_better = False
    ranking_label = "mean per-trial position RMSE (m)"
    ranking_column = "rmse_mean"
    curves = (("rmse_mean", "mean per-trial position RMSE (m)"),)
    recording_charts = (("rmse_mean", "RMSE (m)"), ("divergence_rate", "divergence rate"))
    method_entities = ("estimate",)

    # -------------------------------------------------------------- worker side

    def check_output(self, out, batch: Batch) -> TrackingOutput:
        if not isinstance(out, TrackingOutput):
            raise OutputError(f"expected a TrackingOutput, got {type(out).__name__}")
        check_finite("estimate", np.asarray(out.estimate, float), batch.truth.shape)
        check_estimate("estimate", out.estimate)
        if out.covariance is not None:
            d = batch.truth.shape[-1]
            check_finite("covariance", np.asarray(out.covariance, float), (*batch.truth.shape[:2], d, d))
            check_covariance("covariance", out.covariance, where="(trial, step) pairs")
        check_traces(out.traces, batch.truth.shape[:2], RECORDED_PREFIXES)
        for name, (low, high, what) in SCORED_TRACES.items():
            if name in out.traces:
                check_finite(f"traces[{name!r}]", np.asarray(out.traces[name], float), batch.truth.shape[:2])
                check_range(f"traces[{name!r}]", out.traces[name], low, high, what)
        return out

    def labels(self, batch: Batch) -> list[str]:
        """Names of the state components (``scene.state_labels``, else x0, x1, ...)."""
        labels = batch.scene.state_labels
        return list(labels) if labels is not None else [f"x{j}" for j in range(batch.truth.shape[-1])]

    def trial_metrics(self, batch: Batch, out: TrackingOutput, threshold: float) -> dict[str, np.ndarray]:
        sc = batch.scene
        metrics = tracking_trial_metrics(out.estimate, batch.truth, position_index=sc.position_index,
                                      labels=self.labels(batch), covariance=out.covariance,
                                      divergence_bound_m=float(sc.divergence_bound_m),
                                      derived=sc.derived_components, valid=sc.valid_steps)
        mask = sc.maneuver_mask
        if mask is not None:
            pos_sq = metrics["sq_err_position"]
            metrics |= maneuver_trial_metrics(pos_sq, mask, sc.maneuver_onset_steps, out.traces, sc.valid_steps)
        if sc.position_bound is not None:
            metrics["pcrb_position"] = bound_series(sc.position_bound, sc.valid_steps)
        return metrics | time_series(batch)

    def recorded_scene(self, batch: Batch, i: int) -> RecordedScene:
        flags = batch.scene.outlier_flags
        rec = scene(None if flags is None else np.asarray(flags[i]).reshape(batch.steps, -1).any(axis=1))
        mask = batch.scene.maneuver_mask
        if mask is not None:            # a maneuvering scene: the truth over time and its maneuver
            rec.arrays["maneuvering"] = np.asarray(mask[i], dtype=bool)
            rec.arrays |= {f"truth_{label}": np.asarray(batch.truth[i, :, j], float)
                           for j, label in enumerate(self.labels(batch))}
        return rec

    def trace_unit(self, name: str) -> str:
        """Errors and estimates of a state component: metres for a position (``x``), m/s
        for a velocity (``vx``), m/s² for an acceleration (``ax``), the state labels of
        the scenes (``Scene.state_labels``)."""
        for prefix in RECORDED_PREFIXES:
            if name.startswith(prefix):
                return {"": "m", "v": "m/s", "a": "m/s²"}.get(name[len(prefix):-1], "")
        return ""

    def recorded_method(self, batch: Batch, out: TrackingOutput, i: int, threshold: float) -> MethodTrace:
        err = out.estimate[i] - batch.truth[i]
        labels = self.labels(batch)
        traces = {f"error_{label}": err[:, j] for j, label in enumerate(labels)}
        if batch.scene.maneuver_mask is not None:
            traces |= {f"estimate_{label}": out.estimate[i, :, j] for j, label in enumerate(labels)}
        traces |= {name: np.asarray(values[i], float) for name, values in out.traces.items()}
        return method_trace(batch.scene.drawn_xy(out.estimate[i], batch.t), traces)

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
                log_static_points(stream, layout.path("measurements/glint"), pos[glint], _GLINT_COLOR, 4.5, label="glint")
        for m in layout.methods_of(self):
            estimate = rec.methods[m.label].arrays.get("estimate_xy")
            if estimate is not None:
                log_track(stream, m.path("estimate"), t, north_up(estimate), m.color, label=m.label,
                          label_at=layout.label_at(m))
        _log_maneuver(stream, layout, t, rec)

    def views(self, layout: TrialLayout, rec: TrialRecord) -> Views:
        estimates = [rec.methods[m.label].arrays.get("estimate_xy") for m in layout.methods_of(self)]
        return Views(has_xy=any(e is not None for e in estimates), xy=tuple(e for e in estimates if e is not None))

    def report_sections(self, ctx: ReportContext) -> list[str]:
        from radarbench.bench.tasks.tracking import report
        return report.sections(ctx)

