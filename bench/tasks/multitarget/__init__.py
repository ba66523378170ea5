"""Multi-target tracking: plots of several targets in clutter, tracks scored
against the truths with GOSPA and track-level metrics; no threshold.

A multi-target tracker returns a :class:`MultiTargetOutput`: per scan, a set of
track slots with a state, an identity and a status (tentative, confirmed,
terminated). Only confirmed tracks are scored (:mod:`bench.tasks.multitarget.metrics`:
GOSPA with its localisation / missed / false decomposition, OSPA, initiation
delay, false tracks, breaks, identity switches, purity; docs/architecture.md,
'Tasks'), as the HFSWR tracking chapter ("目标检测与跟踪方法, 海洋遥感技术应用")
describes the tracker the task was built for: M/N initiation, JPDA-UKF
maintenance, termination.

The batch of a multi-target scenario::

    z      (n, K, P, 3)  plots of each scan [range m, azimuth rad, radial velocity m/s],
                         NaN-padded to P = the most plots of any scan in the batch
    truth  (n, K, T, 4)  [x, vx, y, vy] of target T at scan k, NaN while it is absent

and a :class:`MultiTargetScene` with the plot counts and origins, the sensor,
the noise, the clutter density, Pd and the targets' speed bounds and process
noise (docs/architecture.md, 'Scenes').
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import pandas as pd

from radarbench.bench.core import Batch, Scene, has_shape, require, require_arrays
from radarbench.bench.recording.blueprint import Views
from radarbench.bench.recording.layout import TrialLayout
from radarbench.bench.recording.record import MethodTrace, TrialRecord
from radarbench.bench.tasks.base import (OutputError, RecordedScene, ReportContext, Task, check_covariance, check_estimate,
                              time_series)
from radarbench.bench.tasks.multitarget.metrics import (MEANS, SCENE_COLUMNS, multitarget_steps, multitarget_trial_metrics,
                                             summarise_multitarget)

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

__all__ = ["MULTI_TARGET", "STATUS", "MultiTargetOutput", "MultiTargetScene", "MultiTargetTask"]

MULTI_TARGET = "multi-target"
#: ``MultiTargetOutput.status`` codes
STATUS = {"empty": 0, "tentative": 1, "confirmed": 2, "terminated": 3}
#: ``MultiTargetScene.plot_origin`` codes below the target indices
CLUTTER, PADDING = -1, -2


def _number(x) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool) and math.isfinite(x)


@dataclass(frozen=True, kw_only=True, eq=False)
class MultiTargetScene(Scene):
    """What a multi-target scenario tells the trackers and the harness
    (docs/architecture.md, 'Scenes'), besides :class:`~bench.core.Scene`'s
    fields (``position_index`` = (0, 2): x and y of [x, vx, y, vy])."""

    #: (n, K) int: plots in each scan (the first ``n_plots[i, k]`` rows of ``z[i, k]``)
    n_plots: np.ndarray
    #: (n, K, P) int: where each plot came from: target index >= 0, -1 clutter, -2 padding
    plot_origin: np.ndarray
    #: seconds between scans
    scan_period_s: float
    #: (2,) sensor position (m, east and north)
    sensor_xy: np.ndarray
    #: (3,) measurement noise stds (sigma_r m, sigma_az rad, sigma_vr m/s), independent
    measurement_std: np.ndarray
    #: expected clutter plots per unit volume of the (range m, azimuth rad, radial velocity m/s)
    #: region, uniform over ``surveillance_region`` (Poisson count per scan)
    clutter_density: float
    #: (3, 2) min / max of range (m), azimuth (rad), radial velocity (m/s): where plots can fall
    surveillance_region: np.ndarray
    #: probability that a present target gives a plot in a scan
    pd: float
    #: (min, max) target speed (m/s)
    speed_bounds_m_s: tuple[float, float]
    #: the targets' process noise: std of the white acceleration held over a scan (m/s^2, per axis)
    accel_std_m_s2: float
    #: GOSPA / OSPA cut-off c (m) and order p
    gospa_cutoff_m: float = 5000.0
    gospa_order: float = 2.0
    position_index: tuple[int, ...] = (0, 2)

    @property
    def clutter_per_scan(self) -> float:
        """Expected clutter plots per scan: the density times the region's volume."""
        return float(self.clutter_density * np.prod(np.diff(self.surveillance_region, axis=1)))

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self, "n_plots", has_shape(self.n_plots, (None, None), "iu"), "an (n, K) int array")
        require(self, "plot_origin", has_shape(self.plot_origin, (None, None, None), "i"), "an (n, K, P) int array")
        require_arrays(self, {"sensor_xy": (2,), "measurement_std": (3,), "surveillance_region": (3, 2)})
        require(self, "measurement_std", bool(np.all(self.measurement_std > 0)), "three stds > 0")
        require(self, "surveillance_region", bool(np.all(self.surveillance_region[:, 1] > self.surveillance_region[:, 0])),
                "max > min on every row")
        for name in ("scan_period_s", "gospa_cutoff_m", "gospa_order"):
            require(self, name, _number(getattr(self, name)) and getattr(self, name) > 0, "a number > 0")
        require(self, "clutter_density", _number(self.clutter_density) and self.clutter_density >= 0, "a number >= 0")
        require(self, "pd", _number(self.pd) and 0 <= self.pd <= 1, "a probability")
        require(self, "accel_std_m_s2", _number(self.accel_std_m_s2) and self.accel_std_m_s2 >= 0, "a number >= 0")
        b = self.speed_bounds_m_s
        require(self, "speed_bounds_m_s", isinstance(b, tuple) and len(b) == 2 and all(_number(v) for v in b)
                and 0 <= b[0] < b[1], "(min, max) speeds with 0 <= min < max (m/s)")

    def check(self, batch: Batch) -> None:
        super().check(batch)
        n, K = batch.n, batch.steps
        require(self, "n_plots", self.n_plots.shape == (n, K), f"shape ({n}, {K})")
        require(self, "plot_origin", self.plot_origin.shape == batch.z.shape[:3], f"shape {batch.z.shape[:3]} (z's)")
        require(self, "n_plots", batch.z.ndim == 4 and batch.z.shape[-1] == 3
                and bool(np.all(self.n_plots == (self.plot_origin != PADDING).sum(axis=2))),
                "the count of non-padding plots of plot_origin, with z of shape (n, K, P, 3)")
        require(self, "plot_origin", bool(np.all(self.plot_origin < batch.truth.shape[2]))
                and bool(np.all(self.plot_origin >= PADDING)), f"codes in [-2, {batch.truth.shape[2]})")


@dataclass
class MultiTargetOutput:
    """Output of a multi-target tracker (J track slots, the method's choice).

    state : (n, K, J, 4) float — [x, vx, y, vy] of the track in slot j at scan
        k; NaN where the slot is empty.
    track_id : (n, K, J) int64 — the track's identity, -1 where empty; an
        identity is never reused within a trial (a slot may hold different
        identities over time).
    status : (n, K, J) int8 — :data:`STATUS`: 0 empty, 1 tentative, 2
        confirmed, 3 terminated at this scan (kept one scan for recordings).
    position_covariance : (n, K, J, 2, 2) float or None — the (x, y) block of
        the track's covariance (gates in recordings).

    Metrics score the confirmed tracks (status 2) only.
    """

    state: np.ndarray
    track_id: np.ndarray
    status: np.ndarray
    position_covariance: np.ndarray | None = None


def check_multitarget_output(out, batch: Batch) -> MultiTargetOutput:
    """``out`` if it is a well-formed :class:`MultiTargetOutput` for ``batch``, else OutputError."""
    if not isinstance(out, MultiTargetOutput):
        raise OutputError(f"expected a MultiTargetOutput, got {type(out).__name__}")
    n, K = batch.n, batch.steps
    state, ids, status = np.asarray(out.state), np.asarray(out.track_id), np.asarray(out.status)
    if state.ndim != 4 or state.shape[:2] != (n, K) or state.shape[3] != 4:
        raise OutputError(f"state has shape {state.shape}, expected ({n}, {K}, J, 4)")
    J = state.shape[2]
    for name, a, kinds in (("track_id", ids, "iu"), ("status", status, "iu")):
        if a.shape != (n, K, J) or a.dtype.kind not in kinds:
            raise OutputError(f"{name} has shape {a.shape} ({a.dtype}), expected ({n}, {K}, {J}) int")
    if np.any((status < 0) | (status > 3)):
        raise OutputError("status has codes outside 0..3 (empty, tentative, confirmed, terminated)")
    occupied = status > 0
    if np.any(occupied != (ids >= 0)):
        raise OutputError("track_id is -1 exactly where status is 0 (empty): they disagree")
    if np.any(~np.isfinite(state[occupied])):
        raise OutputError(f"state has {int(np.count_nonzero(~np.isfinite(state[occupied])))} non-finite values "
                          "in occupied slots")
    check_estimate("state", state[occupied])
    if out.position_covariance is not None:
        cov = np.asarray(out.position_covariance)
        if cov.shape != (n, K, J, 2, 2):
            raise OutputError(f"position_covariance has shape {cov.shape}, expected ({n}, {K}, {J}, 2, 2)")
        if np.any(~np.isfinite(cov[occupied])):
            raise OutputError("position_covariance has non-finite values in occupied slots")
        check_covariance("position_covariance", cov[occupied], where="occupied slots")
    _check_unique_ids(ids)
    return out


def _check_unique_ids(ids: np.ndarray) -> None:
    """OutputError if an identity sits in two slots at one scan."""
    n, K, J = ids.shape
    if J < 2:
        return
    s = np.sort(ids, axis=2)
    if np.any((s[..., 1:] == s[..., :-1]) & (s[..., 1:] >= 0)):
        raise OutputError("track_id: an identity occupies two slots at the same scan")


def _plots_xy(z: np.ndarray, sensor_xy: np.ndarray) -> np.ndarray:
    """(..., 2) east/north of plots [range, azimuth, ...] seen from ``sensor_xy``
    (the inverse of the range and azimuth of the HFSWR measurement; the harness
    does not import models)."""
    return np.stack([sensor_xy[0] + z[..., 0] * np.sin(z[..., 1]), sensor_xy[1] + z[..., 0] * np.cos(z[..., 1])],
                    axis=-1)


class MultiTargetTask(Task):
    """Multi-target tracking: tracks in clutter scored with GOSPA, initiation delay, false tracks, identity."""

    name = MULTI_TARGET
    scene_type = MultiTargetScene
    noun = "multi-target trackers"
    short_noun = "trackers"
    recording_text = ("the true tracks, every plot (target-originated green, clutter grey) and per tracker its "
                      "tentative, confirmed and terminated tracks with their 3-sigma gates, scan by scan, "
                      "and its GOSPA per scan")
    summary_columns = ("n_trials", "realised_snr_db", *SCENE_COLUMNS,
                       *(f"{m}_{s}" for m in MEANS for s in ("mean", "low", "high")),
                       "init_delay_mean", "init_delay_low", "init_delay_high", "initiated_fraction")
    headline_columns = ("gospa_mean", "gospa_low", "gospa_high", "init_delay_mean", "false_track_rate_mean")
    ranking_metric = "gospa_m"
    ranking_higher_is_better = False
    ranking_label = "time-averaged GOSPA (m)"
    ranking_column = "gospa_mean"
    curves = (("gospa_mean", "time-averaged GOSPA (m)"),)
    recording_charts = (("gospa_mean", "GOSPA (m)"), ("false_track_rate_mean", "false tracks per hour"))
    scene_entities = ("truths", "plots")                 # bench/tasks/multitarget/draw.py draws them
    method_entities = ("tracks", "gates", "track_lines")

    # -------------------------------------------------------------- worker side

    def check_output(self, out, batch: Batch) -> MultiTargetOutput:
        return check_multitarget_output(out, batch)

    def trial_metrics(self, batch: Batch, out: MultiTargetOutput, threshold: float) -> dict[str, np.ndarray]:
        sc = batch.scene
        return multitarget_trial_metrics(batch.truth, np.asarray(out.state, float), np.asarray(out.track_id),
                                         np.asarray(out.status), position_index=sc.position_index,
                                         cutoff=sc.gospa_cutoff_m, order=sc.gospa_order,
                                         scan_period_s=sc.scan_period_s) | time_series(batch) | {
            name: np.full(batch.n, float(value)) for name, value in self.scene_columns(sc).items()}

    @staticmethod
    def scene_columns(sc: MultiTargetScene) -> dict[str, float]:
        """What trials.csv and summary.csv repeat of the scene: the axes a sweep varies
        (Pd, clutter) and the GOSPA settings."""
        return {"scene_pd": sc.pd, "clutter_per_scan": sc.clutter_per_scan, "gospa_cutoff_m": sc.gospa_cutoff_m,
                "gospa_order": sc.gospa_order}

    def recorded_scene(self, batch: Batch, i: int) -> RecordedScene:
        sc = batch.scene
        pos = list(sc.position_index)[:2]
        return RecordedScene(arrays={"truths_xy": batch.truth[i][..., pos],
                                     "plots_xy": _plots_xy(batch.z[i], sc.sensor_xy),
                                     "plot_origin": sc.plot_origin[i].astype(np.int64)})

    def recorded_method(self, batch: Batch, out: MultiTargetOutput, i: int, threshold: float) -> MethodTrace:
        sc = batch.scene
        pos = list(sc.position_index)[:2]
        one = slice(i, i + 1)
        status = np.asarray(out.status)
        m = multitarget_trial_metrics(batch.truth[one], np.asarray(out.state, float)[one],
                                      np.asarray(out.track_id)[one], status[one], position_index=sc.position_index,
                                      cutoff=sc.gospa_cutoff_m, order=sc.gospa_order, scan_period_s=sc.scan_period_s)
        arrays = {"track_xy": np.asarray(out.state, float)[i][..., pos],
                  "track_id": np.asarray(out.track_id, np.int64)[i], "track_status": status[i].astype(np.int8)}
        if out.position_covariance is not None:
            arrays["track_cov"] = np.asarray(out.position_covariance, float)[i]
        return MethodTrace(threshold=None, arrays=arrays,
                           traces={"gospa_m": m["gospa"][0], "confirmed_tracks": (status[i] == 2).sum(axis=1)})

    # -------------------------------------------------------------- driver side

    def summarise(self, trials: pd.DataFrame, series: dict) -> pd.DataFrame:
        return summarise_multitarget(trials, series)

    def steps(self, trials: pd.DataFrame, series: dict[str, np.ndarray]) -> pd.DataFrame:
        return multitarget_steps(series).assign(n_trials=len(trials))

    def log_trial(self, stream, layout: TrialLayout, rec: TrialRecord) -> None:
        from radarbench.bench.tasks.multitarget import draw
        draw.log_scene(stream, layout, rec)
        t = np.asarray(rec.t, dtype=np.float64)
        for m in layout.methods_of(self):
            draw.log_method(stream, layout, m, rec.methods[m.label], t)

    def views(self, layout: TrialLayout, rec: TrialRecord) -> Views:
        xy = tuple(rec.arrays[name] for name in ("truths_xy", "plots_xy") if name in rec.arrays)
        return Views(has_xy=bool(xy), xy=xy)

    def report_sections(self, ctx: ReportContext) -> list[str]:
        from radarbench.bench.tasks.multitarget import report
        return report.sections(ctx)
