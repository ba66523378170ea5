"""Method ``cumulant``: third-order cumulant test on the whitened innovation."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.stats

from radarbench.bench.core import Batch, DetectionOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.models.windows import sliding_sum
from radarbench.methods.maneuver.base import MAX_WINDOW_STEPS, InnovationDetector, sidak_level, steps_problem
from radarbench.models.kalman import InnovationSequence


def window_lengths(steps: int, M: int) -> np.ndarray:
    """L_k = min(k + 1, M): samples in the (possibly partial) window at step k."""
    return np.minimum(np.arange(1, steps + 1), M).astype(float)


def window_third_moment(x: np.ndarray, M: int, centred: bool) -> np.ndarray:
    """Sliding-window third moment of ``x`` (n, K) over its last ``M`` samples.

    raw:     m3_k = (1/L) sum x_j^3
    centred: m3_k = (1/L) sum (x_j - xbar_k)^3, xbar_k the window mean,
             the zero-lag third-order cumulant estimate,
    with the sums over j = k-L+1 .. k and L = min(k+1, M) (partial windows
    at the start). All windows at once from cumulative sums S_p = sum x^p:
    sum (x - xbar)^3 = S3 - 3 xbar S2 + 3 xbar^2 S1 - L xbar^3
                     = S3 - 3 xbar S2 + 2 L xbar^3   (S1 = L xbar).
    The expansion cancels when |xbar| >> the spread; in float64 that costs
    ~1e-16 (|xbar| + spread)^3 K absolute, harmless at detector scales.
    """
    x = np.asarray(x, dtype=np.float64)
    L = window_lengths(x.shape[1], M)
    S3 = sliding_sum(x ** 3, M)
    if not centred:
        return S3 / L
    S1 = sliding_sum(x, M)
    S2 = sliding_sum(x ** 2, M)
    xbar = S1 / L
    return (S3 - 3.0 * xbar * S2 + 2.0 * L * xbar ** 3) / L


def lagged_deviation(x: np.ndarray, M: int) -> np.ndarray:
    """Step 1 of Song, Ji & Gao (2004): each sample minus the mean of the M samples before it.

    x̄(k) = (1/M) Σ_{i=k−M}^{k−1} x(i) for k ≥ M, x̄(k) = x̄(M) for k < M,
    x̃(k) = x(k) − x̄(k), along axis 1 of ``x`` (n, K). Needs K ≥ M (x̄(M)
    is the mean of x(0..M−1)); with fewer samples no x̄ exists and NaN is
    returned.
    """
    x = np.asarray(x, dtype=np.float64)
    n, K = x.shape
    if K < M:
        return np.full_like(x, np.nan)
    S1 = sliding_sum(x, M)                  # S1[:, k] = sum x(k-M+1 .. k)
    xbar = np.empty_like(x)
    xbar[:, M:] = S1[:, M - 1:K - 1] / M    # x̄(k) = S1[k-1] / M, k >= M
    xbar[:, :M] = S1[:, M - 1:M] / M        # x̄(M) for k < M
    return x - xbar


def window_power_sums(x: np.ndarray, M: int, centre: np.ndarray | None,
                      powers: tuple[int, ...]) -> dict[int, np.ndarray]:
    """Sliding-window sums Σ_j (x_j − a_k)^p, j over the last L = min(k+1, M)
    samples, for each p in ``powers``; ``centre`` a_k (n, K) or None (a = 0).

    Binomial expansion on the raw power sums S_q = Σ x^q (one
    :func:`models.windows.sliding_sum` each):
    Σ (x − a)^p = Σ_q C(p, q) (−a)^(p−q) S_q, with S_0 = L.
    """
    x = np.asarray(x, dtype=np.float64)
    if centre is None:
        return {p: sliding_sum(x ** p, M) for p in powers}
    L = window_lengths(x.shape[1], M)[None, :]
    top = max(powers)
    S = {0: np.broadcast_to(L, x.shape)} | {q: sliding_sum(x ** q, M) for q in range(1, top + 1)}
    return {p: sum(math.comb(p, q) * (-centre) ** (p - q) * S[q] for q in range(p + 1)) for p in powers}


def third_moment_null_variance(L: np.ndarray, centred: bool) -> np.ndarray:
    """Exact variance of the window third moment for i.i.d. N(0, 1) samples.

    raw: E[x^6] / L = 15 / L. centred: 6 (L-1)(L-2) / L^3 (the sample third
    central moment of a normal sample; asymptotically 6 / L).
    """
    if centred:
        return 6.0 * (L - 1.0) * (L - 2.0) / L ** 3
    return 15.0 / L


@register_method
class Cumulant(InnovationDetector):
    r"""Sliding-window third-order (zero-lag) cumulant of the whitened innovation, chi-square test.

    After Song, Ji & Gao (2004), "A new method of maneuver detection based on
    higher-order cumulants", Acta Electronica Sinica; the cumulant statistics
    after Giannakis & Tsatsanis, IEEE TASSP 38(7), 1990. Under the null the
    whitened innovation $x$ (:func:`models.kalman.innovations`) is i.i.d.
    $\mathcal{N}(0, 1)$ per component, so its third-order cumulant is zero; a maneuver
    biases the innovation and, while a window straddles the onset, skews it.

    Per component $i$, over the last $M$ samples (:func:`window_third_moment`):

    * ``moment = "centred"`` (default): $c_3 = \frac{1}{M} \sum (x - \bar{x})^3$, the
      zero-lag third-order cumulant. It is blind to a *constant* bias: for a
      window that straddles a step bias $\mu$ with biased fraction $p$,
      $\kappa_3 = p (1-p) (1-2p) \mu^3$, so it reacts to the onset transient,
      vanishes at $p = 1/2$ and once the window is fully biased.
    * ``moment = "raw"``: $c_3 = \frac{1}{M} \sum x^3$, which also sees a constant bias
      ($\mu^3 + 3 \mu$).
    * ``moment = "lagged"``: the paper's Steps 1-2 (sec. 3). Step 1 de-means
      each sample by the mean of the $M$ samples *before* it (:func:`lagged_deviation`),
      $\tilde{x}(k) = x(k) - \bar{x}(k)$; Step 2, eq. (9),
      $\hat{c}_{3x}^{(i)} = \frac{1}{M} \sum_{k=i-M}^{i-1} \tilde{x}^3(k)$.
      A turn's bias, a ramp then a near-constant level in the innovation, is
      not removed by a lagged mean while it grows, so this moment is not blind
      to it the way the same-window centring is. Time index: the paper's
      window for "sample $i$" is the $M$ samples $i-M, \dots, i-1$; here the statistic
      at step $k$ is the one whose window ends at $k$ (the paper's $i = k + 1$),
      i.e. the decision made when sample $k$ arrives, as Step 5 describes
      ("当第 i+1 个观测数据到来时, 用最新的 M 个观测数据重复步骤1~4", when
      sample $i+1$ arrives, repeat Steps 1-4 on the latest $M$ samples). $\tilde{x}(k)$
      for $k < M$ uses $\bar{x}(M)$, the mean of $x(0), \dots, x(M-1)$, known at step $M-1$, so the
      first window is complete, without look-ahead, at step $M-1$: the
      statistic is zero before it and ``valid_from = M − 1``.

    Variance $V$ of the normalisation:

    * ``variance = "model"`` (default): the exact null variance below
      (centred and raw only; the lagged moment's windows overlap the means
      they are de-meaned by, so it has no simple closed form);
    * ``variance = "sample"``: the paper's Step 3, eq. (10), the sample
      variance of the cubed values over the same window (for "centred" the
      cubes are of $x$ minus the window mean, for "raw" of $x$):

    $$
    \sigma^2(\hat{c}_{3x}^{(i)}) \approx \frac{1}{M} \sum_{k=i-M}^{i-1}
        \left(\tilde{x}^3(k) - \hat{c}_{3x}^{(i)}\right)^2 \qquad (10)
    $$

    Normalised statistic $T_i = c_3^2 / V$:

    * ``"consistent"`` (default): $V = \operatorname{Var}(c_3)$ under the null, exactly
      $6 (M-1)(M-2) / M^3$ (centred) or $15 / M$ (raw), so $T_i \sim \chi^2(1)$
      asymptotically in $M$; with the sample variance, $V = \hat{\sigma}^2 / M$
      ($T_i = M \hat{c}^2 / \hat{\sigma}^2$).
    * ``"paper"``: the normalisation as printed, eq. (11),
      $\bar{c}_{3x}^{(i)} = (\hat{c}_{3x}^{(i)})^2 / \sigma^2(\hat{c}_{3x}^{(i)})$, with $\sigma^2$ the
      variance of $x^3$ (model: 15 raw, $6 (M-1)(M-2) / M^2$ centred; sample: eq. 10), i.e. the
      consistent statistic divided by $M$: $M$ times too small for the $\chi^2(1)$ test eq. (8)
      compares it with. The nominal threshold is the same $\chi^2$ quantile for
      both, as in the paper, so the calibration table shows the paper's
      miscalibration.

    The paper works on the "观测数据" (observed data) $x(k)$, a scalar sequence
    whose Gaussian part is the measurement noise; it does not say which
    sequence of a tracker that is. Every detector here works on the whitened
    innovation of the reference CV filter (:func:`models.kalman.innovations`),
    one sequence per measurement component, so the paper's scalar test runs
    per component and ``combine`` joins them.

    Components are combined by ``"sum"`` ($\sum_i T_i \sim \chi^2(n_z)$, the whitened
    components being independent) or ``"max"`` ($\max_i T_i$ against the
    $\chi^2(1)$ quantile at per-component level $1 - (1 - P_{fa})^{1/n_z}$).
    Before the window fills ($k < M-1$) the statistic uses the partial window
    of $L = k+1$ samples with $M$ replaced by $L$ (zero where the centred variance
    vanishes, $L \le 2$); ``valid_from = M - 1``. $c_3$ of a non-Gaussian sum
    converges slowly, so the $\chi^2$ law is only approximate at small $M$.
    """

    name = "cumulant"

    @dataclass(frozen=True)
    class Params:
        window: int = param(32, "sliding-window length M (steps)", ge=3, le=MAX_WINDOW_STEPS,
                            why="3 samples are the fewest with a non-zero centred third moment; at most the "
                                "longest scene (10 000 steps), and at most the scenario's steps (checked "
                                "per scenario config)")
        moment: str = param("centred", "centred: de-meaned third moment (cumulant); "
                            "raw: (1/M) sum x^3; lagged: the paper's Steps 1-2, de-meaned by the "
                            "mean of the M samples before each sample", choices=("centred", "raw", "lagged"))
        combine: str = param("sum", "sum: sum over components ~ chi2(n_z); "
                             "max: max over components", choices=("sum", "max"))
        normalisation: str = param(
            "consistent", "consistent: c3^2 / Var(c3); paper: c3^2 / Var(x^3) as "
            "printed (M times too small)", choices=("consistent", "paper"))
        variance: str = param(
            "model", "model: exact null variance of the cubes (centred, raw); sample: "
            "their sample variance over the window (the paper's eq. 10)",
            choices=("model", "sample"))

        def validate(self) -> None:
            if self.moment == "lagged" and self.variance != "sample":
                raise ConfigError("variance", 'moment = "lagged" needs variance = "sample" '
                                  "(no closed-form null variance)")

    def detect(self, batch: Batch, inn: InnovationSequence, params) -> DetectionOutput:
        x = inn.whitened                                   # (n, K, m)
        if params.variance == "sample":
            return self._run_sample_variance(x, params)
        centred = params.moment == "centred"
        L = window_lengths(x.shape[1], params.window)
        V = third_moment_null_variance(L, centred)
        if params.normalisation == "paper":
            V = V * L                                      # Var(x^3), per sample
        per_axis = np.stack([window_third_moment(x[..., i], params.window, centred) ** 2
                             for i in range(x.shape[-1])], axis=-1)
        per_axis = np.divide(per_axis, V[None, :, None], out=np.zeros_like(per_axis),
                             where=V[None, :, None] > 0)
        statistic = per_axis.sum(axis=-1) if params.combine == "sum" else per_axis.max(axis=-1)
        traces = {f"innovation_{i}": x[..., i] for i in range(x.shape[-1])}
        return DetectionOutput(statistic=statistic, valid_from=self.valid_from(params, x.shape[1]),
                               traces=traces)

    def _run_sample_variance(self, x: np.ndarray, params) -> DetectionOutput:
        """Steps 1-4 with the sample variance (eqs. 9-11), per component."""
        M = params.window
        per_axis = np.stack([sample_normalised_cumulant(x[..., i], M, params.moment, params.normalisation)
                             for i in range(x.shape[-1])], axis=-1)
        statistic = per_axis.sum(axis=-1) if params.combine == "sum" else per_axis.max(axis=-1)
        traces = {f"innovation_{i}": x[..., i] for i in range(x.shape[-1])}
        return DetectionOutput(statistic=statistic, valid_from=self.valid_from(params, x.shape[1]), traces=traces)

    def valid_from(self, params, steps: int) -> int:
        """Once the window of M steps is full (the last step if the scene is shorter)."""
        return min(params.window, steps) - 1

    def nominal_threshold(self, params, pfa: float, batch: Batch) -> float:
        """The chi2 quantile of eq. (8): chi2(n_z) for the sum, chi2(1) per
        component (at the Sidak level 1 - (1 - pfa)^(1/n_z)) for the max, both
        by the survival-function inverse (finite down to the smallest pfa)."""
        n_z = self.measurement_dim(batch)
        if params.combine == "sum":
            return float(scipy.stats.chi2.isf(pfa, n_z))
        return float(scipy.stats.chi2.isf(sidak_level(pfa, n_z), 1))

    def check_scenario(self, params, scenario_params) -> str | None:
        return steps_problem(params.window - 1, f"the window of {params.window} steps", scenario_params)



def sample_normalised_cumulant(x: np.ndarray, M: int, moment: str, normalisation: str) -> np.ndarray:
    """The normalised cumulant of one component ``x`` (n, K) with the sample
    variance of the cubes: Song, Ji & Gao (2004), sec. 3,

        (9)  ĉ⁽ⁱ⁾ = (1/M) Σ_{k=i−M}^{i−1} x̃³(k)
        (10) σ²(ĉ⁽ⁱ⁾) ≈ (1/M) Σ_{k=i−M}^{i−1} (x̃³(k) − ĉ⁽ⁱ⁾)²
        (11) c̄⁽ⁱ⁾ = (ĉ⁽ⁱ⁾)² / σ²(ĉ⁽ⁱ⁾)

    computed for every window at once from sliding sums of the cubes and
    sixth powers: σ² = (1/L) Σ y⁶ − ĉ², y the de-meaned values. ``moment``:
    "lagged" (Step 1, x̃ = x − mean of the M samples before; zero before the
    first full window at step M−1), "centred" (y = x − window mean) or "raw"
    (y = x), the last two with partial windows L = k+1 at the start.
    ``normalisation`` "paper" is eq. (11) as printed; "consistent" multiplies
    it by L, the estimate of ĉ² / Var(ĉ). Zero where σ² vanishes.
    """
    x = np.asarray(x, dtype=np.float64)
    K = x.shape[1]
    L = np.broadcast_to(window_lengths(K, M)[None, :], x.shape)
    if moment == "lagged":
        sums = window_power_sums(lagged_deviation(x, M), M, None, (3, 6))
    else:
        centre = sliding_sum(x, M) / L if moment == "centred" else None
        sums = window_power_sums(x, M, centre, (3, 6))
    c3 = sums[3] / L
    var = sums[6] / L - c3 ** 2
    scale = L if normalisation == "consistent" else 1.0
    ok = var > 1e-12 * (sums[6] / L)          # a (near-)constant window carries no test
    if moment == "lagged":
        ok &= np.arange(K)[None, :] >= M - 1
    out = np.zeros_like(x)
    np.divide(scale * c3 ** 2, var, out=out, where=ok)
    return out
