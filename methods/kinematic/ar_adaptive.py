"""Method ``ar-adaptive``: the AR-model adaptive tracker of maneuvering targets (patent)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np
import scipy.stats

from radarbench.bench.batched import inner, matmul, matvec
from radarbench.bench.core import TRACKING, Batch, Method, TrackingOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.models.kalman import predict_batched, update_where
from radarbench.models.kinematics import KinematicModel, kinematic_model_of

#: the largest state dimension M (lagged positions) and polynomial order N
MAX_STATE_DIM = 12
MAX_ORDER = 6
#: relative ridge of the coefficient solve: P_k|k may be singular (a noise-free
#: polynomial prior, Q = 0); a'(P + eps tr(P)/M I)a picks the smallest-norm
#: coefficients among the equally good ones
COEFFICIENT_RIDGE = 1e-9
#: the reported covariance is D (P + eps R I) D': with Q_k = 0 the lagged positions' P
#: tends to a singular matrix (the model knows the motion is a polynomial), which makes
#: D P D' singular to rounding and the NEES 0/0; eps R I is far below any error that matters
OUTPUT_COVARIANCE_FLOOR = 1e-9


# ----------------------------------------------------------------- the AR model

def exactness_constraints(M: int, N: int) -> np.ndarray:
    """V (M, N+1), V[i-1, j] = (-i)^j: a' V = e_0' says the predictor
    x_k+1 = sum_i a_i x_k+1-i is exact on every polynomial of degree <= N."""
    i = np.arange(1, M + 1, dtype=float)[:, None]
    return (-i) ** np.arange(N + 1)[None, :]


def ar_coefficients(M: int, N: int, P: np.ndarray | None = None) -> np.ndarray:
    """MMSE AR coefficients of polynomial order N on M lagged positions.

    a = argmin a' P a  subject to  V' a = e_0  (:func:`exactness_constraints`)
      = P^-1 V (V' P^-1 V)^-1 e_0,
    with P the error covariance of the lagged positions the prediction is made
    from (``P`` (n, M, M), a small ridge added, see :data:`COEFFICIENT_RIDGE`)
    or P = I (``P`` None: the least-squares polynomial extrapolation, the
    minimum-norm exact predictor; returns (M,)). See :class:`ARAdaptive`.
    """
    V = exactness_constraints(M, N)
    e0 = np.zeros(N + 1)
    e0[0] = 1.0
    if P is None:
        return V @ np.linalg.solve(V.T @ V, e0)
    ridge = COEFFICIENT_RIDGE * sum(P[:, i, i] for i in range(M)) / M
    Pr = P + ridge[:, None, None] * np.eye(M)
    PiV = np.linalg.solve(Pr, np.broadcast_to(V, (len(P), M, N + 1)))          # (n, M, N+1)
    lam = np.linalg.solve(matmul(V.T, PiV), np.broadcast_to(e0[:, None], (len(P), N + 1, 1)))
    return matmul(PiV, lam)[..., 0]


def companion(a: np.ndarray) -> np.ndarray:
    """The transition (..., M, M) of the lagged-position state: first row a,
    then the shift x_k-i+1 -> slot i."""
    M = a.shape[-1]
    F = np.zeros(a.shape[:-1] + (M, M))
    F[..., 0, :] = a
    F[..., np.arange(1, M), np.arange(M - 1)] = 1.0
    return F


def kinematic_map(M: int, dt: float) -> np.ndarray:
    """D (3, M): [position, velocity, acceleration] at t_k from the lagged positions.

    Row 0 is the filtered position x_k|k itself; rows 1 and 2 are the first
    and second derivatives at t_k of the least-squares quadratic through the
    M lagged positions at t_k - i T, i = 0..M-1 (exact when the positions lie
    on a polynomial of degree <= 2; M = 3: (3x_k - 4x_k-1 + x_k-2)/2T and
    (x_k - 2x_k-1 + x_k-2)/T^2).
    """
    tau = -dt * np.arange(M, dtype=float)
    basis = np.stack([np.ones(M), tau, tau ** 2], axis=1)                   # p(tau) = c0 + c1 tau + c2 tau^2
    fit = np.linalg.pinv(basis)                                              # (3, M): c = fit @ x
    D = np.zeros((3, M))
    D[0, 0] = 1.0
    D[1], D[2] = fit[1], 2.0 * fit[2]
    return D


def lag_map(M: int, dt: float) -> np.ndarray:
    """L (M, 3): the lagged positions x_k-i = p - i T v + (i T)^2 a / 2 of a
    kinematic state [p, v, a], for the prior of the AR state."""
    lag = dt * np.arange(M, dtype=float)
    return np.stack([np.ones(M), -lag, 0.5 * lag ** 2], axis=1)


def matched_noise(excess: np.ndarray) -> np.ndarray:
    """Q_k's scale by covariance matching, projected on the PSD cone.

    ``excess`` (n, W): the last W samples nu_j^2 - (H F P_j-1|j-1 F' H' + R),
    whose mean is an unbiased estimate of q (E nu^2 = H F P F' H' + q + R for
    the model Q = q e_0 e_0'). The estimate q_hat e_0 e_0' is a symmetric
    matrix with the one eigenvalue q_hat; its projection on the PSD cone in
    the Frobenius norm (eigenvalue clipping) is max(q_hat, 0) e_0 e_0'.
    """
    return np.maximum(np.mean(excess, axis=-1), 0.0)


# ----------------------------------------------------------------- the filter

@dataclass(frozen=True)
class ARFilterResult:
    """Output of :func:`ar_adaptive_filter` on ``B`` independent position series of ``K`` steps.

    x_post (B, K, M), P_post (B, K, M, M): the lagged-position state and its covariance;
    high (B, K) bool: the high-order model filtered step k; switch (B, K) bool: the chi^2
    test rejected the low-order model at step k; q (B, K): Q_k's scale after step k (m^2);
    nis (B, K): the tested low-order NIS (NaN where untested).
    """

    x_post: np.ndarray
    P_post: np.ndarray
    high: np.ndarray
    switch: np.ndarray
    q: np.ndarray
    nis: np.ndarray


def ar_adaptive_filter(z: np.ndarray, dt: float, R: float, x0: np.ndarray, P0: np.ndarray,
                       params, valid: np.ndarray | None = None) -> ARFilterResult:
    """The patent's steps (2)-(7) on ``B`` position series ``z`` (B, K) at once
    (see :class:`ARAdaptive`); ``x0`` (3,), ``P0`` (3, 3) the kinematic prior
    of step 0, R the measurement-noise variance (m^2). Loops over steps only.
    ``valid`` (B, K) bool: the steps each series has (a ragged batch; None: all). At
    a missing step the filter predicts only (the low order, or the latched high one)
    and runs no test; the windows (covariance matching, the latched switch back) and
    the M-step start count the steps a series has."""
    B, K = z.shape
    valid = np.ones((B, K), bool) if valid is None else np.asarray(valid, bool)
    seen = np.zeros(B, int)                             # steps each series has had before step k
    M, W = params.state_dim, params.window
    L = lag_map(M, dt)
    x = np.broadcast_to(L @ x0, (B, M)).copy()
    P = np.broadcast_to(L @ P0 @ L.T, (B, M, M)).copy()
    e0e0 = np.zeros((M, M))
    e0e0[0, 0] = 1.0
    H, R_mat = e0e0[:1], np.array([[R]])
    chi1 = float(scipy.stats.chi2.isf(params.alpha, 1))
    chiW = float(scipy.stats.chi2.isf(params.alpha, W))
    acc_row = kinematic_map(M, dt)[2]
    a_fixed = {N: ar_coefficients(M, N) for N in (params.order_low, params.order_high)}

    out = ARFilterResult(x_post=np.empty((B, K, M)), P_post=np.empty((B, K, M, M)),
                         high=np.zeros((B, K), bool), switch=np.zeros((B, K), bool),
                         q=np.empty((B, K)), nis=np.full((B, K), np.nan))
    q = np.full(B, params.q0_m2)
    excess = np.zeros((B, W))                           # ring buffer of covariance-matching samples
    accel_nis = np.zeros((B, W))                        # ring buffer of the acceleration test (latched)
    in_high = np.zeros(B, bool)                         # latched mode
    high_run = np.zeros(B, int)
    for k in range(K):
        ok = valid[:, k]
        if k == 0:
            xp, Pp, high, switch = x, P, np.zeros(B, bool), np.zeros(B, bool)
        else:
            Q = q[:, None, None] * e0e0
            xp, Pp = predict_batched(x, P, companion(_coefficients(params, params.order_low, P, a_fixed)), Q)
            nis_low = (z[:, k] - xp[:, 0]) ** 2 / (Pp[:, 0, 0] + R)
            tested = ok & (seen >= M) if params.switching == "per-step" else (ok & ~in_high & (seen >= M))
            switch = tested & (nis_low > chi1)
            high = (switch | in_high) if params.switching == "latched" else switch
            out.nis[tested, k] = nis_low[tested]
            rows = np.flatnonzero(high)             # the high order only where a trial uses it (most steps: none)
            if rows.size:
                F_high = companion(_coefficients(params, params.order_high, P[rows], a_fixed))
                xp[rows], Pp[rows] = predict_batched(x[rows], P[rows], F_high, Q[rows])
        upd = update_where(xp, Pp, z[:, k, None], H, R_mat, ok)
        x, P, nu, S = upd.x, upd.P, upd.nu[:, 0], upd.S[:, 0, 0]
        matched = ok & (seen >= M)                      # the lags before this step are all measured
        excess[matched, seen[matched] % W] = (nu ** 2 - S + q)[matched]    # nu^2 - (H F P F' H' + R)
        if params.state_noise == "matching":
            q = np.where(matched & (seen >= M + W - 1), matched_noise(excess), q)
        if params.switching == "latched":
            in_high, high_run = _latched_mode(high, in_high, high_run, x, P, acc_row, accel_nis, chiW, ok, seen)
        seen += ok
        out.x_post[:, k], out.P_post[:, k] = x, P
        out.high[:, k], out.switch[:, k], out.q[:, k] = high, switch, q
    return out


def _coefficients(params, N: int, P: np.ndarray, fixed: dict) -> np.ndarray:
    """The order-N coefficients of every trial: MMSE under P_k|k, or the fixed least-squares ones."""
    if params.coefficients == "filter" and params.state_dim > N + 1:
        return ar_coefficients(params.state_dim, N, P)
    return np.broadcast_to(fixed[N], (len(P), params.state_dim))


def _latched_mode(high, in_high, run, x, P, acc_row, accel_nis, chiW, ok, seen):
    """The switch back of ``switching = "latched"``: once the high-order model has
    filtered W steps in a row, back to the low order when the sum of the last W
    normalised squared acceleration estimates, sum a_j^2 / var(a_j), is below the
    chi^2(W) quantile at level alpha (the acceleration is not significant). Only the
    series with a measurement at this step (``ok``; ``seen``: their earlier ones) move."""
    W = accel_nis.shape[1]
    acc = inner(x, acc_row)
    var = inner(matvec(P, acc_row), acc_row)
    accel_nis[ok, seen[ok] % W] = (acc ** 2 / np.maximum(var, 1e-300))[ok]
    run = np.where(ok, np.where(high, run + 1, 0), run)
    back = ok & high & (run >= W) & (accel_nis.sum(axis=1) < chiW)
    return high & ~back, np.where(back, 0, run)


# ----------------------------------------------------------------- the method

@register_method
class ARAdaptive(Method):
    r"""AR-model adaptive tracker: χ² switch between AR orders, Q by sliding-window covariance matching (patent).

    After the patent "基于最优AR模型的自适应机动目标跟踪方法" (adaptive
    maneuvering-target tracking based on an optimal AR model). The patent
    prints the steps and no equation; what follows is our derivation of each
    step, in the patent's symbols ($Q_0$, $W$, $M$, $N$, $\alpha$).

    **Step (1), parameters**: initial state-noise variance $Q_0$ (``q0_m2``),
    sliding window $W$ (``window``), state dimension $M$ (``state_dim``),
    polynomial orders $N$ (``order_low``, ``order_high``: the patent's "低阶"
    and "高阶" models share $M$), significance $\alpha$ (``alpha``). The defaults are
    ours (the patent prints none): $M = 4$, $N = 1$ and 2, $W = 10$, $\alpha = 0.01$,
    $Q_0 = 1$ m². Initialisation: the AR state's prior is the scenario's
    kinematic prior $(x_0, P_0)$ mapped to the lagged positions
    (:func:`lag_map`), so every tracker of the suite starts from the same
    information.

    **State-space form.** Per position axis the state is the $M$ latest
    positions, $X_k = [x_k, x_{k-1}, \dots, x_{k-M+1}]'$, with (:func:`companion`)

    $$
    \begin{aligned}
    X_{k+1} &= F(a) X_k + w_k, &
      F(a) &= \begin{bmatrix} a_1 \; \cdots \; a_M \\ I_{M-1} \quad 0 \end{bmatrix}, \\
    z_k &= e_0' X_k + v_k, &
      v_k &\sim \mathcal{N}(0, R), \quad w_k \sim \mathcal{N}(0, Q_k), \quad Q_k = q_k e_0 e_0'
    \end{aligned}
    $$

    (the new position is the AR prediction $\sum_i a_i x_{k+1-i}$ plus noise; the
    other components are shifts, without noise). Filtered by the one batched
    Kalman filter's per-trial steps (:func:`models.kalman.predict_batched`,
    :func:`models.kalman.update_batched`). Velocity and
    acceleration are not states ("不需要估计目标的速度和加速度", no velocity or
    acceleration estimated); the scenario's $[p, v, a]'$ is read off $X$ by
    :func:`kinematic_map` (filtered position; derivatives of the
    least-squares quadratic through the lagged positions) with covariance
    $D P D'$.

    **Steps (2)/(5), MMSE AR coefficients of order N.** A predictor
    $x_{k+1} = \sum_{i=1}^{M} a_i x_{k+1-i}$ is exact on every polynomial of degree
    $\le N$ iff $\sum_i a_i = 1$ and $\sum_i a_i (-i)^j = 0$, $j = 1, \dots, N$ (apply it to
    $(t - t_{k+1})^j$), i.e. $V'a = e_0$ with $V_{ij} = (-i)^j$ ($M \ge N + 1$
    unknowns). The prediction error on such a trajectory from the estimate
    $\hat{X}_{k|k}$ is $a'(X_k - \hat{X}_{k|k}) + w_k$, of variance $a' P_{k|k} a + q_k$, so the
    minimum-mean-square-error coefficients "in the Kalman-filter framework"
    (our reading; the patent prints no equation) solve $\min_a a' P_{k|k} a$ subject
    to $V'a = e_0$ (:func:`ar_coefficients`):

    $$
    a = P^{-1} V (V' P^{-1} V)^{-1} e_0
    $$

    recomputed every step and per trial, so they follow the noise statistics
    ("AR模型系数可以根据噪声统计特性的变化进行实时调整"; ``coefficients =
    "filter"``, the default). With $P = I$ (``coefficients = "min-norm"``,
    ours) this is the least-squares polynomial extrapolation, the MMSE
    predictor from $M$ raw measurements of equal, independent errors. With
    $M = N + 1$ both are the unique exact predictor: $N = 1$, $M = 2$ gives
    $x_{k+1} = 2x_k - x_{k-1}$; $N = 2$, $M = 3$ gives $x_{k+1} = 3x_k - 3x_{k-1} + x_{k-2}$.
    ($M = 4$, $N = 1$, min-norm: $a = (1, 0.5, 0, -0.5)$.)

    **Steps (3)/(6), $Q_k$ by covariance matching** over the sliding window $W$
    (after Mehra, "Approaches to adaptive filtering", and Myers & Tapley,
    "Adaptive sequential estimation with unknown noise statistics"): for the
    model above $E[\nu_j^2] = e_0' F P_{j-1|j-1} F' e_0 + q + R$, so (:func:`matched_noise`)

    $$
    \hat{q}_k = \frac{1}{W} \sum_{j=k-W+1}^{k}
        \left(\nu_j^2 - e_0' F_j P_{j-1|j-1} F_j' e_0 - R\right), \qquad
    Q_k = \max(\hat{q}_k, 0)\, e_0 e_0'
    $$

    the projection of $\hat{q}_k e_0 e_0'$ on the positive-semi-definite cone
    (eigenvalue clipping: its one eigenvalue is $\hat{q}_k$): our reading of the
    patent's "保证了状态噪声方差的半正定性" (keeps the state-noise covariance
    PSD); the estimator and the clipping are ours, the patent prints neither. Samples
    count from step $M$ on (every lag of the prediction measured); $Q_0$ is used
    until the window holds $W$ of them. $Q_k$ is estimated at every step,
    whichever order filtered it ("在整个滤波的过程中").

    **The ablation of the adaptive Q** (ours, not the patent's):
    ``state_noise = "fixed"`` keeps $Q_k = Q_0 e_0 e_0'$ at every step, $Q_0$
    being ``q0_m2``, the patent's own initial value of step (1). Everything
    else (coefficients, χ² switch, switch back, $W$ for the latched rule) is
    unchanged, so the paired difference between ``state_noise = "matching"``
    and ``"fixed"`` at the same $Q_0$ is the effect of the covariance matching
    alone; the fixed value is a parameter rather than, say, the CV filter's
    $Q$ because the AR state has no velocity for a CV $Q$ to act on. $Q_0$ is the
    variance added to the new position per step, so to the first difference
    $x_k - x_{k-1}$ ($T$ times the velocity) too; the CV filter's DWNA adds
    $\sigma_a^2 T^4/4$ to the position and $\sigma_a^2 T^4$ to that difference: equal noise on
    the velocity is $\sigma_a = \sqrt{Q_0} / T^2$, equal noise on the position
    $\sigma_a = 2\sqrt{Q_0} / T^2$ (the ar-tracking preset sweeps both models on the first).

    **Step (4), the χ² switching rule.** At every tested step the low-order
    prediction's innovation $\nu_k$ with $S_k = e_0' P_{k|k-1} e_0 + R$ gives
    $\epsilon_k = \nu_k^2 / S_k$, $\chi^2(1)$ under a matched model; the step is a maneuver
    when $\epsilon_k > \chi^2_1(\alpha)$ (``scipy.stats.chi2.isf``), and step $k$ is then
    filtered by the high-order model instead (steps 5–6), from the same
    $\hat{X}_{k-1|k-1}$, $P_{k-1|k-1}$: the state keeps its dimension $M$, so nothing is
    re-initialised ("无缝切换"). Tests start at step $M$.

    **The switch back** (the patent leaves it open):

    * ``switching = "per-step"`` (default, the flow chart as printed):
      step (7) returns to step (2), so every step starts from the low-order
      model and the high order filters exactly the steps whose low-order
      innovation fails the test; the switch back is the next step that
      passes. A false switch is one rejection on a quiet step; with a
      matched model the tests are independent, each at level $\alpha$.
    * ``switching = "latched"`` (ours, the variable-dimension filter's rule,
      Bar-Shalom & Birmiwal): the high order stays until it has filtered $W$
      steps and the acceleration estimate $\hat{a}_j$ (:func:`kinematic_map`) is
      insignificant, $\sum_{\text{last } W} \hat{a}_j^2 / \operatorname{var}(\hat{a}_j) < \chi^2_W(\alpha)$;
      only low-order steps are tested.

    Estimates: $[p, v, a]'$ per axis and its covariance; traces ``mode`` (1.0
    where the high order filtered the step), ``switch`` (1.0 where the χ²
    test rejected the low order), ``q_k`` ($Q_k$'s scale after the step,
    m²; the mean over axes in 2-D), ``nis`` (the tested low-order NIS). In
    2-D each axis is tracked by its own AR filter (the patent's range
    tracker, per coordinate); ``mode`` and ``switch`` are 1 where either
    axis is.
    """

    name = "ar-adaptive"
    task = TRACKING
    needs = frozenset({"kinematic-model"})
    handles = frozenset({"valid-step-masks"})
    reference_name = "per-trial filterpy KalmanFilter loop with the same switching and Q_k"
    reference_trials = 20
    perf_targets = {"*": {"speedup": 50.0}}

    @dataclass(frozen=True)
    class Params:
        q0_m2: float = param(1.0, "initial state-noise variance Q0 of the new position (m^2), used until the "
                             "window holds W samples", ge=0.0, le=1e10,
                             why="0 (a noise-free polynomial) up to (100 km)^2")
        window: int = param(10, "sliding window W of the covariance matching (steps)", ge=1, le=1000,
                            why="one innovation at least; at most 1000 steps of memory per trial")
        state_dim: int = param(4, "state dimension M: the number of lagged positions", ge=3,
                               le=MAX_STATE_DIM, why="three lags: the acceleration estimate needs three; at "
                               "most 12 (the coefficient solve loses precision beyond)")
        order_low: int = param(1, "polynomial order N of the low-order (quiet) AR model", ge=0,
                               le=MAX_ORDER - 1, why="0 (constant position) to one below the highest")
        order_high: int = param(2, "polynomial order N of the high-order (maneuver) AR model", ge=1,
                                le=MAX_ORDER, why="above the low order; at most 6 (M - 1 at most, checked)")
        alpha: float = param(0.01, "significance level alpha of the chi-square maneuver test", gt=0.0, lt=0.5,
                             why="a probability; a test at level 0.5 or above rejects more often than not")
        coefficients: str = param("filter", "filter: MMSE coefficients under the filter's P_k|k "
                                  "(our MMSE reading of the patent's steps (2)/(5), which print no "
                                  "equation); min-norm: least-squares extrapolation (P = I)",
                                  choices=("filter", "min-norm"))
        switching: str = param("per-step", "per-step: each step starts from the low order (the patent's "
                               "flow chart); latched: high order until the acceleration is insignificant",
                               choices=("per-step", "latched"))
        state_noise: str = param("matching", "matching: Q_k by sliding-window covariance matching over W steps "
                                 "(the patent's); fixed: Q_k = Q0 at every step, no adaptation (our ablation)",
                                 choices=("matching", "fixed"))

        def validate(self) -> None:
            if self.order_high <= self.order_low:
                raise ConfigError("order_high", f"expected > order_low = {self.order_low}, got {self.order_high}")
            if self.order_high > self.state_dim - 1:
                raise ConfigError("order_high", f"an order-{self.order_high} predictor needs state_dim >= "
                                  f"{self.order_high + 1}, got {self.state_dim}")

    def run(self, batch: Batch, params) -> TrackingOutput:
        model = kinematic_model_of(batch.scene)
        runner = partial(ar_adaptive_filter, valid=batch.scene.valid_steps)
        return _assemble(batch, model, params, _filter_axes(batch, model, params, runner))

    def reference_run(self, batch: Batch, params) -> TrackingOutput:
        """The same tracker by a per-trial, per-step filterpy loop (``bench perf``'s baseline, the tests' oracle)."""
        model = kinematic_model_of(batch.scene)
        return _assemble(batch, model, params, _filter_axes(batch, model, params, reference_filter))

    def check_scenario(self, params, scenario_params) -> str | None:
        steps = getattr(scenario_params, "steps", None)
        if steps is not None and steps <= params.state_dim:
            return f"state_dim = {params.state_dim} lagged positions need more than {params.state_dim} steps, " \
                   f"the scenario has {steps}"
        return None


def _filter_axes(batch: Batch, model: KinematicModel, params, runner) -> list[ARFilterResult]:
    """One AR filter per axis, each over all trials at once (``runner``: the
    batched filter or the reference), from the axis's block of the prior."""
    z, R = np.asarray(batch.z, float), model.noise_std_m ** 2
    x0, P0 = model.x0.reshape(model.dims, 3), model.P0
    return [runner(z[..., j], model.dt_s, R, x0[j], P0[3 * j:3 * j + 3, 3 * j:3 * j + 3], params)
            for j in range(model.dims)]


def _assemble(batch: Batch, model: KinematicModel, params, axes: list[ARFilterResult]) -> TrackingOutput:
    """The scenario's [p, v, a] per axis from the lagged positions (covariance
    D P D', block diagonal over axes), and the traces."""
    n, K, D = batch.n, batch.steps, model.dims
    Dm = kinematic_map(params.state_dim, model.dt_s)
    estimate = np.concatenate([matvec(Dm, res.x_post) for res in axes], axis=-1)
    covariance = np.zeros((n, K, 3 * D, 3 * D))
    floor = OUTPUT_COVARIANCE_FLOOR * model.noise_std_m ** 2 * np.eye(params.state_dim)
    for j, res in enumerate(axes):
        covariance[:, :, 3 * j:3 * j + 3, 3 * j:3 * j + 3] = matmul(matmul(Dm, res.P_post + floor), Dm.T)
    traces = {"mode": np.any([res.high for res in axes], axis=0).astype(float),
              "switch": np.any([res.switch for res in axes], axis=0).astype(float),
              "q_k": np.mean([res.q for res in axes], axis=0),
              "nis": np.max([np.nan_to_num(res.nis, nan=0.0) for res in axes], axis=0)}
    return TrackingOutput(estimate=estimate, covariance=covariance, traces=traces)


# ----------------------------------------------------------------- the reference

def reference_filter(z: np.ndarray, dt: float, R: float, x0: np.ndarray, P0: np.ndarray,
                     params) -> ARFilterResult:
    """:func:`ar_adaptive_filter` by a per-series, per-step loop on filterpy's
    ``KalmanFilter`` (its predict and update), the coefficients, the test, Q_k
    and the switch back written out step by step: the oracle of the tests and
    ``bench perf``'s baseline."""
    from filterpy.kalman import KalmanFilter

    B, K = z.shape
    M, W = params.state_dim, params.window
    L = lag_map(M, dt)
    chi1 = float(scipy.stats.chi2.isf(params.alpha, 1))
    chiW = float(scipy.stats.chi2.isf(params.alpha, W))
    acc_row = kinematic_map(M, dt)[2]
    out = ARFilterResult(x_post=np.empty((B, K, M)), P_post=np.empty((B, K, M, M)),
                         high=np.zeros((B, K), bool), switch=np.zeros((B, K), bool),
                         q=np.empty((B, K)), nis=np.full((B, K), np.nan))
    H = np.zeros((1, M))
    H[0, 0] = 1.0
    for b in range(B):
        kf = KalmanFilter(dim_x=M, dim_z=1)
        kf.H, kf.R = H, np.array([[R]])
        kf.x, kf.P = L @ x0, L @ P0 @ L.T
        q, samples, acc_tests, in_high, run = params.q0_m2, [], [], False, 0
        for k in range(K):
            high = switch = False
            if k > 0:
                x_prev, P_prev = kf.x.copy(), kf.P.copy()
                preds = {}
                for N in (params.order_low, params.order_high):
                    if params.coefficients == "filter" and M > N + 1:
                        a = ar_coefficients(M, N, P_prev[None])[0]
                    else:
                        a = ar_coefficients(M, N)
                    kf.x, kf.P = x_prev.copy(), P_prev.copy()
                    kf.predict(F=companion(a), Q=q * np.outer(H[0], H[0]))
                    preds[N] = (kf.x.copy(), kf.P.copy())
                x_low, P_low = preds[params.order_low]
                tested = k >= M and (params.switching == "per-step" or not in_high)
                nis = (z[b, k] - x_low[0]) ** 2 / (P_low[0, 0] + R)
                if tested:
                    out.nis[b, k] = nis
                    switch = nis > chi1
                high = switch or (params.switching == "latched" and in_high)
                kf.x, kf.P = preds[params.order_high] if high else preds[params.order_low]
            kf.update(np.array([z[b, k]]))
            if k >= M:
                samples.append(float(kf.y[0] ** 2 - kf.S[0, 0] + q))
                if len(samples) >= W and params.state_noise == "matching":
                    q = max(float(np.mean(samples[-W:])), 0.0)
            if params.switching == "latched":
                acc = float(acc_row @ kf.x)
                acc_tests.append(acc ** 2 / max(float(acc_row @ kf.P @ acc_row), 1e-300))
                run = run + 1 if high else 0
                in_high = high and not (run >= W and sum(acc_tests[-W:]) < chiW)
                if high and not in_high:
                    run = 0
            out.x_post[b, k], out.P_post[b, k] = kf.x, kf.P
            out.high[b, k], out.switch[b, k], out.q[b, k] = high, switch, q
    return out
