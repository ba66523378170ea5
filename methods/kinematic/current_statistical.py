"""Method ``current-statistical``: Zhou's "current statistical" model with
adaptive acceleration variance, batched over trials."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from radarbench.bench.core import Batch, TrackingOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.kinematic.base import SIGMA_WHY, KinematicTracker, output
from radarbench.models.kalman import kernel_array, predict_one, update_one, update_scratch
from radarbench.models.kinematics import (KinematicModel, current_statistical_input, current_statistical_variance, per_axis,
                               singer)

AMAX_WHY = "from 0.1 m/s^2 to 100 g; above the largest acceleration the target can have"


def _axis_blocks(block: np.ndarray, dims: int) -> np.ndarray:
    """(dims, ...) the per-axis ``block`` placed on each axis alone: for a (3, 3)
    block, kron(E_jj, block); for a (3,) vector, its place in the stacked state."""
    eye = np.eye(dims)
    if block.ndim == 1:
        return np.stack([np.kron(eye[j], block) for j in range(dims)])
    return np.stack([np.kron(np.outer(eye[j], eye[j]), block) for j in range(dims)])


@register_method
class CurrentStatistical(KinematicTracker):
    r"""Current statistical model (Zhou & Kumar) with adaptive acceleration variance, batched over trials.

    Zhou Hongren & K. S. P. Kumar, "A 'current' statistical model and
    adaptive algorithm for estimating maneuvering targets" (1984), as in Li
    & Jilkov's survey part I, sec. 4.3 (the model the AR-model patent names
    as the non-zero-mean Markov model). Per axis, state $[p, v, a]'$: the
    acceleration is a first-order Markov process around the "current" mean
    $\bar{a}$, $\dot{a} = -\alpha (a - \bar{a}) + w$; discretised,
    $x_{k+1} = F x_k + U \bar{a} + w_k$ with the Singer $F(\alpha)$, $U$
    (:func:`models.kinematics.current_statistical_input`) and
    $Q = \sigma_a^2 Q_1(\alpha)$ (the Singer $Q$ for unit $\sigma$). The algorithm:
    $\bar{a}$ is the current acceleration estimate $a_{k|k}$, so the prediction is

    $$
    x_{k+1|k} = F x_{k|k} + U a_{k|k}, \qquad P_{k+1|k} = F P_{k|k} F' + Q_k
    $$

    (the CA prediction) with the adaptive variance

    $$
    \sigma_a^2 = \begin{cases}
      \frac{4 - \pi}{\pi} (a_{\max} - a_{k|k})^2 & a_{k|k} \ge 0 \\
      \frac{4 - \pi}{\pi} (a_{-\max} + a_{k|k})^2 & a_{k|k} < 0
    \end{cases}
    $$

    per axis ($a_{-\max}$: ``a_max_neg``; $a_{k|k}$ clipped to $[-a_{-\max}, a_{\max}]$ and
    the std held at ``accel_std_floor_m_s2``, ours, where the printed formula would
    give 0). Started from the scene's prior. Covariances depend on the data
    (through $Q_k$) and carry the trial axis. Traces: ``mode`` 1, ``switch`` 0,
    ``accel_std`` (n, K) the adaptive $\sigma_a$ of the first axis used to predict
    the next step.
    """

    name = "current-statistical"
    reference_name = "per-trial filterpy KalmanFilter loop (Q and B u set per step)"

    @dataclass(frozen=True)
    class Params:
        alpha_per_s: float = param(0.1, "maneuver rate alpha = 1 / maneuver time constant (1/s)", ge=1e-4,
                                   le=100.0, why="time constants from 10 ms to about 3 h")
        a_max_m_s2: float = param(50.0, "largest positive acceleration a_max (m/s^2)", ge=0.1, le=1e3,
                                  why=AMAX_WHY)
        a_max_neg_m_s2: float = param(50.0, "largest negative acceleration, as a magnitude a_-max (m/s^2)",
                                      ge=0.1, le=1e3, why=AMAX_WHY)
        accel_std_floor_m_s2: float = param(0.1, "smallest adaptive acceleration std (m/s^2), where the "
                                            "formula gives 0", ge=1e-3, le=1e3, why=SIGMA_WHY)

        def validate(self) -> None:
            if self.accel_std_floor_m_s2 > max(self.a_max_m_s2, self.a_max_neg_m_s2):
                raise ConfigError("accel_std_floor_m_s2", "above the largest acceleration")

    def _matrices(self, model: KinematicModel, params):
        """Stacked F (d, d), per-axis unit Q blocks (dims, d, d) and input columns (dims, d)."""
        F_axis, Q_unit = singer(model.dt_s, params.alpha_per_s, 1.0)
        U = current_statistical_input(model.dt_s, params.alpha_per_s)
        return per_axis(F_axis, model.dims), _axis_blocks(Q_unit, model.dims), _axis_blocks(U, model.dims)

    def _variance(self, a_bar: np.ndarray, params) -> np.ndarray:
        return current_statistical_variance(a_bar, params.a_max_m_s2, params.a_max_neg_m_s2,
                                            params.accel_std_floor_m_s2 ** 2)

    def track(self, batch: Batch, model: KinematicModel, params) -> TrackingOutput:
        F, Q_axes, U_axes = self._matrices(model, params)
        n, K, _ = batch.z.shape
        valid = batch.scene.valid_steps
        xs, Ps, std = _current_statistical_kernel(
            np.ascontiguousarray(batch.z, dtype=float), np.ones((n, K), bool) if valid is None else
            np.ascontiguousarray(valid, dtype=bool), kernel_array(np.broadcast_to(model.x0, (n, F.shape[0]))),
            np.ascontiguousarray(model.P0, dtype=float), np.ascontiguousarray(model.H, dtype=float),
            np.ascontiguousarray(model.R, dtype=float), kernel_array(F), Q_axes, U_axes, np.arange(2, F.shape[0], 3),
            float(params.a_max_m_s2), float(params.a_max_neg_m_s2), float(params.accel_std_floor_m_s2) ** 2)
        out = output(xs, Ps, 1)
        out.traces["accel_std"] = std
        return out

    def reference_track(self, batch: Batch, model: KinematicModel, params) -> TrackingOutput:
        from filterpy.kalman import KalmanFilter

        F, Q_axes, U_axes = self._matrices(model, params)
        n, K, m = batch.z.shape
        d, acc = F.shape[0], np.arange(2, F.shape[0], 3)
        xs, Ps = np.empty((n, K, d)), np.empty((n, K, d, d))
        for i in range(n):
            kf = KalmanFilter(dim_x=d, dim_z=m, dim_u=m)
            kf.F, kf.H, kf.R, kf.B = F, model.H, model.R, U_axes.T
            kf.x, kf.P = model.x0.copy(), model.P0.copy()
            for k in range(K):
                kf.update(batch.z[i, k])
                xs[i, k], Ps[i, k] = kf.x, kf.P
                a_bar = kf.x[acc]
                kf.Q = np.einsum("j,jab->ab", self._variance(a_bar, params), Q_axes)
                kf.predict(u=a_bar)
        return output(xs, Ps, 1)


@numba.njit(cache=True)
def _current_statistical_kernel(z, valid, x0, P0, H, R, F, Q_axes, U_axes, acc, a_max, a_max_neg, floor):
    """:meth:`CurrentStatistical.track` trial by trial and step by step: the update
    (:func:`models.kalman.update_one`; a missing step passes through), the adaptive
    variance per axis (:func:`models.kinematics.current_statistical_variance`, the same
    operations), Q_k = sum_j sigma_j^2 Q_j and u = sum_j a_bar_j U_j in axis order, and the
    prediction (:func:`models.kalman.predict_one`). One compiled loop instead of a dozen
    NumPy calls per step, the fixed cost of a small batch, with the same bits.
    Returns x, P after each update and the first axis's sigma_a (n, K)."""
    n, K, m = z.shape
    d, dims = F.shape[0], acc.shape[0]
    xs, Ps, std = np.empty((n, K, d)), np.empty((n, K, d, d)), np.empty((n, K))
    x, P, Q, u, FP = np.empty(d), np.empty((d, d)), np.empty((d, d)), np.empty(d), np.empty((d, d))
    nu, S, scratch, var = np.empty(m), np.empty((m, m)), update_scratch(d, m), np.empty(dims)
    scale = (4.0 - math.pi) / math.pi
    for i in range(n):
        x[:], P[:, :] = x0[i], P0
        for k in range(K):
            if valid[i, k]:
                update_one(x, P, z[i, k], H, R, xs[i, k], Ps[i, k], nu, S, scratch)
            else:
                xs[i, k], Ps[i, k] = x, P
            for j in range(dims):
                a = min(max(xs[i, k, acc[j]], -a_max_neg), a_max) if not np.isnan(xs[i, k, acc[j]]) else np.nan
                room = a_max - a if a >= 0.0 else a_max_neg + a
                v = scale * (room * room)
                var[j] = v if np.isnan(v) or v > floor else floor
            std[i, k] = np.sqrt(var[0])
            for a in range(d):
                acc_u = xs[i, k, acc[0]] * U_axes[0, a]
                for j in range(1, dims):
                    acc_u += xs[i, k, acc[j]] * U_axes[j, a]
                u[a] = acc_u
                for b in range(d):
                    acc_q = var[0] * Q_axes[0, a, b]
                    for j in range(1, dims):
                        acc_q += var[j] * Q_axes[j, a, b]
                    Q[a, b] = acc_q
            predict_one(xs[i, k], Ps[i, k], F, Q, u, x, P, FP)
    return xs, Ps, std
