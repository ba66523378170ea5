r"""GO- and SO-CFAR: the greatest-of and smallest-of the two half-windows'
means as the noise estimate, their closed-form false-alarm probabilities and
threshold factors (:mod:`models.cfar`; docs/architecture.md, 'Models').

The CFAR detectors of the HFSWR chain (hfswr-cfar-mn-jpda-ukf in the shared
papers, sec. 1 "CFAR检测") run along range and along Doppler separately, each
with a 1-D window of L reference cells on each side of the cell under test
(behind ``guard`` cells). GO and SO keep that geometry: along each axis the
two halves are the leading side ($i - g - L, \dots, i - g - 1$) and the lagging side
($i + g + 1, \dots, i + g + L$), cut at the map's edges exactly as CA's window
(:func:`models.cfar.window_counts`: $n_l$, $n_r$ cells). With the half means
$m_l = \frac{1}{n_l} \sum_{\text{left}}$, $m_r = \frac{1}{n_r} \sum_{\text{right}}$,

$$
\text{GO: } \mu = \max(m_l, m_r), \qquad \text{SO: } \mu = \min(m_l, m_r),
$$

and a cell whose one half lies wholly outside the map uses the other half
alone (then $\mu$ is CA's mean and its Pfa CA's closed form at $N' = n$). The
dimensions are combined and the peak detection folded in as for CA and OS.

**Closed forms.** For square-law detected (exponential) noise, $x > T\mu$ with
independent halves (sums $\Gamma(n_l)$, $\Gamma(n_r)$), conditioning on which half
is the larger (ours, by direct integration; for $n_l = n_r = n$ they reduce to
the forms of Hansen & Sawyers 1980 and Gandhi & Kassam 1988):

$$
\begin{aligned}
P_{fa}^{SO}(T) &= \sum_{a \in \{l, r\}} (1 + T/n_a)^{-n_a}\, I_{p_a}(n_a, n_o), \\
P_{fa}^{GO}(T) &= \sum_{a \in \{l, r\}} (1 + T/n_a)^{-n_a}\, I_{q_a}(n_o, n_a)
\end{aligned}
$$

with $o$ the other half, $N = n_l + n_r$, $p_a = (n_a + T)/(N + T)$,
$q_a = 1 - p_a = n_o/(N + T)$, and $I_x(\alpha, \beta)$ the regularised incomplete
beta function, for integer arguments the finite negative-binomial sum
$I_x(\alpha, \beta) = \sum_{i<\beta} \binom{\alpha - 1 + i}{i} x^\alpha (1 - x)^i$ (all
terms positive: no cancellation however small Pfa gets). At $n_l = n_r = n$:

$$
P_{fa}^{SO} = 2 \sum_{k=0}^{n-1} \binom{n - 1 + k}{k} (2 + T/n)^{-(n + k)}, \qquad
P_{fa}^{GO} = 2 (1 + T/n)^{-n} - P_{fa}^{SO}.
$$

(A form sometimes quoted with $(1 + T/n)^{-n}$ in place of $(2 + T/n)^{-n}$ in
the SO sum fails at $T = 0$, where it gives more than 1.) The NumPy form
:func:`halves_pfa` evaluates $I_x$ by ``scipy.special.betainc``, the kernels
:func:`halves_log_survival` by the finite sum: two implementations, checked
against each other and against simulation in tests/property/test_cfar_halves.py.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.optimize
import scipy.special

#: the detectors of this module, by the name :mod:`models.cfar` dispatches on
HALVES = ("go", "so")


# ------------------------------------------------------------------ closed forms

@numba.njit(cache=True)
def _log_beta_tail(alpha: int, beta: int, log_x: float, y: float) -> float:
    """log I_x(alpha, beta) = log sum_{i<beta} C(alpha - 1 + i, i) x^alpha y^i
    (y = 1 - x): the finite sum by the ratio of successive terms."""
    term, total = 1.0, 1.0
    for i in range(1, beta):
        term *= (alpha - 1 + i) / i * y
        total += term
    return alpha * log_x + math.log(total)


@numba.njit(cache=True)
def _log_half(t: float, n_a: int, n_o: int, greatest: bool) -> float:
    """log of half a's term: log[(1 + t/n_a)^(-n_a) I_{q_a}(n_o, n_a)] (GO) or
    log[(1 + t/n_a)^(-n_a) I_{p_a}(n_a, n_o)] (SO)."""
    total = n_a + n_o + t
    log_p = math.log1p(-n_o / total)             # p_a = (n_a + t)/(N + t), near 1 without rounding
    log_q = math.log(n_o / total)
    front = -n_a * math.log1p(t / n_a)
    if greatest:
        return front + _log_beta_tail(n_o, n_a, log_q, math.exp(log_p))
    return front + _log_beta_tail(n_a, n_o, log_p, math.exp(log_q))


@numba.njit(cache=True)
def halves_log_survival(t: float, n_l: int, n_r: int, greatest: bool) -> float:
    """-ln Pfa(t) of GO (``greatest``) or SO at the ratio t = x / mu, halves of
    n_l and n_r cells (one empty: CA's N' log(1 + t/N') of the other)."""
    if not t > 0.0:
        return 0.0                               # t = 0 (or NaN): every cell passes
    if math.isinf(t):
        return math.inf
    if n_l == 0 or n_r == 0:
        n = n_l + n_r
        return n * math.log1p(t / n)
    a = _log_half(t, n_l, n_r, greatest)
    b = _log_half(t, n_r, n_l, greatest)
    hi, lo = (a, b) if a > b else (b, a)
    return -(hi + math.log1p(math.exp(lo - hi)))


def halves_pfa(T, n_l, n_r, greatest: bool):
    """Pfa of GO (``greatest``) or SO at threshold factor T (NumPy form, any
    broadcast shapes): the closed form above by ``scipy.special.betainc``."""
    T, n_l, n_r = np.broadcast_arrays(np.asarray(T, dtype=float), np.asarray(n_l, dtype=float),
                                      np.asarray(n_r, dtype=float))
    one_sided = (n_l == 0) | (n_r == 0)
    nl, nr = np.where(one_sided, 1.0, n_l), np.where(one_sided, 1.0, n_r)
    total = nl + nr + T
    pfa = 0.0
    for a, o in ((nl, nr), (nr, nl)):
        front = (1.0 + T / a) ** -a
        pfa = pfa + front * (scipy.special.betainc(o, a, o / total) if greatest
                             else scipy.special.betainc(a, o, (a + T) / total))
    n = n_l + n_r
    return np.where(one_sided, (1.0 + T / np.maximum(n, 1.0)) ** -n, pfa)


def halves_threshold_factor(pfa: float, n_l: int, n_r: int, greatest: bool) -> float:
    """T of GO or SO for ``pfa`` (0 for pfa >= 1): the root of
    -ln Pfa(T) = -ln pfa (:func:`halves_log_survival`, increasing in T), by
    Brent's method on log T, bracketed by doubling from CA's T at N = n_l + n_r."""
    if pfa >= 1.0:
        return 0.0
    target = -math.log(pfa)

    def excess(log_T: float) -> float:
        return halves_log_survival(math.exp(log_T), n_l, n_r, greatest) - target

    n = n_l + n_r
    lo = hi = math.log(max(n * math.expm1(target / n), 1e-300))
    while excess(lo) > 0.0:
        lo -= 1.0
    while excess(hi) < 0.0:
        hi += 1.0
    return float(math.exp(scipy.optimize.brentq(excess, lo, hi, xtol=1e-13, rtol=1e-15, maxiter=500)))


def halves_factor_along(pfa: float, left: np.ndarray, right: np.ndarray, greatest: bool) -> np.ndarray:
    """(M,) T per cell of an axis whose halves hold ``left`` and ``right`` cells
    (:func:`models.cfar.window_counts`), one root per distinct pair."""
    pairs = list(zip(left.tolist(), right.tolist()))
    factors = {pair: halves_threshold_factor(pfa, *pair, greatest) for pair in set(pairs)}
    return np.array([factors[pair] for pair in pairs])


# ------------------------------------------------------------------ noise estimate

@numba.njit(cache=True, inline="always")
def halves_mu(left_sum: float, right_sum: float, inv_l: float, inv_r: float, greatest: bool) -> float:
    """max (GO) or min (SO) of the half means; an empty half (inv = 0) defers to the other."""
    m_l = left_sum * inv_l
    m_r = right_sum * inv_r
    if inv_l == 0.0:
        return m_r
    if inv_r == 0.0:
        return m_l
    if greatest:
        return m_l if m_l > m_r else m_r
    return m_l if m_l < m_r else m_r


def inverse_counts(counts: np.ndarray) -> np.ndarray:
    """1/n per cell, 0 where a half is empty (:func:`halves_mu`)."""
    counts = np.asarray(counts, dtype=float)
    return np.divide(1.0, counts, out=np.zeros_like(counts), where=counts > 0)
