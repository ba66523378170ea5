"""Kinematic trackers as they were computed before their compiled kernels:
batched NumPy steps over trials (and modes), one call per step. Kept as the kernels'
bit-for-bit oracles: the committed results were made by these steps.

* :func:`stepwise_imm_filter` — ``methods/kinematic/imm.py``'s ``imm_filter``;
* :func:`stepwise_current_statistical` — ``current-statistical``'s ``track``."""

from __future__ import annotations

import numba
import numpy as np

from radarbench.methods.kinematic.base import output
from radarbench.methods.kinematic.imm import IMMResult
from radarbench.models.kalman import LinearGaussianModel, predict_batched, update_where


@numba.njit(cache=True)
def _moments(weights: np.ndarray, X: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of a Gaussian mixture per trial: weights (n, r) over r components
    X (r, n, d), P (r, n, d, d): x = sum w_j x_j, P = sum w_j (P_j + (x_j - x)(x_j - x)')
    (compiled: NumPy would make a call per small matrix)."""
    r, n, d = X.shape
    x, P_mix = np.zeros((n, d)), np.zeros((n, d, d))
    for i in range(n):
        for j in range(r):
            for a in range(d):
                x[i, a] += weights[i, j] * X[j, i, a]
        for j in range(r):
            w = weights[i, j]
            for a in range(d):
                da = X[j, i, a] - x[i, a]
                for b in range(a, d):
                    value = w * (0.5 * (P[j, i, a, b] + P[j, i, b, a]) + da * (X[j, i, b] - x[i, b]))
                    P_mix[i, a, b] += value
                    if b != a:
                        P_mix[i, b, a] += value
    return x, P_mix


def _logsumexp(a: np.ndarray, axis: int) -> np.ndarray:
    """log sum exp(a) along ``axis`` (scipy's, without its overhead on small axes)."""
    top = np.max(a, axis=axis, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        return np.squeeze(top, axis) + np.log(np.sum(np.exp(a - top), axis=axis))


def stepwise_imm_filter(models: list[LinearGaussianModel], transition: np.ndarray, mu0: np.ndarray, z: np.ndarray,
                        x0: np.ndarray, P0: np.ndarray, valid: np.ndarray | None = None) -> IMMResult:
    """The IMM as the batched NumPy steps it was before its compiled kernel."""
    n, K, _ = z.shape
    r, d = len(models), models[0].dim_x
    H, R = models[0].H, models[0].R
    M = np.asarray(transition, float)
    X = np.broadcast_to(np.asarray(x0, float), (r, n, d)).copy()
    P = np.broadcast_to(np.asarray(P0, float), (r, n, d, d)).copy()
    log_cbar = np.broadcast_to(np.log(np.asarray(mu0, float) @ M), (n, r))
    xs, Ps, mus = np.empty((n, K, d)), np.empty((n, K, d, d)), np.empty((n, K, r))
    with np.errstate(divide="ignore"):                          # a zero transition is log 0 = -inf
        log_M = np.log(M)
    for k in range(K):
        upd = update_where(X, P, z[None, :, k], H, R, None if valid is None else valid[:, k])  # axes (r, n)
        log_mu = log_cbar + upd.log_likelihood.T                # (n, r)
        mu = np.exp(log_mu - _logsumexp(log_mu, axis=1)[:, None])
        xs[:, k], Ps[:, k] = _moments(mu, upd.x, upd.P)
        mus[:, k] = mu
        with np.errstate(divide="ignore"):
            log_joint = np.log(mu)[:, :, None] + log_M          # (n, i, j): log M_ij mu_i
        log_cbar = _logsumexp(log_joint, axis=1)                # (n, j)
        omega = np.exp(log_joint - log_cbar[:, None, :])         # (n, i, j)
        mixed = [_moments(np.ascontiguousarray(omega[:, :, j]), upd.x, upd.P) for j in range(r)]
        predicted = [predict_batched(x_j, P_j, mode.F, mode.Q) for (x_j, P_j), mode in zip(mixed, models)]
        X = np.stack([x_j for x_j, _ in predicted])
        P = np.stack([P_j for _, P_j in predicted])
    return IMMResult(x=xs, P=Ps, mu=mus)


def stepwise_current_statistical(self, batch, model, params):
    """``CurrentStatistical.track`` before its kernel (``self``: the method)."""
    F, Q_axes, U_axes = self._matrices(model, params)
    n, K, _ = batch.z.shape
    d, acc = F.shape[0], np.arange(2, F.shape[0], 3)
    xs, Ps, std = np.empty((n, K, d)), np.empty((n, K, d, d)), np.empty((n, K))
    x = np.broadcast_to(model.x0, (n, d)).copy()
    P = np.broadcast_to(model.P0, (n, d, d)).copy()
    valid = batch.scene.valid_steps
    for k in range(K):
        upd = update_where(x, P, batch.z[:, k], model.H, model.R, None if valid is None else valid[:, k])
        xs[:, k], Ps[:, k] = upd.x, upd.P
        a_bar = upd.x[:, acc]                                  # (n, dims): the current mean
        var = self._variance(a_bar, params)
        std[:, k] = np.sqrt(var[:, 0])
        x, P = predict_batched(upd.x, upd.P, F, np.einsum("nj,jab->nab", var, Q_axes), a_bar @ U_axes)
    out = output(xs, Ps, 1)
    out.traces["accel_std"] = std
    return out
