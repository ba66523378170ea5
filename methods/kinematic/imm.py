"""Method ``imm-cv-ca``: the interacting multiple model (IMM) estimator with a
CV and a CA mode, batched over trials and modes."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numba
import numpy as np

from radarbench.bench.core import Batch, TrackingOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.kinematic.base import KinematicTracker, ca_noise_param, cv_ca_modes, cv_noise_param, output
from radarbench.models.kalman import LinearGaussianModel, kernel_array, predict_one, update_one, update_scratch
from radarbench.models.kinematics import KinematicModel
from radarbench.models.turn import ct_jacobian


@dataclass(frozen=True)
class IMMResult:
    """Output of :func:`imm_filter`: the combined estimate x (n, K, d) and covariance
    P (n, K, d, d) after each update, and the mode probabilities mu (n, K, r)."""

    x: np.ndarray
    P: np.ndarray
    mu: np.ndarray


def unreachable_mode(transition: np.ndarray, mu0: np.ndarray, names) -> str | None:
    """Why an IMM with this Markov chain fails, or None. Every mode must be reachable at
    the first step (c_bar = mu0 M > 0) and from every mode (the chain irreducible): once the
    data drive a mode's probability to zero (it underflows), a mode reachable only from it
    has c_bar_j = 0, its mixing weights omega_ij = M_ij mu_i / c_bar_j are 0/0 and the
    estimate turns NaN at every later step (an absorbing mode, or an identity matrix)."""
    M = np.asarray(transition, float) > 0
    first = np.asarray(mu0, float) @ np.asarray(transition, float) > 0
    if not first.all():
        return f"mode {names[int(np.argmin(first))]} is never reached from the initial probabilities"
    reach = M.copy()
    for _ in range(len(M)):                                 # transitive closure: k steps for r modes
        reach |= (reach.astype(int) @ M.astype(int)) > 0
    for i, row in enumerate(reach):
        if not row.all():
            j = int(np.argmin(row))
            return f"mode {names[j]} is never reached again once in mode {names[i]} (no path of non-zero " \
                   f"transitions; the filter's mixing weights are 0/0 once a mode's probability underflows)"
    return None


def transition_param(second: str):
    """The ``transition`` parameter of a two-mode IMM whose modes are CV and ``second``."""
    return param((0.95, 0.05, 0.05, 0.95), f"mode transition matrix, row by row: P(CV->CV), P(CV->{second}), "
                 f"P({second}->CV), P({second}->{second}); each row sums to 1", ge=0.0, le=1.0, min_len=4,
                 max_len=4, why="probabilities")


def initial_probabilities_param(second: str):
    """The ``initial_probabilities`` parameter of a two-mode IMM whose modes are CV and ``second``."""
    return param((0.9, 0.1), f"mode probabilities (CV, {second}) before the first step; they sum to 1", ge=0.0,
                 le=1.0, min_len=2, max_len=2, why="probabilities")


def check_markov_chain(transition: tuple[float, ...], initial: tuple[float, ...], names) -> None:
    """ConfigError naming the parameter (``transition``, ``initial_probabilities``) unless the
    r x r transition matrix (row by row) has rows summing to 1, the initial probabilities sum
    to 1 and every mode stays reachable (:func:`unreachable_mode`)."""
    r = len(names)
    rows = np.reshape(transition, (r, r)).sum(axis=1)
    if not np.allclose(rows, 1.0, atol=1e-9):
        raise ConfigError("transition", f"each row must sum to 1, got row sums {rows.tolist()}")
    if not np.isclose(sum(initial), 1.0, atol=1e-9):
        raise ConfigError("initial_probabilities", "must sum to 1")
    problem = unreachable_mode(np.reshape(transition, (r, r)), np.asarray(initial), names)
    if problem:
        raise ConfigError("transition", problem)


def imm_filter(models: list[LinearGaussianModel], transition: np.ndarray, mu0: np.ndarray, z: np.ndarray,
               x0: np.ndarray, P0: np.ndarray, valid: np.ndarray | None = None,
               turn: tuple[bool, ...] | None = None, dt: float = 0.0) -> IMMResult:
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
    ``IMMEstimator`` does when its ``update`` comes first. ``valid`` (n, K) bool: the
    steps each trial has (a ragged batch; None: all); at a missing step every mode
    predicts only and its likelihood is 1, so mu_j = c_bar_j (:func:`models.kalman.update_where`).
    ``turn`` (r,) bool (None: none): the modes that are coordinated turns with an unknown
    turn rate on the state [x, vx, y, vy, Omega] (:mod:`models.turn`): such a mode predicts
    as an EKF over ``dt`` (s), x_j = f(x0_j), P_j = J P0_j J' + Q_j with J the Jacobian at
    x0_j (its F is not used); its update is linear like every mode's.
    """
    n, K, _ = z.shape
    r, d = len(models), models[0].dim_x
    M = np.asarray(transition, float)
    with np.errstate(divide="ignore"):                          # a zero transition is log 0 = -inf
        log_M = np.log(M)
        log_cbar0 = np.log(np.asarray(mu0, float) @ M)
    stack = lambda name: np.ascontiguousarray([getattr(mode, name) for mode in models], dtype=float)  # noqa: E731
    x, P, mu = _imm_kernel(np.ascontiguousarray(z, dtype=float),
                           np.ones((n, K), bool) if valid is None else np.ascontiguousarray(valid, dtype=bool),
                           kernel_array(np.broadcast_to(np.asarray(x0, float), (n, d))),
                           np.ascontiguousarray(P0, dtype=float), stack("F"), stack("Q"),
                           np.ascontiguousarray(models[0].H, dtype=float), np.ascontiguousarray(models[0].R, dtype=float),
                           log_cbar0, log_M, np.zeros(r, bool) if turn is None else np.asarray(turn, bool),
                           float(dt))
    return IMMResult(x=x, P=P, mu=mu)


@numba.njit(cache=True, inline="always")
def _logsumexp_into(a, out):
    """log sum exp(a) of a (r,) vector, as NumPy computes it along an axis of r <= 8
    (in index order): the maximum (NaN if any), 0 where it is not finite."""
    top = a[0]
    for j in range(1, a.shape[0]):
        if not np.isnan(top) and (np.isnan(a[j]) or a[j] > top):
            top = a[j]
    if not np.isfinite(top):
        top = 0.0
    total = 0.0
    for j in range(a.shape[0]):
        total += np.exp(a[j] - top)
    out[0] = top + np.log(total)


@numba.njit(cache=True)
def _mixture_into(weights, X, P, x, P_mix):
    """One trial's Gaussian mixture (the sums in the order of the batched NumPy steps it replaced):
    weights (r,), X (r, d), P (r, d, d) into x (d,), P_mix (d, d)."""
    r, d = X.shape
    x[:] = 0.0
    P_mix[:, :] = 0.0
    for j in range(r):
        for a in range(d):
            x[a] += weights[j] * X[j, a]
    for j in range(r):
        w = weights[j]
        for a in range(d):
            da = X[j, a] - x[a]
            for b in range(a, d):
                value = w * (0.5 * (P[j, a, b] + P[j, b, a]) + da * (X[j, b] - x[b]))
                P_mix[a, b] += value
                if b != a:
                    P_mix[b, a] += value


@numba.njit(cache=True)
def _imm_kernel(z, valid, x0, P0, F, Q, H, R, log_cbar0, log_M, turn, dt):
    """:func:`imm_filter` trial by trial and step by step, every mode's update and
    prediction by :func:`models.kalman.update_one` / :func:`models.kalman.predict_one`;
    F, Q (r, d, d) per mode. The same operations in the same order as the batched NumPy
    steps it replaced (a per-step loop of a dozen calls was the fixed cost of a small
    batch), so the same bits; a ``turn`` mode predicts by
    :func:`models.turn.ct_jacobian`. Returns x (n, K, d), P (n, K, d, d), mu (n, K, r)."""
    n, K, m = z.shape
    r, d = F.shape[0], F.shape[1]
    xs, Ps, mus = np.empty((n, K, d)), np.empty((n, K, d, d)), np.empty((n, K, r))
    X, P = np.empty((r, d)), np.empty((r, d, d))
    X_upd, P_upd = np.empty((r, d)), np.empty((r, d, d))
    nu, S, scratch = np.empty(m), np.empty((m, m)), update_scratch(d, m)
    zero_u, FP = np.zeros(d), np.empty((d, d))
    log_cbar, log_mu, mu, lse = np.empty(r), np.empty(r), np.empty(r), np.empty(1)
    log_joint, omega, column = np.empty((r, r)), np.empty((r, r)), np.empty(r)
    x_mix, P_mix = np.empty(d), np.empty((d, d))
    for i in range(n):
        for j in range(r):
            X[j], P[j] = x0[i], P0
        log_cbar[:] = log_cbar0
        for k in range(K):
            for j in range(r):                      # mode-matched updates; a missing step: predict only, Lambda = 1
                if valid[i, k]:
                    log_lik = update_one(X[j], P[j], z[i, k], H, R, X_upd[j], P_upd[j], nu, S, scratch)[1]
                else:
                    X_upd[j], P_upd[j], log_lik = X[j], P[j], 0.0
                log_mu[j] = log_cbar[j] + log_lik
            _logsumexp_into(log_mu, lse)
            for j in range(r):
                mu[j] = np.exp(log_mu[j] - lse[0])
            _mixture_into(mu, X_upd, P_upd, xs[i, k], Ps[i, k])
            mus[i, k] = mu
            for a in range(r):                      # log M_ij mu_i
                log_mu_a = np.log(mu[a])
                for b in range(r):
                    log_joint[a, b] = log_mu_a + log_M[a, b]
            for b in range(r):
                column[:] = log_joint[:, b]
                _logsumexp_into(column, lse)
                log_cbar[b] = lse[0]
            for a in range(r):
                for b in range(r):
                    omega[a, b] = np.exp(log_joint[a, b] - log_cbar[b])
            for j in range(r):                      # mixing, then each mode's prediction
                column[:] = omega[:, j]
                _mixture_into(column, X_upd, P_upd, x_mix, P_mix)
                if turn[j]:                         # EKF prediction: J at the mixed estimate, then x = f(x)
                    f, J = ct_jacobian(x_mix, dt)
                    predict_one(x_mix, P_mix, J, Q[j], zero_u, X[j], P[j], FP)
                    X[j] = f
                else:
                    predict_one(x_mix, P_mix, F[j], Q[j], zero_u, X[j], P[j], FP)
    return xs, Ps, mus


def _turn_predict(kf, dt: float):
    """A FilterPy filter's ``predict`` replaced by the coordinated turn's EKF prediction
    (:func:`models.turn.ct_jacobian`): x = f(x), P = J P J' + Q."""
    def predict(u=None, B=None, F=None, Q=None):
        f, J = ct_jacobian(np.asarray(kf.x, float), dt)
        kf.P = J @ kf.P @ J.T + kf.Q
        kf.x = f
        kf.x_prior, kf.P_prior = kf.x.copy(), kf.P.copy()
    kf.predict = predict


def filterpy_imm(models: list[LinearGaussianModel], transition: np.ndarray, mu0: np.ndarray, z: np.ndarray,
                 x0: np.ndarray, P0: np.ndarray, turn: tuple[bool, ...] | None = None, dt: float = 0.0) -> IMMResult:
    """The reference: FilterPy's ``IMMEstimator`` per trial (update, then predict); a
    ``turn`` mode's filter predicts as the coordinated turn's EKF (:func:`imm_filter`)."""
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
            if turn is not None and turn[len(filters)]:
                _turn_predict(kf, dt)
            filters.append(kf)
        imm = IMMEstimator(filters, np.array(mu0, float), np.asarray(transition, float))
        for k in range(K):
            imm.update(z[i, k])
            xs[i, k], Ps[i, k], mus[i, k] = imm.x, imm.P, imm.mu
            imm.predict()
    return IMMResult(x=xs, P=Ps, mu=mus)


@register_method
class IMMCVCA(KinematicTracker):
    r"""IMM with a CV and a CA mode (transition matrix a parameter), batched over trials and modes.

    Modes on the scenario's $[p, v, a]'$ state per axis: CV (DWNA, $\sigma_a$; the
    acceleration not modelled: its row of $F$ and of $Q$ zero,
    :func:`models.kinematics.embed_cv`) and CA (DWPA, $\sigma_j$); the
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
        transition: tuple[float, ...] = transition_param("CA")
        initial_probabilities: tuple[float, ...] = initial_probabilities_param("CA")

        def validate(self) -> None:
            check_markov_chain(self.transition, self.initial_probabilities, ("CV", "CA"))

    @staticmethod
    def modes(model: KinematicModel, params) -> list[LinearGaussianModel]:
        """The CV and the CA mode on [p, v, a] per axis."""
        return cv_ca_modes(model, params.accel_noise_m_s2, params.accel_increment_m_s2)

    def _run(self, imm, batch: Batch, model: KinematicModel, params) -> TrackingOutput:
        res = imm(self.modes(model, params), np.reshape(params.transition, (2, 2)),
                  np.asarray(params.initial_probabilities), batch.z, model.x0, model.P0)
        return output(res.x, res.P, res.mu[..., 1])

    def track(self, batch, model, params):
        return self._run(partial(imm_filter, valid=batch.scene.valid_steps), batch, model, params)

    def reference_track(self, batch, model, params):
        return self._run(filterpy_imm, batch, model, params)
