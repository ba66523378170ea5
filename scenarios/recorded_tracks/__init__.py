"""Scenario ``recorded-tracks``: segments of recorded trajectories (a user's CSV or
Parquet file, or the real aircraft of the ``traffic`` package's sample data) as the
truth, measured in Gaussian noise at the SNR level; tracking and maneuver detection.

The scenario is here; reading and checking the files in :mod:`.files`, the span bank it
draws segments from in :mod:`.bank`."""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pandas as pd

from radarbench.bench.batched import matvec
from radarbench.bench.sweep.capabilities import VALID_STEP_MASKS
from radarbench.bench.core import MANEUVER_DETECTION, TRACKING, Batch, Scenario, Timeline
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_scenario
from radarbench.bench.tasks.detection import DetectionScene
from radarbench.bench.tasks.tracking import TrackingScene
from radarbench.models.kalman import LinearGaussianFilter, steady_state
from radarbench.models.kinematics import KinematicModel, per_axis, position_index, state_labels
from radarbench.scenarios.cv_turn_cv import cv_model
from radarbench.scenarios.maneuvering import MIN_NOISE_M, NOISE_WHY
from radarbench.scenarios.recorded_tracks.bank import bank_of, is_ragged, maneuver_threshold, replays, source_text
from radarbench.scenarios.recorded_tracks.files import (PLANAR, PLANAR_MEAS, TIME, TRACK, check_sample_name, fetch_samples,
                                                       sample_file)


MAX_STEPS = 10_000
#: where measurements come from (RecordedTracks, 'Measurements')
MEASUREMENTS = ("synthetic", "recorded")
#: the measurement-noise std of bench perf's racetracks (write_racetracks; m)
PERF_NOISE_M = 30.0
#: real turns out of the box: VOR calibration flights (circles and racetracks)
DEFAULT_SAMPLES = ("calibration/ajaccio", "calibration/bornholm", "calibration/cardiff", "calibration/kiruna",
                   "calibration/munich", "calibration/nice", "calibration/toulouse", "calibration/vienna")
SNR_DEFINITION = (
    "snr_db is a measurement-noise level relative to the scenario's reference noise (as in maneuvering-1d): "
    "the position-measurement noise std is noise_std_m times 10^(-snr_db/20) on each axis, so 0 dB is the "
    "reference and +6 dB halves the noise; the recorded motion does not change along the axis; snr_db=None "
    "is the null: the same noise at 0 dB on segments without a maneuver."
)
REPLAY_SNR_DEFINITION = (
    "no SNR axis: the file's recorded measurements are replayed as recorded, their noise std taken as "
    "noise_std_m; snr_db is 0 by convention (the only level a sweep may give)"
)
#: what marks a maneuver (RecordedTracks, 'Maneuvers')
MANEUVER_MEASURES = ("acceleration", "turn-rate")
#: the reference filter of the innovation detectors: [x, vx, y, vy] of the [x, vx, ax, y, vy, ay] state
CV_COMPONENTS = [0, 1, 3, 4]


@dataclass(frozen=True, kw_only=True, eq=False)
class RecordedTrackScene(TrackingScene, DetectionScene):
    """A tracking scene and a detection scene at once: the trackers read the kinematic
    model, the detectors the reference filter (one batch serves both tasks)."""


@register_scenario
class RecordedTracks(Scenario):
    r"""Segments of recorded tracks (a CSV/Parquet file, or the traffic package's real aircraft) as truth; position measurements in Gaussian noise.

    **Source**: ``path``, a CSV (or Parquet, with pyarrow) of one row per recorded
    point: ``track`` (an id, read as text: ``1`` and ``01`` are two tracks; a Parquet
    column of another type is converted to text, with a note on stderr), ``time_s``
    (s, increasing within a track, rows grouped
    by track; in Parquet also a timestamp column), and either ``x_m``, ``y_m`` (planar metres) or ``latitude``,
    ``longitude`` (degrees, WGS-84) with an optional ``altitude_m`` (m above the
    ellipsoid, 0 if absent), converted to east/north metres in the tangent plane
    at each track's first point (:mod:`models.geodesy`). A relative path is read
    from the sweep file's folder; the file's content is part of the config's
    identity, so a changed file is a different sweep. Or, with ``path`` empty,
    ``traffic_samples``: names of the ADS-B trajectories the ``traffic`` package
    ships as sample data (``"calibration/ajaccio"``: VOR calibration flights in
    circles and racetracks; ``gliders/...``, ``ambulances/...``,
    ``featured/zero_gravity``), read with pandas from the installed package or from
    the wheel's samples ``bench data fetch`` keeps; the aircraft (icao24) is the track, altitude
    feet to metres, rows without a position dropped. A bad file (a missing
    column, a column name twice, an empty id, a NaN or non-numeric value, a
    coordinate outside its physical range: latitude within +-90 degrees,
    longitude within +-180 degrees, metres within +-1e8 m, a track with fewer
    than two points, time not increasing within a track, more than
    ``max_file_mb``, a file that cannot be parsed) is refused in one line
    naming the file, its row and value, before anything runs.

    **Truth**: each track is cut into gap-free spans (a gap over ``max_gap_s``
    ends a span) and each span resampled on the grid of ``dt_s``: the recorded
    positions interpolated linearly onto it, then a Savitzky-Golay filter (a
    local least-squares cubic over ``smoothing_s``, so the recorder's
    quantisation and noise do not become acceleration), position, velocity and
    acceleration its value and first two derivatives. The state per axis is ``[p, v, a]``,
    ``("x", "vx", "ax", "y", "vy", "ay")`` with x east and y north
    (:mod:`models.kinematics`). Only the horizontal plane is tracked. With
    ``masked_gap_s`` (over ``max_gap_s``), a gap over ``max_gap_s`` but at most
    ``masked_gap_s`` long no longer ends a span: the grid steps strictly inside
    it are *missing* (the truth there is the straight line across the gap,
    smoothed; no trial is measured or scored there).

    **Maneuvers** (the onset truth): with ``maneuver_measure = "acceleration"``
    (the default) a step maneuvers when the magnitude of the horizontal
    acceleration is at least ``maneuver_threshold_m_s2`` (a turn, a speed
    change, or both; a coordinated turn at rate $\omega$ and speed $v$ has
    $|a| = \omega v$: 3 deg/s at 60 m/s is 3.1 m/s²); with ``"turn-rate"`` when the
    turn rate $|v \times a| / |v|^2$ is at least ``turn_rate_threshold_deg_s`` (turns
    only; none below 1 m/s). Either in runs of at least ``min_maneuver_steps``
    (a shorter run is quiet: a gust, not a maneuver), counted over the steps a
    track has: a missing step never maneuvers.

    **Segments**: a trial is a segment of ``steps`` steps inside one span whose
    first ``onset_step`` steps are quiet and whose step ``onset_step`` maneuvers:
    the onset is at ``onset_step`` in every trial, as in ``cv-turn-cv``. Under
    the null (``snr_db = None``; detectors' calibration) a trial is a segment
    quiet throughout. The segment is drawn uniformly among all of them from the
    trial's own stream; it starts at a recorded step, and its onset step is a
    recorded one. Each segment is moved so that its first position is the
    trackers' prior mean (the origin) plus a draw from the prior: the shape,
    speed and turns are the aircraft's; where it flew is not.

    **Measurements**: $z_k = p_k + v_k$, $v_k \sim \mathcal{N}(0, \sigma^2 I_2)$,
    $\sigma = \sigma_0\, 10^{-\text{SNR}/20}$, $\sigma_0$ = ``noise_std_m`` (the SNR definition of
    ``maneuvering-1d``; the null: 0 dB). With ``measurements = "recorded"`` the trials *replay* the
    file's own measurements instead: columns ``x_meas_m``, ``y_meas_m`` (beside
    planar truth) or ``latitude_meas``, ``longitude_meas`` (beside geodetic
    truth, in the same tangent plane, at the row's ``altitude_m``), one per
    row, no NaN (a missing or NaN column is refused in one line naming the
    file and the column); the truth columns stay the truth. Each sample falls
    on the grid step nearest its time (the first sample where two fall on one
    step; the others dropped), a step with none is missing (``valid_steps``
    False, so the config requires ``valid-step-masks``: only the trackers that
    handle masks pair), and a segment starts at a measured step. The
    measurements move with the segment's truth (the same shift to the prior
    mean). The trackers take ``noise_std_m`` as the measurements' noise std.
    There is no SNR axis: the only level a sweep may give is 0 dB (any other
    is refused before anything runs, :meth:`check_snr`), and the noise draws
    are drawn but unused.

    **Ragged trials** (docs/architecture.md, 'Ragged batches'): replaying, and with
    ``min_steps`` (after ``onset_step``, at most ``steps``) a trial's length $L$
    is drawn uniformly in ``min_steps``..``steps`` from its own stream and its
    steps from $L$ on are padding. With masked gaps or ``min_steps`` the scene's
    ``valid_steps`` (n, K) is False at a segment's missing steps and its
    padding, the measurements there NaN, ``maneuver_mask`` False there; the
    config then requires ``valid-step-masks``, so the maneuver detectors
    (whose windows assume every step) do not run on it and the kinematic
    trackers do. Without either option (the default) every trial has every
    step and ``valid_steps`` is None.

    **Random draws**, in this order whatever the SNR (common random numbers):
    the segment (one uniform), the initial position offset (2), the reference
    filter's initial error (4), the measurement noise (K, 2), the trial's
    length (one uniform; used with ``min_steps``).

    **Scene** (:class:`RecordedTrackScene`, a tracking and a detection scene):
    for the trackers ``model`` a :class:`models.kinematics.KinematicModel`
    (dt, the noise std, 2 axes, prior mean 0 with stds ``initial_*``),
    ``maneuver_mask`` (n, K) and ``maneuver_onset_steps`` (n, 1) (n, 0 under the
    null), ``valid_steps`` (n, K) or None (above); for the detectors ``onset_step`` (None under the null),
    ``null_onset_step``, ``offset_step`` (n,) (the first quiet step after the
    onset, K if the maneuver outlasts the segment), ``detect_window_steps``,
    ``warmup_steps`` and ``reference_filter``: the CV (DWNA) filter of
    ``cv-turn-cv`` at Kalata's ``tracking_index``, started at its steady state
    around the truth.
    """

    name = "recorded-tracks"
    tasks = (TRACKING, MANEUVER_DETECTION)
    #: the parameters its random streams were first keyed by (Scenario.stream_params)
    stream_params = ("path", "traffic_samples", "max_file_mb", "dt_s", "max_gap_s", "masked_gap_s", "min_steps",
                     "smoothing_s", "steps", "onset_step", "maneuver_threshold_m_s2", "maneuver_measure",
                     "turn_rate_threshold_deg_s", "min_maneuver_steps", "detect_window_steps", "warmup_steps",
                     "tracking_index", "noise_std_m", "measurements", "initial_position_std_m",
                     "initial_velocity_std_m_s", "initial_accel_std_m_s2", "divergence_bound_m")
    provides = frozenset({"kinematic-model", "reference-filter"})
    small_params: ClassVar[dict] = {"traffic_samples": ["calibration/ajaccio"], "steps": 30, "onset_step": 10,
                                    "detect_window_steps": 10}
    #: 1,000 trials of 500 steps, the measurements synthesised or replayed, on racetracks
    #: the scenario writes itself (:meth:`perf_data`)
    perf_sizes: ClassVar[dict] = {
        "segments": ({"steps": 500, "onset_step": 20, "detect_window_steps": 20, "dt_s": 1.0}, 1000),
        "replay": ({"steps": 500, "onset_step": 20, "detect_window_steps": 20, "dt_s": 1.0,
                    "measurements": "recorded", "noise_std_m": PERF_NOISE_M}, 1000)}
    perf_snr_db: ClassVar[float] = 0.0
    perf_targets: ClassVar[dict] = {"*": {"seconds_per_trial": 1e-3}}

    @dataclass(frozen=True)
    class Params:
        path: str = param("", "CSV or Parquet of recorded tracks (columns in the scenario's description); "
                          "relative to the sweep file's folder; '' to use traffic_samples", kind="path")
        traffic_samples: tuple[str, ...] = param(
            DEFAULT_SAMPLES, "with path '': the traffic package's sample trajectories, '<category>/<name>' "
            "(bench data fetch gets them)", max_len=64)
        max_file_mb: float = param(500.0, "a larger file is refused (MB)", gt=0.0, le=1e5,
                                   why="any positive size; the file is read whole into memory")
        dt_s: float = param(5.0, "time step T of the resampled tracks (s)", ge=0.05, le=100.0,
                            why="radar revisit times; ADS-B positions come every 0.5 to 10 s")
        max_gap_s: float = param(15.0, "a gap between recorded points longer than this ends a span (s)",
                                 gt=0.0, le=3600.0, why="any positive duration up to an hour")
        masked_gap_s: float = param(0.0, "gaps over max_gap_s and at most this long stay inside a span, their "
                                    "steps missing (a ragged batch; s); 0: every such gap ends a span", ge=0.0,
                                    le=86400.0, why="0, or over max_gap_s (checked) up to a day")
        min_steps: int = param(0, "a trial's length is drawn between this and steps, the rest padding (a ragged "
                               "batch); 0: every trial has steps", ge=0, le=MAX_STEPS,
                               why="0, or after onset_step and at most steps (checked)")
        smoothing_s: float = param(30.0, "span of the Savitzky-Golay filter giving the truth's position, "
                                   "velocity and acceleration (s; rounded to an odd number of steps, 5 at least)",
                                   gt=0.0, le=3600.0, why="any positive duration up to an hour")
        steps: int = param(60, "steps K of a segment (one trial)", ge=5, le=MAX_STEPS,
                           why="five steps at least; the trackers loop over steps in Python")
        onset_step: int = param(20, "step of the maneuver onset in every trial; the steps before it are quiet",
                                ge=1, le=MAX_STEPS - 1, why="after step 0, before the end (checked against steps)")
        maneuver_threshold_m_s2: float = param(
            2.0, "a step maneuvers when its horizontal acceleration is at least this (m/s^2)", gt=0.0, le=1000.0,
            why="any positive acceleration up to 100 g")
        maneuver_measure: str = param("acceleration", "what marks a maneuver: 'acceleration' (horizontal, any "
                                      "direction) or 'turn-rate' (turns only)", choices=MANEUVER_MEASURES)
        turn_rate_threshold_deg_s: float = param(
            1.5, "with maneuver_measure 'turn-rate': a step maneuvers when its turn rate is at least this (deg/s)",
            gt=0.0, le=360.0, why="any positive rate up to a turn per second")
        min_maneuver_steps: int = param(3, "shorter runs of maneuvering steps count as quiet", ge=1,
                                        le=MAX_STEPS, why="one step at least")
        detect_window_steps: int = param(20, "a detection counts if the first alarm at or after the onset comes "
                                         "within this many steps", ge=1, le=MAX_STEPS - 1,
                                         why="within the steps after the onset (checked against them)")
        warmup_steps: int = param(5, "steps ignored before false alarms are counted", ge=0, le=MAX_STEPS - 2,
                                  why="before the onset (checked against it)")
        tracking_index: float = param(0.1, "Kalata's tracking index of the detectors' reference CV filter",
                                      ge=1e-4, le=100.0, why="as in cv-turn-cv")
        noise_std_m: float = param(50.0, "reference std of the position-measurement noise per axis (m), at 0 dB; "
                                   "replaying, the std the trackers assume for the recorded measurements",
                                   ge=MIN_NOISE_M, le=1e4, why=NOISE_WHY)
        measurements: str = param("synthetic", "'synthetic': drawn at the SNR level around the truth; 'recorded': "
                                  "the file's x_meas_m, y_meas_m (or latitude_meas, longitude_meas) replayed "
                                  "on the grid, no SNR axis (snr_db = [0] only)", choices=MEASUREMENTS)
        initial_position_std_m: float = param(50.0, "prior std of the initial position per axis (m)",
                                              ge=1e-3, le=1e5, why="P0 stays positive definite")
        initial_velocity_std_m_s: float = param(200.0, "prior std of the initial velocity per axis (m/s); the "
                                                "prior mean is 0", ge=1e-3, le=1e4,
                                                why="P0 stays positive definite; at most 10 km/s")
        initial_accel_std_m_s2: float = param(5.0, "prior std of the initial acceleration per axis (m/s^2)",
                                              ge=1e-3, le=1e3, why="P0 stays positive definite; at most 100 g")
        divergence_bound_m: float = param(1000.0, "a trial diverged if its position error exceeds this (m)",
                                          gt=0.0, le=1e7, why="any positive distance")

        def validate(self) -> None:
            """The checks that cost nothing: the steps, the source, the file's size (the
            file's content, and whether the traffic samples are installed, are checked by
            :meth:`RecordedTracks.check_config` and :meth:`RecordedTracks.data_files`)."""
            for name, last in (("onset_step", self.onset_step), ("warmup_steps", self.warmup_steps + 1),
                               ("detect_window_steps", self.onset_step + self.detect_window_steps)):
                if last > (self.steps - 1 if name == "onset_step" else self.steps):
                    raise ConfigError(name, f"{getattr(self, name)} does not fit {self.steps} steps with the "
                                      f"onset at step {self.onset_step}")
            if self.warmup_steps >= self.onset_step:
                raise ConfigError("warmup_steps", f"must be < onset_step = {self.onset_step}")
            if self.min_steps and not self.onset_step < self.min_steps <= self.steps:
                raise ConfigError("min_steps", f"{self.min_steps} is not 0 or in onset_step + 1 = "
                                  f"{self.onset_step + 1} to steps = {self.steps} (every trial holds the onset)")
            if 0.0 < self.masked_gap_s <= self.max_gap_s:
                raise ConfigError("masked_gap_s", f"{self.masked_gap_s:g} s masks no gap: it is 0 or over "
                                  f"max_gap_s = {self.max_gap_s:g} s")
            if self.path:
                size_mb = os.path.getsize(self.path) / 1e6
                if size_mb > self.max_file_mb:
                    raise ConfigError("path", f"{self.path}: {size_mb:.6g} MB is over max_file_mb = "
                                      f"{self.max_file_mb:g} MB")
            elif not self.traffic_samples:
                raise ConfigError("path", "no tracks: give a path or traffic_samples")
            else:
                for name in self.traffic_samples:
                    check_sample_name(name)

    def perf_data(self, size: str, folder: Path) -> dict:
        """Every perf size reads :func:`write_racetracks` in ``folder`` (not the traffic samples:
        ``bench perf`` needs no optional extra)."""
        return {"path": str(write_racetracks(folder / "racetracks.csv"))}

    def fetch_data(self, source: Path | None = None) -> str | None:
        """The traffic wheel's sample trajectories (:func:`fetch_samples`), unless the
        traffic package is installed (its samples are read from there)."""
        import importlib.util
        if importlib.util.find_spec("traffic") is not None:
            return None
        return fetch_samples(source)

    def data_files(self, params) -> list[Path]:
        """The file, or the traffic samples read (their content is the config's identity)."""
        return [Path(params.path)] if params.path else [sample_file(name) for name in params.traffic_samples]

    def check_config(self, params) -> None:
        """Reads and checks the tracks (ConfigError naming the file) and that they hold a
        segment with an onset and a quiet one; says on stderr what reading converted (a
        Parquet file's ids of another type than text)."""
        bank = bank_of(params)
        for note in bank.notes:
            print(f"note: {note}", file=sys.stderr)
        for what, starts in (("with a maneuver onset at step onset_step after quiet steps", bank.onsets),
                             ("quiet throughout (for the detectors' null trials)", bank.quiet)):
            if len(starts) == 0:
                field = "maneuver_threshold_m_s2" if params.maneuver_measure == "acceleration" else \
                    "turn_rate_threshold_deg_s"
                raise ConfigError(field, f"{source_text(params)}: no segment of {params.steps} steps {what} at "
                                  f"{field} = {maneuver_threshold(params):g}")

    def timeline(self, params) -> Timeline:
        """A segment of ``steps`` steps whose onset is at ``onset_step`` in every trial."""
        return Timeline(steps=params.steps, onset_step=params.onset_step, warmup_steps=params.warmup_steps)

    def requires(self, params) -> frozenset[str]:
        """``valid-step-masks`` when the trials may miss steps (masked gaps, or ``min_steps``)."""
        return frozenset({VALID_STEP_MASKS}) if is_ragged(params) else frozenset()

    def check_snr(self, params, snr_db: float) -> str | None:
        if replays(params) and snr_db != 0.0:
            return ("measurements = 'recorded' replays the file's measurements as recorded (no SNR axis): "
                    "give snr_db = [0]")
        low = params.noise_std_m * 10.0 ** (-snr_db / 20.0)
        return None if low >= MIN_NOISE_M else f"the noise std scaled to it, {low:.3g} m, is below {MIN_NOISE_M:g} m"

    def unit_memory_bytes(self, params, n: int) -> int:
        """About 150 float64 values per trial and step, as ``maneuvering-1d`` (truth, draws,
        a tracker's estimate and covariance), and the resampled tracks."""
        return 8 * 150 * n * params.steps

    @staticmethod
    def model(p, snr_db: float | None) -> KinematicModel:
        """The trackers' :class:`~models.kinematics.KinematicModel` at ``snr_db``: prior mean 0."""
        P0 = per_axis(np.diag([p.initial_position_std_m, p.initial_velocity_std_m_s, p.initial_accel_std_m_s2]) ** 2, 2)
        return KinematicModel(dt_s=float(p.dt_s), noise_std_m=float(noise_std(p, snr_db)), dims=2,
                              x0=np.zeros(6), P0=P0)

    def generate(self, params, snr_db: float | None, n: int, rng) -> Batch:
        p, K = params, params.steps
        u = rng.random(1)[:, 0]                                   # draws first, fixed order and shapes
        e0 = rng.standard_normal(2)
        e_ref = rng.standard_normal(4)
        g = rng.standard_normal((K, 2))
        u_length = rng.random(1)[:, 0]
        bank, null = bank_of(p), snr_db is None
        starts = bank.quiet if null else bank.onsets
        start = starts[np.minimum((u * len(starts)).astype(np.int64), len(starts) - 1)]
        steps = start[:, None] + np.arange(K)                     # (n, K) rows of the bank
        pos = bank.pos[steps] - bank.pos[start][:, None] + p.initial_position_std_m * e0[:, None, :]
        # (n, K, 2 axes, [p, v, a]) -> [x, vx, ax, y, vy, ay]
        truth = np.stack([pos, bank.vel[steps], bank.acc[steps]], axis=-1).reshape(n, K, 6)
        model = self.model(p, snr_db)
        if bank.z is None:
            z = pos + model.noise_std_m * g
        else:                          # the recorded error about the truth, moved with the truth
            z = pos + (bank.z[steps] - bank.pos[steps])
        valid = self._valid_steps(p, bank.valid[steps], u_length) if is_ragged(p) else None
        if valid is not None:
            z = np.where(valid[..., None], z, np.nan)
        scene = RecordedTrackScene(
            snr_definition=REPLAY_SNR_DEFINITION if replays(p) else SNR_DEFINITION,
            realised_snr_db=np.full(n, 0.0 if null else float(snr_db)),
            position_index=position_index(2), model=model, state_labels=state_labels(2),
            measurement_labels=("x", "y"), divergence_bound_m=float(p.divergence_bound_m),
            maneuver_mask=bank.maneuvering[steps] if valid is None else bank.maneuvering[steps] & valid,
            maneuver_onset_steps=np.full((n, 0 if null else 1), p.onset_step, np.int64),
            onset_step=None if null else p.onset_step, null_onset_step=p.onset_step,
            offset_step=None if null else self._offsets(bank.maneuvering[steps], p.onset_step),
            detect_window_steps=p.detect_window_steps, warmup_steps=p.warmup_steps,
            reference_filter=self._reference_filter(p, model.noise_std_m, truth[:, 0], e_ref), valid_steps=valid)
        return Batch(t=p.dt_s * np.arange(K), truth=truth, z=z, scene=scene, trials=np.asarray(rng.trials))

    @staticmethod
    def _valid_steps(p, recorded: np.ndarray, u: np.ndarray) -> np.ndarray:
        """(n, K) the steps a trial has: recorded (not inside a masked gap) and before its
        length, drawn uniformly in min_steps..steps (all of them without min_steps)."""
        low = p.min_steps or p.steps
        length = low + np.minimum((u * (p.steps - low + 1)).astype(np.int64), p.steps - low)
        return recorded & (np.arange(p.steps)[None, :] < length[:, None])

    @staticmethod
    def _offsets(maneuvering: np.ndarray, onset: int) -> np.ndarray:
        """(n,) the first quiet step after the onset, K where the maneuver outlasts the segment."""
        after = ~maneuvering[:, onset:]
        return np.where(after.any(axis=1), onset + np.argmax(after, axis=1), maneuvering.shape[1])

    @staticmethod
    def _reference_filter(p, sigma: float, truth0: np.ndarray, e: np.ndarray) -> LinearGaussianFilter:
        """The detectors' CV filter (``cv-turn-cv``'s), started at its steady-state prior
        around the true [x, vx, y, vy] of step 0."""
        model = cv_model(p.dt_s, sigma, p.tracking_index)
        P0 = steady_state(model)[0]
        return LinearGaussianFilter(model=model, x0=truth0[:, CV_COMPONENTS] + matvec(np.linalg.cholesky(P0), e),
                                    P0=P0)


def write_racetracks(path: Path, tracks: int = 4, hours: float = 1.0, seed: int = 0) -> Path:
    """A CSV of ``tracks`` aircraft flying racetracks for ``hours`` (``bench perf``'s data):
    100 m/s, legs of 120 s joined by 180-degree turns at 3 deg/s (5.2 m/s^2), each track
    at its own phase and straight for its last 10 minutes (quiet segments), sampled about
    every second (jittered, 2 % of the samples lost) with recorded measurements in
    N(0, PERF_NOISE_M^2) per axis. Deterministic (``seed``)."""
    rng = np.random.default_rng(seed)
    dt_fine, speed, leg_s, turn_s = 0.1, 100.0, 120.0, 60.0
    t = np.arange(0.0, 3600.0 * hours, dt_fine)
    tables = []
    for k in range(tracks):
        phase = (t + k * (leg_s + turn_s) / tracks) % (leg_s + turn_s)
        turning = (phase >= leg_s) & (t < t[-1] - 600.0)
        heading = np.cumsum(np.where(turning, np.pi / turn_s, 0.0)) * dt_fine
        xy = np.cumsum(speed * np.stack([np.cos(heading), np.sin(heading)], axis=-1), axis=0) * dt_fine
        times = np.arange(0.0, t[-1], 1.0) + rng.uniform(0.0, 0.3, int(np.ceil(t[-1])))
        times = times[rng.random(len(times)) >= 0.02]           # 2 % lost: a replay misses their steps
        truth = np.stack([np.interp(times, t, xy[:, axis]) for axis in range(2)], axis=-1)
        z = truth + PERF_NOISE_M * rng.standard_normal(truth.shape)
        tables.append(pd.DataFrame({TRACK: f"racetrack-{k}", TIME: times, PLANAR[0]: truth[:, 0],
                                    PLANAR[1]: truth[:, 1], PLANAR_MEAS[0]: z[:, 0], PLANAR_MEAS[1]: z[:, 1]}))
    pd.concat(tables, ignore_index=True).to_csv(path, index=False)
    return path


def noise_std(p, snr_db: float | None) -> float:
    """The measurement-noise std (m) at ``snr_db`` (0 dB under the null; replaying,
    ``noise_std_m`` whatever the level: the recorded noise does not change with it)."""
    level = 0.0 if snr_db is None or replays(p) else float(snr_db)
    return p.noise_std_m * 10.0 ** (-level / 20.0)
