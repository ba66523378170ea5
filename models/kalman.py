r"""The one batched linear Kalman filter of the project.

Every maneuver detector looks at the innovation of a reference linear filter
that the scenario supplies (a :class:`LinearGaussianFilter`, the detection
scene's ``reference_filter``; docs/architecture.md, 'Scenes'). This module
runs that filter over all Monte Carlo trials at once and whitens its
innovations; :func:`reference_innovations` is the same by a per-trial
filterpy loop (the oracle of the tests, the baseline of ``bench perf``).

Notation after Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to
Tracking and Navigation* (2001), sec. 5.2 (and the FilterPy names):

$$
\begin{aligned}
x_k &= F x_{k-1} + w, & w &\sim \mathcal{N}(0, Q), \\
z_k &= H x_k + v, & v &\sim \mathcal{N}(0, R), \\
\nu_k &= z_k - H x_{k|k-1} & &\text{innovation}, \\
S_k &= H P_{k|k-1} H' + R & &\text{its covariance}, \\
K_k &= P_{k|k-1} H' S_k^{-1} & &\text{gain}, \\
x_{k|k} &= x_{k|k-1} + K_k \nu_k, \\
P_{k|k} &= (I - K_k H) P_{k|k-1} (I - K_k H)' + K_k R K_k' & &\text{Joseph form}, \\
x_{k+1|k} &= F x_{k|k}, \quad P_{k+1|k} = F P_{k|k} F' + Q.
\end{aligned}
$$

The covariance recursion of a linear filter does not depend on the data, so
``P``, ``S`` and ``K`` are computed once per step and shared by all trials;
only the state recursion carries the trial axis ``n``.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numba
import numpy as np
import scipy.linalg

from radarbench.bench.batched import inner, matvec
from radarbench.bench.core import require, require_arrays


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
    gain     : (K, d, m) the filter's gains K_k (shared by all trials), or None where
               not kept (the filterpy reference)
    """

    nu: np.ndarray
    S: np.ndarray
    whitened: np.ndarray
    nis: np.ndarray
    gain: np.ndarray | None = None


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


#: how many covariance sequences :func:`covariance_sequence` keeps (least recently used dropped first)
COVARIANCE_MEMO_SIZE = 64
_covariance_memo: OrderedDict = OrderedDict()


def covariance_sequence(model: LinearGaussianModel, P0: np.ndarray, steps: int):
    """The data-independent part of the filter, for ``steps`` steps.

    ``P0`` is the prior covariance of step 0. Returns ``(P_prior, P_post, S,
    K)`` with shapes ``(K, d, d), (K, d, d), (K, m, m), (K, d, m)`` (fresh
    arrays the caller may write).

    It depends on the model, ``P0`` and ``steps`` only, never on the data, so
    it is computed once per distinct (F, H, Q, R, P0, steps), keyed on their
    bytes, and kept in a small LRU memo: a sweep calls the filter once per
    chunk of trials with the same model (the fixed cost per call).
    """
    P0 = np.asarray(P0, dtype=float)
    key = (steps, *((a.shape, a.dtype.str, a.tobytes()) for a in (model.F, model.H, model.Q, model.R, P0)))
    found = _covariance_memo.get(key)
    if found is None:
        found = _covariance_memo[key] = _covariance_sequence(model, P0, steps)
        if len(_covariance_memo) > COVARIANCE_MEMO_SIZE:
            _covariance_memo.popitem(last=False)
    else:
        _covariance_memo.move_to_end(key)
    return tuple(a.copy() for a in found)


def _covariance_sequence(model: LinearGaussianModel, P0: np.ndarray, steps: int):
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


def kernel_array(a, dtype=float) -> np.ndarray:
    """``a`` as the compiled kernels take their arrays: C-contiguous and writeable, copied
    if it is not. Numba types a read-only array apart from a writeable one, so a read-only
    view (a prior shared by the trials, broadcast to (n, d): at n = 1 it is already
    contiguous and stays a view) would compile another specialisation of the kernel, on
    a batch's first call, inside a timed unit."""
    return np.require(a, dtype=dtype, requirements="CW")


def kalman_filter(model: LinearGaussianModel, z: np.ndarray, x0: np.ndarray,
                  P0: np.ndarray, valid: np.ndarray | None = None) -> KalmanResult:
    """Run the filter on ``n`` trials of ``K`` measurements at once.

    Convention: ``x0`` (n, d) and ``P0`` (d, d) are the *prior* of step 0,
    x_0|-1 and P_0|-1. Step 0 updates with ``z[:, 0]`` directly, then predicts
    step 1, and so on. Starting from the steady-state prior
    (:func:`steady_state`) gives a constant gain and innovations that are
    stationary from step 0.

    z : (n, K, m) measurements; ``x0`` may also be a single (d,) shared by
    all trials. ``valid`` (n, K) bool: the steps each trial has (a ragged batch,
    ``Scene.valid_steps``; None: every step), see :func:`masked_kalman_filter`.
    Returns a :class:`KalmanResult`.
    """
    if valid is not None:
        return masked_kalman_filter(model, z, x0, P0, valid)
    z = np.asarray(z, dtype=float)
    n, steps, _ = z.shape
    F, H = model.F, model.H
    P_prior, P_post, S, K = covariance_sequence(model, P0, steps)

    x0 = kernel_array(np.broadcast_to(np.asarray(x0, dtype=float), (n, model.dim_x)))
    x_prior, x_post, nu = _state_kernel(np.ascontiguousarray(z), x0, np.ascontiguousarray(F, dtype=float),
                                        np.ascontiguousarray(H, dtype=float), K)
    return KalmanResult(x_prior=x_prior, x_post=x_post, nu=nu, P_prior=P_prior,
                        P_post=P_post, S=S, gain=K)


@numba.njit(cache=True)
def _state_kernel(z, x0, F, H, gain):
    """The state recursion of :func:`kalman_filter`, trial by trial and step by step:
    ``nu_k = z_k - H x_k|k-1``, ``x_k|k = x_k|k-1 + K_k nu_k``, ``x_k+1|k = F x_k|k``
    (the module docstring). Each product is summed in index order, with no fused
    multiply-add, as :func:`bench.batched.matvec` does: a trial's numbers are the same
    bits whatever its batch, and the same as the NumPy loop this kernel replaced (one
    call per step was the filter's fixed cost). Returns x_prior, x_post
    (n, K, d) and nu (n, K, m)."""
    n, steps, m = z.shape
    d = F.shape[0]
    x_prior, x_post, nu = np.empty((n, steps, d)), np.empty((n, steps, d)), np.empty((n, steps, m))
    x = np.empty(d)
    for i in range(n):
        x[:] = x0[i]
        for k in range(steps):
            x_prior[i, k] = x
            for j in range(m):
                acc = H[j, 0] * x[0]
                for c in range(1, d):
                    acc += H[j, c] * x[c]
                nu[i, k, j] = z[i, k, j] - acc
            for a in range(d):
                acc = gain[k, a, 0] * nu[i, k, 0]
                for j in range(1, m):
                    acc += gain[k, a, j] * nu[i, k, j]
                x_post[i, k, a] = x[a] + acc
            for a in range(d):
                acc = F[a, 0] * x_post[i, k, 0]
                for c in range(1, d):
                    acc += F[a, c] * x_post[i, k, c]
                x[a] = acc
    return x_prior, x_post, nu


def masked_kalman_filter(model: LinearGaussianModel, z: np.ndarray, x0: np.ndarray, P0: np.ndarray,
                         valid: np.ndarray) -> KalmanResult:
    """:func:`kalman_filter` on a ragged batch (docs/architecture.md, 'Ragged batches'):
    at a step trial i does not have (``valid[i, k]`` False; its measurement may be NaN)
    the filter predicts only, x_k|k = x_k|k-1 and P_k|k = P_k|k-1, with nu NaN and a
    zero gain (S is still H P_k|k-1 H' + R). Which steps update differs per trial, so the
    covariances carry the trial axis: P_prior, P_post (n, K, d, d), S (n, K, m, m), gain
    (n, K, d, m). One compiled loop over trials and steps (:func:`_masked_kernel`) on the
    per-trial steps below: a trial's numbers do not depend on the others of its batch."""
    z = np.ascontiguousarray(z, dtype=float)
    x0 = np.broadcast_to(np.asarray(x0, dtype=float), (z.shape[0], model.dim_x))
    arrays = _masked_kernel(z, np.ascontiguousarray(valid, dtype=bool), kernel_array(x0),
                            np.ascontiguousarray(P0, dtype=float), *(np.ascontiguousarray(A, dtype=float)
                                                                     for A in (model.F, model.H, model.Q, model.R)))
    return KalmanResult(*arrays)


def whiten(nu: np.ndarray, S: np.ndarray):
    """``(whitened, nis)``: L^-1 nu with S = L L' per step, and nu' S^-1 nu."""
    L_inv = np.linalg.inv(np.linalg.cholesky(S))          # (K, m, m)
    whitened = matvec(L_inv, nu)
    nis = inner(whitened, whitened)
    return whitened, nis


def _sequence(nu: np.ndarray, S: np.ndarray, gain: np.ndarray | None = None) -> InnovationSequence:
    whitened, nis = whiten(nu, S)
    return InnovationSequence(nu=nu, S=S, whitened=whitened, nis=nis, gain=gain)


def innovations(filt: LinearGaussianFilter, z: np.ndarray) -> InnovationSequence:
    """Innovations of ``filt`` on measurements ``z`` (n, K, m), all trials at
    once (:func:`kalman_filter`), with their whitened form."""
    result = kalman_filter(filt.model, z, filt.x0, filt.P0)
    return _sequence(result.nu, result.S, result.gain)


def reference_innovations(filt: LinearGaussianFilter, z: np.ndarray) -> InnovationSequence:
    """The same as :func:`innovations` by the per-trial filterpy loop
    (:func:`filterpy_innovations`): the reference implementation."""
    return _sequence(*filterpy_innovations(filt.model, z, filt.x0, filt.P0))


def filterpy_steps(model: LinearGaussianModel, z: np.ndarray, x0: np.ndarray, P0: np.ndarray):
    """Per trial i and step k, a filterpy ``KalmanFilter`` just updated with
    ``z[i, k]`` (it predicts the next step when the caller has read it): yields
    ``(i, k, kf)``. The per-trial loop the references share."""
    from filterpy.kalman import KalmanFilter

    n, steps, m = z.shape
    x0 = np.broadcast_to(np.asarray(x0, float), (n, model.dim_x))
    for i in range(n):
        kf = KalmanFilter(dim_x=model.dim_x, dim_z=m)
        kf.F, kf.H, kf.Q, kf.R = model.F, model.H, model.Q, model.R
        kf.x, kf.P = x0[i].copy(), np.array(P0, float)
        for k in range(steps):
            kf.update(z[i, k])
            yield i, k, kf
            kf.predict()


def filterpy_innovations(model: LinearGaussianModel, z: np.ndarray, x0: np.ndarray, P0: np.ndarray):
    """The reference: innovations by a per-trial, per-step filterpy ``KalmanFilter``
    loop, same conventions as :func:`kalman_filter` (update, then predict).
    Used by ``bench perf`` as the baseline and by the tests as the oracle
    (through :func:`reference_innovations`)."""
    steps, m = z.shape[1:]
    nu, S = np.empty_like(z, dtype=float), np.empty((steps, m, m))
    for i, k, kf in filterpy_steps(model, z, x0, P0):
        nu[i, k], S[k] = kf.y, kf.S
    return nu, S


# ---------------------------------------------------------------- per-trial covariances
# Adaptive and switching filters (variable dimension, current statistical, IMM) change F,
# Q or the state per trial, so their covariances carry the trial axis. The same equations
# as above, one step at a time, batched over any leading axes (trials, modes).

def inverse_logdet(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(S^-1, log det S) of symmetric positive-definite matrices (..., m, m): one and
    two measured components (ranges, planar positions) in closed form, else
    ``numpy.linalg``."""
    m = S.shape[-1]
    if m == 1:
        return 1.0 / S, np.log(S[..., 0, 0])
    if m == 2:
        a, b, c, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
        det = a * d - b * c
        inv = np.stack([np.stack([d, -b], axis=-1), np.stack([-c, a], axis=-1)], axis=-2) / det[..., None, None]
        return inv, np.log(det)
    return np.linalg.inv(S), np.linalg.slogdet(S)[1]


# Kernels: one trial at a time in compiled loops. NumPy's stacked matmul and linalg make a
# call per small matrix, and a single BLAS product over the stack (vec(F P F') =
# (F kron F) vec P) is fast alone but multi-threaded, hundreds of times slower on a
# loaded machine; compiled loops over d <= 6 states stay fast and single-threaded.

@numba.njit(cache=True, inline="always")
def _product_into(A, B, out):
    """out = A @ B for small matrices."""
    for a in range(A.shape[0]):
        for b in range(B.shape[1]):
            acc = 0.0
            for c in range(A.shape[1]):
                acc += A[a, c] * B[c, b]
            out[a, b] = acc


@numba.njit(cache=True)
def small_inverse_into(S, S_inv):
    """S_inv = S^-1 of a small symmetric positive-definite matrix (closed form for one
    and two rows); returns log det S."""
    m = S.shape[0]
    if m == 1:
        S_inv[0, 0] = 1.0 / S[0, 0]
        return np.log(S[0, 0])
    if m == 2:
        det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
        S_inv[0, 0], S_inv[1, 1] = S[1, 1] / det, S[0, 0] / det
        S_inv[0, 1], S_inv[1, 0] = -S[0, 1] / det, -S[1, 0] / det
        return np.log(det)
    S_inv[:, :] = np.linalg.inv(S)
    return np.log(np.linalg.det(S))


@numba.njit(cache=True)
def predict_one(x, P, F, Q, u, x_out, P_out, FP):
    """One trial's prediction into x_out (d,), P_out (d, d): F x + u, F P F' + Q
    (symmetric by construction); FP (d, d) scratch."""
    d = x.shape[0]
    for a in range(d):
        acc = u[a]
        for b in range(d):
            acc += F[a, b] * x[b]
        x_out[a] = acc
    _product_into(F, P, FP)
    for a in range(d):
        for b in range(a, d):
            acc = 0.0
            for c in range(d):
                acc += FP[a, c] * F[b, c]
            value = acc + 0.5 * (Q[a, b] + Q[b, a])
            P_out[a, b] = value
            P_out[b, a] = value


@numba.njit(cache=True)
def update_one(x, P, z, H, R, x_out, P_out, nu, S, scratch):
    """One trial's Joseph-form update into x_out, P_out, nu (m,), S (m, m); ``scratch``
    from :func:`update_scratch`. Returns (NIS, log N(nu; 0, S))."""
    d, m = x.shape[0], z.shape[0]
    PHt, gain, A, AP, S_inv = scratch
    for a in range(d):
        for j in range(m):
            acc = 0.0
            for b in range(d):
                acc += P[a, b] * H[j, b]
            PHt[a, j] = acc
    for j in range(m):
        for l in range(m):
            acc = 0.5 * (R[j, l] + R[l, j])
            for a in range(d):
                acc += 0.5 * (H[j, a] * PHt[a, l] + H[l, a] * PHt[a, j])
            S[j, l] = acc
    logdet = small_inverse_into(S, S_inv)
    for j in range(m):
        acc = z[j]
        for a in range(d):
            acc -= H[j, a] * x[a]
        nu[j] = acc
    nis = 0.0
    for j in range(m):
        for l in range(m):
            nis += nu[j] * S_inv[j, l] * nu[l]
    _product_into(PHt, S_inv, gain)
    for a in range(d):
        acc = x[a]
        for j in range(m):
            acc += gain[a, j] * nu[j]
        x_out[a] = acc
    for a in range(d):                                              # A = I - K H
        for b in range(d):
            acc = 1.0 if a == b else 0.0
            for j in range(m):
                acc -= gain[a, j] * H[j, b]
            A[a, b] = acc
    _product_into(A, P, AP)
    for a in range(d):                                              # A P A' + K R K', symmetric
        for b in range(a, d):
            acc = 0.0
            for c in range(d):
                acc += AP[a, c] * A[b, c]
            for j in range(m):
                for l in range(m):
                    acc += gain[a, j] * R[j, l] * gain[b, l]
            P_out[a, b] = acc
            P_out[b, a] = acc
    return nis, -0.5 * (nis + logdet + m * np.log(2.0 * np.pi))


@numba.njit(cache=True)
def update_scratch(d, m):
    """Scratch arrays of :func:`update_one`: P H', gain, I - K H, (I - K H) P, S^-1."""
    return np.empty((d, m)), np.empty((d, m)), np.empty((d, d)), np.empty((d, d)), np.empty((m, m))


@numba.njit(cache=True)
def _masked_kernel(z, valid, x0, P0, F, H, Q, R):
    """:func:`masked_kalman_filter`, trial by trial and step by step: returns x_prior,
    x_post (n, K, d), nu (n, K, m), P_prior, P_post (n, K, d, d), S (n, K, m, m) and
    the gain (n, K, d, m), in :class:`KalmanResult`'s order."""
    n, K, m = z.shape
    d = x0.shape[1]
    x_prior, x_post, nu = np.empty((n, K, d)), np.empty((n, K, d)), np.full((n, K, m), np.nan)
    P_prior, P_post = np.empty((n, K, d, d)), np.empty((n, K, d, d))
    S, gain = np.empty((n, K, m, m)), np.zeros((n, K, d, m))
    x, P, FP, zero_u = np.empty(d), np.empty((d, d)), np.empty((d, d)), np.zeros(d)
    z_zero = np.zeros(m)
    scratch = update_scratch(d, m)
    for i in range(n):
        x[:], P[:, :] = x0[i], P0
        for k in range(K):
            x_prior[i, k], P_prior[i, k] = x, P
            if valid[i, k]:
                update_one(x, P, z[i, k], H, R, x_post[i, k], P_post[i, k], nu[i, k], S[i, k], scratch)
                gain[i, k] = scratch[1]
            else:                                       # predict only; S = H P H' + R all the same
                update_one(x, P, z_zero, H, R, x_post[i, k], P_post[i, k], nu[i, k], S[i, k], scratch)
                x_post[i, k], P_post[i, k], nu[i, k] = x, P, np.nan
            predict_one(x_post[i, k], P_post[i, k], F, Q, zero_u, x, P, FP)
    return x_prior, x_post, nu, P_prior, P_post, S, gain


@numba.njit(cache=True)
def _predict_kernel(x, P, F, Q, u):
    """x (n, d), P (n, d, d), F (n, d, d), Q (n, d, d) (any strides), u (n, d)."""
    n, d = x.shape
    x_out, P_out = np.empty((n, d)), np.empty((n, d, d))
    FP = np.empty((d, d))
    for i in range(n):
        predict_one(x[i], P[i], F[i], Q[i], u[i], x_out[i], P_out[i], FP)
    return x_out, P_out


@numba.njit(cache=True)
def _update_kernel(x, P, z, H, R):
    """x (n, d), P (n, d, d), z (n, m), H (m, d), R (m, m): the Joseph-form update;
    returns x, P, nu, S, NIS, log-likelihood."""
    n, d = x.shape
    m = z.shape[1]
    x_out, P_out = np.empty((n, d)), np.empty((n, d, d))
    nu_out, S_out = np.empty((n, m)), np.empty((n, m, m))
    nis_out, loglik_out = np.empty(n), np.empty(n)
    scratch = update_scratch(d, m)
    for i in range(n):
        nis_out[i], loglik_out[i] = update_one(x[i], P[i], z[i], H, R, x_out[i], P_out[i], nu_out[i], S_out[i],
                                               scratch)
    return x_out, P_out, nu_out, S_out, nis_out, loglik_out


def _stacked(a: np.ndarray, tail: int) -> np.ndarray:
    """``a`` with its leading axes flattened into one (the kernels' trial axis)."""
    return np.ascontiguousarray(a, dtype=float).reshape(-1, *a.shape[a.ndim - tail:])


def _per_trial(A: np.ndarray, lead: tuple, d: int, n: int) -> np.ndarray:
    """A (d, d) shared or (..., d, d) per trial as an (n, d, d) view (no copy when shared)."""
    return np.broadcast_to(A, (*lead, d, d)).reshape(-1, d, d) if A.ndim > 2 else np.broadcast_to(A, (n, d, d))


def predict_batched(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray, u: np.ndarray | None = None):
    """x_k+1|k = F x_k|k (+ u), P_k+1|k = F P_k|k F' + Q, over leading axes: x (..., d),
    P (..., d, d); F and Q (d, d) shared or per trial (..., d, d) (e.g. the AR tracker's
    per-trial coefficients); u (..., d) an additive input (e.g. B u) or None."""
    lead, d = x.shape[:-1], x.shape[-1]
    xs, Ps = _stacked(x, 1), _stacked(P, 2)
    Fs, Qs = (_per_trial(np.asarray(A, dtype=float), lead, d, len(xs)) for A in (F, Q))
    us = np.zeros_like(xs) if u is None else _stacked(np.broadcast_to(u, x.shape), 1)
    x_next, P_next = _predict_kernel(xs, Ps, Fs, Qs, us)
    return x_next.reshape(x.shape), P_next.reshape(P.shape)


@dataclass(frozen=True)
class BatchedUpdate:
    """Output of :func:`update_batched`: the updated state and covariance, the
    innovation nu (..., m), its covariance S (..., m, m), the NIS nu' S^-1 nu (...)
    and log N(nu; 0, S) (...), the mode likelihood of an IMM."""

    x: np.ndarray
    P: np.ndarray
    nu: np.ndarray
    S: np.ndarray
    nis: np.ndarray
    log_likelihood: np.ndarray


def update_batched(x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray, R: np.ndarray) -> BatchedUpdate:
    """The measurement update of the module docstring (Joseph form, FilterPy's
    ``KalmanFilter.update``) over leading axes: x (..., d), P (..., d, d), z (..., m)."""
    lead, m = x.shape[:-1], z.shape[-1]
    z = np.broadcast_to(z, (*lead, m))
    x_new, P_new, nu, S, nis, log_likelihood = _update_kernel(
        _stacked(x, 1), _stacked(P, 2), _stacked(z, 1), np.ascontiguousarray(H, dtype=float),
        np.ascontiguousarray(R, dtype=float))
    x_new, P_new, nu = x_new.reshape(x.shape), P_new.reshape(P.shape), nu.reshape(z.shape)
    S, nis, log_likelihood = S.reshape(*lead, m, m), nis.reshape(lead), log_likelihood.reshape(lead)
    return BatchedUpdate(x=x_new, P=P_new, nu=nu, S=S, nis=nis, log_likelihood=log_likelihood)


def update_where(x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray, R: np.ndarray,
                 valid: np.ndarray | None) -> BatchedUpdate:
    """:func:`update_batched` where ``valid`` (broadcast over the leading axes of ``x``)
    is True; elsewhere a step the trial does not have (a ragged batch): the state and
    covariance pass through (predict only), nu and the NIS are NaN and the
    log-likelihood 0 (no measurement, no evidence for any mode). S is H P H' + R
    either way. ``valid`` None: every trial, :func:`update_batched` itself."""
    if valid is None:
        return update_batched(x, P, z, H, R)
    lead = x.shape[:-1]
    valid = np.broadcast_to(np.asarray(valid, dtype=bool), lead)
    z = np.where(valid[..., None], np.broadcast_to(z, (*lead, z.shape[-1])), 0.0)    # no NaN in the kernel
    upd = update_batched(x, P, z, H, R)
    return BatchedUpdate(x=np.where(valid[..., None], upd.x, x), P=np.where(valid[..., None, None], upd.P, P),
                         nu=np.where(valid[..., None], upd.nu, np.nan), S=upd.S,
                         nis=np.where(valid, upd.nis, np.nan), log_likelihood=np.where(valid, upd.log_likelihood, 0.0))


def filterpy_track(model: LinearGaussianModel, z: np.ndarray, x0: np.ndarray, P0: np.ndarray):
    """The reference of a time-invariant tracker: per-trial, per-step filterpy
    ``KalmanFilter`` (update, then predict, as :func:`kalman_filter`); returns the
    updated states (n, K, d) and covariances (n, K, d, d)."""
    n, steps = z.shape[:2]
    xs, Ps = np.empty((n, steps, model.dim_x)), np.empty((n, steps, model.dim_x, model.dim_x))
    for i, k, kf in filterpy_steps(model, z, x0, P0):
        xs[i, k], Ps[i, k] = kf.x, kf.P
    return xs, Ps
