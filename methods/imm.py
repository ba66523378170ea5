"""Method ``imm-cv-ca``: the interacting multiple model (IMM) estimator with a
CV and a CA mode, batched over trials and modes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.special

from bench.core import Batch, TrackingOutput
from bench.errors import ConfigError
from bench.params import param
from bench.registry import register_method
from methods._kinematic_base import KinematicTracker, ca_noise_param, cv_ca_modes, cv_noise_param, output
from models.kalman import LinearGaussianModel, predict_batched, update_batched
from models.kinematics import KinematicModel


@dataclass(frozen=True)
class IMMResult:
    """Output of :func:`imm_filter`: the combined estimate x (n, K, d) and covariance
    P (n, K, d, d) after each update, and the mode probabilities mu (n, K, r)."""

    x: np.ndarray
    P: np.ndarray
    mu: np.ndarray


def _moments(weights: np.ndarray, X: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of a Gaussian mixture: weights (..., r) over r components
    X (r, ..., d), P (r, ..., d, d): x = sum w_j x_j, P = sum w_j (P_j + (x_j - x)(x_j - x)')."""
    w = np.moveaxis(weights, -1, 0)
    x = np.einsum("r...,r...i->...i", w, X)
    dX = X - x
    P_mix = np.einsum("r...,r...ij->...ij", w, P + dX[..., :, None] * dX[..., None, :])
    return x, 0.5 * (P_mix + np.swapaxes(P_mix, -1, -2))


def imm_filter(models: list[LinearGaussianModel], transition: np.ndarray, mu0: np.ndarray, z: np.ndarray,
               x0: np.ndarray, P0: np.ndarray) -> IMMResult:
    """The IMM of Blom & Bar-Shalom (1988), in FilterPy's ``IMMEstimator`` order
    (Bar-Shalom, Li & Kirubarajan 2001, sec. 11.6.6), for all trials and modes at once.

    ``models``: r linear models on one state space (same H, R); ``transition``
    M (r, r), M_ij = P(mode j at k+1 | mode i at k); ``mu0`` (r,) the mode
    probabilities before step 0. Each step, with c_bar = mu_{k-1} M:

        mode-matched updates  x_j, P_j, Lambda_j = N(nu_j; 0, S_j)
        mu_j = c_bar_j Lambda_j / sum_i c_bar_i Lambda_i        (in logs: no underflow)
        combined  x = sum_j mu_j x_j,  P = sum_j mu_j (P_j + (x_j - x)(x_j - x)')
        mixing    omega_ij = M_ij mu_i / c_bar'_j,  c_bar' = mu M
                  x0_j = sum_i omega_ij x_i,  P0_j = sum_i omega_ij (P_i + (x_i - x0_j)(.)')
        prediction of each mode from (x0_j, P0_j) with its F_j, Q_j.

    Step 0 updates every mode from the prior (x0, P0) with c_bar = mu0 M, as
    ``IMMEstimator`` does when its ``update`` comes first.
    """
    n, K, _ = z.shape
    r, d = len(models), models[0].dim_x
    H, R = models[0].H, models[0].R
    F = np.stack([m.F for m in models])[:, None]                # (r, 1, d, d)
    Q = np.stack([m.Q for m in models])[:, None]
    M = np.asarray(transition, float)
    X = np.broadcast_to(np.asarray(x0, float), (r, n, d)).copy()
    P = np.broadcast_to(np.asarray(P0, float), (r, n, d, d)).copy()
    log_cbar = np.broadcast_to(np.log(np.asarray(mu0, float) @ M), (n, r))
    xs, Ps, mus = np.empty((n, K, d)), np.empty((n, K, d, d)), np.empty((n, K, r))
    with np.errstate(divide="ignore"):                          # a zero transition is log 0 = -inf
        log_M = np.log(M)
    for k in range(K):
        upd = update_batched(X, P, z[None, :, k], H, R)         # leading axes (r, n)
        log_mu = log_cbar + upd.log_likelihood.T                # (n, r)
        mu = np.exp(log_mu - scipy.special.logsumexp(log_mu, axis=1, keepdims=True))
        xs[:, k], Ps[:, k] = _moments(mu, upd.x, upd.P)
        mus[:, k] = mu
        with np.errstate(divide="ignore"):
            log_joint = np.log(mu)[:, :, None] + log_M          # (n, i, j): log M_ij mu_i
        log_cbar = scipy.special.logsumexp(log_joint, axis=1)   # (n, j)
        omega = np.exp(log_joint - log_cbar[:, None, :])         # (n, i, j)
        mixed = [_moments(omega[:, :, j], upd.x, upd.P) for j in range(r)]
        X = np.stack([m[0] for m in mixed])
        P = np.stack([m[1] for m in mixed])
        X, P = predict_batched(X, P, F, Q)
    return IMMResult(x=xs, P=Ps, mu=mus)


def filterpy_imm(models: list[LinearGaussianModel], transition: np.ndarray, mu0: np.ndarray, z: np.ndarray,
                 x0: np.ndarray, P0: np.ndarray) -> IMMResult:
    """The reference: FilterPy's ``IMMEstimator`` per trial (update, then predict)."""
    from filterpy.kalman import IMMEstimator, KalmanFilter

    n, K, m = z.shape
    d, r = models[0].dim_x, len(models)
    xs, Ps, mus = np.empty((n, K, d)), np.empty((n, K, d, d)), np.empty((n, K, r))
    for i in range(n):
        filters = []
        for model in models:
            kf = KalmanFilter(dim_x=d, dim_z=m)
            kf.F, kf.H, kf.Q, kf.R = model.F, model.H, model.Q, model.R
            kf.x, kf.P = np.array(x0, float), np.array(P0, float)
            filters.append(kf)
        imm = IMMEstimator(filters, np.array(mu0, float), np.asarray(transition, float))
        for k in range(K):
            imm.update(z[i, k])
            xs[i, k], Ps[i, k], mus[i, k] = imm.x, imm.P, imm.mu
            imm.predict()
    return IMMResult(x=xs, P=Ps, mu=mus)


@register_method
class IMMCVCA(KinematicTracker):
    """IMM with a CV and a CA mode (transition matrix a parameter), batched over trials and modes.

    Modes on the scenario's [p, v, a] state per axis: CV (DWNA, sigma_a; the
    acceleration not modelled: its row of F and of Q zero,
    :func:`models.kinematics.embed_cv`) and CA (DWPA, sigma_j); the
    estimator is :func:`imm_filter` (Blom & Bar-Shalom), FilterPy's
    ``IMMEstimator`` the reference. Both modes start from the scene's prior.
    Returns the combined estimate and covariance. Traces: ``mode`` the
    probability of the CA mode, ``switch`` 0 (an IMM makes no decision).
    """

    name = "imm-cv-ca"
    reference_name = "per-trial filterpy IMMEstimator loop"

    @dataclass(frozen=True)
    class Params:
        accel_noise_m_s2: float = cv_noise_param(1.0)
        accel_increment_m_s2: float = ca_noise_param(3.0)
        transition: tuple[float, ...] = param(
            (0.95, 0.05, 0.05, 0.95), "mode transition matrix, row by row: P(CV->CV), P(CV->CA), "
            "P(CA->CV), P(CA->CA); each row sums to 1", ge=0.0, le=1.0, min_len=4, max_len=4,
            why="probabilities")
        initial_probabilities: tuple[float, ...] = param(
            (0.9, 0.1), "mode probabilities (CV, CA) before the first step; they sum to 1", ge=0.0, le=1.0,
            min_len=2, max_len=2, why="probabilities")

        def validate(self) -> None:
            rows = np.reshape(self.transition, (2, 2)).sum(axis=1)
            if not np.allclose(rows, 1.0, atol=1e-9):
                raise ConfigError("transition", f"each row must sum to 1, got row sums {rows.tolist()}")
            if not np.isclose(sum(self.initial_probabilities), 1.0, atol=1e-9):
                raise ConfigError("initial_probabilities", "must sum to 1")
            if not (np.asarray(self.initial_probabilities) @ np.reshape(self.transition, (2, 2)) > 0).all():
                raise ConfigError("transition", "a mode can never be reached from the initial probabilities")

    @staticmethod
    def modes(model: KinematicModel, params) -> list[LinearGaussianModel]:
        """The CV and the CA mode on [p, v, a] per axis."""
        return cv_ca_modes(model, params.accel_noise_m_s2, params.accel_increment_m_s2)

    def _run(self, imm, batch: Batch, model: KinematicModel, params) -> TrackingOutput:
        res = imm(self.modes(model, params), np.reshape(params.transition, (2, 2)),
                  np.asarray(params.initial_probabilities), batch.z, model.x0, model.P0)
        return output(res.x, res.P, res.mu[..., 1])

    def track(self, batch, model, params):
        return self._run(imm_filter, batch, model, params)

    def reference_track(self, batch, model, params):
        return self._run(filterpy_imm, batch, model, params)
