"""Scenario ``maneuvering-1d``: range (or planar position) of a target that is
quiet, maneuvers, and is quiet again, measured in Gaussian noise."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from radarbench.bench.batched import matvec
from radarbench.bench.core import TRACKING, Batch, Scenario
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_scenario
from radarbench.bench.tasks.tracking import TrackingScene
from radarbench.models.kinematics import (KinematicModel, cv, cv_components, per_axis, position_index,
                                          position_measurement, singer, state_labels)
from radarbench.models.pcrb import linear_dynamics_pcrb, position_mse_bound
from radarbench.models.turn import ct_transition, turn_acceleration

MAX_STEPS = 10_000
MIN_NOISE_M = 1e-3
NOISE_WHY = ("a millimetre to 10 km: below it the trackers' covariances lose definiteness in float64 "
             "(the noise scaled to each SNR level is held to the same floor)")
#: the maneuver profiles
PROFILES = ("piecewise", "singer", "turn")

SNR_DEFINITION = (
    "snr_db is a measurement-noise level relative to the scenario's reference noise: the "
    "position-measurement noise std is noise_std_m times 10^(-snr_db/20) on each axis, so 0 dB "
    "is the reference and +6 dB halves the noise (as in the glint scenario); the target's motion "
    "does not change along the axis; snr_db=None is the null: the same noise at 0 dB and no "
    "maneuver (the acceleration profile is zero)."
)


def _axis_values(values: tuple[float, ...], dims: int) -> np.ndarray:
    """Per-axis values (x, y) of a 1- or 2-value parameter for ``dims`` axes; a missing y is 0."""
    out = np.zeros(2)
    out[:len(values)] = values
    return out[:dims]


@register_scenario
class Maneuvering(Scenario):
    r"""Target with a quiet / maneuver / quiet acceleration profile (or a Singer process); position measurements in Gaussian noise.

    The test target of the AR-model patent ("基于最优AR模型的自适应机动目标跟踪方法",
    adaptive maneuvering-target tracking based on an optimal AR model), whose
    simulation 1 tracks a target whose true acceleration is its figure 3 and
    compares range and velocity estimates (figures 4-7). Our copy of the
    patent ends at paragraph [0026] with the figures' captions only: no
    figure's shape, no embodiment, no number. The profile and every default
    below are ours.

    **State** per axis $[p, v, a]'$ (m, m/s, m/s²), axes stacked:
    ``("x", "vx", "ax")`` in 1-D (``dims = 1``: the range), ``("x", "vx",
    "ax", "y", "vy", "ay")`` in 2-D; $a_k$ is the acceleration held over
    $[t_k, t_{k+1})$, and the motion is integrated exactly for it:

    $$
    p_{k+1} = p_k + v_k T + a_k T^2/2, \qquad v_{k+1} = v_k + a_k T.
    $$

    **Profile** ``"piecewise"`` (default, ours): quiet ($a = 0$) from 0 to ``maneuver_start_s`` = 40 s, a maneuver
    of ``maneuver_accel_m_s2`` = 20 m/s^2 (about 2 g; in 2-D the second
    value, default -10 m/s^2, on y) for ``maneuver_duration_s`` = 20 s, i.e.
    from 40 s to 60 s, quiet again to the end (``steps`` = 100 at ``dt_s`` =
    1 s). Segment boundaries are rounded to whole steps. The default 1-D
    target starts at 20 km closing at 200 m/s; the maneuver turns it round
    ($v = +200$ m/s at 60 s), so the range is 12 km at 40 s and 60 s and 19.8 km
    at the last step (99 s). ``process_noise_m_s2`` adds a white acceleration
    $\sigma_w w_k$ ($w_k \sim \mathcal{N}(0, 1)$, held over each step; DWNA) on each axis; the
    default 0 keeps the motion deterministic apart from the initial state.

    **Profile** ``"turn"`` (planar, ``dims = 2``): the piecewise profile's segments, the
    maneuver a coordinated turn at ``turn_rate_deg_s`` (speed held, the velocity rotating;
    the exact transition of :func:`models.turn.ct_transition`), the acceleration of each
    maneuvering step the turn's, $\Omega\, (-v_y, v_x)$; quiet steps are straight lines.
    ``maneuver_accel_m_s2`` and ``process_noise_m_s2`` are not used.

    **Profile** ``"singer"``: the acceleration of each axis is Singer's
    zero-mean first-order Markov process, $\dot{a} = -\alpha a + w$ with
    stationary std ``singer_sigma_m_s2`` and ``singer_alpha_per_s``; the
    state follows the exact discretisation $x_{k+1} = F x_k + w_k$,
    $w_k \sim \mathcal{N}(0, Q)$ (:func:`models.kinematics.singer`), $a_0$ drawn from the stationary
    law. No maneuver onsets are defined (``maneuver_mask`` and
    ``maneuver_onset_steps`` are None).

    **Initial state**: position and velocity of each trial drawn from
    $\mathcal{N}(x_0, P_0)$ of the model's prior (``initial_*``; stds
    ``initial_position_std_m``, ``initial_velocity_std_m_s``); the initial
    acceleration is the profile's (0) for ``"piecewise"``. Trackers start
    from $(x_0, P_0)$, the acceleration prior std being
    ``initial_accel_std_m_s2`` (the Singer $\sigma$ for ``"singer"``).

    **Measurements** (:data:`SNR_DEFINITION`; $\sigma_0$ = ``noise_std_m``):

    $$
    z_k = p_k + v_k, \qquad v_k \sim \mathcal{N}(0, \sigma^2 I), \qquad
    \sigma = \sigma_0\, 10^{-\text{SNR}/20};
    $$

    the realised SNR of a trial is ``snr_db`` itself. Under the null
    (``snr_db = None``) the noise is that of 0 dB and the profile is zero
    (no maneuver), the Singer process unchanged.

    **Random draws**, in this order whatever the profile, dims or SNR (common
    random numbers): initial state (2, 3) standard normals, process (K, 2, 3)
    standard normals, measurement noise (K, 2) standard normals.

    **Scene** (:class:`~bench.tasks.tracking.TrackingScene`): ``model`` a
    :class:`models.kinematics.KinematicModel` (dt, the noise std at the SNR,
    dims, prior), ``state_labels``, ``position_index`` ((0,) or (0, 3)),
    ``maneuver_mask`` (n, K) the steps whose true acceleration is the
    maneuver's, ``maneuver_onset_steps`` (n, 1) its first step (0 onsets
    under the null or with a zero maneuver), ``measurements_xy`` (1-D: time
    (s) against the measured range, for plots), ``divergence_bound_m``,
    ``position_bound`` (n, K) the posterior Cramér-Rao bound (:meth:`position_bound`).
    """

    name = "maneuvering-1d"
    tasks = (TRACKING,)
    #: the parameters its random streams were first keyed by (Scenario.stream_params)
    stream_params = ("steps", "dt_s", "dims", "profile", "maneuver_start_s", "maneuver_duration_s",
                     "maneuver_accel_m_s2", "singer_alpha_per_s", "singer_sigma_m_s2", "process_noise_m_s2",
                     "noise_std_m", "initial_position_m", "initial_velocity_m_s", "initial_position_std_m",
                     "initial_velocity_std_m_s", "initial_accel_std_m_s2", "divergence_bound_m")
    provides = frozenset({"kinematic-model"})
    small_params: ClassVar[dict] = {"steps": 40, "maneuver_start_s": 15.0, "maneuver_duration_s": 10.0}
    perf_sizes: ClassVar[dict] = {"default": ({}, 1000)}
    perf_snr_db: ClassVar[float] = 0.0

    @dataclass(frozen=True)
    class Params:
        steps: int = param(100, "number of measurement steps K", ge=2, le=MAX_STEPS,
                           why="two steps at least; the trackers loop over steps in Python, so at most 10 000")
        dt_s: float = param(1.0, "time step T between measurements (s)", ge=1e-3, le=100.0,
                            why="radar revisit times, 1 ms to 100 s")
        dims: int = param(1, "axes: 1 = range only, 2 = planar position (x, y)", ge=1, le=2,
                          why="range or planar position")
        profile: str = param("piecewise", "'piecewise': quiet / maneuver / quiet acceleration; "
                             "'singer': Singer-process acceleration", choices=PROFILES)
        maneuver_start_s: float = param(40.0, "start of the maneuver (s)", ge=0.0, le=1e6,
                                        why="within the scene (checked against steps x dt_s)")
        maneuver_duration_s: float = param(20.0, "duration of the maneuver (s)", ge=0.0, le=1e6,
                                           why="0 is no maneuver; clipped at the end of the scene")
        maneuver_accel_m_s2: tuple[float, ...] = param(
            (20.0, -10.0), "acceleration during the maneuver per axis (x, y) (m/s^2); 1-D uses x, "
            "a missing y is 0", ge=-1000.0, le=1000.0, min_len=1, max_len=2, why="at most 100 g")
        singer_alpha_per_s: float = param(0.1, "Singer maneuver rate alpha = 1/time constant (1/s)",
                                          ge=1e-4, le=100.0, why="time constants from 10 ms to about 3 h")
        singer_sigma_m_s2: float = param(10.0, "Singer stationary acceleration std sigma_m (m/s^2)",
                                         ge=0.0, le=1000.0, why="0 is no acceleration; at most 100 g")
        turn_rate_deg_s: float = param(3.0, "turn rate of the 'turn' profile's maneuver (deg/s; > 0 "
                                       "counter-clockwise; 3 deg/s is an aircraft's standard rate turn)",
                                       ge=-360.0, le=360.0, why="up to a full circle per second either way")
        process_noise_m_s2: float = param(0.0, "std of a white acceleration added on each axis, held "
                                          "over each step (m/s^2; piecewise profile)", ge=0.0, le=1000.0,
                                          why="0 is a deterministic profile; at most 100 g")
        noise_std_m: float = param(50.0, "reference std of the position-measurement noise per axis (m), "
                                   "at 0 dB", ge=MIN_NOISE_M, le=1e4, why=NOISE_WHY)
        initial_position_m: tuple[float, ...] = param(
            (20_000.0, 5_000.0), "prior mean initial position per axis (x, y) (m); 1-D uses x",
            ge=-1e7, le=1e7, min_len=1, max_len=2, why="within 10 000 km")
        initial_velocity_m_s: tuple[float, ...] = param(
            (-200.0, 100.0), "prior mean initial velocity per axis (x, y) (m/s); 1-D uses x",
            ge=-1e4, le=1e4, min_len=1, max_len=2, why="at most 10 km/s")
        initial_position_std_m: float = param(50.0, "prior std of the initial position per axis (m)",
                                              ge=1e-3, le=1e5, why="a millimetre to 100 km: P0 stays "
                                              "positive definite in float64")
        initial_velocity_std_m_s: float = param(20.0, "prior std of the initial velocity per axis (m/s)",
                                                ge=1e-3, le=1e4, why="P0 stays positive definite")
        initial_accel_std_m_s2: float = param(1.0, "prior std of the initial acceleration the trackers "
                                              "assume per axis (m/s^2; piecewise profile)", ge=1e-3,
                                              le=1e3, why="P0 stays positive definite; at most 100 g")
        divergence_bound_m: float = param(1000.0, "a trial diverged if its position error exceeds this (m)",
                                          gt=0.0, le=1e7, why="any positive distance")

        def validate(self) -> None:
            if self.profile == "turn" and self.dims != 2:
                raise ConfigError("dims", f"the 'turn' profile is a planar turn: dims must be 2, got {self.dims}")
            if self.profile != "singer" and self.maneuver_start_s >= self.steps * self.dt_s:
                raise ConfigError("maneuver_start_s", f"{self.maneuver_start_s} s is not before the end of "
                                  f"the scene ({self.steps} steps of {self.dt_s} s)")

    def check_snr(self, params, snr_db: float) -> str | None:
        """The noise std scaled to ``snr_db`` stays at or above 1 mm."""
        low = params.noise_std_m * 10.0 ** (-snr_db / 20.0)
        if low < MIN_NOISE_M:
            return (f"the noise std scaled to it, {low:.3g} m, is below {MIN_NOISE_M:g} m; at most "
                    f"{20.0 * math.log10(params.noise_std_m / MIN_NOISE_M):.4g} dB for this config")
        return None

    def unit_memory_bytes(self, params, n: int) -> int:
        """About 150 float64 values per trial and step: truth (6), draws (8), measurements,
        and a tracker's estimate with its covariance (6 + 36) and per-mode scratch."""
        return 8 * 150 * n * params.steps

    @staticmethod
    def maneuver_steps(p) -> tuple[int, int]:
        """[start, end) steps of the piecewise maneuver (boundaries rounded to steps)."""
        start = min(int(round(p.maneuver_start_s / p.dt_s)), p.steps)
        end = min(int(round((p.maneuver_start_s + p.maneuver_duration_s) / p.dt_s)), p.steps)
        return start, max(end, start)

    @staticmethod
    def model(p, snr_db: float | None = None) -> KinematicModel:
        """The scene's :class:`~models.kinematics.KinematicModel` at ``snr_db``."""
        scale = 10.0 ** (-(0.0 if snr_db is None else float(snr_db)) / 20.0)
        accel_std = p.singer_sigma_m_s2 if p.profile == "singer" else p.initial_accel_std_m_s2
        x0 = np.stack([_axis_values(p.initial_position_m, p.dims), _axis_values(p.initial_velocity_m_s, p.dims),
                       np.zeros(p.dims)], axis=1).ravel()
        P0 = per_axis(np.diag([p.initial_position_std_m, p.initial_velocity_std_m_s,
                               max(accel_std, 1e-3)]) ** 2, p.dims)
        return KinematicModel(dt_s=float(p.dt_s), noise_std_m=float(p.noise_std_m * scale), dims=int(p.dims),
                              x0=x0, P0=P0)

    def acceleration_profile(self, p, null: bool) -> np.ndarray:
        """(K, dims) the piecewise profile's acceleration per step (zero under the null)."""
        accel = np.zeros((p.steps, p.dims))
        if not null:
            start, end = self.maneuver_steps(p)
            accel[start:end] = _axis_values(p.maneuver_accel_m_s2, p.dims)
        return accel

    def generate(self, params, snr_db: float | None, n: int, rng) -> Batch:
        p, K, D = params, params.steps, params.dims
        e0 = rng.standard_normal((2, 3))                        # draws first, fixed order and shapes
        w = rng.standard_normal((K, 2, 3))
        g = rng.standard_normal((K, 2))
        model = self.model(p, snr_db)
        null = snr_db is None
        x0 = model.x0.reshape(D, 3)
        std0 = np.sqrt(np.diag(model.P0)).reshape(D, 3)
        if p.profile == "singer":
            truth = self._singer_truth(p, x0 + std0 * e0[:, :D], w[..., :D, :])
            mask = onsets = None
        elif p.profile == "turn":
            init = x0[:, :2] + std0[:, :2] * e0[:, :D, :2]
            truth = self._turn_truth(p, init, null)
            mask, onsets = self._maneuver_truth(p, null, n)
        else:
            init = x0[:, :2] + std0[:, :2] * e0[:, :D, :2]        # (n, D, 2) position, velocity
            accel = self.acceleration_profile(p, null) + p.process_noise_m_s2 * w[..., :D, 0]   # (n, K, D)
            truth = self._integrate(init, accel, p.dt_s)
            mask, onsets = self._maneuver_truth(p, null, n)
        z = truth[..., list(position_index(D))] + model.noise_std_m * g[..., :D]
        t = p.dt_s * np.arange(K)
        xy = np.stack([np.broadcast_to(t, z.shape[:2]), z[..., 0]], axis=-1) if D == 1 else None
        scene = TrackingScene(
            snr_definition=SNR_DEFINITION, realised_snr_db=np.full(n, 0.0 if null else float(snr_db)),
            position_index=position_index(D), measurements_xy=xy, model=model, state_labels=state_labels(D),
            measurement_labels=("x", "y")[:D], divergence_bound_m=float(p.divergence_bound_m),
            maneuver_mask=mask, maneuver_onset_steps=onsets,
            position_bound=np.broadcast_to(self.position_bound(p, model, null), (n, K)).copy())
        return Batch(t=t, truth=truth, z=z, scene=scene, trials=np.asarray(rng.trials))

    @staticmethod
    def _integrate(init: np.ndarray, accel: np.ndarray, dt: float) -> np.ndarray:
        """(n, K, 3 D) states from initial (n, D, 2) [p, v] and accelerations (n, K, D) held
        over each step: v_k = v_0 + T sum_{j<k} a_j, p_k = p_0 + sum_{j<k} (v_j T + a_j T^2/2)."""
        n, K, D = accel.shape
        dv = np.cumsum(accel * dt, axis=1)
        v = init[:, None, :, 1] + np.concatenate([np.zeros((n, 1, D)), dv[:, :-1]], axis=1)
        dp = np.cumsum(v * dt + accel * (dt * dt / 2.0), axis=1)
        pos = init[:, None, :, 0] + np.concatenate([np.zeros((n, 1, D)), dp[:, :-1]], axis=1)
        return np.stack([pos, v, accel], axis=-1).reshape(n, K, 3 * D)

    @staticmethod
    def _singer_truth(p, init: np.ndarray, w: np.ndarray) -> np.ndarray:
        """(n, K, 3 D): x_{k+1} = F x_k + L w_k per axis (L L' = Q), from ``init`` (n, D, 3)."""
        F, Q = singer(p.dt_s, p.singer_alpha_per_s, p.singer_sigma_m_s2)
        lam, V = np.linalg.eigh(Q)                          # a square root that tolerates a semi-definite Q
        L = V * np.sqrt(np.clip(lam, 0.0, None))
        n, K, D, _ = w.shape
        truth = np.empty((n, K, D, 3))
        x = init
        for k in range(K):                                  # over time; trials and axes batched
            truth[:, k] = x
            x = matvec(F, x) + matvec(L, w[:, k])
        return truth.reshape(n, K, 3 * D)

    def turn_rates(self, p, null: bool) -> np.ndarray:
        """(K,) the 'turn' profile's turn rate (rad/s) over each step: the maneuver's inside it."""
        omega = np.zeros(p.steps)
        if not null:
            start, end = self.maneuver_steps(p)
            omega[start:end] = np.deg2rad(p.turn_rate_deg_s)
        return omega

    def position_bound(self, p, model: KinematicModel, null: bool) -> np.ndarray:
        """(K,) the posterior Cramér-Rao bound on the position MSE (m^2) (:mod:`models.pcrb`),
        the same for every trial (the measurement is linear): the dynamics the truth follows,
        its known maneuver an input (the bound of an estimator that knows the profile).
        Piecewise: [p, v] per axis, F and Q of the DWNA model with ``process_noise_m_s2``;
        turn: [x, vx, y, vy] with the turn's F(Omega_k) per step, Q = 0; Singer: [p, v, a] per
        axis with Singer's F, Q. Prior: the scene's P0 on those components; J_z = H'H/sigma^2."""
        if p.profile == "singer":
            F_axis, Q_axis = singer(p.dt_s, p.singer_alpha_per_s, p.singer_sigma_m_s2)
            idx, per = list(range(3 * p.dims)), 3
        else:
            F_axis, Q_axis = cv(p.dt_s, p.process_noise_m_s2 if p.profile == "piecewise" else 0.0)
            idx, per = cv_components(p.dims), 2
        F = per_axis(F_axis, p.dims)
        if p.profile == "turn":
            F = np.stack([ct_transition(w, p.dt_s) for w in self.turn_rates(p, null)[:-1]])
        H = position_measurement(p.dims, per)
        Jz = np.broadcast_to(H.T @ H / model.noise_std_m ** 2, (1, p.steps, len(idx), len(idx)))
        bound = linear_dynamics_pcrb(model.P0[np.ix_(idx, idx)], F, per_axis(Q_axis, p.dims), Jz)[0]
        return position_mse_bound(bound, position_index(p.dims, per))

    def _turn_truth(self, p, init: np.ndarray, null: bool) -> np.ndarray:
        """(n, K, 6) states of the 'turn' profile from initial (n, 2, 2) [p, v] per axis: each
        step's transition the turn's F(Omega) inside the maneuver (none under the null), the
        CV transition (Omega = 0) elsewhere; the acceleration held over a step the turn's."""
        n, K = init.shape[0], p.steps
        omega = self.turn_rates(p, null)
        state = init.reshape(n, 4)                          # [x, vx, y, vy]
        out = np.empty((n, K, 2, 3))
        for k in range(K):                                  # over time; trials batched
            out[:, k, :, :2] = state.reshape(n, 2, 2)
            out[:, k, :, 2] = turn_acceleration(state[:, [1, 3]], omega[k])
            state = matvec(ct_transition(omega[k], p.dt_s), state)
        return out.reshape(n, K, 6)

    def _maneuver_truth(self, p, null: bool, n: int) -> tuple[np.ndarray, np.ndarray]:
        """(n, K) mask of the maneuver's steps and (n, O) onset steps (O = 1, or 0 without a maneuver)."""
        start, end = self.maneuver_steps(p)
        size = p.turn_rate_deg_s if p.profile == "turn" else _axis_values(p.maneuver_accel_m_s2, p.dims)
        present = not null and end > start and np.any(np.asarray(size) != 0)
        mask = np.zeros((n, p.steps), bool)
        if not present:
            return mask, np.zeros((n, 0), np.int64)
        mask[:, start:end] = True
        return mask, np.full((n, 1), start, np.int64)
