r"""The posterior Cramér-Rao bound (PCRB) of filtering: the bound on the mean square error
of any estimator of the state from the measurements up to each step
(docs/architecture.md, 'Models'; the tracking task draws it under the RMSE curves).

Tichavský, Muravchik & Nehorai, "Posterior Cramér-Rao bounds for discrete-time
nonlinear filtering", IEEE Trans. Signal Processing 46(5), 1998:
the information matrix $J_k$ ($E[(\hat{x} - x)(\hat{x} - x)'] \ge J_k^{-1}$) follows
(:func:`pcrb_recursion`)

$$
\begin{aligned}
J_{k+1} &= D^{22}_k - D^{21}_k (J_k + D^{11}_k)^{-1} D^{12}_k, \\
D^{11}_k &= E[-\Delta_{x_k}^{x_k} \log p(x_{k+1} \mid x_k)], \quad
D^{12}_k = E[-\Delta_{x_k}^{x_{k+1}} \log p(x_{k+1} \mid x_k)] = (D^{21}_k)', \\
D^{22}_k &= E[-\Delta_{x_{k+1}}^{x_{k+1}} \log p(x_{k+1} \mid x_k)]
  + E[-\Delta_{x_{k+1}}^{x_{k+1}} \log p(z_{k+1} \mid x_{k+1})].
\end{aligned}
$$

For linear dynamics with additive Gaussian noise,
$x_{k+1} = F_k x_k + u_k + w_k$, $w_k \sim \mathcal{N}(0, Q_k)$: $D^{11} = F' Q^{-1} F$,
$D^{12} = -F' Q^{-1}$, $D^{22} = Q^{-1} + J_z$, and by the matrix inversion lemma
(:func:`linear_dynamics_pcrb`)

$$
J_{k+1} = (Q_k + F_k J_k^{-1} F_k')^{-1} + J_z(k+1), \qquad J_z = E[H' R_F^{-1} H],
$$

which needs no inverse of $Q$, so a singular $Q$ (a deterministic maneuver, noise
entering through a gain $G$) is allowed. $H$ is the measurement's Jacobian at the true
state; $R_F^{-1}$ the Fisher information of the measurement noise density ($1/\sigma^2$
for Gaussian noise; more for glint noise of the same variance:
:func:`models.glint.glint_fisher_information`). Step 0 is measured:
$J_0 = P_0^{-1} + J_z(0)$, as the trackers update with $z_0$ first.

Expectations over the true trajectory are taken along each trial's own truth (the
Jacobian at its states): exact where $H$ is constant (linear measurements), and for the
spherical measurement a bound per trajectory whose mean over trials the summary reports.
"""

from __future__ import annotations

import numpy as np


def pcrb_recursion(J0: np.ndarray, D11: np.ndarray, D12: np.ndarray, D22: np.ndarray) -> np.ndarray:
    """J_k (K, ..., d, d) of the module docstring's recursion from J0 (..., d, d), with
    D11, D12, D22 (K - 1, ..., d, d) per transition k -> k + 1 (D21 = D12')."""
    steps = D11.shape[0] + 1
    J = np.empty((steps, *J0.shape))
    J[0] = J0
    for k in range(steps - 1):
        D21 = np.swapaxes(D12[k], -1, -2)
        J[k + 1] = D22[k] - D21 @ np.linalg.solve(J[k] + D11[k], D12[k])
    return J


def linear_dynamics_pcrb(P0: np.ndarray, F: np.ndarray, Q: np.ndarray, Jz: np.ndarray) -> np.ndarray:
    """The bound's covariance J_k^-1 (n, K, d, d) for linear Gaussian dynamics: P0 (d, d)
    the prior of step 0, F and Q (d, d) or (K - 1, d, d) per transition (time-varying), Jz
    (n, K, d, d) the measurement information per trial and step (module docstring)."""
    n, K, d, _ = Jz.shape
    F = np.broadcast_to(F, (K - 1, d, d)) if np.ndim(F) == 2 else np.asarray(F)
    Q = np.broadcast_to(Q, (K - 1, d, d)) if np.ndim(Q) == 2 else np.asarray(Q)
    bound = np.empty((n, K, d, d))
    J = np.linalg.inv(P0) + Jz[:, 0]
    for k in range(K):
        if k:
            predicted = F[k - 1] @ np.linalg.inv(J) @ F[k - 1].T + Q[k - 1]
            J = np.linalg.inv(0.5 * (predicted + np.swapaxes(predicted, -1, -2))) + Jz[:, k]
        bound[:, k] = np.linalg.inv(J)
    return bound


def measurement_information(H: np.ndarray, fisher: np.ndarray) -> np.ndarray:
    """J_z = H' diag(fisher) H (..., d, d) of measurement Jacobians H (..., m, d) and the
    noise's Fisher information per component ``fisher`` (m,), the components independent."""
    return np.swapaxes(H, -1, -2) @ (np.asarray(fisher, float)[:, None] * H)


def position_mse_bound(bound: np.ndarray, position_index) -> np.ndarray:
    """The bound on the position's mean square error (..., ): the trace of the position
    block of the bound's covariance (..., d, d)."""
    idx = list(position_index)
    return np.trace(bound[..., idx, :][..., :, idx], axis1=-2, axis2=-1)
