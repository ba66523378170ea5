r"""The adaptive regression CFAR: a curve fitted to each power spectrum is the
noise estimate, and the nominal significance of a cell against it under
homogeneous exponential noise (docs/architecture.md, 'Models').

The HFSWR chapter ("目标检测与跟踪方法-海洋遥感技术应用", the shared paper
hfswr-cfar-mn-jpda-ukf, sec. 1 (3)): "the adaptive regression detector fits
the power spectrum by curve regression and obtains an estimate of the
noise as a whole ... the fitted result is the noise estimate; the noise
estimate times the threshold factor $K$ is the detection threshold, and $K$
controls the false-alarm rate" (自适应回归检测器采用曲线回归方法拟合功率谱,获得
噪声整体估计 ... 拟合出的结果即为噪声估计,将噪声估计值乘以门限因子K获得检测门限,
通过K控制虚警率的大小). It prints neither the curve family nor its order, nor
how $K$ follows from the false-alarm rate. Ours, each a parameter of
:class:`Curve`:

* **family** ``"log-polynomial"`` (default): a least-squares polynomial in
  the log power $\ln x$, the spectrum in dB as radar engineers plot it.
  Narrow clutter lines 30 dB above the noise pull such a fit up by a few
  dB at most; the same lines drag a fit in the linear power far above the
  noise around them. ``"polynomial"``: least squares in the linear power,
  kept beside it as the ablation.
* **order** of the polynomial (Legendre basis over the line, well
  conditioned at high order).
* **robust iterations**: refits leaving out the cells above
  ``exclusion_factor`` times the current noise level.

**Noise level.** Under exponential noise of level $\sigma^2$, $x = \sigma^2 E$
with $E \sim \operatorname{Exp}(1)$, and the fit of the fitted variable $y = f(x)$ estimates
$\sigma^2$ through the moments of $f(E)$ over the cells it keeps
(:func:`noise_moments`): $m = E[\ln E] = -\gamma$ (Euler's constant) for the
plain log fit, so the level is $e^{\text{fit} - m}$; $m = 1$ for the plain linear
fit. With robust iterations the kept cells are those with $E \le c$ ($c$ the
exclusion factor), and $m$, $v$ become the censored moments
(:func:`censored_exponential_moments`, :func:`log_exponential_moments`).

**Nominal significance.** $S = -\log_{10} P_{fa}(t)$ at $t = x / \text{level}$, derived under
homogeneous exponential noise from the cell's leverage $h$ (the hat-matrix
diagonal $\phi_i' G^{-1} \phi_i$; for a cell the robust fit left out, $g$, the
variance factor of its fit): our derivation, in the docstrings of
:func:`polynomial_significance` and :func:`log_polynomial_significance`,
checked against simulation in tests/property/test_cfar_regression_properties.py.

All functions take lines (P, M) — $P$ power spectra of $M$ cells — or maps
(n, R, D) with a leading trial axis, and fit every line at once: one
$Q \times Q$ normal-equation solve per line by batched matrix products.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numba
import numpy as np
import scipy.integrate
import scipy.optimize
import scipy.special

from radarbench.models.cfar.windows import MAX_SIGNIFICANCE

FAMILIES = ("log-polynomial", "polynomial")
_LOG10 = math.log(10.0)
_EULER_GAMMA = float(np.euler_gamma)
#: Gauss-Hermite nodes and weights (probabilists' weight exp(-x^2) form) for the log family's null
_GH_NODES, _GH_WEIGHTS = np.polynomial.hermite.hermgauss(12)
_LOG_GH_WEIGHTS = np.log(_GH_WEIGHTS)


@dataclass(frozen=True)
class Curve:
    """The fitted curve: ``family`` (:data:`FAMILIES`), polynomial ``order``,
    robust ``iterations`` and their ``exclusion_factor`` c (cells above c
    times the noise level are left out of the next fit)."""

    family: str = "log-polynomial"
    order: int = 4
    iterations: int = 2
    exclusion_factor: float = 4.6

    @property
    def is_log(self) -> bool:
        return self.family == "log-polynomial"


# ------------------------------------------------------------------ moments of the noise

def censored_exponential_moments(c: float) -> tuple[float, float]:
    """(mean, variance) of E ~ Exp(1) given E <= c:
    beta = (1 - (1 + c) e^-c) / (1 - e^-c), E[E^2 | E <= c] = (2 - (c^2 + 2c + 2) e^-c) / (1 - e^-c)."""
    if math.isinf(c):
        return 1.0, 1.0
    tail = math.exp(-c)
    beta = (1.0 - (1.0 + c) * tail) / (1.0 - tail)
    second = (2.0 - (c * c + 2.0 * c + 2.0) * tail) / (1.0 - tail)
    return beta, second - beta * beta


@functools.lru_cache(maxsize=64)
def log_exponential_moments(c: float) -> tuple[float, float]:
    """(mean, variance) of ln E, E ~ Exp(1), given E <= c; (-gamma, pi^2/6) for c = inf.

    The mean has the closed form (integration by parts, Ein(c) = E1(c) + ln c + gamma)
    E[ln E; E <= c] = -gamma - E1(c) - e^-c ln c; the second moment by quadrature."""
    if math.isinf(c):
        return -_EULER_GAMMA, math.pi ** 2 / 6.0
    mass = -math.expm1(-c)
    mean = (-_EULER_GAMMA - scipy.special.exp1(c) - math.exp(-c) * math.log(c)) / mass
    # ln^2 e e^-e, split at 1 for the integrable log singularity at 0
    second = sum(scipy.integrate.quad(lambda e: math.log(e) ** 2 * math.exp(-e), lo, hi, limit=200)[0]
                 for lo, hi in ((0.0, min(1.0, c)), (min(1.0, c), c)))
    return mean, second / mass - mean * mean


def noise_moments(curve: Curve, censored: bool | None = None) -> tuple[float, float]:
    """(m, v): mean and variance of the fitted variable f(E) over the cells a
    fit keeps, E ~ Exp(1): censored at the exclusion factor when the fit
    follows a robust exclusion (default: when the curve has iterations)."""
    if censored is None:
        censored = curve.iterations > 0
    c = curve.exclusion_factor if censored else math.inf
    return log_exponential_moments(c) if curve.is_log else censored_exponential_moments(c)


# ------------------------------------------------------------------ the fit

def legendre_basis(M: int, order: int) -> np.ndarray:
    """(M, order + 1): Legendre polynomials P_0..P_order at M points evenly
    spread over [-1, 1] (the polynomial family, well conditioned at high order)."""
    return np.polynomial.legendre.legvander(np.linspace(-1.0, 1.0, M), order)


def fitted_variable(x: np.ndarray, curve: Curve) -> np.ndarray:
    """y = ln x for the log family (x floored at the smallest normal float), x for the linear one."""
    x = np.asarray(x, dtype=np.float64)
    return np.log(np.maximum(x, np.finfo(np.float64).tiny)) if curve.is_log else x


def noise_level(fit: np.ndarray, curve: Curve, m: float) -> np.ndarray:
    """sigma^2 estimated from the fit of y = f(x) with E f(E) = m: exp(fit - m) or fit / m."""
    return np.exp(fit - m) if curve.is_log else fit / m


def regression_fit(lines: np.ndarray, curve: Curve) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares polynomial fit of every line (P, M) in the curve's
    fitted variable: "curve regression fitted to the power spectrum; the
    fit is the noise estimate" (通过曲线回归分析对功率谱进行曲线拟合,拟合出的结果即为噪声估计).

    Robust iterations (ours; the document prints none): after each fit the
    cells above ``exclusion_factor`` times the noise level (:func:`noise_level`
    with the moments of that fit's cells) are left out and the line refitted,
    ``iterations`` times; a line keeps its previous cells if fewer than
    2 (order + 1) would remain. Returns the noise level sigma^2 (P, M), the
    cells of the final fit (P, M) bool and every cell's leverage
    q_i = phi_i' G^-1 phi_i (P, M), G = sum over kept cells of phi phi'
    (for a kept cell, the hat-matrix diagonal h_ii).
    """
    x = np.asarray(lines, dtype=np.float64)
    y = fitted_variable(x, curve)
    Q = curve.order + 1
    phi = legendre_basis(x.shape[1], curve.order)                       # (M, Q)
    outer = (phi[:, :, None] * phi[:, None, :]).reshape(-1, Q * Q)      # (M, Q^2): phi_m phi_m'
    included = np.ones(x.shape, dtype=bool)
    for it in range(curve.iterations + 1):
        w = included.astype(np.float64)
        G_inv = np.linalg.inv((w @ outer).reshape(-1, Q, Q))            # (P, Q, Q): one matmul for every G
        coef = np.matmul(G_inv, ((w * y) @ phi)[:, :, None])[:, :, 0]   # (P, Q)
        level = noise_level(coef @ phi.T, curve, noise_moments(curve, censored=it > 0)[0])
        if it == curve.iterations:
            break
        keep = x <= curve.exclusion_factor * level
        enough = keep.sum(axis=1) >= 2 * Q
        included = np.where(enough[:, None], keep, included)
    leverage = G_inv.reshape(-1, Q * Q) @ outer.T                      # phi_i' G^-1 phi_i, (P, M)
    return level, included, leverage


# ------------------------------------------------------------------ nominal significance

def polynomial_significance(t, included, leverage, curve: Curve):
    """S = -log10 Pfa(t), t = x / level, for the linear family, by a
    moment-matched gamma law of the rest of the fit (our derivation).

    Plain fit: the fit at cell i is y_i = sum_j h_ij x_j with sum_j h_ij = 1
    (the basis holds the constant) and sum_j h_ij^2 = h_ii (H idempotent),
    so y_i = h x_i + R with E R = sigma^2 (1 - h), Var R = sigma^4 (h - h^2);
    R taken as a gamma variable of those moments (shape (1 - h)/h, scale
    h sigma^2), "x_i > t y_i" is x_i (1 - h t) > t R and

        Pfa(t) = (1 - h t)^((1 - h)/h)     for t < 1/h, 0 beyond,

    exact when the weights are equal (a CA window that includes the cell
    under test: h = 1/(N + 1) gives (1 - t/(N + 1))^N). With robust
    iterations the fit of censored cells (mean beta, variance v, E <= c) is
    divided by beta, and its variance factor is h v / beta^2; a cell the
    robust fit left out is independent of its level estimate, of mean
    sigma^2 and variance g v / beta^2 sigma^4, and the same gamma law gives
    Pfa(t) = (1 + q t)^(-1/q), q = g v / beta^2 (CA's form with N = 1/q).
    """
    beta, var = noise_moments(curve)
    q = np.clip(leverage, 1e-12, 1.0 - 1e-9)
    q_out = q * var / beta ** 2
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inside = -((1.0 - q) / q) * np.log1p(-np.minimum(q * t, 1.0)) / _LOG10
        outside = np.log1p(q_out * t) / (q_out * _LOG10)
        return np.where(included, inside, outside)


@numba.njit(cache=True)
def _log_expectation(a, b, nodes, log_weights, terms):
    """ln E[exp(-exp(a + b Z))], Z ~ N(0, 1), by Gauss-Hermite quadrature
    centred on the mode of the log integrand f(z) = -exp(a + b z) - z^2/2
    (Newton on f'(z) = -b exp(a + b z) - z) and scaled by its curvature, so
    deep tails (a >> 0, the integrand's mass far out in the lower tail of
    Z) keep their accuracy. ``terms``: scratch of len(nodes), the caller's
    (no allocation per cell)."""
    z = 0.0
    for _ in range(50):
        e = math.exp(min(a + b * z, 700.0))
        step = (-b * e - z) / (-b * b * e - 1.0)
        z -= step
        if abs(step) < 1e-12:
            break
    s = 1.0 / math.sqrt(b * b * math.exp(min(a + b * z, 700.0)) + 1.0)
    top = -math.inf
    for k in range(nodes.size):
        u = z + math.sqrt(2.0) * s * nodes[k]
        terms[k] = log_weights[k] + nodes[k] * nodes[k] - math.exp(min(a + b * u, 700.0)) - 0.5 * u * u
        top = max(top, terms[k])
    total = 0.0
    for k in range(nodes.size):
        total += math.exp(terms[k] - top)
    return top + math.log(total) + math.log(math.sqrt(2.0) * s) - 0.5 * math.log(2.0 * math.pi)


@numba.njit(cache=True)
def _log_polynomial_sig(log_t, included, leverage, m, v, nodes, log_weights, out):
    terms = np.empty(nodes.size)
    for i in range(log_t.size):
        q = min(max(leverage[i], 1e-12), 1.0 - 1e-9)
        if included[i]:
            a = (log_t[i] - q * m) / (1.0 - q)
            b = math.sqrt(v * (q - q * q)) / (1.0 - q)
        else:
            a = log_t[i]
            b = math.sqrt(v * q)
        out[i] = -_log_expectation(a, b, nodes, log_weights, terms) / math.log(10.0)


def log_polynomial_significance(t, included, leverage, curve: Curve):
    """S = -log10 Pfa(t), t = x / level, for the log family (our derivation).

    With u_j = ln E_j - m (mean 0, variance v over the kept cells,
    :func:`noise_moments`), the log of the level estimate is off by
    U = sum_j h_ij u_j, and "x_i > t level_i" is ln E_i > ln t + U. For a
    cell of the fit (leverage h), U = h u_i + R with R = sum_{j != i} h_ij u_j
    of variance v (h - h^2) (sum_j h_ij^2 = h), so the test is
    (1 - h) ln E_i > ln t - h m + R; for a cell the robust fit left out, U
    is independent of E_i with variance v g. R (or U) taken as normal — a
    weighted sum of many log-exponentials — and P(E > e^w) = exp(-e^w) give

        Pfa(t) = E_Z[exp(-exp(a + b Z))],
        a = (ln t - h m)/(1 - h), b = sqrt(v (h - h^2))/(1 - h)   (kept cell),
        a = ln t,                 b = sqrt(v g)                   (left-out cell),

    computed by :func:`_log_expectation`.
    """
    m, v = noise_moments(curve)
    with np.errstate(divide="ignore"):
        log_t = np.log(np.asarray(t, dtype=np.float64))
    flat = np.ascontiguousarray(log_t).ravel()
    out = np.empty(flat.size)
    _log_polynomial_sig(flat, np.ascontiguousarray(included, dtype=np.bool_).ravel(),
                        np.ascontiguousarray(leverage, dtype=np.float64).ravel(), m, v, _GH_NODES,
                        _LOG_GH_WEIGHTS, out)
    return out.reshape(log_t.shape)


def significance(x, level, included, leverage, curve: Curve) -> np.ndarray:
    """S = -log10 Pfa at t = x / level for the curve's family, capped at
    MAX_SIGNIFICANCE; a non-positive level (a linear fit that failed there)
    makes any power significant, and a cell of zero power has S = 0."""
    x = np.asarray(x, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(level > 0, x / np.where(level > 0, level, 1.0), np.inf)
    family = log_polynomial_significance if curve.is_log else polynomial_significance
    s = np.where(x > 0, family(np.where(np.isfinite(t), t, 1.0), included, leverage, curve), 0.0)
    s = np.where(np.isfinite(t), s, MAX_SIGNIFICANCE)
    return np.minimum(np.nan_to_num(s, nan=MAX_SIGNIFICANCE, posinf=MAX_SIGNIFICANCE), MAX_SIGNIFICANCE)


# ------------------------------------------------------------------ threshold factors

def threshold_factor(pfa: float, leverage: float, curve: Curve) -> float:
    """K of a kept cell of leverage h: the t with Pfa(t) = pfa. Closed form
    for the plain linear fit, K = (1 - pfa^(h/(1 - h)))/h; otherwise the
    root of S(t) = -log10 pfa in ln t (S is increasing in t), the target
    held just below the cap MAX_SIGNIFICANCE so that a Pfa at the cap
    (1e-300) still has its K."""
    if pfa >= 1.0:
        return 0.0
    if not curve.is_log and curve.iterations == 0:
        h = leverage
        return float(-math.expm1(math.log(pfa) * h / (1.0 - h)) / h)
    target = min(-math.log10(pfa), MAX_SIGNIFICANCE * (1.0 - 1e-9))

    def excess(log_t: float) -> float:
        return float(significance(np.array([1.0]), np.array([math.exp(-log_t)]), np.array([True]),
                                  np.array([leverage]), curve)[0]) - target

    # S reaches the cap by t = 1/h (linear) or t ~ 700 (log): ln t <= 28 for any leverage >= 1e-12
    return float(math.exp(scipy.optimize.brentq(excess, -50.0, 64.0, xtol=1e-10)))


@functools.lru_cache(maxsize=256)
def _factor_along(pfa: float, M: int, curve: Curve) -> np.ndarray:
    phi = legendre_basis(M, curve.order)
    h = np.einsum("mq,qr,mr->m", phi, np.linalg.inv(phi.T @ phi), phi)
    h = np.round(np.clip(h, 1e-12, 1 - 1e-9), 12)
    factors = {value: threshold_factor(pfa, value, curve) for value in np.unique(h).tolist()}
    K = np.array([factors[value] for value in h.tolist()])
    K.setflags(write=False)
    return K


def factor_along(pfa: float, M: int, curve: Curve) -> np.ndarray:
    """(M,) K per cell of a line at its leverage in the full fit (no cell left
    out), read-only and cached: the recording's threshold map."""
    return _factor_along(float(pfa), int(M), curve)


# ------------------------------------------------------------------ the detector

def regression_cfar(maps: np.ndarray, curve: Curve, axis: str,
                    keep: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Adaptive regression CFAR along ``axis`` of maps (n, R, D): the noise
    level of each line (along Doppler: each range cell's power spectrum) and
    the significance (:func:`significance`), both (n, R, D) float32. With
    ``keep`` (n, R, D) bool (the peak detection's local maxima), the
    significance is computed at those cells only and is 0 elsewhere (the
    same values where kept: it is computed cell by cell)."""
    maps = np.asarray(maps, dtype=np.float64)
    lines = maps if axis == "doppler" else maps.transpose(0, 2, 1)
    flat = lines.reshape(-1, lines.shape[-1])
    level, included, leverage = regression_fit(flat, curve)
    if keep is None:
        sig = significance(flat, level, included, leverage, curve)
    else:
        at = (keep if axis == "doppler" else np.asarray(keep).transpose(0, 2, 1)).reshape(flat.shape)
        sig = np.zeros(flat.shape)
        sig[at] = significance(flat[at], level[at], included[at], leverage[at], curve)
    level, sig = level.reshape(lines.shape), sig.reshape(lines.shape)
    if axis == "range":
        level, sig = level.transpose(0, 2, 1), sig.transpose(0, 2, 1)
    return np.ascontiguousarray(level, dtype=np.float32), np.ascontiguousarray(sig, dtype=np.float32)
