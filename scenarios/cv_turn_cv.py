"""Scenario ``cv-turn-cv``: the classic maneuver-detection test track."""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from radarbench.bench.batched import matvec
from radarbench.bench.core import MANEUVER_DETECTION, Batch, Scenario, Timeline
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_scenario
from radarbench.bench.tasks.detection import DetectionScene
from radarbench.models.kalman import LinearGaussianFilter, LinearGaussianModel, kalman_filter, steady_state

#: indices of x and y in the state [x, vx, y, vy]
POSITION_INDEX = (0, 2)
#: the longest scene (steps) and the smallest turn rate (deg/s) accepted
MAX_STEPS = 10_000
MIN_TURN_RATE_DEG_S = 1e-3

SNR_DEFINITION = (
    "SNR at the detector input: the reference CV filter is linear, so its "
    "innovation is a maneuver-induced part nu_m (the filter run on the "
    "noise-free measurements of the deterministic track, started on the truth) "
    "plus a noise part; SNR = mean over the turn steps [onset, onset + "
    "turn_steps) of ||nu_m||^2 / 2, divided by the steady-state innovation "
    "noise variance per component S_11, in dB; under the null the noise "
    "level is that of 0 dB."
)


def cv_model(dt: float, sigma_w: float, tracking_index: float) -> LinearGaussianModel:
    """Per-axis discrete white-noise acceleration (DWNA) model, 2D positions.

    Bar-Shalom, Li & Kirubarajan (2001), sec. 6.3.2: per axis
    F = [[1, T], [0, 1]], G = [T^2/2, T]', Q = sigma_a^2 G G'. The process
    noise is set by Kalata's tracking index lambda = sigma_a T^2 / sigma_w, so
    Q and R = sigma_w^2 I both scale with sigma_w^2 and the gain depends on
    lambda only.
    """
    F = np.kron(np.eye(2), np.array([[1.0, dt], [0.0, 1.0]]))
    G = dwna_gain(dt)
    sigma_a = tracking_index * sigma_w / dt ** 2
    Q = sigma_a ** 2 * G @ G.T
    H = np.zeros((2, 4))
    H[0, POSITION_INDEX[0]] = H[1, POSITION_INDEX[1]] = 1.0
    R = sigma_w ** 2 * np.eye(2)
    return LinearGaussianModel(F=F, H=H, Q=Q, R=R)


def dwna_gain(dt: float) -> np.ndarray:
    """Noise gain G (4, 2) mapping a per-axis acceleration into [x, vx, y, vy]."""
    return np.kron(np.eye(2), np.array([[dt ** 2 / 2.0], [dt]]))


def ct_transition(omega: float, dt: float) -> np.ndarray:
    """Exact coordinated-turn transition for [x, vx, y, vy], turn rate omega
    (rad/s, positive = counter-clockwise), known turn rate; see Li & Jilkov,
    "Survey of maneuvering target tracking. Part I", IEEE TAES 39(4), 2003.
    """
    s, c = np.sin(omega * dt), np.cos(omega * dt)
    return np.array([
        [1.0, s / omega, 0.0, -(1.0 - c) / omega],
        [0.0, c, 0.0, -s],
        [0.0, (1.0 - c) / omega, 1.0, s / omega],
        [0.0, s, 0.0, c],
    ])


def deterministic_track(p, turn: bool) -> np.ndarray:
    """The noise-free state (K, 4): start at the origin heading +x.

    The turn acts on the transitions *into* steps onset .. onset+turn_steps-1,
    so the measurement at ``onset_step`` is the first one the turn moves, and
    ``onset_step + turn_steps`` is the first step reached by a CV transition
    again. Without ``turn`` the track is the same CV line throughout.
    """
    F_cv = cv_model(p.dt_s, 1.0, p.tracking_index).F
    F_ct = ct_transition(np.deg2rad(p.turn_rate_deg_s), p.dt_s)
    x = np.empty((p.steps, 4))
    x[0] = (0.0, p.speed_m_s, 0.0, 0.0)
    for k in range(1, p.steps):
        in_turn = turn and p.onset_step <= k < p.onset_step + p.turn_steps
        x[k] = (F_ct if in_turn else F_cv) @ x[k - 1]
    return x


def filter_response(model: LinearGaussianModel, track: np.ndarray) -> np.ndarray:
    """Innovation (K, 2) of the steady-state filter on noise-free measurements
    of ``track``, started exactly on the truth: the maneuver-induced part nu_m.
    """
    P_prior = steady_state(model)[0]
    z = (track @ model.H.T)[None]
    return kalman_filter(model, z, track[None, 0], P_prior).nu[0]


@functools.lru_cache(maxsize=64)
def maneuver_innovation(p) -> np.ndarray:
    """nu_m (K, 2) of the turn for params ``p``; independent of sigma_w, so
    computed once per params (they are frozen, hence hashable)."""
    nu_m = filter_response(cv_model(p.dt_s, 1.0, p.tracking_index), deterministic_track(p, turn=True))
    nu_m.setflags(write=False)
    return nu_m


def maneuver_power(p) -> float:
    """P_m: mean over the turn steps of ||nu_m(k)||^2 / m (m^2)."""
    nu_m = maneuver_innovation(p)
    turn = slice(p.onset_step, p.onset_step + p.turn_steps)
    return float(np.mean(np.sum(nu_m[turn] ** 2, axis=-1)) / nu_m.shape[-1])


def noise_std_for_snr(p, snr_db: float) -> float:
    """sigma_w (m) that gives ``snr_db`` under :data:`SNR_DEFINITION`.

    nu_m does not depend on sigma_w (the gain depends on the tracking index
    only) while S = sigma_w^2 S_unit, so SNR = P_m / (sigma_w^2 S_unit_11).
    """
    S_unit = steady_state(cv_model(p.dt_s, 1.0, p.tracking_index))[2]
    return float(np.sqrt(maneuver_power(p) / (S_unit[0, 0] * 10.0 ** (snr_db / 10.0))))


@register_scenario
class CvTurnCv(Scenario):
    r"""Constant velocity, coordinated turn, constant velocity; 2D position measurements.

    The truth is a deterministic track (CV along +x from the origin, a
    coordinated turn of ``turn_steps`` steps from ``onset_step``, CV again),
    plus, with ``process_noise``, the reference filter's own discrete
    white-noise acceleration, so the filter is matched apart from the turn.
    The process-noise part is superposed linearly, with the CV $F$:

    $$
    n_k = F n_{k-1} + G w_k, \qquad n_{-1} = 0.
    $$

    The reference filter (the scene's ``reference_filter``, a
    :class:`models.kalman.LinearGaussianFilter`) is the per-axis DWNA CV
    filter (:func:`cv_model`). It starts in steady state: its ``P0`` is the
    steady-state prior covariance and its ``x0`` $= x^{\text{true}}_0 + \operatorname{chol}(P_0)\, e$, so under the
    matched model its innovations are white and
    stationary from step 0.

    SNR: see :data:`SNR_DEFINITION`. Under the null
    (``snr_db=None``) the track is the same CV line without the turn and the
    noise level is that of 0 dB: every shipped detector normalises by $S$, so
    the scale of the null is immaterial to them. Random draws, in this order
    whatever the SNR or hypothesis: initial estimate error (4,), process noise
    (K, 2), measurement noise (K, 2); trial i sees the same standard normals
    at every SNR.

    **Scene** (a :class:`~bench.tasks.detection.DetectionScene`;
    docs/architecture.md, 'Scenes'): ``onset_step`` / ``offset_step`` (None
    under the null), ``null_onset_step`` (the onset, also under the null),
    ``detect_window_steps``, ``warmup_steps``, ``reference_filter``,
    ``position_index`` (0, 2), ``snr_definition``, ``realised_snr_db`` (n,).
    The measurements are the plane positions themselves (no
    ``measurements_xy``).
    """

    name = "cv-turn-cv"
    tasks = (MANEUVER_DETECTION,)
    #: the parameters its random streams were first keyed by (Scenario.stream_params)
    stream_params = ("steps", "dt_s", "onset_step", "turn_steps", "speed_m_s", "turn_rate_deg_s", "tracking_index",
                     "process_noise", "detect_window_steps", "warmup_steps", "onset_jitter_steps")
    provides = frozenset({"reference-filter"})
    #: ``bench perf`` sizes: name -> (scenario params, trials)
    perf_sizes = {"paper": ({}, 1000)}

    def timeline(self, params) -> Timeline:
        """``steps`` steps; the earliest onset is ``onset_step`` (a jitter only delays it)."""
        return Timeline(steps=params.steps, onset_step=params.onset_step, warmup_steps=params.warmup_steps)

    def unit_memory_bytes(self, params, n: int) -> int:
        """About 32 float64 values per trial and step: the truth (4), its process
        noise (4), the measurements (2) and their draws (6), the reference filter's
        innovations and covariances and the detectors' sliding sums."""
        return 8 * 32 * n * params.steps

    @dataclass(frozen=True)
    class Params:
        steps: int = param(160, "number of measurement steps K", ge=2, le=MAX_STEPS,
                           why="two steps at least; the track and the filters loop over steps in "
                               "Python, so at most 10 000 (60 times the paper's 160)")
        dt_s: float = param(1.0, "sampling interval T (s)", ge=1e-3, le=100.0,
                            why="radar revisit times, 1 ms to 100 s; the filter's Q grows as T^4 "
                                "and sigma_a as T^-2, and stays well conditioned within")
        onset_step: int = param(80, "first step moved by the turn (step index)", ge=1, le=MAX_STEPS - 1,
                                why="after step 0, with a turn step after it within the steps (checked "
                                    "against them)")
        turn_steps: int = param(40, "duration of the turn (steps)", ge=1, le=MAX_STEPS - 1,
                                why="one step at least, within the steps after the onset (checked against "
                                    "them)")
        speed_m_s: float = param(200.0, "target speed (m/s)", ge=0.1, le=10_000.0,
                                 why="a walking target to Mach 30; the SNR sets the noise relative "
                                     "to the maneuver, so the speed only sets the scale")
        turn_rate_deg_s: float = param(
            3.0, "turn rate (deg/s), positive = left (counter-clockwise); non-zero, at least "
            "0.001 in magnitude", ge=-90.0, le=90.0,
            why="a quarter turn per second at most (beyond it the turn aliases at T = 1 s); a rate "
                "below 0.001 deg/s moves the track by less than the noise can be scaled to")
        tracking_index: float = param(
            0.1, "Kalata's tracking index lambda = sigma_a T^2 / sigma_w of the "
            "reference filter (dimensionless); fixes its gain whatever the noise level",
            ge=1e-4, le=100.0, why="from a nearly constant-velocity filter (gain ~0.01) to one "
                                   "that follows every measurement; the steady-state Riccati "
                                   "solution is well conditioned within")
        process_noise: bool = param(
            True, "truth includes the filter's white-noise acceleration (matched "
            "filter); false: deterministic track (filter Q then over-estimated)")
        detect_window_steps: int = param(
            40, "a detection counts if the first alarm at or after onset comes "
            "within this many steps", ge=1, le=MAX_STEPS - 1,
            why="one step at least, within the steps after the onset (checked against them)")
        warmup_steps: int = param(10, "steps ignored before false alarms are counted", ge=0,
                                  le=MAX_STEPS - 2, why="before the onset (checked against it)")
        onset_jitter_steps: int = param(
            0, "each trial's onset is drawn uniformly from onset_step .. onset_step + this "
            "(steps), from the trial's own stream; 0: every trial starts the turn at onset_step",
            ge=0, le=MAX_STEPS - 2, why="within the steps, before a turn step (checked against them)")

        @property
        def last_onset(self) -> int:
            return self.onset_step + self.onset_jitter_steps

        def validate(self) -> None:
            if abs(self.turn_rate_deg_s) < MIN_TURN_RATE_DEG_S:
                raise ConfigError("turn_rate_deg_s", f"must be at least {MIN_TURN_RATE_DEG_S:g} deg/s in "
                                  f"magnitude (a zero rate is no maneuver), got {self.turn_rate_deg_s!r}")
            if self.last_onset + self.turn_steps > self.steps:
                raise ConfigError("turn_steps", f"onset_step + onset_jitter_steps + turn_steps = "
                                  f"{self.last_onset + self.turn_steps} exceeds steps = {self.steps}")
            if self.warmup_steps >= self.onset_step:
                raise ConfigError("warmup_steps", f"must be < onset_step = {self.onset_step} "
                                  f"(no null region left), got {self.warmup_steps}")
            if self.last_onset + self.detect_window_steps > self.steps:
                raise ConfigError("detect_window_steps", f"onset_step + onset_jitter_steps + "
                                  f"detect_window_steps = {self.last_onset + self.detect_window_steps} "
                                  f"exceeds steps = {self.steps}")

    def generate(self, params, snr_db: float | None, n: int, rng) -> Batch:
        p = params
        K, T = p.steps, p.dt_s
        # Draw first, in a fixed order, so every SNR and the null share the noise.
        e = rng.standard_normal(4)
        w = rng.standard_normal((K, 2))
        v = rng.standard_normal((K, 2))
        onset = self._onsets(p, rng)           # int, or (n,) with jitter (drawn last)

        null = snr_db is None
        sigma_w = noise_std_for_snr(p, 0.0 if null else snr_db)
        model = cv_model(T, sigma_w, p.tracking_index)
        P0 = steady_state(model)[0]

        track = self._tracks(p, onset, turn=not null)
        truth = track + self._process_noise(p, sigma_w, w)
        z = truth[..., POSITION_INDEX] + sigma_w * v
        x0 = truth[:, 0] + matvec(np.linalg.cholesky(P0), e)

        scene = DetectionScene(
            onset_step=None if null else onset, null_onset_step=onset,
            offset_step=None if null else onset + p.turn_steps, detect_window_steps=p.detect_window_steps,
            warmup_steps=p.warmup_steps, reference_filter=LinearGaussianFilter(model=model, x0=x0, P0=P0),
            snr_definition=SNR_DEFINITION, realised_snr_db=self._realised_snr_db(p, model, z, x0, P0, onset, null),
            position_index=POSITION_INDEX)
        return Batch(t=T * np.arange(K), truth=truth, z=z, scene=scene, trials=np.asarray(rng.trials))

    @staticmethod
    def _onsets(p, rng):
        """``onset_step``, or with jitter one onset per trial, uniform on
        onset_step .. onset_step + onset_jitter_steps, drawn after the noise
        from each trial's own stream (so the noise, and every SNR level and
        hypothesis, keep the same draws: common random numbers hold)."""
        if p.onset_jitter_steps == 0:
            return p.onset_step
        u = rng.random(1)[:, 0]
        return p.onset_step + np.minimum((u * (p.onset_jitter_steps + 1)).astype(np.int64),
                                         p.onset_jitter_steps)

    @staticmethod
    def _tracks(p, onset, turn: bool) -> np.ndarray:
        """The deterministic track, (1, K, 4) for one onset or (n, K, 4) per trial."""
        if np.ndim(onset) == 0:
            return deterministic_track(p, turn=turn)[None]
        by_onset = {int(o): deterministic_track(dataclasses.replace(p, onset_step=int(o)), turn=turn)
                    for o in np.unique(onset)}
        return np.stack([by_onset[int(o)] for o in onset])

    @staticmethod
    def _process_noise(p, sigma_w: float, w: np.ndarray) -> np.ndarray:
        """(n, K, 4) accumulated DWNA noise, zeros if ``process_noise`` is off."""
        noise = np.zeros((w.shape[0], p.steps, 4))
        if not p.process_noise:
            return noise
        F = cv_model(p.dt_s, 1.0, p.tracking_index).F
        Gw = matvec(dwna_gain(p.dt_s), (p.tracking_index * sigma_w / p.dt_s ** 2) * w)
        noise[:, 0] = Gw[:, 0]
        for k in range(1, p.steps):
            noise[:, k] = matvec(F, noise[:, k - 1]) + Gw[:, k]
        return noise

    @staticmethod
    def _realised_snr_db(p, model, z, x0, P0, onset, null: bool) -> np.ndarray:
        """Per trial: 10 log10(P_m / mean over the turn of ||nu - nu_m||^2 / m).

        By linearity nu - nu_m is exactly the noise part of the innovation.
        Trials are grouped by onset (one group without jitter); P_m does not
        depend on the onset (the filter is time-invariant and the track before
        the turn is predicted exactly, so nu_m only shifts).
        """
        if null:
            return np.full(z.shape[0], np.nan)
        nu = kalman_filter(model, z, x0, P0).nu
        onsets = np.broadcast_to(onset, (z.shape[0],))
        out = np.empty(z.shape[0])
        for o in np.unique(onsets):
            q = dataclasses.replace(p, onset_step=int(o))
            rows = onsets == o
            turn = slice(q.onset_step, q.onset_step + q.turn_steps)
            noise_power = np.mean(np.sum((nu[rows] - maneuver_innovation(q))[:, turn] ** 2, axis=-1),
                                  axis=-1) / 2.0
            out[rows] = 10.0 * np.log10(maneuver_power(q) / noise_power)
        return out
