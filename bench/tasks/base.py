"""What a *task* is to the harness: everything it owns, behind one signature.

A task (maneuver detection, tracking, track-before-detect, ...) says what a
method's output must look like, what the calibration samples on null
trials, how an output becomes per-trial metrics and those become a summary
and per-step tables, what a recorded trial keeps and how it is drawn in
Rerun, and which report sections it writes (docs/architecture.md, 'Tasks').
The runner, the report, the recording and the metrics module only loop over
the tasks present; they never name one. Tasks are found by
:func:`bench.registry.tasks`: the built-ins and the entry-point group
``bench.tasks``.

A task also defines its *scene type* (:attr:`Task.scene_type`): a frozen
dataclass derived from :class:`bench.core.Scene` with typed, documented,
validated fields, everything its methods and metrics read of a batch beyond
times, truth and measurements (docs/architecture.md, 'Scenes'). The
built-ins' are :class:`~bench.tasks.detection.DetectionScene`,
:class:`~bench.tasks.tracking.TrackingScene` and
:class:`~bench.tasks.tbd.TBDScene`, defined in the task's module; the
scenarios of a task build its scene in ``generate`` (a plugin task defines
its own, next to its Task, and its scenarios import it). A scenario serving
two tasks builds a scene deriving from both types.

Worker side (must stay light: no rerun, no matplotlib at import):
:meth:`check_scene`, :meth:`check_output`, :meth:`null_values`,
:meth:`null_peaks`, :meth:`null_cells`, :meth:`trial_metrics`,
:meth:`recorded_scene`, :meth:`recorded_method`. Driver side: :meth:`summarise`,
:meth:`apply_calibration`, :meth:`calibrated_trial_columns`, :meth:`steps`, :meth:`log_trial`, :meth:`views`,
:meth:`report_sections`, :meth:`trial_sections`.

Per-trial metrics are 1-D columns (``trials.csv``) or 2-D *series* (n, K)
(per-step values: kept in the store, summarised per step, never in
``trials.csv``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd

from radarbench.bench.core import Batch, Scene
from radarbench.bench.recording.blueprint import Views
from radarbench.bench.recording.layout import TrialLayout
from radarbench.bench.recording.record import MethodTrace, TrialRecord

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

__all__ = ["COVARIANCE_TOLERANCE", "MAX_ESTIMATE", "OutputError", "RecordedScene", "ReportContext", "Task", "Views",
           "check_covariance", "check_estimate", "check_finite", "check_range", "time_series"]


class OutputError(RuntimeError):
    """A method returned something malformed; recorded as that method's failure."""


@dataclass
class RecordedScene:
    """What a task keeps of a recorded trial's scene, beyond the harness's
    truth and measurements: the record's ``arrays`` (per step), ``images``
    (quantised) and ``info`` (JSON). (Not the batch's :class:`bench.core.Scene`,
    which is what a scenario hands to the methods.)"""

    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    images: dict[str, np.ndarray] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def union(cls, scenes) -> RecordedScene:
        """The scenes of several tasks in one; ValueError when two keep the same name."""
        out = cls()
        for scene in scenes:
            for mine, theirs in ((out.arrays, scene.arrays), (out.images, scene.images), (out.info, scene.info)):
                clash = set(mine) & set(theirs)
                if clash:
                    raise ValueError(f"two tasks keep {sorted(clash)} in the same recorded trial")
                mine.update(theirs)
        return out


@dataclass(frozen=True)
class ReportContext:
    """What a task's report sections may use. ``summary``, ``trials``,
    ``steps``, ``series`` and ``calibrations`` hold the task's configs only."""

    summary: pd.DataFrame            # summary.csv rows
    trials: pd.DataFrame             # trials.csv rows
    steps: pd.DataFrame              # steps.csv rows (may be empty, without columns)
    series: dict                     # (scenario, config, snr_db) -> {name: (n, K)}
    calibrations: list               # bench.calibration.CalibrationResult
    records: list[TrialRecord]       # every recorded trial of the run (pick the task's own)
    store: Any                       # bench.results.store.Store (null values for ROC, Gumbel fits, ...)
    fig_dir: Path
    title: str                       # the sweep's name
    pfa: float                       # requested Pfa
    chance_pd: float                 # [calibration] chance_pd
    timeline_snr_db: float | None    # [record] timeline_snr_db
    configs: frozenset[str]          # the task's method config labels
    task: Any = None                 # the Task the context is for (its attributes: has_roc, ...)


def check_finite(name: str, a: np.ndarray, shape: tuple) -> None:
    """OutputError unless ``a`` has ``shape`` and only finite values."""
    if a.shape != shape:
        raise OutputError(f"{name} has shape {a.shape}, expected {shape}")
    bad = int(np.count_nonzero(~np.isfinite(a)))
    if bad:
        raise OutputError(f"{name} has {bad} non-finite values")


def check_traces(traces, shape: tuple, reserved_prefixes: tuple[str, ...] = ()) -> None:
    """OutputError unless ``traces`` maps names to real arrays of ``shape`` (n, K), none named
    like the series the task records itself (``reserved_prefixes``): each is recorded whole
    (NaN allowed, e.g. at a ragged batch's missing steps), so none may be dropped."""
    if not isinstance(traces, dict):
        raise OutputError(f"traces must be a dict of name -> {shape} arrays, got {type(traces).__name__}")
    for name, values in traces.items():
        if not isinstance(name, str) or not name:
            raise OutputError(f"traces: every name must be a non-empty str, got {name!r}")
        if name.startswith(reserved_prefixes):
            raise OutputError(f"traces[{name!r}]: names starting with {' or '.join(map(repr, reserved_prefixes))} "
                              "are the task's own recorded series; rename the trace")
        a = np.asarray(values)
        if a.dtype.kind not in "biuf" or a.shape != shape:
            raise OutputError(f"traces[{name!r}] must be a real array of shape {shape}, "
                              f"got {a.dtype} of shape {a.shape}")


#: How far a covariance may be from symmetric positive semi-definite and still be taken as
#: one, on the scale of the matrix scaled to unit variances (D^-1/2 P D^-1/2, D its
#: diagonal; entries in [-1, 1]): its largest asymmetry, and the shift t such that
#: D^-1/2 P D^-1/2 + t I must have a Cholesky factor (eigenvalues >= -t). Rounding costs
#: ~1e-15 a step; the adaptive trackers' covariances drift to ~1e-11 asymmetric; 1e-6
#: leaves that room and still refuses any covariance that could turn a NEES negative.
COVARIANCE_TOLERANCE = 1e-6


def check_covariance(name: str, cov: np.ndarray, where: str = "steps") -> None:
    """OutputError unless every matrix of the finite stack ``cov`` (..., d, d) is symmetric
    positive semi-definite within :data:`COVARIANCE_TOLERANCE` at unit variances (a zero or
    negative variance is left unscaled, so it shows as such): one batched Cholesky of
    P + t D = D^1/2 (D^-1/2 P D^-1/2 + t I) D^1/2 over the leading (trial, step, ...) axes.
    The eigenvalues are computed only to say how bad a refused stack is (``eigvalsh``
    costs ten Cholesky factorisations)."""
    cov = np.asarray(cov, float)
    if cov.size == 0:
        return
    d = cov.shape[-1]
    var = np.diagonal(cov, axis1=-2, axis2=-1)
    unit_var = np.where(var > 0, var, 1.0)
    asymmetry = (np.abs(cov - np.swapaxes(cov, -1, -2)) / np.sqrt(unit_var[..., :, None] * unit_var[..., None, :])
                 ).max(axis=(-2, -1))
    shifted = cov.reshape(*cov.shape[:-2], d * d).copy()
    shifted[..., ::d + 1] += COVARIANCE_TOLERANCE * unit_var
    try:
        np.linalg.cholesky(shifted.reshape(cov.shape))
        if asymmetry.max() <= COVARIANCE_TOLERANCE:
            return
    except np.linalg.LinAlgError:
        pass
    scale = np.sqrt(unit_var)
    unit = cov / (scale[..., :, None] * scale[..., None, :])
    smallest = np.linalg.eigvalsh(0.5 * (unit + np.swapaxes(unit, -1, -2)))[..., 0]
    count = int(np.count_nonzero((asymmetry > COVARIANCE_TOLERANCE) | (smallest < -COVARIANCE_TOLERANCE)))
    raise OutputError(f"{name} is not a covariance (symmetric positive semi-definite within "
                      f"{COVARIANCE_TOLERANCE:g} at unit variances) at {max(count, 1)} of {smallest.size} {where}: "
                      f"smallest eigenvalue {smallest.min():.3g}, largest asymmetry {asymmetry.max():.3g}")


def check_range(name: str, a: np.ndarray, low: float, high: float = np.inf, what: str = "") -> None:
    """OutputError unless every value of ``a`` lies in [low, high] (``what``: what the
    values are, e.g. "a probability"; NaN is left to :func:`check_finite`)."""
    a = np.asarray(a, float)
    out = (a < low) | (a > high)
    count = int(np.count_nonzero(out))
    if count:
        span = f"[{low:g}, {high:g}]" if np.isfinite(high) else f">= {low:g}"
        worst = a[out][np.argmax(np.abs(a[out] - np.clip(a[out], low, high)))]
        raise OutputError(f"{name} has {count} values outside {span}{' (' + what + ')' if what else ''}, "
                          f"e.g. {worst:.6g}")


#: The largest magnitude of a state estimate: the square of anything beyond overflows
#: float64, so no error, RMSE, GOSPA or NEES of it can be computed (a diverged filter).
MAX_ESTIMATE = 1e150


def check_estimate(name: str, a: np.ndarray) -> None:
    """OutputError unless every (finite) value of the state estimate ``a`` is within
    :data:`MAX_ESTIMATE` in magnitude."""
    check_range(name, a, -MAX_ESTIMATE, MAX_ESTIMATE, "beyond it a squared error overflows float64")


def time_series(batch: Batch) -> dict[str, np.ndarray]:
    """The step times as a series, so per-step tables carry time in seconds."""
    return {"t_s": np.broadcast_to(np.asarray(batch.t, float), (batch.n, batch.steps))}


class Task:
    """One task. Subclasses set ``name`` and override what applies to them."""

    #: registry name, the value of ``Method.task`` and ``Scenario.tasks``
    name: ClassVar[str] = ""
    #: the scene type its scenarios put on a batch (:class:`bench.core.Scene` or a subclass)
    scene_type: ClassVar[type[Scene]] = Scene
    #: whether a threshold is calibrated on null trials for this task
    calibrated: ClassVar[bool] = False
    #: calibration modes that apply (any mode is accepted when none applies)
    calibration_modes: ClassVar[tuple[str, ...]] = ("nominal", "empirical", "gumbel", "pot")
    #: what the requested Pfa is counted over, e.g. "per step"
    pfa_unit: ClassVar[str] = ""
    #: whether the requested Pfa is per cell of a value map: calibration then reads the null
    #: cells' order statistics (``null_cells``), not the pooled ``null_values``
    pfa_per_cell: ClassVar[bool] = False
    #: whether summary.csv's ``pfa`` is measured on the evaluation trials (else: on the null ones)
    evaluation_pfa: ClassVar[bool] = False
    #: its methods, in the report's prose ("detectors") and in short ("TBD")
    noun: ClassVar[str] = ""
    short_noun: ClassVar[str] = ""
    #: what one null trial contributes to the calibration, in a few words
    null_sample: ClassVar[str] = ""
    #: sentences added to the calibration section's explanation (the columns it fills)
    calibration_text: ClassVar[str] = ""
    #: paragraph after the calibration table when the task's configs were calibrated
    calibration_note: ClassVar[str] = ""
    #: what a recorded trial shows of its methods, for the report's recording paragraph
    recording_text: ClassVar[str] = ""
    #: summary.csv columns the task writes (shared ones included)
    summary_columns: ClassVar[tuple[str, ...]] = ()
    #: the few of them worth a glance (the recording's summary table)
    headline_columns: ClassVar[tuple[str, ...]] = ()
    #: the per-trial column of trials.csv that ranks the task's methods (at a glance,
    #: paired comparisons, ``bench compare``): a 0/1 indicator (a detection) or an error
    ranking_metric: ClassVar[str] = ""
    #: whether a larger ``ranking_metric`` is better (detection) or worse (an error)
    ranking_higher_is_better: ClassVar[bool] = True
    #: how the report names the mean of ``ranking_metric`` over trials, with its unit ("Pd", "RMSE (m)")
    ranking_label: ClassVar[str] = ""
    #: whether ``ranking_metric`` is a 0/1 indicator (paired comparisons add McNemar's exact test)
    ranking_binary: ClassVar[bool] = False
    #: a per-trial 0/1 column of trials.csv (filled by :meth:`calibrated_trial_columns`) at a
    #: threshold that gives every config the same chance Pd: the fair basis to rank detectors
    #: whose chance Pd differs. Where set, *Results at a glance* ranks on it (``ranking_metric``
    #: a secondary column) and the paired comparisons cover it too; "": none
    equal_chance_metric: ClassVar[str] = ""
    #: how the report names its mean ("Pd at equal chance Pd")
    equal_chance_label: ClassVar[str] = ""
    #: why no trial of a scene has ``ranking_metric`` when none has (the glance says so instead
    #: of ranking), e.g. "no targets"
    ranking_undefined: ClassVar[str] = "no trial has a value"
    #: the summary.csv column that is the mean over trials of ``ranking_metric`` (with
    #: ``_low``/``_high``), and of ``equal_chance_metric`` where set: what the glance ranks,
    #: as the figures draw it; "": none
    ranking_column: ClassVar[str] = ""
    equal_chance_column: ClassVar[str] = ""
    #: the summary.csv columns (with ``_low``/``_high``) drawn against SNR in report.html's
    #: interactive figures, each with its axis title and unit: the glance's metric first
    #: (:meth:`glance_column`; a test holds every task to it), other views after; (): none
    curves: ClassVar[tuple[tuple[str, str], ...]] = ()
    #: whether the task's report draws a ROC (Pd against per-step Pfa from the stored statistics)
    has_roc: ClassVar[bool] = False
    #: the recording's summary charts: (summary.csv column, axis title with its unit), one
    #: curve per config against SNR, per scenario config (docs/architecture.md, 'Recordings')
    recording_charts: ClassVar[tuple[tuple[str, str], ...]] = (("pd", "Pd"), ("rmse_mean", "RMSE (m)"))
    def trace_unit(self, name: str) -> str:
        """The unit of a recorded trace (a view's y axis names it), "" for none or unknown."""
        return ""

    @classmethod
    def glance_column(cls) -> str:
        """The summary column of what *Results at a glance* ranks on: the outcome at
        equal chance Pd where the task has one, else the ranking metric."""
        return cls.equal_chance_column or cls.ranking_column

    #: the summary column that finds a scenario config's most informative SNR level, the
    #: one whose value (averaged over configs) is nearest ``informative_target``: the
    #: recording's tabs open there (e.g. Pd = 0.5); "" for none (the middle level)
    informative_column: ClassVar[str] = ""
    informative_target: ClassVar[float] = 0.5
    #: children of a trial root / of a method entity the task logs (reserved names)
    scene_entities: ClassVar[tuple[str, ...]] = ()
    method_entities: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def summary(cls) -> str:
        """One line, from the first line of the class docstring."""
        doc = (cls.__doc__ or "").strip()
        return doc.splitlines()[0] if doc else ""

    # -------------------------------------------------------------- plan time

    def check_pair(self, method, method_params, scenario, scenario_params) -> str | None:
        """Why a config of ``method`` (a Method instance) cannot be scored on a scenario
        config (``scenario`` a Scenario instance), in one phrase, from what both declare
        (e.g. a statistic formed only after the scenario's onset leaves no false-alarm
        step); None (the default): it can. Checked with ``Method.check_scenario`` for every
        pair of a sweep before anything runs (:func:`bench.sweep.feasibility.check_pairs`)."""
        return None

    # -------------------------------------------------------------- worker side

    def check_scene(self, batch: Batch) -> None:
        """TypeError unless ``batch.scene`` is of this task's :attr:`scene_type`
        (a scenario listing the task in ``Scenario.tasks`` must build one)."""
        if not isinstance(batch.scene, self.scene_type):
            raise TypeError(f"task {self.name!r} needs a {self.scene_type.__name__} on the batch, "
                            f"the scenario gave a {type(batch.scene).__name__}")

    def check_output(self, out, batch: Batch):
        """``out`` if it is a well-formed output for ``batch``, else OutputError."""
        raise NotImplementedError

    def null_values(self, batch: Batch, out) -> np.ndarray:
        """The calibration sample of a null batch (calibrated tasks)."""
        raise NotImplementedError

    def null_peaks(self, batch: Batch, out) -> np.ndarray | None:
        """Per null trial, the statistic the chance detection rate is read on; None: none."""
        return None

    def null_cells(self, batch: Batch, out) -> np.ndarray | None:
        """Per null trial, order statistics of a value map for the per-cell Pfa; None: none."""
        return None

    def trial_metrics(self, batch: Batch, out, threshold: float) -> dict[str, np.ndarray]:
        """Per-trial metrics at ``threshold`` (NaN for uncalibrated tasks): (n,) columns and (n, K) series."""
        raise NotImplementedError

    def recorded_scene(self, batch: Batch, i: int) -> RecordedScene:
        """What trial ``i``'s record keeps of the scene for this task."""
        return RecordedScene()

    def recorded_method(self, batch: Batch, out, i: int, threshold: float) -> MethodTrace:
        """What trial ``i``'s record keeps of one method config's output."""
        return MethodTrace(threshold=threshold)

    # -------------------------------------------------------------- driver side

    def summarise(self, trials: pd.DataFrame, series: dict) -> pd.DataFrame:
        """One summary row per (scenario config, method config, SNR) of the task's trials."""
        raise NotImplementedError

    def apply_calibration(self, summary: pd.DataFrame, trials: pd.DataFrame, cal) -> None:
        """Fill the summary columns that come from ``cal`` (one config on one
        scenario config; its rows exist), in place."""

    def calibrated_trial_columns(self, trials: pd.DataFrame, cal) -> dict[str, pd.Series]:
        """Per-trial columns of trials.csv that need ``cal`` (e.g. :attr:`equal_chance_metric`),
        for the trials of its scenario config and method config (indexed like ``trials``)."""
        return {}

    def unranked_reason(self, trials: pd.DataFrame) -> str:
        """Why one method config, whose trials on one scenario config are ``trials``
        (trials.csv rows), must not be ranked although it has ``ranking_metric`` values
        (e.g. its Pfa is undefined, so its Pd means nothing): a phrase *Results at a
        glance* prints beside it. "" (the default): it may be ranked."""
        return ""

    def steps(self, trials: pd.DataFrame, series: dict[str, np.ndarray]) -> pd.DataFrame | None:
        """Per-step table of one (scenario, config, SNR) cell from its trials and
        series; None: the task has none."""
        return None

    def log_trial(self, stream, layout: TrialLayout, rec: TrialRecord) -> None:
        """Draw the task's part of a recorded trial: its scene and its
        methods (``layout.methods_of(self)``); traces are drawn by the harness."""

    def views(self, layout: TrialLayout, rec: TrialRecord) -> Views:
        """The task's views in the trial's tab of the default blueprint."""
        return Views()

    def report_sections(self, ctx: ReportContext) -> list[str]:
        """Markdown sections of the task's results."""
        return []

    def trial_sections(self, ctx: ReportContext) -> list[str]:
        """Markdown sections about single recorded trials, after every task's results."""
        return []
