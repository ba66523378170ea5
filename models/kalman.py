"""The one batched linear Kalman filter of the project.

Every maneuver detector looks at the innovation of a reference linear filter
that the scenario supplies (a :class:`LinearGaussianFilter`, the detection
scene's ``reference_filter``; docs/architecture.md, 'Scenes'). This module
runs that filter over all Monte Carlo trials at once and whitens its
innovations; :func:`reference_innovations` is the same by a per-trial
filterpy loop (the oracle of the tests, the baseline of ``bench perf``).

Notation after Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to
Tracking and Navigation* (2001), sec. 5.2 (and the FilterPy names)::

    x_k = F x_{k-1} + w,   w ~ N(0, Q)
    z_k = H x_k + v,       v ~ N(0, R)

    nu_k = z_k - H x_k|k-1                 innovation
    S_k  = H P_k|k-1 H' + R                its covariance
    K_k  = P_k|k-1 H' S_k^-1               gain
    x_k|k = x_k|k-1 + K_k nu_k
    P_k|k = (I - K_k H) P_k|k-1 (I - K_k H)' + K_k R K_k'   (Joseph form)
    x_k+1|k = F x_k|k,   P_k+1|k = F P_k|k F' + Q

The covariance recursion of a linear filter does not depend on the data, so
``P``, ``S`` and ``K`` are computed once per step and shared by all trials;
only the state recursion carries the trial axis ``n``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from bench.core import require, require_arrays


@dataclass(frozen=True, eq=False)
class LinearGaussianModel:
    """A time-invariant linear-Gaussian state-space model (d states, m measured)."""

    #: (d, d) state transition
    F: np.ndarray
    #: (m, d) measurement matrix
    H: np.ndarray
    #: (d, d) process-noise covariance
    Q: np.ndarray
    #: (m, m) measurement-noise covariance
    R: np.ndarray

    def __post_init__(self) -> None:
        require_arrays(self, {"F": (None, None), "H": (None, None)})
        d, m = self.F.shape[0], self.H.shape[0]
        require_arrays(self, {"F": (d, d), "H": (m, d), "Q": (d, d), "R": (m, m)})

    @property
    def dim_x(self) -> int:
        return int(self.F.shape[0])

    @property
    def dim_z(self) -> int:
        return int(self.H.shape[0])


@dataclass(frozen=True, eq=False)
class LinearGaussianFilter:
    """A linear Kalman filter ready to run: its model and the prior of step 0
    (x_0|-1, P_0|-1; see :func:`kalman_filter`). What a maneuver-detection
    scenario hands to the innovation detectors (the detection scene's
    ``reference_filter``)."""

    #: the model the filter assumes (F, H, Q, R)
    model: LinearGaussianModel
    #: (n, d) prior mean of step 0 per trial, or (d,) shared by all trials
    x0: np.ndarray
    #: (d, d) prior covariance of step 0
    P0: np.ndarray

    def __post_init__(self) -> None:
        require(self, "model", isinstance(self.model, LinearGaussianModel), "a LinearGaussianModel")
        d = self.model.dim_x
        require(self, "x0", isinstance(self.x0, np.ndarray) and self.x0.ndim in (1, 2) and self.x0.shape[-1] == d,
                f"an array of shape (n, {d}) or ({d},)")
        require_arrays(self, {"P0": (d, d)})

    @property
    def dim_x(self) -> int:
        return self.model.dim_x

    @property
    def dim_z(self) -> int:
        return self.model.dim_z


@dataclass(frozen=True)
class KalmanResult:
    """Output of :func:`kalman_filter` (``n`` trials, ``K`` steps).

    x_prior : (n, K, d) predicted state x_k|k-1 (step 0: the given ``x0``)
    x_post  : (n, K, d) updated state x_k|k
    nu      : (n, K, m) innovation z_k - H x_k|k-1
    P_prior : (K, d, d) predicted covariance (shared by all trials)
    P_post  : (K, d, d) updated covariance
    S       : (K, m, m) innovation covariance
    gain    : (K, d, m) Kalman gain
    """

    x_prior: np.ndarray
    x_post: np.ndarray
    nu: np.ndarray
    P_prior: np.ndarray
    P_post: np.ndarray
    S: np.ndarray
    gain: np.ndarray


@dataclass(frozen=True)
class InnovationSequence:
    """What every detector consumes (:func:`innovations`).

    nu       : (n, K, m) innovation
    S        : (K, m, m) innovation covariance, S_k = L_k L_k' (Cholesky)
    whitened : (n, K, m) L_k^-1 nu_k, i.i.d. N(0, I) under a matched model
    nis      : (n, K) normalised innovation squared nu' S^-1 nu ~ chi2(m)
    """

    nu: np.ndarray
    S: np.ndarray
    whitened: np.ndarray
    nis: np.ndarray


def steady_state(model: LinearGaussianModel):
    """Steady-state ``(P_prior, P_post, S, K)`` of the filter.

    ``P_prior`` solves the discrete algebraic Riccati equation
    P = F P F' - F P H' (H P H' + R)^-1 H P F' + Q (Bar-Shalom et al. 2001,
    sec. 5.2.5). SciPy solves the control form, so the filter form is obtained
    with the transposes: ``solve_discrete_are(F', H', Q, R)``.
    """
    F, H, Q, R = model.F, model.H, model.Q, model.R
    P_prior = scipy.linalg.solve_discrete_are(F.T, H.T, Q, R)
    P_prior = 0.5 * (P_prior + P_prior.T)
    S, K, P_post = _update_covariance(P_prior, H, R)
    return P_prior, P_post, S, K


def _update_covariance(P, H, R):
    """S, K and the Joseph-form P_k|k from the prior covariance P."""
    S = H @ P @ H.T + R
    K = np.linalg.solve(S, H @ P).T          # P H' S^-1 (S is symmetric)
    I_KH = np.eye(P.shape[0]) - K @ H
    P_post = I_KH @ P @ I_KH.T + K @ R @ K.T
    return S, K, P_post


def covariance_sequence(model: LinearGaussianModel, P0: np.ndarray, steps: int):
    """The data-independent part of the filter, for ``steps`` steps.

    ``P0`` is the prior covariance of step 0. Returns ``(P_prior, P_post, S,
    K)`` with shapes ``(K, d, d), (K, d, d), (K, m, m), (K, d, m)``.
    """
    F, H, Q, R = model.F, model.H, model.Q, model.R
    d, m = model.dim_x, model.dim_z
    P_prior = np.empty((steps, d, d))
    P_post = np.empty((steps, d, d))
    S = np.empty((steps, m, m))
    K = np.empty((steps, d, m))
    P = np.asarray(P0, dtype=float)
    for k in range(steps):
        P_prior[k] = P
        S[k], K[k], P_post[k] = _update_covariance(P, H, R)
        P = F @ P_post[k] @ F.T + Q
    return P_prior, P_post, S, K


def kalman_filter(model: LinearGaussianModel, z: np.ndarray, x0: np.ndarray,
                  P0: np.ndarray) -> KalmanResult:
    """Run the filter on ``n`` trials of ``K`` measurements at once.

    Convention: ``x0`` (n, d) and ``P0`` (d, d) are the *prior* of step 0,
    x_0|-1 and P_0|-1. Step 0 updates with ``z[:, 0]`` directly, then predicts
    step 1, and so on. Starting from the steady-state prior
    (:func:`steady_state`) gives a constant gain and innovations that are
    stationary from step 0.

    z : (n, K, m) measurements; ``x0`` may also be a single (d,) shared by
    all trials. Returns a :class:`KalmanResult`.
    """
    z = np.asarray(z, dtype=float)
    n, steps, _ = z.shape
    F, H = model.F, model.H
    P_prior, P_post, S, K = covariance_sequence(model, P0, steps)

    x_prior = np.empty((n, steps, model.dim_x))
    x_post = np.empty_like(x_prior)
    nu = np.empty_like(z)
    x = np.broadcast_to(np.asarray(x0, dtype=float), (n, model.dim_x)).copy()
    for k in range(steps):
        x_prior[:, k] = x
        nu[:, k] = z[:, k] - x @ H.T
        x_post[:, k] = x + nu[:, k] @ K[k].T
        x = x_post[:, k] @ F.T
    return KalmanResult(x_prior=x_prior, x_post=x_post, nu=nu, P_prior=P_prior,
                        P_post=P_post, S=S, gain=K)


def whiten(nu: np.ndarray, S: np.ndarray):
    """``(whitened, nis)``: L^-1 nu with S = L L' per step, and nu' S^-1 nu."""
    L_inv = np.linalg.inv(np.linalg.cholesky(S))          # (K, m, m)
    whitened = np.einsum("kij,nkj->nki", L_inv, nu)
    nis = np.sum(whitened ** 2, axis=-1)
    return whitened, nis


def _sequence(nu: np.ndarray, S: np.ndarray) -> InnovationSequence:
    whitened, nis = whiten(nu, S)
    return InnovationSequence(nu=nu, S=S, whitened=whitened, nis=nis)


def innovations(filt: LinearGaussianFilter, z: np.ndarray) -> InnovationSequence:
    """Innovations of ``filt`` on measurements ``z`` (n, K, m), all trials at
    once (:func:`kalman_filter`), with their whitened form."""
    result = kalman_filter(filt.model, z, filt.x0, filt.P0)
    return _sequence(result.nu, result.S)


def reference_innovations(filt: LinearGaussianFilter, z: np.ndarray) -> InnovationSequence:
    """The same as :func:`innovations` by the per-trial filterpy loop
    (:func:`filterpy_innovations`): the reference implementation."""
    return _sequence(*filterpy_innovations(filt.model, z, filt.x0, filt.P0))


def filterpy_innovations(model: LinearGaussianModel, z: np.ndarray, x0: np.ndarray, P0: np.ndarray):
    """The reference: innovations by a per-trial, per-step filterpy ``KalmanFilter``
    loop, same conventions as :func:`kalman_filter` (update, then predict).
    Used by ``bench perf`` as the baseline and by the tests as the oracle
    (through :func:`reference_innovations`)."""
    from filterpy.kalman import KalmanFilter

    n, steps, m = z.shape
    x0 = np.broadcast_to(np.asarray(x0, float), (n, model.dim_x))
    nu, S = np.empty_like(z, dtype=float), np.empty((steps, m, m))
    for i in range(n):
        kf = KalmanFilter(dim_x=model.dim_x, dim_z=m)
        kf.F, kf.H, kf.Q, kf.R = model.F, model.H, model.Q, model.R
        kf.x, kf.P = x0[i].copy(), np.array(P0, float)
        for k in range(steps):
            kf.update(z[i, k])
            nu[i, k], S[k] = kf.y, kf.S
            kf.predict()
    return nu, S


# ------------------------------------------------ per-trial covariances (adaptive filters)
#
# An adaptive filter (model switching, an online Q) gives every trial its own
# F, Q and so its own P: the covariance recursion carries the trial axis. The
# two steps below are the recursion of the module docstring, batched over
# trials (leading axis n), with a scalar position measurement z = H x + v,
# H = e_0' (the first state component), the case of the AR-model tracker.


def update_first_component(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: float):
    """Kalman update of ``n`` trials with the scalar measurement of state component 0.

    x (n, d), P (n, d, d), z (n,), R the measurement-noise variance. With
    H = e_0': nu = z - x_0, S = P_00 + R, K = P e_0 / S, x+ = x + K nu,
    P+ = (I - K H) P (I - K H)' + K R K' (Joseph form). Returns
    ``(x+, P+, nu, S)``.
    """
    nu = z - x[:, 0]
    S = P[:, 0, 0] + R
    gain = P[:, :, 0] / S[:, None]                               # (n, d)
    I_KH = np.broadcast_to(np.eye(x.shape[1]), P.shape).copy()
    I_KH[:, :, 0] -= gain
    P_post = I_KH @ P @ I_KH.transpose(0, 2, 1) + R * gain[:, :, None] * gain[:, None, :]
    return x + gain * nu[:, None], 0.5 * (P_post + P_post.transpose(0, 2, 1)), nu, S


def predict_per_trial(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray):
    """x_k+1|k = F x_k|k, P_k+1|k = F P F' + Q, with per-trial F (n, d, d) and Q (n, d, d)."""
    return np.einsum("nij,nj->ni", F, x), F @ P @ F.transpose(0, 2, 1) + Q
