"""Method ``imm-cv-ct``: the IMM estimator with a CV and a coordinated-turn (CT) mode of
unknown turn rate, on planar kinematic scenes, batched over trials and modes."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from radarbench.bench.core import Batch, TrackingOutput
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.kinematic.base import SIGMA_WHY, KinematicTracker, cv_noise_param, output
from radarbench.methods.kinematic.imm import (check_markov_chain, filterpy_imm, imm_filter, initial_probabilities_param,
                                              transition_param)
from radarbench.models.kalman import LinearGaussianModel
from radarbench.models.kinematics import KinematicModel, cv, per_axis, position_measurement
from radarbench.models.turn import TURN_RATE_INDEX, ct_noise

#: the CT state [x, vx, y, vy, Omega] within the scenario's [x, vx, ax, y, vy, ay]: its
#: position and velocity components
_KINEMATIC_INDEX = [0, 1, 3, 4]


def ct_measurement() -> np.ndarray:
    """H (2, 5): the positions x, y of [x, vx, y, vy, Omega]."""
    return np.hstack([position_measurement(2, 2), np.zeros((2, 1))])


def cv_mode(model: KinematicModel, sigma_a: float, sigma_omega: float) -> LinearGaussianModel:
    """The CV mode on [x, vx, y, vy, Omega]: DWNA per axis, the turn rate held as a random
    walk it does not use (so mixing keeps the CT mode's estimate of it)."""
    F_axis, Q_axis = cv(model.dt_s, sigma_a)
    F, Q = np.eye(5), np.zeros((5, 5))
    F[:4, :4], Q[:4, :4] = per_axis(F_axis, 2), per_axis(Q_axis, 2)
    Q[TURN_RATE_INDEX, TURN_RATE_INDEX] = (sigma_omega * model.dt_s) ** 2
    return LinearGaussianModel(F=F, H=ct_measurement(), Q=Q, R=model.R)


def ct_mode(model: KinematicModel, sigma_a: float, sigma_omega: float) -> LinearGaussianModel:
    """The CT mode: its F is the identity placeholder (the IMM predicts it by
    :func:`models.turn.ct_jacobian`), Q :func:`models.turn.ct_noise`."""
    return LinearGaussianModel(F=np.eye(5), H=ct_measurement(), Q=ct_noise(model.dt_s, sigma_a, sigma_omega),
                               R=model.R)


def ct_prior(model: KinematicModel, turn_rate_std_rad_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The scene's prior on [x, vx, y, vy] and Omega ~ N(0, std^2) independent of it."""
    x0, P0 = np.zeros(5), np.zeros((5, 5))
    x0[:4] = model.x0[_KINEMATIC_INDEX]
    P0[:4, :4] = model.P0[np.ix_(_KINEMATIC_INDEX, _KINEMATIC_INDEX)]
    P0[TURN_RATE_INDEX, TURN_RATE_INDEX] = turn_rate_std_rad_s ** 2
    return x0, P0


def to_scenario_state(x: np.ndarray, P: np.ndarray, sigma_a: float) -> tuple[np.ndarray, np.ndarray]:
    """[x, vx, y, vy, Omega] (..., 5) and its covariance to the scenario's [x, vx, ax, y, vy, ay]:
    the acceleration is the turn's, a = Omega (-vy, vx), its covariance T P T' by the Jacobian T
    plus the white acceleration sigma_a^2 both modes add (so the covariance stays definite)."""
    vx, vy, omega = x[..., 1], x[..., 3], x[..., TURN_RATE_INDEX]
    T = np.zeros((*x.shape[:-1], 6, 5))
    for row, col in zip((0, 1, 3, 4), range(4)):
        T[..., row, col] = 1.0
    T[..., 2, 3], T[..., 2, TURN_RATE_INDEX] = -omega, -vy           # ax = -Omega vy
    T[..., 5, 1], T[..., 5, TURN_RATE_INDEX] = omega, vx             # ay = Omega vx
    state = np.stack([x[..., 0], vx, -omega * vy, x[..., 2], vy, omega * vx], axis=-1)
    cov = T @ P @ np.swapaxes(T, -1, -2)
    cov[..., [2, 5], [2, 5]] += sigma_a ** 2
    return state, cov


@register_method
class IMMCVCT(KinematicTracker):
    r"""IMM with a CV and a coordinated-turn mode of unknown turn rate (EKF), batched over trials and modes.

    Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
    Navigation* (2001), sec. 11.7: both modes on $[x, v_x, y, v_y, \Omega]'$ (planar scenes,
    ``dims = 2``). CV: DWNA per axis ($\sigma_a$), $\Omega$ a random walk it does not use
    ($F_{\Omega\Omega} = 1$, $Q_{\Omega\Omega} = (\sigma_\Omega T)^2$), so the CT mode's estimate of the
    turn rate survives mixing. CT: the coordinated turn with $\Omega$ held over the step
    (:mod:`models.turn`, eq. 11.7.1-4), predicted as an EKF, $x \leftarrow f(x)$,
    $P \leftarrow J P J' + Q$ with the Jacobian $J$ at the mixed estimate; $Q$ a white
    acceleration $\sigma_a$ (DWNA) per axis and the turn-rate increment $\sigma_\Omega T$.
    Both modes measure the positions linearly, so the mode-matched updates, likelihoods,
    mixing and combination are :func:`imm_filter`'s (the IMM of ``imm-cv-ca``); FilterPy's
    ``IMMEstimator`` with the CT filter's ``predict`` replaced is the reference. Prior:
    the scene's on position and velocity, $\Omega \sim \mathcal{N}(0, \sigma_{\Omega,0}^2)$
    ($\sigma_{\Omega,0}$: ``initial_turn_rate_std_deg_s``). Reported in the scenario's state
    with the turn's acceleration $\Omega\, (-v_y, v_x)$ (:func:`to_scenario_state`). Traces:
    ``mode`` the CT mode's probability, ``switch`` 0.
    """

    name = "imm-cv-ct"
    reference_name = "per-trial filterpy IMMEstimator loop (CT predict replaced)"

    @dataclass(frozen=True)
    class Params:
        accel_noise_m_s2: float = cv_noise_param(1.0)
        turn_accel_noise_m_s2: float = param(1.0, "CT model: std of the white acceleration (m/s^2) beside "
                                             "the turn", ge=1e-3, le=1e3, why=SIGMA_WHY)
        turn_rate_noise_deg_s2: float = param(
            0.5, "std sigma_Omega of the turn rate's change per second, both modes (deg/s^2)", ge=1e-4, le=100.0,
            why="from a constant turn to a turn rate that changes by 100 deg/s in a second")
        initial_turn_rate_std_deg_s: float = param(
            3.0, "prior std of the turn rate (deg/s; 3 deg/s is an aircraft's standard rate turn)",
            ge=1e-3, le=360.0, why="a positive std up to a full circle per second")
        transition: tuple[float, ...] = transition_param("CT")
        initial_probabilities: tuple[float, ...] = initial_probabilities_param("CT")

        def validate(self) -> None:
            check_markov_chain(self.transition, self.initial_probabilities, ("CV", "CT"))

    def check_scenario(self, params, scenario_params) -> str | None:
        dims = getattr(scenario_params, "dims", 2)
        return None if dims == 2 else f"a coordinated turn needs planar positions (dims = 2), the scene has {dims}"

    @staticmethod
    def modes(model: KinematicModel, params) -> list[LinearGaussianModel]:
        sigma_omega = np.deg2rad(params.turn_rate_noise_deg_s2)
        return [cv_mode(model, params.accel_noise_m_s2, sigma_omega),
                ct_mode(model, params.turn_accel_noise_m_s2, sigma_omega)]

    def _run(self, imm, batch: Batch, model: KinematicModel, params) -> TrackingOutput:
        if model.dims != 2:
            raise ValueError(f"imm-cv-ct: a coordinated turn needs a planar scene (dims = 2), got {model.dims}")
        x0, P0 = ct_prior(model, np.deg2rad(params.initial_turn_rate_std_deg_s))
        res = imm(self.modes(model, params), np.reshape(params.transition, (2, 2)),
                  np.asarray(params.initial_probabilities), batch.z, x0, P0, turn=(False, True), dt=model.dt_s)
        x, P = to_scenario_state(res.x, res.P, params.accel_noise_m_s2)
        return output(x, P, res.mu[..., 1])

    def track(self, batch, model, params):
        return self._run(partial(imm_filter, valid=batch.scene.valid_steps), batch, model, params)

    def reference_track(self, batch, model, params):
        return self._run(filterpy_imm, batch, model, params)
