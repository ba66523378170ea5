"""Methods ``dp-tbd`` and ``dp-tbd-mf``: dynamic-programming track-before-detect.

* ``dp-tbd`` — Tonissen & Evans, "Performance of dynamic programming
  techniques for track-before-detect", IEEE TAES 32(4), 1996 (after Barniv,
  IEEE TAES 21(1), 1985): first-order state (the cell), merit = frame value
  plus the best merit of the previous frame within the transition window.
* ``dp-tbd-mf`` — the multi-frame variant of the seed paper: second-order
  state (current cell, previous cell), index function = conditional Gaussian
  log-likelihood ratio of the correlated noise plus the log of a turn-angle
  density. Derived in :class:`DpTbdMf`.

Both run on ``tbd-grid`` batches (frames ``z`` (n, K, H, W)) with the grid,
the frame period and the noise statistics from ``batch.scene``; the compiled
recursions are in :mod:`methods.tbd.kernels` and :mod:`methods.tbd.mf_kernels`. Scores are scene statistics:
there is no analytic threshold for the maximum over a scene, so
``nominal_threshold`` is NaN and the harness calibrates on null scenes
(``empirical``, ``gumbel`` or ``pot``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.special

from radarbench.bench.core import TBD, Batch, Method, TBDOutput
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.tbd import alongtrack, kernels, mf_kernels
from radarbench.methods.tbd.reference import numpy_dp_tbd
from radarbench.models.ar_noise import ar_autocovariance, ar_innovation_std, stationary_predictors

#: the largest window radius supported: (2q + 1)^2 <= 127 displacements, the
#: most an int8 can number (the reference kernels' backpointers)
MAX_WINDOW_RADIUS = 5
#: the largest ``max_speed_m_s``: Mach 30, faster than any target; the window radius it
#: gives at the scenario's frame period and cell size is checked per scenario config
MAX_SPEED_M_S = 10_000.0
SPEED_WHY = ("a speed (> 0) up to Mach 30; the window radius ceil(v T / cell_m) must be at most "
             f"{MAX_WINDOW_RADIUS} cells at the scenario's frame period and cell size (checked per "
             "scenario config)")
LOG_UNIFORM_ANGLE = -math.log(2.0 * math.pi)


def window_radius(max_speed_m_s: float, batch: Batch) -> int:
    """q = ceil(v_max T / cell_m) cells: the box window |dr|, |dc| <= q.

    A target moving at most v_max covers at most v_max T per axis in a frame;
    since its position within a cell is arbitrary, the cell index along an
    axis can change by ceil(v_max T / cell_m) (e.g. 1.41 cells of motion can
    move it 2 cells). The box (an L-inf ball) contains every such move; it
    also admits diagonal moves up to sqrt(2) q cells.
    """
    T = float(batch.scene.frame_period_s)
    cell = float(batch.scene.grid.cell_m)
    q = max(1, math.ceil(max_speed_m_s * T / cell - 1e-9))
    if q > MAX_WINDOW_RADIUS:
        raise ValueError(f"max_speed_m_s = {max_speed_m_s} gives a window radius of {q} cells at "
                         f"T = {T} s and {cell} m cells; at most {MAX_WINDOW_RADIUS} is supported")
    return q


def radius_problem(max_speed_m_s: float, scenario_params) -> str | None:
    """The pair check of both DP methods: the window radius
    (:func:`window_radius`) at the scenario's ``frame_period_s`` and ``cell_m``
    (read by name; unknown: not checked) must be at most MAX_WINDOW_RADIUS."""
    T, cell = getattr(scenario_params, "frame_period_s", None), getattr(scenario_params, "cell_m", None)
    if not isinstance(T, float) or not isinstance(cell, float):
        return None
    q = max(1, math.ceil(max_speed_m_s * T / cell - 1e-9))
    if q > MAX_WINDOW_RADIUS:
        return (f"max_speed_m_s = {max_speed_m_s:g} gives a window radius of {q} cells at "
                f"T = {T:g} s and {cell:g} m cells; at most {MAX_WINDOW_RADIUS} is supported")
    return None


def scene_shape(scenario_params) -> tuple[int, int, int] | None:
    """(K, H, W) of the ``tbd-grid`` scenario's frames (``frames``, ``cells``), or None."""
    K, H = getattr(scenario_params, "frames", None), getattr(scenario_params, "cells", None)
    return (K, H, H) if isinstance(K, int) and isinstance(H, int) else None


def _frames32(batch: Batch) -> np.ndarray:
    z = np.asarray(batch.z)
    if z.ndim != 4:
        raise ValueError(f"expected TBD frames (n, K, H, W), got shape {z.shape}")
    return np.ascontiguousarray(z, dtype=np.float32)


def _outputs(z: np.ndarray):
    n, K, H, W = z.shape
    return np.empty(n), np.empty((n, K, 2), np.int64), np.empty((n, H, W), np.float32)


@register_method
class DpTbd(Method):
    r"""Tonissen-Evans DP track-before-detect: cell merit plus the best previous merit in the window, backtracking.

    Recursion (frames $k = 0, \dots, K-1$, cells $x = (\text{row}, \text{col})$):

    $$
    I_0(x) = z_0(x), \qquad I_k(x) = z_k(x) + \max_{d \in W} I_{k-1}(x - d),
    $$

    with $W$ the box of radius $q = \lceil v_{\max} T / \Delta \rceil$ ($v_{\max}$: ``max_speed_m_s``,
    $\Delta$: ``cell_m``; :func:`window_radius`; predecessors outside the grid are not
    candidates), backpointers $\psi_k(x)$ = the first maximising $d$ in the window
    numbering. Score $= \max_x I_{K-1}(x)$ (the scene statistic the harness thresholds
    at a per-scene Pfa); track: from the first argmax at the last frame,
    $x_{k-1} = x_k - \psi_k(x_k)$; value map $= I_{K-1}$. The merit is the raw frame
    value (the classic merit for a non-fluctuating target in Gaussian noise, where the
    LLR is affine in $z$); under correlated noise it ignores the correlation, which is
    what ``dp-tbd-mf`` exploits.

    Default ``max_speed_m_s`` = 150 m/s: the paper's target moves at 141 m/s
    (1.41 cells per frame in the turn), and at 100 m cells its cell index
    jumps by 2 along one axis on two transitions of the turn (frames 13 and
    17); $q = 2$ (a 5 x 5 window) keeps the whole true cell path admissible.
    The classic 3 x 3 window is ``max_speed_m_s = 100``.

    **Pre-whitening** (``prewhiten = true``, an ablation, not Tonissen's
    method): before the DP each cell's time series is replaced by its
    innovations under the scene's AR model (:func:`prewhiten`), unit
    variance and white under H0. The merit is then the sum along the path
    of whitened values; the target's own contribution is whitened too: a
    target entering a new cell adds $s / \sigma_w$ there (10.4 dB more than $s$
    for the default AR(3)), but while it stays in a cell its residual is
    $s (1 + a_1 + \dots) / \sigma_w$, and the cells it left carry the echoes
    $a_i s / \sigma_w$ for $i$ frames. The recursion is unchanged, so the merit
    is no longer a likelihood ratio for a moving target: it is the classic
    merit on the innovations, which measures what per-cell whitening alone
    buys.

    Implementation: a numba kernel (:func:`methods.tbd.kernels.dp_tbd`),
    batched over trials (one at a time inside, so memory does not grow with
    n), float32 merits. The forward pass computes maxima only: the box
    maximum is separable (along columns, then along rows: $2 (2q + 1)$ maxima
    per cell instead of $(2q + 1)^2$) and keeps $I_k$ of every frame ($K H W$
    float32, 20 MB at 500 x 500 x 20); backtracking recomputes $\psi_k$ at the
    track's cell from $I_{k-1}$, with the first-maximum tie rule. Score, track
    and value map are those of the stacked-argmax reference
    (:mod:`methods.tbd.reference`) and of the original max + argmax kernel
    (``tests/tbd_kernels_oracle.py``), bit for bit.
    """

    name = "dp-tbd"
    task = TBD
    #: ``bench perf`` targets at paper scale (500 x 500 cells, 20 frames, q = 2)
    perf_targets = {"paper": {"speedup": 5.0, "transitions_per_second": 1e10}}
    reference_name = "the same algorithm in vectorised NumPy (max only, backpointers recomputed along the track)"

    @dataclass(frozen=True)
    class Params:
        max_speed_m_s: float = param(150.0, "largest target speed the transition window admits "
                                            "(m/s); window radius q = ceil(v T / cell_m) cells",
                                     gt=0.0, le=MAX_SPEED_M_S, why=SPEED_WHY)
        prewhiten: bool = param(False, "replace each cell's time series by its unit-variance AR "
                                       "innovations (the scene's known model) before the DP; an "
                                       "ablation, not Tonissen's method")

    def run(self, batch: Batch, params) -> TBDOutput:
        z = self._frames(batch, params)
        q = window_radius(params.max_speed_m_s, batch)
        score, track, value = _outputs(z)
        kernels.dp_tbd(z, q, score, track, value)
        return TBDOutput(score=score, track=track, value=value)

    def reference_run(self, batch: Batch, params) -> TBDOutput:
        """The peer ``bench perf`` compares against: the kernel's algorithm in plain vectorised NumPy
        (:func:`methods.tbd.reference.numpy_dp_tbd`); the SciPy stacked-argmax recursion stays the tests' oracle."""
        score, track = numpy_dp_tbd(self._frames(batch, params), window_radius(params.max_speed_m_s, batch))
        return TBDOutput(score=score, track=track)

    @staticmethod
    def _frames(batch: Batch, params):
        """The frames the recursion runs on: the scene's, or their pre-whitened innovations."""
        z = _frames32(batch)
        return prewhiten(z, batch) if params.prewhiten else z

    def work(self, batch: Batch, params) -> tuple[str, float]:
        """State transitions evaluated: cells x window x (frames - 1) per trial."""
        q = window_radius(params.max_speed_m_s, batch)
        n, K, H, W = batch.z.shape
        return "transitions", float(n * H * W * (2 * q + 1) ** 2 * (K - 1))

    def check_scenario(self, params, scenario_params) -> str | None:
        return radius_problem(params.max_speed_m_s, scenario_params)

    def unit_memory_bytes(self, params, scenario_params, n: int) -> int | None:
        """The kernel's int8 back-pointers (K, H, W) and a few float32 (H, W)
        planes for one trial at a time, the (n, H, W) value maps; ``prewhiten``
        adds a float32 copy of the frames (n, K, H, W)."""
        shape = scene_shape(scenario_params)
        if shape is None:
            return None
        K, H, W = shape
        return K * H * W + 24 * H * W + 4 * n * H * W + (4 * n * K * H * W if params.prewhiten else 0)

    # No nominal_threshold (bench.core.Method: NaN, none): the score is a maximum over all
    # cells and paths of a scene, whose null law has no closed form; calibrate on null
    # scenes (``empirical``, or ``gumbel`` or ``pot`` for small Pfa).


def prewhiten(z: np.ndarray, batch: Batch) -> np.ndarray:
    """(n, K, H, W) float32 innovations of each cell's series under the
    scene's AR model (``scene.ar_coefficients``, sigma = ``scene.noise_std``).

    From frame P on: eps_k = (z_k + a1 z_(k-1) + ... + aP z_(k-P)) / sigma_w
    (the convention v_k + sum_i a_i v_(k-i) = w_k of the scene, sigma_w the
    innovation std for stationary variance sigma^2). The first P frames are
    whitened conditionally on the frames before them under the stationary
    law: eps_k = (z_k - phi_k . (z_(k-1), ..., z_0)) / sqrt(nu_k)
    (:func:`models.ar_noise.stationary_predictors`, the Cholesky factor
    of the stationary covariance), so no frame is dropped and every eps_k is
    N(0, 1), independent of the others, under H0. White noise (no AR
    model): z / sigma.
    """
    a = batch.scene.ar_coefficients
    sigma = float(batch.scene.noise_std)
    if not a:
        return np.ascontiguousarray(z / np.float32(sigma), dtype=np.float32)
    a = tuple(float(x) for x in a)
    P = len(a)
    start = stationary_predictors(a, sigma)
    sigma_w = ar_innovation_std(a, sigma ** 2)
    out = np.empty_like(z, dtype=np.float32)
    for k in range(z.shape[1]):
        if k < P:
            phi, nu = start[k]
            pred = sum(phi[j - 1] * z[:, k - j].astype(np.float64) for j in range(1, k + 1))
            out[:, k] = (z[:, k] - pred) / math.sqrt(nu)
        else:
            resid = z[:, k].astype(np.float64)
            for i in range(1, P + 1):
                resid += a[i - 1] * z[:, k - i]
            out[:, k] = resid / sigma_w
    return out


# ------------------------------------------------------------------ dp-tbd-mf

def turn_log_density(theta, prior: str, kappa: float):
    """log p(theta) for the turn angle theta in (-pi, pi].

    ``von-mises``: p = exp(kappa cos theta) / (2 pi I0(kappa)).
    ``laplace``: p = kappa exp(-kappa |theta|) / (2 (1 - exp(-kappa pi))),
    a Laplace density truncated to (-pi, pi]. Both are >= 0, decrease in
    |theta| and integrate to 1 on (-pi, pi]; kappa = 0 gives the uniform
    1 / (2 pi).
    """
    theta = np.asarray(theta, float)
    if kappa == 0.0:
        return np.full(theta.shape, LOG_UNIFORM_ANGLE)
    if prior == "von-mises":
        # log I0(kappa) = log i0e(kappa) + kappa (exponentially scaled, no overflow)
        return kappa * (np.cos(theta) - 1.0) - math.log(2.0 * math.pi * scipy.special.i0e(kappa))
    if prior == "laplace":
        return -kappa * np.abs(theta) + math.log(kappa / (2.0 * -math.expm1(-kappa * math.pi)))
    raise ValueError(f"unknown turn prior {prior!r}")


def displacements(q: int) -> np.ndarray:
    """(D, 2) displacements (dr, dc) of the box window, row-major: index
    (dr + q)(2q + 1) + (dc + q); D // 2 is (0, 0), D - 1 - j is -d_j."""
    r = np.arange(-q, q + 1)
    return np.stack(np.meshgrid(r, r, indexing="ij"), axis=-1).reshape(-1, 2)


def turn_angle(d_prev: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Signed angle (-pi, pi] from displacement d_prev to d (NaN if either is 0)."""
    d_prev, d = np.asarray(d_prev, float), np.asarray(d, float)
    cross = d_prev[..., 0] * d[..., 1] - d_prev[..., 1] * d[..., 0]
    dot = (d_prev * d).sum(axis=-1)
    zero = ~(d_prev.any(axis=-1) & d.any(axis=-1))
    theta = np.arctan2(cross, dot)
    theta = np.where(theta <= -np.pi, np.pi, theta)
    return np.where(zero, np.nan, theta)


def transition_log_weights(q: int, prior: str, kappa: float) -> np.ndarray:
    """(D, D) float64 table lp[d', d] = log p(theta(d', d)); the uniform
    log(1 / 2 pi) where d' or d is the zero displacement (no heading)."""
    disp = displacements(q)
    theta = turn_angle(disp[:, None, :], disp[None, :, :])
    lp = turn_log_density(np.nan_to_num(theta), prior, kappa)
    return np.where(np.isnan(theta), LOG_UNIFORM_ANGLE, lp)


@dataclass(frozen=True)
class ConditionalLLR:
    """Coefficients of the conditional LLR Lambda = coef * r0 + const.

    ``beta1``/``beta2``: one-step predictor of a cell's noise from its two
    previous frames; ``var``: its conditional variance sigma_c^2; for frame 1
    (one previous frame) ``beta_first`` and ``var_first``; ``c`` the signal
    factors of the cases (new, back, stay1, stay2) of frame >= 2 and
    (new, stay) of frame 1.
    """

    s: float
    gamma: tuple[float, float, float]
    beta1: float
    beta2: float
    var: float
    beta_first: float
    var_first: float

    @classmethod
    def from_autocovariance(cls, gamma, s: float) -> ConditionalLLR:
        g0, g1, g2 = (float(x) for x in gamma)
        cov = np.array([[g0, g1, g2], [g1, g0, g1], [g2, g1, g0]])
        if not np.linalg.eigvalsh(cov).min() > 1e-12 * max(g0, 0.0):
            raise ValueError(f"noise autocovariance {tuple(gamma)} is singular or not a covariance: "
                             "the 3 x 3 matrix of frames k, k-1, k-2 must be positive definite")
        beta1, beta2 = np.linalg.solve(cov[1:, 1:], cov[1:, 0])
        var = g0 - beta1 * g1 - beta2 * g2
        beta_first = g1 / g0
        var_first = g0 - g1 * g1 / g0
        return cls(float(s), (g0, g1, g2), float(beta1), float(beta2), float(var), float(beta_first),
                   float(var_first))

    def c_frame2(self) -> np.ndarray:
        """Signal factor c = 1 - beta1 e1 - beta2 e2 for (new, back, stay1, stay2)."""
        b1, b2 = self.beta1, self.beta2
        return np.array([1.0, 1.0 - b2, 1.0 - b1, 1.0 - b1 - b2])

    def c_frame1(self) -> np.ndarray:
        return np.array([1.0, 1.0 - self.beta_first])

    def planes(self, c: np.ndarray, var: float) -> tuple[np.ndarray, np.ndarray]:
        """(coef, const) float32: Lambda = s c r0 / var - s^2 c^2 / (2 var)."""
        s = self.s
        return (np.asarray(s * c / var, np.float32), np.asarray(-(s * c) ** 2 / (2.0 * var), np.float32))


def along_track_llr(values, s: float, gamma) -> np.ndarray:
    """The paper's index term for the last of m = 1, 2 or 3 values along a
    track (eqs. 11-14): ln N_m(v; s, G_m) - ln N_(m-1)(v'; s, G_(m-1))
    - [ln N_m(v; 0, G_m) - ln N_(m-1)(v'; 0, G_(m-1))], ``values[..., 0]`` the
    newest z_k(x_k), v' the older ones, G the Toeplitz covariance of
    gamma(0..m-1). Closed form through the conditional law of the newest value
    (beta, sigma_c^2, c = 1 - sum beta): (s c / sigma_c^2) r0 - (s c)^2 / (2 sigma_c^2).
    """
    v = np.asarray(values, float)
    m = v.shape[-1]
    llr = ConditionalLLR.from_autocovariance(tuple(gamma)[:3], s)
    if m == 1:
        beta, var = np.zeros(0), float(gamma[0])
    elif m == 2:
        beta, var = np.array([llr.beta_first]), llr.var_first
    else:
        beta, var = np.array([llr.beta1, llr.beta2]), llr.var
    c = 1.0 - beta.sum()
    r0 = v[..., 0] - (v[..., 1:] * beta).sum(axis=-1)
    return s * c * r0 / var - (s * c) ** 2 / (2.0 * var)


def noise_autocovariance(batch: Batch) -> tuple[float, float, float]:
    """gamma(0), gamma(1), gamma(2) of the per-cell noise from the batch
    (``noise_autocovariance``; missing lags are 0; without it, white noise
    of variance ``noise_std``^2)."""
    gamma = batch.scene.noise_autocovariance
    if gamma is None:
        gamma = [float(batch.scene.noise_std) ** 2]
    gamma = list(np.asarray(gamma, float)[:3]) + [0.0] * max(0, 3 - len(gamma))
    return tuple(gamma)


def conditional_llr_problem(scenario_params) -> str | None:
    """Why the conditional LLR (:class:`ConditionalLLR`) cannot be built for a scenario
    config, or None: for AR noise, the 3 x 3 covariance of frames k, k-1, k-2, as
    :func:`noise_autocovariance` reads it from the scene (the lags the scene's frames
    hold, missing ones 0), must be positive definite. Parameters read by name
    (``noise``, ``ar_coefficients``, ``frames``; unknown: not checked)."""
    a = tuple(getattr(scenario_params, "ar_coefficients", ()) or ())
    frames = getattr(scenario_params, "frames", None)
    if getattr(scenario_params, "noise", None) != "ar" or not a or not isinstance(frames, int):
        return None
    gamma = list(ar_autocovariance(a, max(frames - 1, 0))[:3]) + [0.0] * max(0, 3 - frames)
    try:
        ConditionalLLR.from_autocovariance(gamma, 1.0)
    except (ValueError, np.linalg.LinAlgError) as exc:
        return f"{exc} ({frames} frames of AR({len(a)}) noise)"
    return None


@register_method
class DpTbdMf(Method):
    r"""Multi-frame DP-TBD: (cell, previous cell) state, conditional LLR of the correlated noise plus a turn-angle prior.

    **Model.** Frame $k$ ($k = 0, \dots, K-1$) holds $z_k(x) = n_k(x) + s\, 1[x = x_k]$ on
    cells $x$, the target at $x_k$. The noise is independent across cells and, in
    each cell, a zero-mean stationary Gaussian process over frames with
    autocovariance $\gamma(h)$ (``scene.noise_autocovariance``). The amplitude
    $s$ is not known to the method: it assumes $s = \sigma\, 10^{D/20}$
    ($D$ = ``design_snr_db``, $\sigma$ = ``scene.noise_std``). A mismatch costs power only; the
    threshold is calibrated on null scenes, so the false-alarm rate holds.

    **State.** $(x_k, d_k)$, $d_k = x_k - x_{k-1}$ in the box window of radius $q$
    (:func:`window_radius`), i.e. the pair (current cell, previous cell).

    **Likelihood term.** By the chain rule, the path's log-likelihood ratio
    against noise alone is a sum over frames of conditional LLRs. "Along the
    path" the method scores, at frame $k$, the cell the path occupies, $x_k$, and
    conditions its value on the *same cell's* two previous frames: the noise
    is independent across cells, so values of other cells (including the
    path's own earlier cells $x_{k-1}$, $x_{k-2}$) carry no information about
    $n_k(x_k)$ (conditioning on them gives $\beta = 0$ and collapses to the white
    LLR); what the path decides is whether the target was in $x_k$ at $k-1$ and
    $k-2$. Write $e_1 = 1[x_{k-1} = x_k] = 1[d_k = 0]$ and $e_2 = 1[x_{k-2} = x_k] =
    1[d_k + d_{k-1} = 0]$. For $(n_k, n_{k-1}, n_{k-2})$ of one cell the
    covariance is the Toeplitz matrix of $(\gamma_0, \gamma_1, \gamma_2)$, so

    $$
    \begin{aligned}
    E[n_k \mid n_{k-1}, n_{k-2}] &= \beta_1 n_{k-1} + \beta_2 n_{k-2}, \\
    \begin{bmatrix} \beta_1 \\ \beta_2 \end{bmatrix} &=
      \begin{bmatrix} \gamma_0 & \gamma_1 \\ \gamma_1 & \gamma_0 \end{bmatrix}^{-1}
      \begin{bmatrix} \gamma_1 \\ \gamma_2 \end{bmatrix}, \\
    \sigma_c^2 &= \gamma_0 - \beta_1 \gamma_1 - \beta_2 \gamma_2.
    \end{aligned}
    $$

    Given $z_{k-1}(x_k)$, $z_{k-2}(x_k)$, the value $z_k(x_k)$ is Gaussian with
    variance $\sigma_c^2$ and mean $\beta_1 z_{k-1} + \beta_2 z_{k-2}$ under H0 (no
    target in the cell), $s + \beta_1 (z_{k-1} - s e_1) + \beta_2 (z_{k-2} - s e_2)$
    under the path hypothesis. With the residual
    $r_0 = z_k - \beta_1 z_{k-1} - \beta_2 z_{k-2}$ (all at $x_k$) and
    $r_1 = r_0 - s c$, $c = 1 - \beta_1 e_1 - \beta_2 e_2$:

    $$
    \Lambda_k(x_k; d_k, d_{k-1}) = \frac{r_0^2 - r_1^2}{2 \sigma_c^2}
      = \frac{s c}{\sigma_c^2} r_0 - \frac{s^2 c^2}{2 \sigma_c^2}.
    $$

    Four cases: $c = 1$ (new cell), $1 - \beta_2$ (back to the cell of $k-2$),
    $1 - \beta_1$ (stayed since $k-1$), $1 - \beta_1 - \beta_2$ (stayed since $k-2$).
    Frame 1 conditions on one previous frame: $\beta = \gamma_1 / \gamma_0$,
    $\sigma_c^2 = \gamma_0 - \gamma_1^2 / \gamma_0$, $c = 1$ or $1 - \beta$ ($d_1 = 0$);
    frame 0 on none: $\Lambda_0 = s z_0 / \gamma_0 - s^2 / (2 \gamma_0)$. The
    default tbd-grid noise (AR(3), $a = (-2, 1.7, -0.64)$, $\gamma_0 = 1$) gives
    $\beta = (1.545, -0.711)$, $\sigma_c^2 = 0.0915$ (the prediction removes
    10.4 dB of the noise power seen by a target entering a new cell) and
    $c = (1, 1.711, -0.545, 0.167)$: a target sitting in one cell is almost
    invisible in the prediction residual, as it should be for strongly
    low-pass noise. White noise gives $\beta = 0$, $c = 1$ and $\Lambda$ affine in
    $z$: the classic merit. Approximation, stated: the sum of these terms is
    the exact path LLR only for noise that is Markov of order 2 in each cell
    and ignoring the information the *unvisited* frames of a visited cell
    carry about its noise (a causal, path-local index, as in the paper).

    **Turn-angle term.** $\theta_k$ = the signed angle from $d_{k-1}$ to $d_k$ in
    $(-\pi, \pi]$; weight $\log p(\theta_k)$ with $p$ a density on $(-\pi, \pi]$ that is
    $\ge 0$, decreasing in $|\theta|$ and integrates to 1
    (:func:`turn_log_density`), $\kappa$ = ``turn_concentration``:

    $$
    p_{\text{von-mises}}(\theta) = \frac{e^{\kappa \cos\theta}}{2\pi I_0(\kappa)}, \qquad
    p_{\text{laplace}}(\theta) = \frac{\kappa\, e^{-\kappa |\theta|}}{2 (1 - e^{-\kappa\pi})}
    $$

    (the Laplace truncated); $\kappa = 0$ is uniform. Zero displacement: when
    $d_{k-1} = 0$ or $d_k = 0$ the heading, hence $\theta$, is undefined; such transitions
    get the uniform density $1/(2\pi)$ (the prior averaged over headings), so the turn
    term neither favours nor forbids a pause, and the LLR decides. Frame 1 has no
    previous displacement: the transition is uniform, weight $\log(1/(2\pi))$ for every
    $d_1$ ("uniform transition at frame 2"). $p(\theta)$ is used as a weight per
    transition (as in the paper), not renormalised over the discrete window;
    every path has the same number of transitions, so the constant does not
    bias path lengths.

    **Recursion.** The path score
    $\sum_k \Lambda_k + \sum_{k \ge 2} \log p(\theta_k) + [K-1 \ge 1] \log\frac{1}{2\pi}$
    is a sum of terms in consecutive states, so

    $$
    \begin{aligned}
    J_0(x) &= \Lambda_0(x), \\
    J_1(x, d) &= \Lambda_1(x; d) + \log\tfrac{1}{2\pi} + J_0(x - d), \\
    J_k(x, d) &= \max_{d'} \left[ J_{k-1}(x - d, d') + \log p(\theta(d', d)) + \Lambda_k(x; d, d') \right]
    \end{aligned}
    $$

    with backpointers $\psi_k(x, d)$ = the first maximising $d'$. Score
    $= \max_{x, d} J_{K-1}(x, d)$; track: from the argmax, $x_{k-1} = x_k - d_k$,
    $d_{k-1} = \psi_k(x_k, d_k)$; value map $= \max_d J_{K-1}(x, d)$. $\Lambda$
    depends on $d'$ only through $d' = -d$, so for each $d$ the generic
    predecessors share one $\Lambda$ plane and the special one gets its own.

    **Choosing the design SNR and the prior.** The constant term
    $-s^2 c^2 / (2 \sigma_c^2)$ makes entering a new cell ($c = 1$) cost more, the
    larger $s$, while sitting in a cell ($c = 0.167$ for the default noise) costs
    almost nothing: when $s$ is far above the true amplitude $A$ (beyond about
    $s = 2A$ the true path's expected LLR per frame, $s (A - s/2) / \sigma_c^2$,
    is negative), the best path stops following the target and the detector
    collapses. A small study (100 x 100 cells, 20 frames, Pfa 1e-2 from 300
    null scenes, 100 trials per point) gave Pd at true SNR -6 / -5 dB of
    0.37 / 0.84 (design 0 dB), 0.53 / 0.91 (2 dB), 0.10 / 0.56 (4 dB), with
    $\kappa = 5$; $\kappa = 3, 5, 8$ gave 0.46, 0.53, 0.62 at -6 dB (design 2 dB)
    and the truncated Laplace with $\kappa = 5$ matched von Mises with $\kappa = 8$.
    Defaults: design 2 dB, von Mises, $\kappa = 5$ (a 45 degree turn costs 1.5,
    a 90 degree one 5 nats, the scene's 20 degree-per-frame turn 0.3).

    **Along-track likelihood** (``likelihood = "along-track"``; the default
    ``"per-cell"`` is the conditional LLR above). The paper writes the index
    term as (eqs. 11-14)

    $$
    \ln \frac{p(z_k, z_{k-1}, z_{k-2} \mid X_k)}{p(z_{k-1}, z_{k-2} \mid X_k)}
      - \ln \frac{p(z_k, z_{k-1}, z_{k-2} \mid H_0)}{p(z_{k-1}, z_{k-2} \mid H_0)},
    $$

    with the 3-D and 2-D densities "均值为s，方差为σ²，相关系数为r的...联合高斯分布"
    (mean $s$, variance $\sigma^2$, correlation coefficient $r$) under H1 and mean 0
    under H0, the values taken along the track: $z_k(x_k)$, $z_{k-1}(x_{k-1})$,
    $z_{k-2}(x_{k-2})$. Reading: the paper models the noise sequence $v_k$ of
    eq. (4) as one AR process over scans and never distinguishes whether the
    track changed cells, so the correlation between the values $j$ frames
    apart along the track is the noise's lag-$j$ autocorrelation
    $\rho(j) = \gamma(j) / \gamma(0)$ whatever the cells (the Toeplitz matrix of
    $\gamma(0), \gamma(1), \gamma(2)$; "r" is $\rho(1)$, $\rho(2)$ follows from the AR model). This is
    the paper's model of the data, not ours: in the scene the noise of
    different cells is independent, so for a moving track the term subtracts
    the prediction from *other* cells' noise (:func:`along_track_llr`; the
    kernel is :mod:`methods.tbd.alongtrack`). Frame 1 uses the 2-D / 1-D
    ratio ($\rho(1)$), frame 0 the 1-D density.

    **Cost.** $(2q + 1)^4$ transitions per cell and frame (625 at $q = 2$).
    The kernels (:func:`methods.tbd.mf_kernels.dp_tbd_mf`,
    :func:`methods.tbd.alongtrack.dp_tbd_mf_along_track`) compute maxima
    only and recompute $\psi_k$ on the track; the turn weight depends on $d'$ and
    $d$ only through their headings, which factorises the maximum over $d'$
    (16 weighted candidates per heading instead of 24 per displacement at
    $q = 2$); the frames advance together row by row, and only the volumes
    $J_k$ of frames 1, 5, 9, ... and $K - 1$ are kept (about 150 MB at
    500 x 500 x 20, $q = 2$, for one trial at a time). Results are those of
    the original max + argmax kernels (``tests/tbd_kernels_oracle.py``) bit for
    bit. Default ``max_speed_m_s`` = 150 ($q = 2$) keeps the paper's true
    cell path admissible (see :class:`DpTbd`).
    """

    name = "dp-tbd-mf"
    task = TBD
    #: ``bench perf`` target at paper scale (500 x 500 cells, 20 frames, q = 2)
    perf_targets = {"paper": {"seconds_per_trial": 0.15}}

    @dataclass(frozen=True)
    class Params:
        max_speed_m_s: float = param(150.0, "largest target speed the transition window admits "
                                            "(m/s); window radius q = ceil(v T / cell_m) cells",
                                     gt=0.0, le=MAX_SPEED_M_S, why=SPEED_WHY)
        design_snr_db: float = param(2.0, "assumed target SNR 10 log10(s^2 / sigma^2) (dB) that sets "
                                          "the amplitude s in the log-likelihood ratio (methods are not "
                                          "told the true SNR); keep it within ~8 dB above the SNRs of "
                                          "interest (see the class docstring)", ge=-30.0, le=40.0,
                                     why="-30..40 dB spans every scene SNR of interest; the float32 "
                                         "merits keep their resolution within it")
        turn_prior: str = param("von-mises", "turn-angle density p(theta) on (-pi, pi]: "
                                             "'von-mises' or 'laplace' (truncated)",
                                choices=("von-mises", "laplace"))
        turn_concentration: float = param(5.0, "kappa of the turn-angle density (von Mises "
                                               "concentration, dimensionless; Laplace rate, 1/rad); "
                                               "0: uniform", ge=0.0, le=100.0,
                                      why="0 is the uniform density; at 100 the density is a spike "
                                          "(std 0.1 rad) and exp(kappa) stays far from float overflow")
        likelihood: str = param("per-cell", "index term: 'per-cell' (conditional LLR of the cell's own "
                                            "previous frames) or 'along-track' (the paper's 3-D / 2-D "
                                            "Gaussian ratio of the values along the track)",
                                choices=("per-cell", "along-track"))

    def run(self, batch: Batch, params) -> TBDOutput:
        z = _frames32(batch)
        q = window_radius(params.max_speed_m_s, batch)
        gamma = noise_autocovariance(batch)
        s = math.sqrt(gamma[0]) * 10.0 ** (params.design_snr_db / 20.0)
        llr = ConditionalLLR.from_autocovariance(gamma, s)
        coef0, const0 = llr.planes(np.array([1.0]), gamma[0])
        coef1, const1 = llr.planes(llr.c_frame1(), llr.var_first)
        coef2, const2 = llr.planes(llr.c_frame2(), llr.var)
        lp = transition_log_weights(q, params.turn_prior, params.turn_concentration).astype(np.float32)
        score, track, value = _outputs(z)
        if params.likelihood == "along-track":
            (a0,), (b0,) = coef0, const0
            a1, b1 = (x[1] for x in llr.planes(llr.c_frame1(), llr.var_first))
            a2, b2 = (x[3] for x in llr.planes(llr.c_frame2(), llr.var))
            alongtrack.dp_tbd_mf_along_track(
                z, q, lp, np.float32(LOG_UNIFORM_ANGLE), np.float32(llr.beta_first), np.float32(llr.beta1),
                np.float32(llr.beta2), a0, b0, a1, b1, a2, b2, score, track, value)
            return TBDOutput(score=score, track=track, value=value)
        mf_kernels.dp_tbd_mf(z, q, lp, np.float32(LOG_UNIFORM_ANGLE),
                               np.float32(llr.beta_first), np.array([llr.beta1, llr.beta2], np.float32),
                               coef0, const0, coef1, const1, coef2, const2, score, track, value)
        return TBDOutput(score=score, track=track, value=value)

    def work(self, batch: Batch, params) -> tuple[str, float]:
        """State transitions evaluated: cells x (2q+1)^4 x (frames - 2) per trial."""
        q = window_radius(params.max_speed_m_s, batch)
        n, K, H, W = batch.z.shape
        return "transitions", float(n * H * W * (2 * q + 1) ** 4 * max(K - 2, 0))

    def check_scenario(self, params, scenario_params) -> str | None:
        """The window radius (:func:`radius_problem`) and the conditional LLR's
        covariance (:func:`conditional_llr_problem`)."""
        return radius_problem(params.max_speed_m_s, scenario_params) or conditional_llr_problem(scenario_params)

    def unit_memory_bytes(self, params, scenario_params, n: int) -> int | None:
        """The kernel's int8 back-pointers (K, D, H, W) and float32 merit volumes
        (D, H, W) (four with the along-track likelihood, two otherwise) for one
        trial at a time, D = (2q + 1)^2 predecessors, and the (n, H, W) value maps."""
        shape = scene_shape(scenario_params)
        T, cell = getattr(scenario_params, "frame_period_s", None), getattr(scenario_params, "cell_m", None)
        if shape is None or not isinstance(T, float) or not isinstance(cell, float):
            return None
        K, H, W = shape
        q = max(1, math.ceil(params.max_speed_m_s * T / cell - 1e-9))
        D = (2 * q + 1) ** 2
        volumes = 4 if params.likelihood == "along-track" else 2
        return max(K, 3) * D * H * W + (4 * volumes + 1) * D * H * W + 32 * H * W + 4 * n * H * W

    # No nominal_threshold (bench.core.Method: NaN, none): the score is a maximum over all
    # cells and paths of a scene, whose null law has no closed form; calibrate on null
    # scenes (``empirical``, or ``gumbel`` or ``pot`` for small Pfa).
