"""Method ``huber-ekf``: the Huber M-estimator extended Kalman filter, the classical
robust baseline of the ``glint`` scenario (batched over trials)."""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.stats

from radarbench.bench.batched import inner, matmul, matvec
from radarbench.bench.core import TRACKING, Batch, Method, TrackingOutput
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.glint.ekf import ekf_filter, noise_covariance
from radarbench.models.glint import glint_model_of

#: the largest contamination Huber's equation is solved for: at eps -> 1 the threshold c -> 0
#: and every residual's weight c/|r| -> 0 (no measurement is trusted)
MAX_EPSILON = 0.999


@functools.lru_cache(maxsize=64)
def minimax_threshold(epsilon: float) -> float:
    """Huber's minimax threshold c for the eps-contaminated normal (1 - eps) N(0, 1) + eps H
    (Huber, "Robust estimation of a location parameter", Ann. Math. Stat. 35, 1964, sec. 4):
    the root of 2 phi(c)/c - 2 Phi(-c) = eps/(1 - eps); inf at eps = 0 (no contamination:
    the least-squares estimate, every weight 1)."""
    if epsilon <= 0.0:
        return math.inf
    target = min(epsilon, MAX_EPSILON) / (1.0 - min(epsilon, MAX_EPSILON))
    excess = lambda c: 2.0 * scipy.stats.norm.pdf(c) / c - 2.0 * scipy.stats.norm.cdf(-c) - target  # noqa: E731
    return float(scipy.optimize.brentq(excess, 1e-8, 40.0, xtol=1e-14))


def huber_weights(r: np.ndarray, c: float) -> np.ndarray:
    """psi(r)/r of Huber's rho: 1 for |r| <= c, c/|r| beyond."""
    return np.minimum(1.0, c / np.maximum(np.abs(r), 1e-300))


def huber_rho(r: np.ndarray, c: float) -> np.ndarray:
    """Huber's rho: r^2/2 for |r| <= c, c |r| - c^2/2 beyond."""
    a = np.abs(r)
    return np.where(a <= c, 0.5 * r * r, c * a - 0.5 * c * c)


def clipping_patterns(m: int) -> np.ndarray:
    """(3^m, m) every assignment of m residuals to -1 (clipped below -c), 0 (inside), +1
    (clipped above c), the all-inside one first."""
    return np.array(list(itertools.product((0.0, -1.0, 1.0), repeat=m)))


def huber_reweigh(c: float):
    """The ``reweigh`` of :func:`methods.glint.ekf.ekf_filter` for Huber's threshold ``c``:
    the weighted covariance R W^-1 at the M-estimate of the linearised update (class docstring).

    The objective is strictly convex and quadratic on each region where every residual's
    side (below -c, inside, above c) is fixed: for a pattern s_i in {-1, 0, +1} its
    stationary point solves (P^-1 + sum_(s_i = 0) H_i' H_i / sigma_i^2) d =
    sum_(s_i = 0) H_i' nu_i / sigma_i^2 + sum_(s_i != 0) H_i' c s_i / sigma_i, and the pattern
    of the minimum gives the minimum. With m <= 3 measured components all 3^m patterns are
    solved at once and the one whose point has the least objective kept: the exact
    M-estimate (reweighting converges to it only linearly, Newton's method on the pattern can
    cycle). At it, d = K nu with K the gain for R W^-1, w_i = psi(r_i)/r_i = min(1, c/|r_i|),
    which is returned."""

    def reweigh(nu: np.ndarray, H: np.ndarray, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        if math.isinf(c):
            return np.broadcast_to(R, (len(nu), *R.shape))
        sigma = np.sqrt(np.diag(R))
        P_inv = np.linalg.inv(P)
        Hs = H / sigma[:, None]                                     # rows H_i / sigma_i
        Hs_t = Hs.transpose(0, 2, 1)
        patterns = clipping_patterns(nu.shape[-1])[:, None, :]      # (3^m, 1, m)
        inside = (patterns == 0.0).astype(float)
        info = P_inv + matmul(Hs_t, inside[..., None] * Hs)          # (3^m, n, d, d)
        pull = inside * nu / sigma + c * patterns                   # (3^m, n, m)
        delta = np.linalg.solve(info, matvec(Hs_t, pull)[..., None])[..., 0]
        r = (nu - matvec(H, delta)) / sigma
        cost = huber_rho(r, c).sum(axis=-1) + 0.5 * inner(delta, matvec(P_inv, delta))
        best = np.argmin(cost, axis=0)                              # (n,)
        r_best = np.take_along_axis(r, best[None, :, None], axis=0)[0]
        return R / huber_weights(r_best, c)[:, :, None]

    return reweigh


@register_method
class HuberEKF(Method):
    r"""Huber M-estimator EKF on the glint noise's ε-contaminated density (batched over trials).

    The classical robust filter of glint tracking (Song & Sun cite Masreliez's
    score-function filter, ref. [7], and the robust preprocessing of Hewer, Martin & Zeh,
    ref. [6]). Of the two, Huber's M-estimator: Masreliez's update
    $x = x_{\text{pred}} + P H' g(\nu)$, $g = -\nabla \log p(\nu)$, needs the score of the
    *predictive* innovation density, the convolution of $\mathcal{N}(0, H P H')$ with the
    glint density; for the spherical measurement $H P H'$ is not diagonal, so that density
    is a multivariate integral per step and trial with no closed form. Huber's estimator
    needs only $\psi$ of each whitened residual, and its threshold follows from the same
    $\epsilon$ the scene's glint density has (Huber's minimax $c$ for
    $(1 - \epsilon) \mathcal{N} + \epsilon H$), so at $\epsilon = 0$ it is the EKF exactly.

    Prediction, linearisation and the covariance recursion are :func:`ekf_filter`'s
    (the exact linear dynamics with the known control; $H = \partial h / \partial x$ at
    $x_{\text{pred}}$; $R = \operatorname{diag}(\sigma_i^2)$, the Gaussian core of the glint
    density). The update is the M-estimate of the linearised regression $\nu = H d + e$,
    $d = x - x_{\text{pred}} \sim \mathcal{N}(0, P)$ (Boncelet & Dickinson, "A variant of
    Huber robust regression", SIAM J. Sci. Stat. Comput. 5, 1984), with Huber's $\rho$ on
    the measurement residuals only (the prior is Gaussian; $c$ from Huber 1964):

    $$
    \begin{aligned}
    d &= \arg\min_d \sum_i \rho_c(r_i) + \tfrac12 d' P^{-1} d, \qquad r_i = (\nu - H d)_i / \sigma_i, \\
    \rho_c(r) &= \begin{cases} r^2/2 & |r| \le c \\ c |r| - c^2/2 & |r| > c \end{cases}, \qquad
    \frac{2 \phi(c)}{c} - 2 \Phi(-c) = \frac{\epsilon}{1 - \epsilon}
    \end{aligned}
    $$

    solved exactly over the patterns of clipped residuals (:func:`huber_reweigh`). At the
    minimum, with $W = \operatorname{diag}(w_i)$, $w_i = \psi_c(r_i)/r_i = \min(1, c/|r_i|)$,
    the estimate is a Kalman update with $R W^{-1}$,

    $$
    K = P H' (H P H' + R W^{-1})^{-1}, \qquad d = K \nu;
    $$

    then $x = x_{\text{pred}} + K \nu$ and $P = (I - K H) P (I - K H)' + K R W^{-1} K'$
    (Joseph form with the final weights: the covariance of the weighted update, as the
    Huber-based filters report it). ``epsilon`` is the scene's (``"scene"``) unless a
    number is given. Returns $x_{k|k}$ and $P_{k|k}$; traces ``nis`` (the innovation's
    under $R$).
    """

    name = "huber-ekf"
    task = TRACKING
    needs = frozenset({"glint-model"})

    @dataclass(frozen=True)
    class Params:
        epsilon: float = param(
            -1.0, "contamination eps that sets Huber's threshold c (minimax for (1 - eps) N + eps H); "
            "-1: the scene's glint probability", ge=-1.0, le=MAX_EPSILON,
            why="a probability, or -1 for the scene's; at eps -> 1 every weight tends to 0")

    @staticmethod
    def threshold(model, params) -> float:
        """Huber's c for this config on a scene whose glint model is ``model``."""
        eps = model.epsilon if params.epsilon < 0.0 else params.epsilon
        return minimax_threshold(float(eps))

    def run(self, batch: Batch, params) -> TrackingOutput:
        model = glint_model_of(batch.scene)
        res = ekf_filter(batch.z, model, noise_covariance(model, "core"),
                         reweigh=huber_reweigh(self.threshold(model, params)))
        return TrackingOutput(estimate=res.x_post, covariance=res.P_post, traces={"nis": res.nis})
