"""Maneuver detection: a statistic per step, thresholded at a per-step Pfa.

A detector returns a :class:`~bench.core.DetectionOutput`; the harness
calibrates its threshold on the null trials' statistic after warm-up, then
scores detection, delay and false alarms around the maneuver onset
(:mod:`bench.tasks.detection.metrics`; docs/architecture.md, 'Tasks' and
'Metrics'). The chance detection rate and the equal-chance Pd follow Song,
Ji & Gao 2004 (the cumulant detector's paper) in reading Pd per window.

Its scenarios put a :class:`DetectionScene` on the batch: the onset, the
detection window, the warm-up and the reference filter the innovation
detectors run (docs/architecture.md, 'Scenes').

A recorded trial keeps, per detector, the statistic, the alarms and the
threshold in force, drawn under ``.../{method}/statistic``, ``threshold``
(Scalars at every step) and ``alarms`` (Scalars at alarm steps only, drawn
as points), with a "statistics" view on top of the trial's tab.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from radarbench.bench.core import MANEUVER_DETECTION, Batch, DetectionOutput, Scene, has_shape, require
from radarbench.bench.recording.blueprint import Views, legend_headroom, relative, trial_time_axis
from radarbench.bench.recording.draw import log_series
from radarbench.bench.recording.layout import TrialLayout
from radarbench.bench.recording.paths import rerun_path
from radarbench.bench.recording.record import MethodTrace, TrialRecord, check_shape
from radarbench.bench.tasks.base import OutputError, RecordedScene, ReportContext, Task, check_traces
from radarbench.bench.tasks.detection.metrics import detection_trial_metrics, equal_chance_pd, summarise_detection

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

__all__ = ["DetectionScene", "DetectionTask", "method_trace"]


def _is_steps(value) -> bool:
    """A step index (int >= 0) or one per trial ((n,) integers >= 0)."""
    if isinstance(value, np.ndarray):
        return has_shape(value, (None,), "iu") and bool(np.all(value >= 0))
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= 0


@dataclass(frozen=True, kw_only=True, eq=False)
class DetectionScene(Scene):
    """What a maneuver-detection scenario tells the detectors and the harness
    (docs/architecture.md, 'Scenes'), besides :class:`~bench.core.Scene`'s fields.

    Steps are indices into the batch's K steps; a step field holds one int for
    every trial or an (n,) integer array (e.g. onsets drawn per trial).
    """

    #: first step the maneuver moves, per trial; None under the null (no maneuver)
    onset_step: int | np.ndarray | None
    #: where the maneuver would start: on null trials the harness reads the chance
    #: detection rate there (Song, Ji & Gao 2004 read Pd per window); None: not measured
    null_onset_step: int | np.ndarray | None = None
    #: first step after the maneuver; None under the null or when it never ends
    offset_step: int | np.ndarray | None = None
    #: a detection counts if the first alarm at or after the onset comes within this many steps
    detect_window_steps: int
    #: steps ignored before false alarms are counted (and before calibration samples)
    warmup_steps: int = 0
    #: the reference filter the innovation detectors run: a
    #: :class:`models.kalman.LinearGaussianFilter` (F, H, Q, R and the prior x0, P0 of
    #: step 0); None: the scenario has none. Typed Any here because the harness never
    #: imports models; the methods check its type.
    reference_filter: Any = None

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("onset_step", "null_onset_step", "offset_step"):
            value = getattr(self, name)
            require(self, name, value is None or _is_steps(value), "None, a step index >= 0 or (n,) of them")
        require(self, "detect_window_steps", _is_steps(self.detect_window_steps) and self.detect_window_steps >= 1,
                "an int >= 1")
        require(self, "warmup_steps", _is_steps(self.warmup_steps), "an int >= 0")

    def check(self, batch: Batch) -> None:
        super().check(batch)
        n, K = batch.n, batch.steps
        for name in ("onset_step", "null_onset_step", "offset_step"):
            value = getattr(self, name)
            require(self, name, value is None or (np.ndim(value) == 0 or np.shape(value) == (n,))
                    and bool(np.all(np.asarray(value) <= K)), f"steps <= {K}, one or ({n},)")


def method_trace(statistic, threshold: float | None, alarms, traces: dict | None = None) -> MethodTrace:
    """What a recorded trial keeps of a detector: statistic (K,), alarms (K,) bool, threshold."""
    statistic, alarms = np.asarray(statistic), np.asarray(alarms, dtype=bool)
    check_shape(statistic, (None,), "statistic")
    check_shape(alarms, statistic.shape, "alarms")
    return MethodTrace(threshold=threshold, traces=traces or {},
                       arrays={"statistic": statistic, "alarms": alarms})


def _drawn(tr: MethodTrace) -> dict[str, bool]:
    """Which of a detector's entities are logged (and so shown in its view)."""
    stat = "statistic" in tr.arrays
    return {"statistic": stat,
            "threshold": stat and tr.threshold is not None and math.isfinite(tr.threshold),
            "alarms": stat and "alarms" in tr.arrays and bool(tr.arrays["alarms"].any())}


#: The maneuver onset marker: a mid grey, seen on the viewer's light and dark themes.
ONSET_COLOR = (150, 150, 150)


def _onset(rec: TrialRecord) -> int | None:
    """The recorded onset step, if the trial has one within its steps."""
    onset = rec.info.get("onset_step")
    return int(onset) if onset is not None and 0 <= int(onset) < len(rec.t) else None


def _value_range(tr: MethodTrace) -> tuple[float, float]:
    """The range a detector's plot shows: its statistic and its threshold."""
    values = [float(np.min(tr.arrays["statistic"])), float(np.max(tr.arrays["statistic"]))]
    if tr.threshold is not None and math.isfinite(tr.threshold):
        values.append(float(tr.threshold))
    return min(values), max(values)


class DetectionTask(Task):
    """Maneuver detection: a per-step statistic, alarms at a calibrated per-step Pfa."""

    name = MANEUVER_DETECTION
    scene_type = DetectionScene
    calibrated = True
    calibration_modes = ("nominal", "empirical")
    pfa_unit = "per step"
    evaluation_pfa = True
    noun = short_noun = "detectors"
    null_sample = "all steps after warm-up"
    calibration_text = (
        "*Pfa in evaluation* is the per-step false-alarm rate measured before the maneuver onset in the "
        "evaluation trials, averaged over SNR levels. *Chance Pd* is how often the detection rule fires "
        "on null trials (no maneuver) within the detection window: the floor Pd falls to as SNR goes "
        "down, drawn as a dotted line in the Pd figure.")
    calibration_note = (
        "Per-step Pfa intervals (here and in summary.csv) are counted over trials, the independent "
        "units: a window statistic's alarms cluster within a trial, so its interval is wider than one "
        "that treats steps as independent (ratio-estimator variance over trials, Student's quantile on "
        "the trials that alarmed). Scene Pfa (TBD) has one value per scene: Wilson's interval.")
    recording_text = "per detector the statistic, the threshold in force and the alarms"
    summary_columns = ("n_trials", "pd", "pd_low", "pd_high", "pfa", "pfa_low", "pfa_high", "delay_mean",
                       "delay_low", "delay_high", "delay_median", "rmse_mean", "threshold", "realised_snr_db",
                       "pd_step", "pd_step_low", "pd_step_high",
                       "pd_equal_chance", "pd_equal_chance_low", "pd_equal_chance_high")
    headline_columns = ("pd", "pd_low", "pd_high", "pfa", "pfa_low", "pfa_high", "delay_mean")
    ranking_metric = "detected"
    ranking_undefined = "Pd undefined: no trial has a value"
    ranking_higher_is_better = True
    ranking_label = "Pd"
    ranking_binary = True
    equal_chance_metric = "detected_equal_chance"
    equal_chance_label = "Pd at equal chance Pd"
    ranking_column, equal_chance_column = "pd", "pd_equal_chance"
    curves = (("pd_equal_chance", "Pd at equal chance Pd"), ("pd", "Pd, any alarm in the window"))
    has_roc = True
    recording_charts = (("pd_equal_chance", "Pd at equal chance Pd"), ("delay_mean", "mean delay (steps)"))
    informative_column = "pd"
    method_entities = ("statistic", "threshold", "alarms", "onset")

    # -------------------------------------------------------------- plan time

    def check_pair(self, method, method_params, scenario, scenario_params) -> str | None:
        """A detector is scored on the steps its statistic is formed (from its declared
        ``valid_from``): false alarms from there to the onset, detections from the onset.
        Refused where that leaves no step before the scenario's earliest onset (its
        declared ``timeline``): no false-alarm step, so its Pfa is undefined, and the
        statistic is not formed at the onset."""
        timeline = scenario.timeline(scenario_params)
        if timeline is None or timeline.onset_step is None:
            return None
        valid_from = int(method.valid_from(method_params, timeline.steps))
        if max(valid_from, timeline.warmup_steps) < timeline.onset_step:
            return None
        after = f"after the warm-up of {timeline.warmup_steps} steps" if timeline.warmup_steps > valid_from else \
            f"from step {valid_from} (valid_from)"
        return (f"its statistic is formed {after}, not before the maneuver onset at step "
                f"{timeline.onset_step}: no false-alarm step before the onset, so it cannot be scored")

    # -------------------------------------------------------------- worker side

    def check_output(self, out, batch: Batch) -> DetectionOutput:
        if not isinstance(out, DetectionOutput):
            raise OutputError(f"expected a DetectionOutput, got {type(out).__name__}")
        shape = (batch.n, batch.steps)
        if out.statistic.shape != shape:
            raise OutputError(f"statistic has shape {out.statistic.shape}, expected {shape}")
        bad = int(np.count_nonzero(~np.isfinite(out.statistic)))
        if bad:
            raise OutputError(f"statistic has {bad} non-finite values")
        check_traces(out.traces, shape)
        return out

    def null_start(self, batch: Batch, out: DetectionOutput) -> int:
        """First step of the null region: after warm-up and once the statistic is formed."""
        return max(int(batch.scene.warmup_steps), int(out.valid_from))

    def null_values(self, batch: Batch, out: DetectionOutput) -> np.ndarray:
        """Per-step statistic values of a null batch, after warm-up: the calibration sample."""
        return out.statistic[:, self.null_start(batch, out):].ravel()

    def null_peaks(self, batch: Batch, out: DetectionOutput) -> np.ndarray | None:
        """Per null trial, the largest statistic in the detection window placed
        where the maneuver would start: ``mean(peaks >= threshold)`` is the
        chance detection rate, the floor Pd falls to as SNR goes down."""
        onset = batch.scene.null_onset_step
        if onset is None:
            return None
        steps = np.asarray(onset)[..., None] + np.arange(int(batch.scene.detect_window_steps))
        steps = np.broadcast_to(steps, (batch.n, steps.shape[-1]))   # per-trial onsets (jitter)
        window = np.take_along_axis(out.statistic, np.minimum(steps, batch.steps - 1), axis=1)
        return np.where(steps >= int(out.valid_from), window, -np.inf).max(axis=1)   # a formed statistic only

    def trial_metrics(self, batch: Batch, out: DetectionOutput, threshold: float) -> dict[str, np.ndarray]:
        return detection_trial_metrics(out.statistic, threshold, onset=np.asarray(batch.scene.onset_step),
                                       detect_window=int(batch.scene.detect_window_steps),
                                       null_start=self.null_start(batch, out), valid_from=int(out.valid_from))

    def recorded_scene(self, batch: Batch, i: int) -> RecordedScene:
        """The trial's maneuver onset step (none under the null), marked in its plots."""
        onset = batch.scene.onset_step
        if onset is None:
            return RecordedScene()
        return RecordedScene(info={"onset_step": int(np.broadcast_to(np.asarray(onset), (batch.n,))[i])})

    def recorded_method(self, batch: Batch, out: DetectionOutput, i: int, threshold: float) -> MethodTrace:
        stat = out.statistic[i]
        alarms = (stat >= threshold) & (np.arange(stat.shape[0]) >= int(out.valid_from))
        return method_trace(stat, threshold, alarms, {k: v[i] for k, v in out.traces.items()})

    # -------------------------------------------------------------- driver side

    def summarise(self, trials: pd.DataFrame, series: dict) -> pd.DataFrame:
        return summarise_detection(trials)

    def apply_calibration(self, summary: pd.DataFrame, trials: pd.DataFrame, cal) -> None:
        """Pd of each SNR level at the calibration's window threshold (the same
        chance Pd for every detector)."""
        mine = trials[(trials.scenario == cal.scenario) & (trials.config == cal.method)]
        for snr, g in mine.groupby("snr_db"):
            rows = (summary.scenario == cal.scenario) & (summary.config == cal.method) & (summary.snr_db == snr)
            for col, value in equal_chance_pd(g["peak_statistic"], cal.equal_chance_threshold).items():
                summary.loc[rows, col] = value

    def unranked_reason(self, trials: pd.DataFrame) -> str:
        """A config with no false-alarm step before the onset in any trial has no Pfa, so
        its Pd is at no known false-alarm rate: never ranked."""
        if "null_steps" in trials and not trials["null_steps"].sum() > 0:
            return "Pfa undefined: no false-alarm step before the onset"
        return ""

    def calibrated_trial_columns(self, trials: pd.DataFrame, cal) -> dict[str, pd.Series]:
        """``detected_equal_chance``: 1 where the trial's peak statistic in the detection
        window reaches the window threshold of equal chance Pd (the per-trial outcome
        whose mean is ``pd_equal_chance``), 0 otherwise; none without that threshold."""
        if not math.isfinite(cal.equal_chance_threshold) or "peak_statistic" not in trials:
            return {}
        mine = trials[(trials.scenario == cal.scenario) & (trials.config == cal.method)]
        return {self.equal_chance_metric: (mine.peak_statistic >= cal.equal_chance_threshold).astype(float)}

    def log_trial(self, stream, layout: TrialLayout, rec: TrialRecord) -> None:
        import rerun as rr

        t = np.asarray(rec.t, dtype=np.float64)
        every = np.arange(t.shape[0])
        onset = _onset(rec)
        for m in layout.methods_of(self):
            tr = rec.methods[m.label]
            drawn = _drawn(tr)
            stat = tr.arrays.get("statistic")
            if drawn["statistic"]:
                log_series(stream, m.path("statistic"), t, every, stat,
                           rr.SeriesLines(names=m.label, colors=[m.color], widths=[1.5]))
            if drawn["threshold"]:
                # Lighter and thinner than the statistic: a reference line.
                log_series(stream, m.path("threshold"), t, every, np.full(t.shape[0], tr.threshold),
                           rr.SeriesLines(names="threshold", colors=[(*m.color, 150)], widths=[1.0]))
            if drawn["alarms"]:
                hits = np.flatnonzero(tr.arrays["alarms"])
                log_series(stream, m.path("alarms"), t, hits, stat[hits],
                           rr.SeriesPoints(names="alarms", colors=[m.color], markers=["cross"],
                                           marker_sizes=[5.0]))
            if drawn["statistic"] and onset is not None:
                # A down-pointing marker above the data at the onset step; its height also
                # makes the plot's automatic range leave room for the legend.
                log_series(stream, m.path("onset"), t, np.array([onset]),
                           np.array([legend_headroom(*_value_range(tr))]),
                           rr.SeriesPoints(names="maneuver onset", colors=[ONSET_COLOR], markers=["down"],
                                           marker_sizes=[8.0]))

    def views(self, layout: TrialLayout, rec: TrialRecord) -> Views:
        """One plot per detector (statistic, threshold, alarms, onset): statistics of
        different detectors live on different scales (a NIS in units of χ², a
        cumulant, wavelet energies), so they never share an axis. Each plot's axis
        leaves room above the data for its legend."""
        import rerun.blueprint as rrb

        origin, views = rerun_path(layout.root), []
        for m in layout.methods_of(self):
            tr = rec.methods[m.label]
            shown = [child for child, on in _drawn(tr).items() if on]
            if not shown:
                continue
            if _onset(rec) is not None:
                shown.append("onset")
            views.append(rrb.TimeSeriesView(origin=origin, name=m.label, axis_x=trial_time_axis(layout),
                                            contents=[relative(layout, m.path(c)) for c in shown],
                                            plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop, visible=True)))
        if not views:
            return Views()
        top = views[0] if len(views) == 1 else rrb.Horizontal(*views) if len(views) <= 3 else rrb.Grid(*views)
        return Views(top=[top])

    def report_sections(self, ctx: ReportContext) -> list[str]:
        from radarbench.bench.tasks.detection import report
        return report.sections(ctx)

    def trial_sections(self, ctx: ReportContext) -> list[str]:
        from radarbench.bench.tasks.detection import report
        return report.timeline(ctx)
