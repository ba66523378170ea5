"""The adaptive regression CFAR on homogeneous exponential noise
(models/cfar/regression.py): its derived nominal significance against
simulation, the quadrature and the censored moments it rests on, and the
threshold factors that invert it.

Cells of one line share the fit, so the Pfa tests take one cell per line
(independent Bernoulli(pfa) exceedances: the binomial law is exact), with
the band of tests/property/test_cfar_properties.py (level 1 - 1e-6, narrow
enough to see a 25 % error).
"""

import math

import numpy as np
import pytest
import scipy.integrate
import scipy.optimize
import scipy.special
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.models import cfar
from radarbench.models.cfar import regression
from radarbench.models.cfar.regression import Curve
from tests.property.test_cfar_properties import CELLS, PFA, _assert_binomial, _noise


def test_linear_order_zero_has_its_exact_pfa():
    """Order 0 without robust iterations: the fit is the line's mean with the
    cell under test included, h = 1/M, and the gamma form is exact,
    Pfa(t) = (1 - t/M)^(M - 1). One cell per line (the fit couples a line's cells)."""
    maps = _noise(5, (CELLS, 1, 64))
    _, sig = regression.regression_cfar(maps, Curve("polynomial", 0, 0), "doppler")
    _assert_binomial(sig[:, :, 17] > -math.log10(PFA), PFA)


@pytest.mark.slow                     # enough null cells for the binomial tolerance
@pytest.mark.parametrize("order", [0, 4])
def test_log_fit_interior_cell_has_its_nominal_pfa(order):
    """The plain log-polynomial fit: an interior cell's exceedances at the
    nominal K follow the derived Pfa (normal approximation of the rest of
    the fit, :func:`models.cfar.regression.log_polynomial_significance`)."""
    maps = _noise(7 + order, (CELLS, 1, 128), scale=2.5)
    _, sig = regression.regression_cfar(maps, Curve("log-polynomial", order, 0), "doppler")
    _assert_binomial(sig[:, :, 40] > -math.log10(PFA), PFA)


@settings(derandomize=True, deadline=None, max_examples=25)
@given(a=st.floats(-6.0, 12.0), b=st.floats(0.01, 1.0))
def test_gauss_hermite_expectation_matches_direct_integration(a, b):
    """ln E[exp(-exp(a + b Z))] by the mode-centred 12-node rule against
    adaptive quadrature over the normal density, deep tails included: Pfa
    within 1e-4 relatively (far below any sampling error of a measured Pfa).
    b up to 1: a leverage of 0.4, far above any fit's here."""
    quad = _log_expectation_by_quadrature(a, b)
    gh = regression._log_expectation(a, b, regression._GH_NODES, regression._LOG_GH_WEIGHTS,
                                          np.empty(regression._GH_NODES.size))
    assert math.isclose(gh, quad, rel_tol=1e-4, abs_tol=1e-4), (gh, quad)


def _log_expectation_by_quadrature(a: float, b: float) -> float:
    # the integrand's mode z* solves b exp(a + b z) + z = 0 (found by bracketing, not Newton);
    # integrate +-40 around it, the log-integrand shifted by its maximum so nothing underflows
    mode = scipy.optimize.brentq(lambda z: b * math.exp(min(a + b * z, 700.0)) + z, -1e4, 0.0)

    def log_f(z):
        return -math.exp(min(a + b * z, 700.0)) - 0.5 * z * z

    top = log_f(mode)
    value = scipy.integrate.quad(lambda z: math.exp(log_f(z) - top), mode - 40, mode + 40, points=[mode],
                                 limit=500, epsabs=0, epsrel=1e-10)[0]
    return top + math.log(value) - 0.5 * math.log(2 * math.pi)


@pytest.mark.parametrize("c", [1.0, 4.6, 12.0])
def test_censored_log_moments_match_a_sample(c):
    """Mean and variance of ln E given E <= c against 4e6 draws, within 6
    standard errors of the sample estimates (computed from the sample)."""
    mean, var = regression.log_exponential_moments(c)
    e = np.random.default_rng(3).exponential(size=4_000_000)
    u = np.log(e[e <= c])
    n = u.size
    assert abs(u.mean() - mean) < 6 * math.sqrt(u.var() / n)
    centred = (u - u.mean()) ** 2
    assert abs(centred.mean() - var) < 6 * math.sqrt(centred.var() / n)
    assert regression.log_exponential_moments(math.inf) == (-np.euler_gamma, math.pi ** 2 / 6)


@pytest.mark.parametrize("family", regression.FAMILIES)
@pytest.mark.parametrize("iterations", [0, 2])
def test_threshold_factor_inverts_the_significance(family, iterations):
    curve = Curve(family, 4, iterations)
    for pfa in (0.1, 1e-3, 1e-8):
        for h in (1 / 65, 0.01, 0.2):
            K = regression.threshold_factor(pfa, h, curve)
            s = regression.significance(np.array([K]), np.array([1.0]), np.array([True]), np.array([h]), curve)
            assert math.isclose(float(s[0]), -math.log10(pfa), rel_tol=1e-6), (pfa, h, K, s)
    # the recording asks for K at the capped significance (Pfa 1e-300) of a threshold at the cap
    assert all(math.isfinite(regression.threshold_factor(1e-300, h, curve)) for h in (1 / 65, 0.2))
    along = regression.factor_along(1e-3, 96, curve)
    assert along.shape == (96,) and not along.flags.writeable and np.all(along > 1)


@pytest.mark.parametrize("family", regression.FAMILIES)
def test_a_strong_target_is_detected_by_either_family(family):
    """A cell 30 dB above homogeneous noise passes at Pfa 1e-6 along range
    and Doppler and survives the peak detection."""
    maps = _noise(11, (3, 64, 128))
    maps[:, 30, 70] = 1000.0
    per_axis = {a: regression.regression_cfar(maps, Curve(family, 4, 2), a) for a in ("range", "doppler")}
    statistic, _ = cfar.fold(maps, per_axis, "both", 1, 1)
    assert np.all(statistic[:, 30, 70] > 6.0)


def test_censored_exponential_moments_are_the_truncated_law():
    for c in (0.5, 4.6, 30.0):
        beta, var = regression.censored_exponential_moments(c)
        mass = -math.expm1(-c)
        m1 = scipy.integrate.quad(lambda e: e * math.exp(-e), 0, c)[0] / mass
        m2 = scipy.integrate.quad(lambda e: e * e * math.exp(-e), 0, c)[0] / mass
        assert math.isclose(beta, m1, rel_tol=1e-9) and math.isclose(var, m2 - m1 * m1, rel_tol=1e-7)
