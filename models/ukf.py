r"""The unscented transform and Kalman update of the project's UKF (compiled, one track at a time).

After the HFSWR tracking chapter ("目标检测与跟踪方法 (Target detection and
tracking methods), 海洋遥感技术应用"), section 2(2), "UKF 预测" / "UKF 更新"
(UKF prediction and update, eqs. 6.75 onwards), with the scaled sigma points
of Wan & van der Merwe (FilterPy's ``MerweScaledSigmaPoints``, the oracle of
the tests). The chapter's text describes each step; its equation images did
not survive in our copy, so the formulas below are the standard ones those
sentences name, in the chapter's symbols where it gives them. Sigma points
(eq. 6.75, scale $\zeta$; $\sqrt{P}$ the lower Cholesky factor, $[\cdot]_i$ its $i$-th column)
and unscented weights $\omega$:

$$
\begin{aligned}
\chi_0 &= x, \quad \chi_i = x + \zeta [\sqrt{P}]_i, \quad \chi_{n+i} = x - \zeta [\sqrt{P}]_i
  \quad (i = 1, \dots, n), \\
\lambda &= \alpha^2 (n + \kappa) - n, \quad \zeta = \sqrt{n + \lambda}, \\
\omega_0^m &= \frac{\lambda}{n + \lambda}, \quad \omega_0^c = \omega_0^m + 1 - \alpha^2 + \beta,
  \quad \omega_i^m = \omega_i^c = \frac{1}{2 (n + \lambda)}.
\end{aligned}
$$

Prediction ("通过状态转移方程传递 sigma 点 ... 引入状态噪声的协方差矩阵"):

$$
\chi_i^- = f(\chi_i), \quad x^- = \sum_i \omega_i^m \chi_i^-, \quad
P^- = \sum_i \omega_i^c (\chi_i^- - x^-)(\chi_i^- - x^-)' + Q_k.
$$

The sigma points are redrawn from $(x^-, P^-)$ ("考虑到状态噪声的影响, 利用传递状态及
状态协方差估计对 sigma 点重新估计"), then go through the measurement equation, and the
update with the $i$-th validated plot $z(i)$ is Kalman's ("利用经典卡尔曼滤波的更新过程"):

$$
\begin{aligned}
Z_i &= h(\chi_i), \quad \hat{z} = \sum_i \omega_i^m Z_i, \quad
S = \sum_i \omega_i^c (Z_i - \hat{z})(Z_i - \hat{z})' + R, \\
P_{xz} &= \sum_i \omega_i^c (\chi_i - x^-)(Z_i - \hat{z})', \\
K &= P_{xz} S^{-1}, \quad x(i) = x^- + K (z(i) - \hat{z}), \quad P(i) = P^- - K S K'.
\end{aligned}
$$

FilterPy's ``UnscentedKalmanFilter.update`` reuses the propagated points
$\chi_i^-$ instead of redrawing them; the tests set its ``sigmas_f`` to the redrawn
points to follow the chapter. An angle component of $Z$ (the azimuth) is averaged
through its differences from $Z_0$ (:func:`unscented_mean`), so a plot near the
$\pm\pi$ cut is handled.

Everything here is a numba function on one track's arrays, called from the
trackers' compiled scan loop (``methods/multitarget/kernels.py``); :func:`merwe_weights`
is plain NumPy (computed once per run). docs/architecture.md, 'Models'.
"""

from __future__ import annotations

import math

import numba
import numpy as np


def merwe_weights(n: int, alpha: float, beta: float, kappa: float):
    """``(Wm, Wc, zeta)``: the scaled unscented weights (2n+1,) and the sigma
    point scale ζ = √(n + λ), λ = α²(n + κ) − n (Wan & van der Merwe)."""
    lam = alpha * alpha * (n + kappa) - n
    Wm = np.full(2 * n + 1, 0.5 / (n + lam))
    Wc = Wm.copy()
    Wm[0] = lam / (n + lam)
    Wc[0] = lam / (n + lam) + 1.0 - alpha * alpha + beta
    return Wm, Wc, math.sqrt(n + lam)


@numba.njit(cache=True)
def cholesky_lower(P, L):  # pragma: no cover - compiled
    """Lower Cholesky factor of the symmetric ``P`` (n, n) into ``L``; False
    if ``P`` is not positive definite (a pivot ≤ 0)."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1):
            s = P[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if s <= 0.0:
                    return False
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
        for j in range(i + 1, n):
            L[i, j] = 0.0
    return True


@numba.njit(cache=True)
def sigma_points(x, P, zeta, L, chi):  # pragma: no cover - compiled
    """χ (2n+1, n) of eq. 6.75: x, x ± ζ [√P]_i. ``L`` (n, n) is scratch for
    the Cholesky factor. False if ``P`` is not positive definite."""
    n = x.shape[0]
    if not cholesky_lower(P, L):
        return False
    for d in range(n):
        chi[0, d] = x[d]
    for i in range(n):
        for d in range(n):
            chi[1 + i, d] = x[d] + zeta * L[d, i]
            chi[1 + n + i, d] = x[d] - zeta * L[d, i]
    return True


@numba.njit(cache=True)
def unscented_mean(Y, Wm, angle, mean):  # pragma: no cover - compiled
    """mean = Σ ω_i^m Y_i; the component ``angle`` (−1: none) is averaged
    through its differences from Y_0 wrapped to (−π, π] and wrapped back."""
    m = Y.shape[1]
    for d in range(m):
        if d == angle:
            s = 0.0
            for i in range(Y.shape[0]):
                s += Wm[i] * wrap(Y[i, d] - Y[0, d])
            mean[d] = wrap(Y[0, d] + s)
        else:
            s = 0.0
            for i in range(Y.shape[0]):
                s += Wm[i] * Y[i, d]
            mean[d] = s


@numba.njit(cache=True)
def unscented_covariance(Y, ymean, X, xmean, Wc, angle, out):  # pragma: no cover - compiled
    """out = Σ ω_i^c (X_i − x̄)(Y_i − ȳ)' (X = Y: the covariance); the
    component ``angle`` of Y's deviations is wrapped (X's never are)."""
    p, q = X.shape[1], Y.shape[1]
    out[:, :] = 0.0
    for i in range(Y.shape[0]):
        for a in range(p):
            dx = X[i, a] - xmean[a]
            for b in range(q):
                dy = Y[i, b] - ymean[b]
                if b == angle:
                    dy = wrap(dy)
                out[a, b] += Wc[i] * dx * dy


@numba.njit(cache=True, inline="always")
def wrap(a):  # pragma: no cover - compiled
    """An angle wrapped to (−π, π] (as :func:`models.spherical.wrap_angle`)."""
    w = (a + math.pi) % (2.0 * math.pi) - math.pi
    return math.pi if w == -math.pi else w


@numba.njit(cache=True)
def inverse_and_logdet(S, Sinv):  # pragma: no cover - compiled
    """S⁻¹ into ``Sinv`` and log det S of a symmetric positive-definite
    ``S`` (m, m) by its Cholesky factor; −inf log det if S is not positive definite."""
    m = S.shape[0]
    L = np.zeros((m, m))
    if not cholesky_lower(S, L):
        return -np.inf
    logdet = 0.0
    for i in range(m):
        logdet += 2.0 * math.log(L[i, i])
    Linv = np.zeros((m, m))                 # L⁻¹ by forward substitution
    for c in range(m):
        for i in range(m):
            s = 1.0 if i == c else 0.0
            for k in range(i):
                s -= L[i, k] * Linv[k, c]
            Linv[i, c] = s / L[i, i]
    for i in range(m):                      # S⁻¹ = L⁻ᵀ L⁻¹
        for j in range(m):
            s = 0.0
            for k in range(max(i, j), m):
                s += Linv[k, i] * Linv[k, j]
            Sinv[i, j] = s
    return logdet


@numba.njit(cache=True)
def kalman_gain(Pxz, Sinv):  # pragma: no cover - compiled
    """K = P_xz S⁻¹ (n, m)."""
    return Pxz @ Sinv


@numba.njit(cache=True)
def updated_covariance(P, K, S):  # pragma: no cover - compiled
    """P(i) = P⁻ − K S K' (the same for every validated plot), symmetrised."""
    out = P - K @ S @ K.T
    return 0.5 * (out + out.T)
