"""Method ``wavelet``: Hong-style multiresolution test on the whitened innovation."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pywt
import scipy.stats

from radarbench.bench.core import Batch, DetectionOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.maneuver.base import InnovationDetector, sidak_level, steps_problem
from radarbench.models.kalman import InnovationSequence

MODES = ("decimated", "sliding")
COEFFICIENTS = ("approximation", "detail", "both")

#: largest filter-bank orthonormality error accepted for a wavelet: PyWavelets
#: flags ``dmey`` (an FIR approximation of the Meyer wavelet) as orthogonal,
#: but its filters are orthonormal only to ~2e-3, so its coefficients of white
#: noise are not exactly i.i.d. N(0, 1); haar, dbN, symN, coifN pass at ~1e-12.
ORTHONORMALITY_TOL = 1e-8


@functools.lru_cache(maxsize=None)
def orthonormality_error(wavelet: str) -> float:
    """max |<h, h(. - 2s)> - delta_s|, |<g, g(. - 2s)> - delta_s|, |<h, g(. - 2s)>|
    over the shifts s of the decomposition filters h (low-pass) and g
    (high-pass): zero for an orthonormal two-channel filter bank (Mallat 1989)."""
    w = pywt.Wavelet(wavelet)
    h, g = np.asarray(w.dec_lo), np.asarray(w.dec_hi)
    F = len(h)
    errors = [abs(h @ h - 1.0), abs(g @ g - 1.0)]
    for s in range(2, F, 2):
        errors += [abs(h[s:] @ h[:-s]), abs(g[s:] @ g[:-s])]
    for s in range(0, F, 2):
        errors += [abs(h[s:] @ g[:F - s]), abs(g[s:] @ h[:F - s])]
    return float(max(errors))


def check_wavelet(wavelet: str) -> None:
    """Raise ``ConfigError('wavelet', ...)`` unless PyWavelets knows ``wavelet``
    as a discrete wavelet with an orthonormal filter bank."""
    if wavelet not in pywt.wavelist(kind="discrete"):
        raise ConfigError("wavelet", f"unknown wavelet {wavelet!r}: expected an orthogonal "
                          "discrete wavelet of PyWavelets, e.g. 'haar', 'db2', 'sym4', 'coif1'")
    if not pywt.Wavelet(wavelet).orthogonal:
        raise ConfigError("wavelet", f"{wavelet!r} is not orthogonal (biorthogonal): its "
                          "coefficients of white noise are not i.i.d. N(0, 1), so the chi2 "
                          "threshold would not hold; use haar, dbN, symN or coifN")
    err = orthonormality_error(wavelet)
    if err > ORTHONORMALITY_TOL:
        raise ConfigError("wavelet", f"{wavelet!r} is only approximately orthogonal (filter-bank "
                          f"orthonormality error {err:.1e}); use haar, dbN, symN or coifN")


@functools.lru_cache(maxsize=None)
def _alignment(wavelet: str, levels: int) -> tuple[tuple[int, int], ...]:
    """Per level j = 1..levels, ``(newest, support)`` of PyWavelets' stationary
    transform: output index i of ``pywt.swt`` at level j depends on the input
    samples i + newest - support + 1 .. i + newest (no others).

    Measured once from the response to an impulse, so the causal alignment does
    not rely on PyWavelets' internal indexing convention. ``support`` is
    (F - 1)(2^j - 1) + 1 for a filter of length F (2^j for Haar), less if end
    taps vanish.
    """
    F = pywt.Wavelet(wavelet).dec_len
    longest = (F - 1) * (2 ** levels - 1) + 1
    block = 2 ** levels
    length = -(-4 * longest // block) * block
    p0 = length // 2
    impulse = np.zeros(length)
    impulse[p0] = 1.0
    out = pywt.swt(impulse, wavelet, level=levels)          # coarsest level first
    result = []
    for j in range(1, levels + 1):
        cA, cD = out[levels - j]
        energy = cA ** 2 + cD ** 2
        nz = np.flatnonzero(energy > 1e-24 * energy.max())
        lo, hi = int(nz[0]), int(nz[-1])
        result.append((p0 - lo, hi - lo + 1))
    return tuple(result)


def support(wavelet: str, level: int) -> int:
    """Samples that one level-``level`` coefficient spans: 2^j for Haar,
    (F - 1)(2^j - 1) + 1 for a filter of length F."""
    return _alignment(wavelet, level)[level - 1][1]


def first_step(wavelet: str, level: int, mode: str) -> int:
    """First step at which a level-``level`` coefficient exists (zeros before).

    sliding: the first full window, support - 1. decimated: the first release
    step k with (k + 1) a multiple of 2^j and a full support, i.e.
    2^j ceil(support / 2^j) - 1 (2^j - 1 for Haar).
    """
    N = support(wavelet, level)
    if mode == "sliding":
        return N - 1
    L = 2 ** level
    return -(-N // L) * L - 1


def valid_from(wavelet: str, levels: int, coarsest: int, mode: str) -> int:
    """First step at which every tested level (levels - coarsest + 1 .. levels)
    has a coefficient: 2^J - 1 for Haar in either mode."""
    return max(first_step(wavelet, j, mode) for j in tested_levels(levels, coarsest))


def tested_levels(levels: int, coarsest: int) -> range:
    """The ``coarsest`` coarsest levels: J - coarsest + 1 .. J."""
    return range(levels - coarsest + 1, levels + 1)


@dataclass(frozen=True)
class LevelCoefficients:
    """Causal coefficients of one level, aligned on the step axis.

    approximation, detail : like the input, (n, K) or (n, K, m); at step k the
        coefficient of the last window (sliding) or of the last complete block
        (decimated, held until the next block ends) that ends at or before k;
        zero before ``first_step``.
    first_step : first step with a coefficient.
    release : (K,) bool, True at the steps where a new coefficient becomes
        available (every step from ``first_step`` in sliding mode; the block
        ends k = b 2^j - 1 in decimated mode).
    """

    level: int
    approximation: np.ndarray
    detail: np.ndarray
    first_step: int
    release: np.ndarray


def causal_coefficients(x: np.ndarray, wavelet: str = "haar", levels: int = 4,
                        mode: str = "decimated") -> dict[int, LevelCoefficients]:
    """Causal orthonormal wavelet coefficients of ``x`` at levels 1..``levels``.

    ``x`` is (n, K) or (n, K, m), transformed along axis 1 for every trial and
    component at once with ``pywt.swt`` (the undecimated transform, unnormalised
    ``norm=False``, so every coefficient is the inner product of x with a
    unit-norm function). The transform is periodic; it runs on x zero-padded
    on the right to a multiple of 2^levels, and each output is re-indexed to
    the step of its newest sample (:func:`_alignment`). Outputs whose window
    is not entirely inside 0..k (start-up, or the periodic wrap) are set to
    zero, so the coefficient at step k depends on x[:, :k + 1] only.

    * ``sliding``: at step k, the coefficient of the last ``support`` samples.
    * ``decimated``: only the coefficients at block ends, (k + 1) = 0 mod 2^j,
      are kept and held until the next one. They are the decimated DWT of x
      (Mallat's pyramid: level j+1 at a block end uses level j at block ends
      only), orthonormal, so i.i.d. N(0, 1) for white N(0, 1) input.

    For Haar, with L = 2^j and the PyWavelets filters dec_lo = [1, 1]/sqrt 2,
    dec_hi = [-1, 1]/sqrt 2 (correlation order: older sample first):
    approximation = (sum of the last L samples) / sqrt(L),
    detail = (sum of the older L/2 - sum of the newer L/2) / sqrt(L),
    so a step up gives a negative detail.
    """
    if mode not in MODES:
        raise ConfigError("mode", f"expected one of {', '.join(map(repr, MODES))}, got {mode!r}")
    x = np.asarray(x, dtype=np.float64)
    squeeze = x.ndim == 2
    x3 = x[..., None] if squeeze else x
    n, K, m = x3.shape
    block = 2 ** levels
    total = max(block, -(-K // block) * block)
    padded = np.zeros((n, total, m))
    padded[:, :K] = x3
    out = pywt.swt(padded, wavelet, level=levels, axis=1)   # [(cA_J, cD_J), ..., (cA_1, cD_1)]
    steps = np.arange(K)
    result = {}
    for j, (newest, _) in enumerate(_alignment(wavelet, levels), start=1):
        cA, cD = out[levels - j]
        first = first_step(wavelet, j, mode)
        if mode == "decimated":
            L = 2 ** j
            source = ((steps + 1) // L) * L - 1           # last block end <= k
            release = ((steps + 1) % L == 0) & (steps >= first)
        else:
            source = steps
            release = steps >= first
        index = (source - newest) % total
        keep = (steps >= first)[None, :, None]
        a = np.where(keep, cA[:, index], 0.0)
        d = np.where(keep, cD[:, index], 0.0)
        if squeeze:
            a, d = a[..., 0], d[..., 0]
        result[j] = LevelCoefficients(level=j, approximation=a, detail=d, first_step=first,
                                      release=release)
    return result


@dataclass(frozen=True)
class WaveletStatistic:
    """Output of :func:`wavelet_statistic`.

    statistic : (n, K) max over the tested levels of the level statistics,
        zero before ``valid_from``.
    per_level : {j: (n, K)} sum of the squared selected coefficients of level
        j over the components, zero before the level's first coefficient.
    valid_from : first step at which every tested level has a coefficient.
    """

    statistic: np.ndarray
    per_level: dict[int, np.ndarray]
    valid_from: int


def wavelet_statistic(x: np.ndarray, wavelet: str = "haar", levels: int = 4, coarsest: int = 2,
                      coefficients: str = "both", mode: str = "decimated") -> WaveletStatistic:
    """The detector's kernel on a whitened innovation ``x`` (n, K) or (n, K, m).

    T_j(k) = sum_i [A_j,i(k)^2] + [D_j,i(k)^2] (the bracketed terms selected by
    ``coefficients``), T(k) = max over j in J-coarsest+1..J of T_j(k), with the
    causal coefficients of :func:`causal_coefficients`. Causal: T(k) depends
    on x[:, :k + 1] only.
    """
    if coefficients not in COEFFICIENTS:
        raise ConfigError("coefficients", f"expected one of {', '.join(map(repr, COEFFICIENTS))}, "
                          f"got {coefficients!r}")
    if not 1 <= coarsest <= levels:
        raise ConfigError("coarsest", f"expected an int between 1 and levels = {levels}, "
                          f"got {coarsest!r}")
    x = np.asarray(x, dtype=np.float64)
    x3 = x[..., None] if x.ndim == 2 else x
    coefs = causal_coefficients(x3, wavelet, levels, mode)
    per_level = {}
    for j in tested_levels(levels, coarsest):
        c = coefs[j]
        T = np.zeros(x3.shape[:2])
        if coefficients in ("approximation", "both"):
            T += np.sum(c.approximation ** 2, axis=-1)
        if coefficients in ("detail", "both"):
            T += np.sum(c.detail ** 2, axis=-1)
        per_level[j] = T
    start = valid_from(wavelet, levels, coarsest, mode)
    statistic = np.max(np.stack(list(per_level.values())), axis=0)
    statistic[:, :start] = 0.0
    return WaveletStatistic(statistic=statistic, per_level=per_level, valid_from=start)


def null_threshold(pfa: float, df: int, n_levels: int) -> float:
    """Sidak threshold of the max of ``n_levels`` chi2(df) statistics:
    chi2.isf(alpha, df) with alpha = 1 - (1 - pfa)^(1 / n_levels), computed as
    -expm1(log1p(-pfa) / n_levels) (:func:`methods.maneuver.base.sidak_level`) so it
    stays finite down to the smallest pfa."""
    return float(scipy.stats.chi2.isf(sidak_level(pfa, n_levels), df))


@register_method
class Wavelet(InnovationDetector):
    r"""Multiresolution (wavelet) test of the whitened innovation at the coarse levels, after Hong.

    After L. Hong, "Multiresolutional filtering using wavelet transform", IEEE
    TAES 29(4), 1993, and "Multiresolutional multiple-model target tracking",
    IEEE TAES 30(2), 1994: the innovation is analysed on a dyadic pyramid of
    resolutions; a maneuver shows first as a bias of the innovation, which
    the coarse (long-block) approximation accumulates. Transform: Mallat,
    "A theory for multiresolution signal decomposition: the wavelet
    representation", IEEE PAMI 11(7), 1989; stationary variant: Nason &
    Silverman, "The stationary wavelet transform and some statistical
    applications", Lecture Notes in Statistics 103, 1995. PyWavelets does the
    transforms (:func:`causal_coefficients`).

    Input: the whitened innovation $x_k = L_k^{-1} \nu_k$ of the scenario's
    reference filter (:func:`models.kalman.innovations`), i.i.d. $\mathcal{N}(0, I_m)$
    under the null. Each component is decomposed to level $J$ = ``levels``
    with an orthonormal wavelet (``wavelet``; Haar by default). For Haar and
    a block of $L = 2^j$ samples ending at step $k$ (pyramid $A_0 = x$,
    $A_{j+1} = (A_{j,\text{older}} + A_{j,\text{newer}})/\sqrt{2}$,
    $D_{j+1} = (A_{j,\text{older}} - A_{j,\text{newer}})/\sqrt{2}$):

    $$
    \begin{aligned}
    A_j(k) &= L^{-1/2} \sum_{t=k-L+1}^{k} x_t, \\
    D_j(k) &= L^{-1/2} \Big( \sum_{t=k-L+1}^{k-L/2} x_t - \sum_{t=k-L/2+1}^{k} x_t \Big)
    \end{aligned}
    $$

    A step bias $\mu$ from inside the block with $p$ biased samples gives
    $A_j = \mu p / \sqrt{L}$ ($\mu \sqrt{L}$ for a fully biased block) and
    $|D_j| \le \mu \sqrt{L} / 2$ (onset at the block midpoint; zero once the block
    is fully biased): the approximation sees the bias, the detail the onset.

    Causal, two modes (``mode``):

    * ``decimated`` (Hong's pyramid, default): level-$j$ coefficients are those
      of consecutive non-overlapping blocks of $2^j$ samples (for Haar); one
      becomes available at the end of its block, $k = b\, 2^j - 1$, and is held
      until the next block ends. The wait for the block end is the method's
      inherent delay: $(2^j - 1)/2$ steps on average over the onset phase, on
      top of the time the bias needs to build up. For a longer orthogonal
      filter (length $F$: dbN, symN, coifN) a level-$j$ coefficient spans
      $(F - 1)(2^j - 1) + 1$ samples, so consecutive supports overlap; the
      coefficients are still released every $2^j$ steps (at the same block
      ends), each at the end of its support, and still form an orthonormal
      set (the decimated DWT), but the delay grows with the support.
    * ``sliding``: the undecimated (stationary) transform at every step on the
      last support ($2^j$ for Haar) samples: shorter delay, coefficients
      correlated over time.

    Statistic at step $k$ (:func:`wavelet_statistic`): $T(k) = \max_j T_j(k)$ over the
    tested levels $j = J - c + 1, \dots, J$ ($c$ = ``coarsest`` coarsest levels; by
    default $J-1$ and $J$), $T_j(k) = \sum_i A_{j,i}(k)^2$ and/or $\sum_i D_{j,i}(k)^2$
    over the components $i$ (``coefficients``). Coefficients of an orthonormal transform
    of white $\mathcal{N}(0, 1)$ noise are i.i.d. $\mathcal{N}(0, 1)$ and $A_j$, $D_j$ of the same
    block are orthogonal, so $T_j(k) \sim \chi^2(\mathrm{df})$ exactly under the null, with
    $\mathrm{df} = m$ (one kind) or $2m$ (``both``). Nominal threshold: Šidák across the
    tested levels, ``chi2.isf(alpha, df)`` with $\alpha = 1 - (1 - P_{fa})^{1/c}$. The levels
    are correlated (nested blocks: $A_J = (A_{J-1,\text{older}} + A_{J-1,\text{newer}})/\sqrt{2}$),
    so this is approximate; since each event $\{T_j \le t\}$ is a symmetric convex set
    of Gaussian coefficients, the Gaussian correlation inequality (Royen 2014) makes it
    conservative (true per-step Pfa $\le P_{fa}$). The harness's empirical calibration
    corrects it.

    ``valid_from``: the first step at which every tested level has a complete
    block (decimated) or window (sliding): $2^J - 1$ for Haar, later for longer
    filters (:func:`valid_from`). The statistic is 0 before it (never NaN),
    and each level trace is 0 before that level's first coefficient. A
    configuration whose ``valid_from`` is not before the scenario's last step
    raises ConfigError naming ``levels``. Traces: ``innovation_i`` (whitened
    components) and ``level_j`` ($T_j$ of each tested level).
    """

    name = "wavelet"

    @dataclass(frozen=True)
    class Params:
        wavelet: str = param("haar", "orthogonal discrete wavelet of PyWavelets (haar, dbN, symN, "
                             "coifN); longer filters span more samples per coefficient")
        levels: int = param(4, "decomposition depth J: the coarsest block is 2^J steps", ge=1, le=8,
                            why="a block of 2^8 = 256 steps is longer than a maneuver; the first complete "
                                "coarsest block must fall within the scenario's steps (checked per "
                                "scenario config)")
        coarsest: int = param(2, "number of coarsest levels tested (J-coarsest+1 .. J); "
                              "1 <= coarsest <= levels", ge=1, le=8,
                              why="one tested level at least, at most the levels there are")
        coefficients: str = param("both", "coefficients tested: approximation (bias), detail "
                                  "(onset) or both", choices=COEFFICIENTS)
        mode: str = param("decimated", "decimated: non-overlapping blocks, coefficient held "
                          "until the next block ends (Hong); sliding: undecimated transform "
                          "at every step", choices=MODES)

        def validate(self) -> None:
            check_wavelet(self.wavelet)
            if self.coarsest > self.levels:
                raise ConfigError("coarsest", f"expected an int between 1 and levels = "
                                  f"{self.levels}, got {self.coarsest}")

    def detect(self, batch: Batch, inn: InnovationSequence, params) -> DetectionOutput:
        start = self.valid_from(params, batch.steps)
        if start >= batch.steps:
            raise ConfigError("levels", f"level {params.levels} of {params.wavelet!r} "
                              f"({params.mode}) first forms at step {start}, but the scenario "
                              f"has {batch.steps} steps; use fewer levels")
        x = inn.whitened                                   # (n, K, m)
        result = wavelet_statistic(x, params.wavelet, params.levels, params.coarsest,
                                   params.coefficients, params.mode)
        traces = {f"innovation_{i}": x[..., i] for i in range(x.shape[-1])}
        traces.update({f"level_{j}": T for j, T in result.per_level.items()})
        return DetectionOutput(statistic=result.statistic, valid_from=result.valid_from,
                               traces=traces)

    def nominal_threshold(self, params, pfa: float, batch: Batch) -> float:
        n_z = self.measurement_dim(batch)
        df = n_z * (2 if params.coefficients == "both" else 1)
        return null_threshold(pfa, df, params.coarsest)

    def valid_from(self, params, steps: int) -> int:
        """Once every tested level has a complete coefficient (:func:`valid_from`)."""
        return valid_from(params.wavelet, params.levels, params.coarsest, params.mode)

    def check_scenario(self, params, scenario_params) -> str | None:
        start = self.valid_from(params, getattr(scenario_params, "steps", 0))
        return steps_problem(start, f"level {params.levels} of {params.wavelet!r} ({params.mode})",
                             scenario_params)
