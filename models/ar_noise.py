r"""Autoregressive (AR) noise: stationarity, autocovariance, exact predictors.

Convention (the multi-frame DP-TBD paper's, and the ``tbd-grid`` scene's):

$$
v_k + a_1 v_{k-1} + \dots + a_P v_{k-P} = w_k, \qquad w_k \sim \mathcal{N}(0, \sigma_w^2) \text{ white}.
$$

The process is stationary when every root of the characteristic polynomial
$z^P + a_1 z^{P-1} + \dots + a_P$ lies strictly inside the unit circle
(:func:`ar_stationarity_problem`). Its stationary autocovariance
$\gamma(h) = E[v_k v_{k-h}]$ follows from the Yule-Walker equations
(:func:`ar_autocovariance`); the innovation scale $\sigma_w$ that gives a wanted
stationary variance $\gamma(0)$ is :func:`ar_innovation_std`. The first $P$ values
of a stationary path are jointly $\mathcal{N}(0, \Gamma_P)$ (Toeplitz of $\gamma(0), \dots, \gamma(P-1)$):
:func:`stationary_predictors` gives their prediction-error decomposition, used
both to draw a path that is stationary from its first value and to whiten one
exactly (Brockwell & Davis, *Time Series: Theory and Methods*, 2nd ed. 1991,
sec. 3.3 and 5.2).
"""

from __future__ import annotations

import functools

import numpy as np


def ar_roots(a) -> np.ndarray:
    """Roots of z^P + a1 z^(P-1) + ... + aP, the characteristic polynomial of
    v_k + a1 v_(k-1) + ... + aP v_(k-P) = w_k."""
    return np.roots(np.r_[1.0, np.asarray(a, float)])


def ar_stationarity_problem(a) -> str | None:
    """None if the AR model is stationary (all roots strictly inside the unit
    circle), else a one-line reason."""
    a = tuple(float(x) for x in a)
    radius = float(np.max(np.abs(ar_roots(a)))) if a else 0.0
    if radius < 1.0 - 1e-9:
        return None
    poly = f"z^{len(a)}"
    for i, c in enumerate(a, start=1):
        power = len(a) - i
        poly += f" {'-' if c < 0 else '+'} {abs(c):g}" + (f" z^{power}" if power > 1 else " z" if power else "")
    return (f"not stationary: {poly} (convention v_k + a1 v_(k-1) + ... + aP v_(k-P) = w_k) "
            f"has a root of modulus {radius:.4g} >= 1, so the noise would grow without bound")


@functools.lru_cache(maxsize=64)
def ar_autocovariance(a: tuple[float, ...], lags: int, variance: float = 1.0) -> np.ndarray:
    """Stationary autocovariance gamma(0..lags) of the AR(P) model, scaled so
    that gamma(0) = ``variance``.

    Multiplying v_k + sum_i a_i v_(k-i) = w_k by v_(k-h) and taking
    expectations gives, for h = 0..P, sum_(i=0..P) phi_i gamma(|h - i|) =
    sigma_w^2 delta_h (phi_0 = 1, phi_i = a_i): P + 1 linear equations for
    gamma(0..P) (Yule-Walker). Beyond P the same recursion without the
    right-hand side extends it: gamma(h) = -sum_i a_i gamma(h - i).
    Returned read-only (it is cached), as a float64 array of length ``lags + 1``.
    """
    P = len(a)
    phi = np.r_[1.0, np.asarray(a, float)]
    g = _yule_walker_unit(a)
    out = np.empty(max(lags, P) + 1)
    out[:P + 1] = g
    for h in range(P + 1, len(out)):
        out[h] = -np.dot(phi[1:], out[h - 1::-1][:P])
    out = out[:lags + 1] * (variance / g[0])
    out.setflags(write=False)
    return out


def ar_innovation_std(a: tuple[float, ...], variance: float = 1.0) -> float:
    """sigma_w giving a stationary variance ``variance``: gamma scales with
    sigma_w^2, and gamma(0) = g0 for sigma_w = 1."""
    return float(np.sqrt(variance / _yule_walker_unit(a)[0]))


def _yule_walker_unit(a: tuple[float, ...]) -> np.ndarray:
    """gamma(0..P) of the AR(P) model with sigma_w = 1 (the Yule-Walker system)."""
    P = len(a)
    phi = np.r_[1.0, np.asarray(a, float)]
    M = np.zeros((P + 1, P + 1))
    for h in range(P + 1):
        for i in range(P + 1):
            M[h, abs(h - i)] += phi[i]
    return np.linalg.solve(M, np.eye(P + 1)[0])


def stationary_predictors(a: tuple[float, ...], sigma: float = 1.0) -> list[tuple[np.ndarray, float]]:
    """Per frame k < P: (phi_k, nu_k) of the exact conditional law
    v_k | v_(k-1), ..., v_0 ~ N(sum_j phi_k[j-1] v_(k-j), nu_k) of the
    stationary process of standard deviation ``sigma``: phi_k solves
    Gamma_k phi_k = (gamma(1), ..., gamma(k)) (Gamma_k the k x k Toeplitz
    matrix of gamma(0..k-1)) and nu_k = gamma(0) - phi_k . (gamma(1), ...,
    gamma(k)) (the prediction-error decomposition of N(0, Gamma_P), i.e. its
    Cholesky factorisation). From frame P on the conditional law is the AR
    recursion itself: phi = -a, nu = sigma_w^2."""
    P = len(a)
    gamma = ar_autocovariance(tuple(a), P, sigma ** 2)
    out = [(np.zeros(0), float(gamma[0]))]
    for k in range(1, P):
        G = gamma[np.abs(np.subtract.outer(np.arange(k), np.arange(k)))]
        phi = np.linalg.solve(G, gamma[1:k + 1])
        out.append((phi, float(gamma[0] - phi @ gamma[1:k + 1])))
    return out
