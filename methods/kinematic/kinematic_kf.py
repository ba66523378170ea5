"""Methods ``cv-kf``, ``ca-kf`` and ``singer``: single-model Kalman filters of
a kinematic target (the differential models the AR-model patent compares
against), batched over trials by :func:`models.kalman.kalman_filter`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import Batch, TrackingOutput
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.kinematic.base import (SIGMA_WHY, KinematicTracker, ca_model, ca_noise_param, cv_model, cv_noise_param,
                                    cv_prior, linear_model, output, pad_cv)
from radarbench.models.kalman import LinearGaussianModel, filterpy_track, kalman_filter
from radarbench.models.kinematics import KinematicModel, singer


class _LinearTracker(KinematicTracker):
    """A time-invariant Kalman filter: its covariances do not depend on the data,
    so they are computed once per step for all trials (:func:`models.kalman.kalman_filter`,
    docs/architecture.md, 'Performance'); the reference is the per-trial filterpy loop."""

    reference_name = "per-trial filterpy KalmanFilter loop"
    #: the model index the ``mode`` trace reports (0: low order, 1: high order)
    mode: int = 1

    def filter_model(self, model: KinematicModel, params) -> LinearGaussianModel:
        raise NotImplementedError

    def prior(self, model: KinematicModel) -> tuple[np.ndarray, np.ndarray]:
        return model.x0, model.P0

    def finish(self, x: np.ndarray, P: np.ndarray, model: KinematicModel, params) -> TrackingOutput:
        return output(x, P, self.mode)

    def track(self, batch: Batch, model: KinematicModel, params) -> TrackingOutput:
        res = kalman_filter(self.filter_model(model, params), batch.z, *self.prior(model),
                            valid=batch.scene.valid_steps)
        return self.finish(res.x_post, res.P_post, model, params)

    def reference_track(self, batch: Batch, model: KinematicModel, params) -> TrackingOutput:
        x, P = filterpy_track(self.filter_model(model, params), batch.z, *self.prior(model))
        return self.finish(x, P, model, params)


@register_method
class ConstantVelocityKF(_LinearTracker):
    r"""Constant-velocity Kalman filter (white-noise acceleration), batched over trials.

    Per axis, state $[p, v]'$ (discrete white-noise acceleration; Bar-Shalom, Li &
    Kirubarajan, *Estimation with Applications to Tracking and Navigation*,
    sec. 6.3.2):

    $$
    F = \begin{bmatrix} 1 & T \\ 0 & 1 \end{bmatrix}, \quad
    Q = \sigma_a^2\, g g', \quad g = [T^2/2,\ T]', \quad H = [1,\ 0],
    $$

    started from the scene's prior. Reported in the scenario's $[p, v, a]'$ state
    with $a = 0$ of variance $\sigma_a^2$ (:mod:`methods.kinematic.base`).
    Traces: ``mode`` 0, ``switch`` 0.
    """

    name = "cv-kf"
    mode = 0

    @dataclass(frozen=True)
    class Params:
        accel_noise_m_s2: float = cv_noise_param(1.0)

    def filter_model(self, model, params):
        return cv_model(model, params.accel_noise_m_s2)

    def prior(self, model):
        return cv_prior(model)

    def finish(self, x, P, model, params):
        return output(*pad_cv(x, P, model.dims, params.accel_noise_m_s2), self.mode)


@register_method
class ConstantAccelerationKF(_LinearTracker):
    r"""Constant-acceleration Kalman filter (Wiener-process acceleration), batched over trials.

    Per axis, state $[p, v, a]'$ (discrete Wiener-process acceleration; Bar-Shalom
    et al. 2001, sec. 6.3.3):

    $$
    F = \begin{bmatrix} 1 & T & T^2/2 \\ 0 & 1 & T \\ 0 & 0 & 1 \end{bmatrix}, \quad
    Q = \sigma_j^2\, g g', \quad g = [T^2/2,\ T,\ 1]', \quad H = [1,\ 0,\ 0],
    $$

    $\sigma_j$ the std of the acceleration increment over one step. Traces:
    ``mode`` 1, ``switch`` 0.
    """

    name = "ca-kf"

    @dataclass(frozen=True)
    class Params:
        accel_increment_m_s2: float = ca_noise_param(1.0)

    def filter_model(self, model, params):
        return ca_model(model, params.accel_increment_m_s2)


@register_method
class SingerKF(_LinearTracker):
    r"""Singer-model Kalman filter (zero-mean Markov acceleration), batched over trials.

    Singer, "Estimating optimal tracking filter performance for manned
    maneuvering targets" (IEEE Trans. AES, 1970), as in Li & Jilkov's survey
    part I, sec. 4.1: $\dot{a} = -\alpha a + w$, $E[w(t) w(t+\tau)] = 2 \alpha \sigma_m^2 \delta(\tau)$,
    state $[p, v, a]'$ per axis,

    $$
    F = \begin{bmatrix}
      1 & T & (\alpha T - 1 + e^{-\alpha T}) / \alpha^2 \\
      0 & 1 & (1 - e^{-\alpha T}) / \alpha \\
      0 & 0 & e^{-\alpha T}
    \end{bmatrix}
    $$

    and the exact $Q$ (Van Loan; :func:`models.kinematics.singer`). Traces: ``mode`` 1,
    ``switch`` 0.
    """

    name = "singer"

    @dataclass(frozen=True)
    class Params:
        alpha_per_s: float = param(0.1, "maneuver rate alpha = 1 / maneuver time constant (1/s)", ge=1e-4,
                                   le=100.0, why="time constants from 10 ms to about 3 h")
        sigma_m_s2: float = param(10.0, "acceleration std sigma_m (m/s^2)", ge=1e-3, le=1e3, why=SIGMA_WHY)

    def filter_model(self, model, params):
        return linear_model(model, *singer(model.dt_s, params.alpha_per_s, params.sigma_m_s2))
