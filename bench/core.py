"""The interfaces every scenario and method implements (the plugin protocol).

Everything is batched over Monte Carlo trials: arrays carry a leading trial
axis ``n``.

* A :class:`Scenario` generates a :class:`Batch` of ``n`` trials at one SNR
  (or under the null hypothesis, ``snr_db=None``). What the scenario tells the
  methods and the harness beyond times, truth and measurements rides on the
  batch as a :class:`Scene`: a frozen, validated object of the type its task
  defines (:class:`bench.tasks.detection.DetectionScene`,
  :class:`bench.tasks.tracking.TrackingScene`, :class:`bench.tasks.tbd.TBDScene`;
  docs/architecture.md, 'Scenes'), so a misspelt or misshapen field fails in
  :meth:`Scenario.generate`, not deep inside a worker.
* A :class:`Method` turns a Batch into an output for its task:
  :class:`DetectionOutput` for ``maneuver-detection``, :class:`TrackingOutput`
  for ``tracking``, :class:`TBDOutput` for ``tbd``.

Methods are pure: the same batch and params give the same output. They never
decide alarms; the harness applies a threshold (nominal or calibrated) so every
detector is compared at the same false-alarm rate.
"""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from radarbench.bench.params import PATH

MANEUVER_DETECTION = "maneuver-detection"
TRACKING = "tracking"
TBD = "tbd"
TASKS = (MANEUVER_DETECTION, TRACKING, TBD)


class SceneError(ValueError):
    """A scene (or a value inside one) has a field of the wrong type, shape or
    value. The message names the field, e.g. ``DetectionScene.onset_step:
    expected ...``; :attr:`field` is its name."""

    def __init__(self, owner: str, field: str, problem: str):
        self.owner, self.field, self.problem = owner, field, problem
        super().__init__(f"{owner}.{field}: {problem}")


def has_shape(value, shape: tuple, kinds: str | None = None) -> bool:
    """Whether ``value`` is an array of ``shape`` (None: any length) whose
    dtype kind is one of ``kinds`` (e.g. ``"iu"``; None: any)."""
    if not isinstance(value, np.ndarray):
        return False
    return (value.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, value.shape))
            and (kinds is None or value.dtype.kind in kinds))


def _describe(value) -> str:
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} ({value.dtype})"
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 60 else text[:57] + '...'}"


def require(owner, field: str, ok: bool, expected: str) -> None:
    """SceneError naming ``Owner.field`` unless ``ok``: the field of ``owner``
    (a scene, or a value of one) holds something other than ``expected``."""
    if not ok:
        raise SceneError(type(owner).__name__, field,
                         f"expected {expected}, got {_describe(getattr(owner, field))}")


def require_arrays(owner, shapes: dict[str, tuple]) -> None:
    """:func:`require` that each named field of ``owner`` is a real-valued array of
    its shape (None: any length)."""
    for field, shape in shapes.items():
        require(owner, field, has_shape(getattr(owner, field), shape, "fiu"),
                "an array of shape (" + ", ".join("?" if s is None else str(s) for s in shape)
                + (",)" if len(shape) == 1 else ")"))


def _is_index(x) -> bool:
    return isinstance(x, (int, np.integer)) and not isinstance(x, bool) and x >= 0


@dataclass(frozen=True, kw_only=True, eq=False)
class Scene:
    """What a scenario tells the methods and the harness about a batch, beyond
    its times, truth and measurements (docs/architecture.md, 'Scenes').

    Each task defines its own scene type, derived from this one
    (``Task.scene_type``), with typed, documented fields; a scenario builds the
    scene of its task in :meth:`Scenario.generate`. Scenes are frozen (fields
    cannot be rebound) and validated twice: on their own when built
    (:meth:`__post_init__`: types, shapes, ranges) and against the batch they
    ride on (:meth:`check`, called by :class:`Batch`). A misspelt or missing
    field is a TypeError of the constructor; a bad value a :class:`SceneError`
    naming the field. Fields here are the ones the harness reads for every task.
    """

    #: how the scenario defines SNR, in one sentence (quoted by the report); "": not given
    snr_definition: str = ""
    #: (n,) SNR each trial realised (dB; NaN where undefined, e.g. under the null); None: not measured
    realised_snr_db: np.ndarray | None = None
    #: indices of the position components of the state; the first two are drawn in the plane
    #: (a single one, a range, is drawn against time)
    position_index: tuple[int, ...] = (0, 1)
    #: (n, K, 2) measurements in the plane (m), for recordings; None: the first two components of ``z``
    measurements_xy: np.ndarray | None = None
    #: (n, K) bool: the steps each trial has. Padding after a shorter trial and gaps in a
    #: recorded track are False: their measurements are NaN and every tracker, metric and
    #: recording skips them (docs/architecture.md, 'Ragged batches'). None: every step of
    #: every trial.
    valid_steps: np.ndarray | None = None

    def __post_init__(self) -> None:
        require(self, "valid_steps", self.valid_steps is None
                or (isinstance(self.valid_steps, np.ndarray) and self.valid_steps.ndim == 2
                    and self.valid_steps.dtype == bool), "None or an (n, K) bool array")
        require(self, "snr_definition", isinstance(self.snr_definition, str), "a str")
        require(self, "realised_snr_db", self.realised_snr_db is None
                or has_shape(self.realised_snr_db, (None,), "fiu"), "None or an (n,) float array")
        require(self, "position_index", isinstance(self.position_index, tuple) and len(self.position_index) >= 1
                and all(_is_index(j) for j in self.position_index), "a tuple of at least one state index >= 0")
        require(self, "measurements_xy", self.measurements_xy is None
                or has_shape(self.measurements_xy, (None, None, 2), "fiu"), "None or an (n, K, 2) float array")

    def drawn_xy(self, states: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(K, 2) what recordings draw in the plane of one trial's states (K, d): the
        first two position components, or with a single one (a range) the time (s)
        against it."""
        pos = list(self.position_index)
        if len(pos) >= 2:
            return states[:, pos[:2]]
        return np.stack([np.asarray(t, float), states[:, pos[0]]], axis=-1)

    def check(self, batch: Batch) -> None:
        """SceneError unless the scene fits ``batch`` (its trials, steps and
        state size). Subclasses extend it, calling ``super().check(batch)``."""
        n, K, d = batch.n, batch.steps, batch.truth.shape[-1]
        require(self, "realised_snr_db", self.realised_snr_db is None or self.realised_snr_db.shape == (n,),
                f"({n},) values, one per trial")
        require(self, "position_index", max(self.position_index) < d, f"indices < {d}, the state size")
        require(self, "measurements_xy", self.measurements_xy is None
                or self.measurements_xy.shape == (n, K, 2), f"shape ({n}, {K}, 2)")
        require(self, "valid_steps", self.valid_steps is None or self.valid_steps.shape == (n, K),
                f"shape ({n}, {K})")


@dataclass
class Batch:
    """``n`` Monte Carlo trials of one scenario config at one SNR.

    Attributes
    ----------
    t : (K,) float
        Time of each step, seconds.
    truth : (n, K, d) float
        True state per trial and step.
    z : (n, K, m) float
        Point measurements (or ``(n, K, H, W)`` frames for TBD scenes).
    scene : Scene
        Everything else the methods and the harness need, as the scene type of
        the scenario's task (:class:`Scene`); checked against the batch here.
    trials : (n,) int
        Global index of each trial within its SNR level (for seeds and CSV).
    """

    t: np.ndarray
    truth: np.ndarray
    z: np.ndarray
    scene: Scene
    trials: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.scene, Scene):
            raise TypeError(f"Batch.scene: expected a bench.core.Scene (the scene type of the scenario's "
                            f"task), got {type(self.scene).__name__}")
        self.scene.check(self)

    @property
    def n(self) -> int:
        return int(self.truth.shape[0])

    @property
    def steps(self) -> int:
        return int(self.t.shape[0])


@dataclass(frozen=True)
class Timeline:
    """The steps of a scenario config's scenes, from its params (:meth:`Scenario.timeline`).

    steps : int — K, the steps of a scene.
    onset_step : int or None — the earliest step a maneuver starts in any trial
        (None: the scenes have none).
    warmup_steps : int — steps before it that are never counted as false alarms.
    """

    steps: int
    onset_step: int | None
    warmup_steps: int = 0


@dataclass
class DetectionOutput:
    """Output of a maneuver detector.

    statistic : (n, K) float — the test statistic per trial and step; an
        alarm is ``statistic >= threshold``.
    valid_from : int — first step at which the statistic is fully formed
        (e.g. a sliding window is full; :meth:`Method.valid_from` declares it).
        Steps before it are never counted as false alarms or detections, nor used
        for calibration.
    traces : dict of (n, K) arrays — extra per-step series worth seeing in a
        recording (e.g. the whitened innovation).
    """

    statistic: np.ndarray
    valid_from: int = 0
    traces: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class TrackingOutput:
    """Output of a tracker.

    estimate : (n, K, d) float — the state estimate per trial and step, in the
        state space of ``batch.truth`` (same components, same order).
    covariance : (n, K, d, d) float or None — the tracker's own error
        covariance, when it has one (used for NEES).
    traces : dict of (n, K) arrays — extra per-step series, every one kept in a
        recorded trial (named neither ``error_*`` nor ``estimate_*``: the task's own);
        ``mode``, ``switch`` and ``q_k`` are also scored (docs/architecture.md, 'Metrics').
    """

    estimate: np.ndarray
    covariance: np.ndarray | None = None
    traces: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class TBDOutput:
    """Output of a track-before-detect method.

    score : (n,) float — the scene statistic (e.g. the largest merit at the
        last frame); the harness thresholds it at a scene-level Pfa.
    track : (n, K, 2) int — the backtracked cell per frame, ``(row, col)``
        of the batch's grid (row ↔ y, col ↔ x; see ``scene.grid``).
    value : (n, H, W) float32 or None — the merit (value) map at the last
        frame, for recordings.
    """

    score: np.ndarray
    track: np.ndarray
    value: np.ndarray | None = None


def _summary(cls: type) -> str:
    doc = inspect.getdoc(cls) or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


class Component:
    """Shared by scenarios and methods: a registry name, a params dataclass."""

    name: ClassVar[str] = ""
    Params: ClassVar[type]

    @classmethod
    def summary(cls) -> str:
        """One line, from the first line of the class docstring."""
        return _summary(cls)

    @classmethod
    def default_params(cls):
        return cls.Params()

    def data_files(self, params) -> list[Path]:
        """The data files a config with ``params`` reads: their content is part of the
        config's identity, so editing one re-runs the results that read it
        (:mod:`bench.run.identity`). The default: the values of the parameters declared
        ``param(..., kind="path")`` (a sweep resolves them from its own folder), "" left
        out. Override it when the files follow from the parameters otherwise."""
        return [Path(getattr(params, f.name)) for f in dataclasses.fields(params)
                if f.metadata.get("kind") == PATH and getattr(params, f.name)]

    def identity_modules(self, params) -> tuple[str, ...]:
        """Modules beyond its own whose code computes a config with ``params`` (their code is
        part of the config's identity, :mod:`bench.run.identity`): a plugin that runs other
        registered plugins named by its parameters names their modules, which it reaches
        through the registry and no import statement. The default: none."""
        return ()


class Scenario(Component):
    """Supplies batches of trials. Subclasses implement :meth:`generate`.

    Besides ``name`` and ``Params`` a scenario may override the class
    attributes below; the harness and the tests read them directly, so every
    one has a working default.
    """

    #: tasks whose methods can run on this scenario
    tasks: ClassVar[tuple[str, ...]] = ()
    #: the parameters that key the random streams whatever their value; any other keys them
    #: only when set away from its default, so a parameter added at its default changes no
    #: number. A scenario lists here the parameters its streams were first keyed by; None:
    #: every parameter only when set (docs/architecture.md, 'Random streams')
    stream_params: ClassVar[tuple[str, ...] | None] = None
    #: parameters of a small instance (conformance tests, quick looks); empty: the defaults
    small_params: ClassVar[dict[str, Any]] = {}
    #: ``bench perf`` sizes: size name -> (scenario params, trials)
    perf_sizes: ClassVar[dict[str, tuple[dict[str, Any], int]]] = {"default": ({}, 100)}
    #: SNR (dB) at which ``bench perf`` generates its batches
    perf_snr_db: ClassVar[float] = 10.0
    #: ``bench perf`` goals for :meth:`generate` alone: size -> {"seconds_per_trial": goal}
    perf_targets: ClassVar[dict] = {}
    #: the capabilities its scenes provide beyond its tasks' scene types (names of
    #: :data:`bench.sweep.capabilities.CAPABILITIES`); the methods that need them run on it
    provides: ClassVar[frozenset[str]] = frozenset()

    def generate(self, params, snr_db: float | None, n: int, rng) -> Batch:
        """``n`` trials at ``snr_db`` (``None``: the null hypothesis).

        ``rng`` is a :class:`bench.sweep.rng.TrialRNG`: one independent stream per
        trial, so a trial's draws do not depend on how trials are chunked. The
        batch's scene is of the scene type of every task in :attr:`tasks`
        (``Task.scene_type``).
        """
        raise NotImplementedError

    def fetch_data(self, source: Path | None = None) -> str | None:
        """Download the public data the scenario's configs read by default into the user's
        data folder (``bench data fetch``; ``source``: a file already downloaded, for a
        machine offline), checked before it is kept; one line saying what it fetched, or
        None when the scenario reads nothing it could fetch (the default)."""
        return None

    def perf_data(self, size: str, folder: Path) -> dict[str, Any]:
        """Params added to ``bench perf`` size ``size`` (:attr:`perf_sizes`) when it reads a
        data file: the file written into ``folder`` (a temporary folder of the measuring
        process), so the size is timed on data the scenario makes itself, not on a user's
        file or an optional extra's. The default: none."""
        return {}

    def requires(self, params) -> frozenset[str]:
        """The capabilities a method must handle (``Method.handles``) to run on a config
        with ``params``: ``valid-step-masks`` when its trials may differ in length or have
        gaps (:attr:`Scene.valid_steps`); decided from the params alone, at no cost. The
        default: none (every trial has every step)."""
        return frozenset()

    def check_snr(self, params, snr_db: float) -> str | None:
        """Why this config cannot be generated at ``snr_db`` (one phrase), or None
        (the default): checked for every SNR level of a sweep before anything runs."""
        return None

    def unit_memory_bytes(self, params, n: int) -> int | None:
        """Bytes a batch of ``n`` trials of ``params`` takes (its arrays and the
        scratch :meth:`generate` needs), estimated from the array sizes before
        anything is generated; the sweep refuses a unit above its
        ``max_unit_memory_gb``. None (the default): not estimated."""
        return None

    def timeline(self, params) -> Timeline | None:
        """The steps of the scenes a config with ``params`` generates, known from the
        params alone (:class:`Timeline`: their number, the earliest maneuver onset, the
        warm-up), read at plan time by its tasks (the detection task refuses a detector
        whose statistic is formed only at or after the onset). None (the default): not
        declared, nothing is checked against it."""
        return None

    def check_config(self, params) -> None:
        """The checks of a config that cost work in proportion to its size (e.g. whether
        its targets fit on its map): raise ``ConfigError`` naming the field. Run once
        per scenario config after the memory check (:meth:`unit_memory_bytes`), so they
        only ever run on a config whose units fit; ``Params.validate`` keeps to checks
        that cost nothing. The default: none."""


class Method(Component):
    """A detector, tracker or TBD algorithm. Subclasses implement :meth:`run`.

    The other members are optional; their defaults mean "not provided" and
    ``bench perf`` checks for exactly those values:

    * a *reference implementation* (:meth:`reference_run`, declared by setting
      :attr:`reference_name`): the best plain code of the same algorithm, which the
      method is timed against;
    * :meth:`work`: the work a batch is, in the method's own unit (trials by
      default; cells of a map, DP state transitions), for ``<unit>_per_second``;
    * :attr:`perf_targets`: goals the performance report checks;
    * :meth:`least_cost`: what a run must at least move and compute, for its
      fraction of the machine's limits.
    """

    #: the task this method performs (one of :data:`TASKS`)
    task: ClassVar[str] = ""
    #: the capabilities it reads from a scene beyond its task's scene type (names of
    #: :data:`bench.sweep.capabilities.CAPABILITIES`, e.g. a kinematic model): it runs on the
    #: scenarios that provide them all; empty: every scenario of its task
    needs: ClassVar[frozenset[str]] = frozenset()
    #: the capabilities a scenario config may require that it handles (e.g. ragged batches,
    #: ``valid-step-masks``); empty: none, so it never runs on a config that requires one
    handles: ClassVar[frozenset[str]] = frozenset()
    #: ``bench perf``: what :meth:`reference_run` is (one phrase); None: no reference implementation
    reference_name: ClassVar[str | None] = None
    #: ``bench perf``: trials the (slow) reference runs on, at most the method's; None: as many
    reference_trials: ClassVar[int | None] = None
    #: ``bench perf``: parts of :meth:`reference_run` also timed apart, name -> what the part is
    #: (one phrase; e.g. a peer's track initiator, for a row of its filter and association alone);
    #: :meth:`reference_run` then leaves the CPU seconds it spent in each in
    #: :attr:`reference_part_seconds`, and the report adds a row for the reference less each part
    reference_parts: ClassVar[dict[str, str]] = {}
    #: CPU seconds of each of :attr:`reference_parts` in the last :meth:`reference_run`
    reference_part_seconds: dict[str, float] | None = None
    #: ``bench perf``: size name (or ``"*"`` for every size) -> {measure: goal}, measures
    #: ``speedup`` (at least), ``<unit>_per_second`` of a :meth:`work` unit (at least),
    #: ``seconds_per_trial`` (at most)
    perf_targets: ClassVar[dict[str, dict[str, float]]] = {}

    def run(self, batch: Batch, params) -> Any:
        """The task's output (:class:`DetectionOutput`, :class:`TrackingOutput`
        or :class:`TBDOutput`) for every trial of ``batch``."""
        raise NotImplementedError

    def nominal_threshold(self, params, pfa: float, batch: Batch) -> float:
        """The method's own analytic threshold for the false-alarm rate ``pfa`` of its
        task (per step for detectors, per scene for TBD, per cell for CFAR).

        The contract (checked by ``tests/test_conformance.py``): optional. A method that
        has an analytic threshold overrides this and returns a finite number; one
        calibrated empirically (on null trials: ``empirical``, ``gumbel``, ``pot``) does not
        override it, and this default returns NaN, which means "none" everywhere (the
        report leaves the nominal columns empty). A sweep asking for ``nominal``
        calibration of a method that does not override it is refused at validation
        (:meth:`has_nominal_threshold`); an override may still return NaN for a config
        that has none, whose calibration then fails (and its evaluation units with it)."""
        return float("nan")

    @classmethod
    def has_nominal_threshold(cls) -> bool:
        """Whether the method declares an analytic threshold (overrides :meth:`nominal_threshold`)."""
        return cls.nominal_threshold is not Method.nominal_threshold

    def reference_run(self, batch: Batch, params) -> Any:
        """The same output as :meth:`run` by the best plain implementation of the same
        algorithm a competent user would write (vectorised NumPy/SciPy, or the library
        users pick for it): ``bench perf`` times it on its whole batch and one trial per
        call and keeps the faster (docs/architecture.md, 'Performance'). Called only
        when :attr:`reference_name` is set."""
        raise NotImplementedError

    def work(self, batch: Batch, params) -> tuple[str, float]:
        """(unit, count): the work :meth:`run` does on ``batch``, counted in the
        method's own unit (a plural noun: "cells", "transitions"), which ``bench
        perf`` divides by the time to report ``<unit>_per_second``. The default:
        ("trials", the batch's trials)."""
        return "trials", float(batch.n)

    def least_cost(self, batch: Batch, params, output) -> dict[str, float] | str | None:
        """What :meth:`run` must at least do on ``batch`` whatever its implementation, given
        ``output`` (what it returned there, so what it must write): ``{"bytes": n}`` (bytes
        read and written at least once), ``{"float32_operations": n}`` or
        ``"float64_operations"`` (the adds and maxima its algorithm cannot avoid), or
        several; ``bench perf`` shows the time these take at the machine's measured limits
        over the time measured (:mod:`bench.run.limits`). A string: why no honest model exists
        (one phrase). None (the default): no model declared."""
        return None

    def check_scenario(self, params, scenario_params) -> str | None:
        """Why this config cannot run on a scenario config with ``scenario_params``
        (the scenario's resolved Params), in one phrase (e.g. "window = 64 is longer
        than the scenario's 50 steps"); None (the default): it can. Checked for every
        (method config, scenario config) pair of a sweep after grid expansion,
        before anything runs, so a constraint that would fail every unit is refused
        up front. Read the scenario's parameters by name (``getattr`` with a
        default): a method does not import scenarios."""
        return None

    def valid_from(self, params, steps: int) -> int:
        """The first step at which this config's per-step statistic is formed in a scene
        of ``steps`` steps (a sliding window full): the ``valid_from`` of the
        :class:`DetectionOutput` it returns, declared here so the harness reads it at plan
        time against a scenario's :meth:`Scenario.timeline`. The default: 0, from the
        first step."""
        return 0

    def unit_memory_bytes(self, params, scenario_params, n: int) -> int | None:
        """Working memory (bytes) of :meth:`run` on ``n`` trials of a scenario
        config with ``scenario_params``, beyond the batch itself (added to
        :meth:`Scenario.unit_memory_bytes` for the sweep's memory check).
        None (the default): not estimated."""
        return None

