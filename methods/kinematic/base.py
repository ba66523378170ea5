"""What the kinematic trackers (``cv-kf``, ``ca-kf``, ``singer``,
``current-statistical``, ``vd-filter``, ``imm-cv-ca``) share: the scene check,
the models they run in the scenario's state space, and their output.

The scenario's state is ``[p, v, a]`` per axis (:mod:`models.kinematics`). A
tracker whose own state is ``[p, v]`` per axis (CV) reports the acceleration
as 0 with the variance its model gives the acceleration, sigma_a^2 (the
white acceleration of the DWNA model; uncorrelated with position and
velocity): the estimate stays in the scenario's state space, the covariance
stays positive definite, and the NEES over the full state counts the
acceleration error of a CV tracker against that variance.

Traces every kinematic tracker returns (docs/architecture.md, 'Tasks'):
``mode`` (n, K), the model in use (0 = low order / CV, 1 = high order / CA; an
IMM: the probability of its CA mode), and ``switch`` (n, K), 1.0 at a step
where a chi-square test decided a switch to the maneuver model, else 0.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from radarbench.bench.core import TRACKING, Batch, Method, TrackingOutput
from radarbench.methods.maneuver.base import KALMAN_RECURSION
from radarbench.models.kalman import LinearGaussianModel
from radarbench.bench.params import param
from radarbench.models.kinematics import (KinematicModel, ca, cv, cv_components, embed_cv, kinematic_model_of, per_axis,
                               position_measurement)

SIGMA_WHY = "from a millimetre per second squared to 100 g"


class KinematicTracker(Method):
    """Base of the trackers of kinematic scenes (those providing ``kinematic-model``,
    :mod:`bench.sweep.capabilities`); every one skips the steps a ragged batch does not have."""

    task = TRACKING
    needs = frozenset({"kinematic-model"})
    handles = frozenset({"valid-step-masks"})
    reference_trials: ClassVar[int | None] = 20
    #: the issue's goal: 50 times the per-trial filterpy loop
    perf_targets: ClassVar[dict] = {"*": {"speedup": 50.0}}

    def least_cost(self, batch: Batch, params, output) -> str:
        return KALMAN_RECURSION

    def run(self, batch: Batch, params) -> TrackingOutput:
        return self.track(batch, kinematic_model_of(batch.scene), params)

    def reference_run(self, batch: Batch, params) -> TrackingOutput:
        """The per-trial filterpy loop ``bench perf`` compares against."""
        return self.reference_track(batch, kinematic_model_of(batch.scene), params)

    def track(self, batch: Batch, model: KinematicModel, params) -> TrackingOutput:
        raise NotImplementedError

    def reference_track(self, batch: Batch, model: KinematicModel, params) -> TrackingOutput:
        raise NotImplementedError


def linear_model(model: KinematicModel, F_axis: np.ndarray, Q_axis: np.ndarray) -> LinearGaussianModel:
    """The filter model on every axis of ``model`` from a per-axis (F, Q), measuring positions."""
    per_axis_states = F_axis.shape[0]
    return LinearGaussianModel(F=per_axis(F_axis, model.dims), H=position_measurement(model.dims, per_axis_states),
                               Q=per_axis(Q_axis, model.dims), R=model.R)


def cv_model(model: KinematicModel, sigma_a: float) -> LinearGaussianModel:
    """The CV (DWNA) filter model on [p, v] per axis."""
    return linear_model(model, *cv(model.dt_s, sigma_a))


def ca_model(model: KinematicModel, sigma_j: float) -> LinearGaussianModel:
    """The CA (DWPA) filter model on [p, v, a] per axis."""
    return linear_model(model, *ca(model.dt_s, sigma_j))


def cv_ca_modes(model: KinematicModel, sigma_a: float, sigma_j: float) -> list[LinearGaussianModel]:
    """The CV mode (its acceleration outside the model: row and column zero,
    :func:`models.kinematics.embed_cv`) and the CA mode on [p, v, a] per axis: the two
    models a switching tracker (IMM, variable dimension) runs in one state space."""
    return [linear_model(model, *embed_cv(*cv(model.dt_s, sigma_a))), ca_model(model, sigma_j)]


def cv_noise_param(default: float):
    """The ``accel_noise_m_s2`` parameter of a tracker's CV model."""
    return param(default, "CV model: std sigma_a of the white acceleration (m/s^2)", ge=1e-3, le=1e3, why=SIGMA_WHY)


def ca_noise_param(default: float):
    """The ``accel_increment_m_s2`` parameter of a tracker's CA model."""
    return param(default, "CA model: std sigma_j of the acceleration increment over one step (m/s^2)",
                 ge=1e-3, le=1e3, why=SIGMA_WHY)


def cv_prior(model: KinematicModel) -> tuple[np.ndarray, np.ndarray]:
    """The scene's prior (x0, P0) restricted to [p, v] per axis."""
    idx = cv_components(model.dims)
    return model.x0[idx], model.P0[np.ix_(idx, idx)]


def pad_cv(x: np.ndarray, P: np.ndarray, dims: int, sigma_a: float) -> tuple[np.ndarray, np.ndarray]:
    """A CV estimate (..., 2 dims) and covariance (..., 2 dims, 2 dims) in the
    scenario's state (..., 3 dims): acceleration 0 with variance sigma_a^2 (module docstring)."""
    idx = cv_components(dims)
    d = 3 * dims
    x_full = np.zeros((*x.shape[:-1], d))
    x_full[..., idx] = x
    P_full = np.zeros((*P.shape[:-2], d, d))
    P_full[..., np.array(idx)[:, None], np.array(idx)[None, :]] = P
    acc = np.arange(2, d, 3)
    P_full[..., acc, acc] = sigma_a ** 2
    return x_full, P_full


def output(estimate: np.ndarray, covariance: np.ndarray, mode, switch=None) -> TrackingOutput:
    """A :class:`TrackingOutput` with the ``mode`` and ``switch`` traces (n, K):
    ``mode`` an array or a constant model index, ``switch`` zeros when None."""
    shape = estimate.shape[:2]
    mode = np.broadcast_to(np.asarray(mode, float), shape).copy()
    switch = np.zeros(shape) if switch is None else np.asarray(switch, float)
    covariance = np.broadcast_to(covariance, (*shape, *covariance.shape[-2:]))
    return TrackingOutput(estimate=estimate, covariance=covariance, traces={"mode": mode, "switch": switch})
