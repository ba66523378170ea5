r"""Densities of glint measurement noise, in log space, vectorised; and
:class:`GlintModel`, the tracking model under that noise.

Radar glint is modelled per measurement component as a Gaussian receiver
noise with occasional heavy-tailed (Laplacian) glint spikes (Hewer, Martin &
Zeh, "Robust preprocessing for Kalman filtering of glint noise", IEEE TAES
23(1), 1987; Wu, "Maximum likelihood identification of glint noise", IEEE TAES
32(1), 1996). Two ways to combine the parts are in use, and this module gives
both, with the Laplace law parametrised by its *scale* $\eta$ (``eta``; density
$e^{-|x|/\eta} / (2 \eta)$, variance $2 \eta^2$):

``"mixture"`` (default of the ``glint`` scenario, Song & Sun's eq. (5),
$f = (1 - \epsilon) f_g + \epsilon f_l$): with probability $1 - \epsilon$ the noise is
$\mathcal{N}(0, \sigma^2)$, with probability $\epsilon$ it is $\operatorname{Laplace}(0, \eta)$:

$$
p(x) = (1 - \epsilon)\, \mathcal{N}(x; 0, \sigma^2) + \epsilon\, \operatorname{Laplace}(x; 0, \eta),
\qquad \operatorname{var} = (1 - \epsilon) \sigma^2 + 2 \epsilon \eta^2
$$

``"additive"``: the Gaussian receiver noise is always there and a glint spike
is *added* with probability $\epsilon$, so the outlier part is the convolution
$\mathcal{N}(0, \sigma^2) * \operatorname{Laplace}(0, \eta)$:

$$
p(x) = (1 - \epsilon)\, \mathcal{N}(x; 0, \sigma^2) + \epsilon\, (\mathcal{N} * L)(x),
\qquad \operatorname{var} = \sigma^2 + 2 \epsilon \eta^2
$$

The Gaussian-Laplace convolution (the "normal-Laplace" law of Reed &
Jorgensen, "The double Pareto-lognormal distribution", Commun. Stat. Theory
Methods 33(8), 2004, with equal tail rates) has the closed form, $r = \sigma/\eta$:

$$
(\mathcal{N} * L)(x) = \frac{e^{r^2/2}}{4 \eta} \left[
  e^{-x/\eta} \operatorname{erfc}\!\Big(\frac{r - x/\sigma}{\sqrt{2}}\Big)
  + e^{x/\eta} \operatorname{erfc}\!\Big(\frac{r + x/\sigma}{\sqrt{2}}\Big) \right]
$$

Each term overflows (exp) or underflows (erfc) on its own far in the tails. With
$\operatorname{erfc}(a) = \operatorname{erfcx}(a)\, e^{-a^2}$ a term with $a \ge 0$ equals
$e^{-x^2/(2 \sigma^2)} \operatorname{erfcx}(a)$ (no large exponent left), and a term with $a < 0$
has $\operatorname{erfc}(a) \in (1, 2]$, so its logarithm is $\mp x/\eta + r^2/2 + \log \operatorname{erfc}(a)$ with
moderate parts. :func:`gauss_laplace_logpdf` evaluates each term in the form
that is exact for its sign of $a$ and combines them with ``logaddexp``: it is
finite (and asymptotically the Laplace tail $-|x|/\eta + \text{const}$) for any finite $x$.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import scipy.special
import scipy.stats

from radarbench.bench.core import require, require_arrays
from radarbench.models.spherical import MEASUREMENT_LABELS

GLINT_MODELS = ("mixture", "additive")

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


def gaussian_logpdf(x, sigma):
    """log N(x; 0, sigma^2), elementwise (broadcasting)."""
    x = np.asarray(x, float)
    sigma = np.asarray(sigma, float)
    return -0.5 * (x / sigma) ** 2 - np.log(sigma) - _LOG_SQRT_2PI


def laplace_logpdf(x, eta):
    """log Laplace(x; 0, eta) = -|x|/eta - log(2 eta), ``eta`` the scale."""
    x = np.asarray(x, float)
    eta = np.asarray(eta, float)
    return -np.abs(x) / eta - np.log(2.0 * eta)


def _log_erfc_term(a, linear, x, sigma, r):
    """log of exp(linear + r^2/2) erfc(a), stable for both signs of ``a``.

    For a >= 0: exp(linear + r^2/2 - a^2) erfcx(a) and linear + r^2/2 - a^2 =
    -x^2/(2 sigma^2) exactly (both terms of the convolution). For a < 0:
    erfc(a) is in (1, 2] and the exponent linear + r^2/2 is moderate.
    """
    pos = a >= 0.0
    a_pos = np.where(pos, a, 0.0)
    a_neg = np.where(pos, 0.0, a)
    with np.errstate(divide="ignore"):
        from_erfcx = -0.5 * (x / sigma) ** 2 + np.log(scipy.special.erfcx(a_pos))
        from_erfc = linear + 0.5 * r ** 2 + np.log(scipy.special.erfc(a_neg))
    return np.where(pos, from_erfcx, from_erfc)


def gauss_laplace_logpdf(x, sigma, eta):
    """log of the density of N(0, sigma^2) + Laplace(0, eta) (independent sum).

    Closed form in the module docstring; vectorised and broadcasting over
    ``x``, ``sigma`` and ``eta`` (all > 0 except ``x``). Finite for any finite
    ``x``: far in the tails it tends to the Laplace tail -|x|/eta +
    sigma^2/(2 eta^2) - log(2 eta).
    """
    x, sigma, eta = np.broadcast_arrays(np.asarray(x, float), np.asarray(sigma, float),
                                        np.asarray(eta, float))
    r = sigma / eta
    s2 = math.sqrt(2.0)
    t_minus = _log_erfc_term((r - x / sigma) / s2, -x / eta, x, sigma, r)
    t_plus = _log_erfc_term((r + x / sigma) / s2, x / eta, x, sigma, r)
    return np.logaddexp(t_minus, t_plus) - np.log(4.0 * eta)


def glint_logpdf(x, sigma, eta, epsilon, model: str = "mixture"):
    """log p(x) of glint noise (module docstring), elementwise and broadcasting.

    ``epsilon`` = 0 gives the Gaussian N(0, sigma^2) exactly; ``epsilon`` = 1
    gives the pure outlier law. ``model`` is ``"mixture"`` or ``"additive"``.
    """
    if model not in GLINT_MODELS:
        raise ValueError(f"model must be one of {GLINT_MODELS}, got {model!r}")
    eps = np.asarray(epsilon, float)
    core = gaussian_logpdf(x, sigma)
    outlier = laplace_logpdf(x, eta) if model == "mixture" else gauss_laplace_logpdf(x, sigma, eta)
    with np.errstate(divide="ignore"):
        log_core_w, log_out_w = np.log1p(-eps), np.log(eps)
    return np.logaddexp(log_core_w + core, log_out_w + outlier)


def glint_variance(sigma, eta, epsilon, model: str = "mixture"):
    """Variance of the glint noise: (1-eps) sigma^2 + 2 eps eta^2 (mixture) or
    sigma^2 + 2 eps eta^2 (additive)."""
    sigma, eta, eps = (np.asarray(v, float) for v in (sigma, eta, epsilon))
    core = (1.0 - eps) * sigma ** 2 if model == "mixture" else sigma ** 2
    return core + 2.0 * eps * eta ** 2


def glint_tail_probability(c, sigma, eta, epsilon, model: str = "mixture"):
    """P(|x| > c) for c >= 0.

    Mixture: (1-eps) 2 Phi(-c/sigma) + eps exp(-c/eta). Additive: the
    convolution part is P(|N + L| > c) = 2 P(N + L > c) with, conditioning on
    the sign of L (an exponential of mean eta either way, with probability
    1/2), P(N + E > c) = Phi(-c/sigma) + exp(r^2/2 - c/eta) Phi(c/sigma - r)
    and P(N - E > c) = Phi(-c/sigma) - exp(r^2/2 + c/eta) Phi(-c/sigma - r),
    r = sigma/eta (the exponentials are evaluated with ``log_ndtr``).
    """
    c, sigma, eta, eps = (np.asarray(v, float) for v in (c, sigma, eta, epsilon))
    gauss_tail = 2.0 * scipy.stats.norm.sf(c / sigma)
    if model == "mixture":
        out_tail = np.exp(-c / eta)
    else:
        r = sigma / eta
        up = scipy.stats.norm.sf(c / sigma) + np.exp(0.5 * r ** 2 - c / eta
                                                     + scipy.special.log_ndtr(c / sigma - r))
        down = scipy.stats.norm.sf(c / sigma) - np.exp(0.5 * r ** 2 + c / eta
                                                       + scipy.special.log_ndtr(-c / sigma - r))
        out_tail = up + down          # 2 * (1/2)(up + down)
    return (1.0 - eps) * gauss_tail + eps * out_tail


#: grid of the Fisher information's integral: points, and its half-width in units of the
#: wider of sigma and eta (the density beyond is below exp(-40) of its peak)
FISHER_POINTS = 400_001
FISHER_HALF_WIDTH = 60.0


def glint_fisher_information(sigma, eta, epsilon, model: str = "mixture") -> np.ndarray:
    """Fisher information I = E[(d/dx log p(x))^2] of glint noise per component (sigma, eta
    (m,) arrays): the measurement information of the posterior Cramér-Rao bound
    (:mod:`models.pcrb`); 1/sigma^2 at eps = 0. The score by central differences of
    :func:`glint_logpdf` (step 1e-5 sigma), the expectation by the trapezoidal rule on a
    grid of :data:`FISHER_POINTS` over +-:data:`FISHER_HALF_WIDTH` times max(sigma, eta)."""
    return np.array([_fisher_information(float(s), float(e), float(epsilon), model)
                     for s, e in zip(np.atleast_1d(np.asarray(sigma, float)), np.atleast_1d(np.asarray(eta, float)))])


@functools.lru_cache(maxsize=256)
def _fisher_information(sigma: float, eta: float, epsilon: float, model: str) -> float:
    """:func:`glint_fisher_information` of one component, computed once per process."""
    x = np.linspace(-1.0, 1.0, FISHER_POINTS) * FISHER_HALF_WIDTH * max(sigma, eta)
    h = 1e-5 * sigma
    log_p = functools.partial(glint_logpdf, sigma=sigma, eta=eta, epsilon=epsilon, model=model)
    score = (log_p(x + h) - log_p(x - h)) / (2 * h)
    return float(np.trapezoid(score ** 2 * np.exp(log_p(x)), x))


def _is_number(x) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool) and math.isfinite(x)


@dataclass(frozen=True, eq=False)
class GlintModel:
    """Everything a tracker knows of a target seen by a spherical sensor under
    glint noise: linear Cartesian dynamics with a known control, the prior of
    step 0, and the measurement (which components, their glint noise).

    The ``glint`` scenario builds it (Song & Sun, "Filtering method with
    non-Gaussian noise"; the model is derived there) and hands it to the
    trackers as the tracking scene's ``model`` (docs/architecture.md,
    'Scenes'). State [x, y, z, vx, vy, vz] (d = 6), ENU metres;
    x_(k+1) = F x_k + G (u + w_k), w_k = noise_factor g_k, g_k ~ N(0, I_3);
    z_k = h(x_k) + v_k (:mod:`models.spherical`), v_k glint noise per
    measured component (:func:`glint_logpdf`). The line-of-sight basis
    ``los_rotation`` (rows: radial, bearing, elevation unit vectors at the
    prior mean position) is where the control and the disturbance are given.
    """

    #: (d, d) state transition over one step
    F: np.ndarray
    #: (d, 3) gain of the held acceleration (control plus disturbance) into the state
    G: np.ndarray
    #: (3,) known control, Cartesian acceleration (m/s^2)
    u: np.ndarray
    #: (d,) G u, the control's contribution per step
    Bu: np.ndarray
    #: (d, d) process-noise covariance G noise_factor noise_factor' G'
    Q: np.ndarray
    #: (3, 3) the disturbance is w = noise_factor g, g standard normal
    noise_factor: np.ndarray
    #: (3,) disturbance std (m/s^2) along the radial, bearing and elevation directions
    process_noise_los: np.ndarray
    #: isotropic disturbance std sigma_w (m/s^2) of the scenario's parameters
    process_noise_m_s2: float
    #: (d,) prior mean of the state at step 0
    x0: np.ndarray
    #: (d, d) prior covariance of the state at step 0
    P0: np.ndarray
    #: "passive" (bearing, elevation) or "active" (range, bearing, elevation)
    sensor: str
    #: names of the measured components, in the order of z
    measurement_labels: tuple[str, ...]
    #: (m,) std of the Gaussian core per measured component (m or rad)
    sigma: np.ndarray
    #: (m,) Laplace glint scale per measured component (variance 2 eta^2)
    eta: np.ndarray
    #: glint probability per measured component
    epsilon: float
    #: how core and glint combine: one of :data:`GLINT_MODELS`
    glint_model: str
    #: (m,) total variance of the glint noise (:func:`glint_variance`)
    noise_variance: np.ndarray
    #: sampling interval T (s)
    dt_s: float
    #: (3, 3) line-of-sight basis at the prior mean position (rows: radial, bearing, elevation)
    los_rotation: np.ndarray
    #: (3,) the control along the radial, bearing and elevation directions (m/s^2)
    control_los: np.ndarray
    #: every noise std is its reference value times this (10^(-snr_db/20))
    noise_scale: float

    def __post_init__(self) -> None:
        require_arrays(self, {"F": (None, None)})
        d = self.F.shape[0]
        require(self, "sensor", self.sensor in MEASUREMENT_LABELS, f"one of {tuple(MEASUREMENT_LABELS)}")
        labels = MEASUREMENT_LABELS[self.sensor]
        m = len(labels)
        require_arrays(self, {"F": (d, d), "G": (d, 3), "u": (3,), "Bu": (d,), "Q": (d, d), "noise_factor": (3, 3),
                              "process_noise_los": (3,), "x0": (d,), "P0": (d, d), "sigma": (m,), "eta": (m,),
                              "noise_variance": (m,), "los_rotation": (3, 3), "control_los": (3,)})
        require(self, "measurement_labels", self.measurement_labels == labels, f"{labels} (the {self.sensor} sensor's)")
        require(self, "epsilon", _is_number(self.epsilon) and 0.0 <= self.epsilon <= 1.0, "a probability in [0, 1]")
        require(self, "glint_model", self.glint_model in GLINT_MODELS, f"one of {GLINT_MODELS}")
        for name in ("dt_s", "noise_scale"):
            require(self, name, _is_number(getattr(self, name)) and getattr(self, name) > 0, "a number > 0")
        require(self, "process_noise_m_s2", _is_number(self.process_noise_m_s2) and self.process_noise_m_s2 >= 0,
                "a number >= 0")

    @property
    def dim_z(self) -> int:
        """m, the number of measured components."""
        return len(self.measurement_labels)


def glint_model_of(scene) -> GlintModel:
    """The :class:`GlintModel` a tracking scene carries (its ``model``);
    TypeError naming the field when it holds something else."""
    model = getattr(scene, "model", None)
    if not isinstance(model, GlintModel):
        raise TypeError(f"{type(scene).__name__}.model: expected a models.glint.GlintModel, "
                        f"got {type(model).__name__}")
    return model
