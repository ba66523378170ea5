"""Properties of the AR-model adaptive tracker (methods/kinematic/ar_adaptive.py): exact
polynomial prediction, a PSD covariance-matched Q, and the chi-square switch
rule's false-switch rate at its nominal level alpha on a quiet, matched target."""

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings, seed
from hypothesis import strategies as st
from scipy import stats

from radarbench.methods.kinematic.ar_adaptive import (ar_adaptive_filter, ar_coefficients, exactness_constraints, kinematic_map,
                                 lag_map, matched_noise)


def _random_pd(rng, M):
    A = rng.standard_normal((M, M))
    return A @ A.T + 1e-3 * np.eye(M)


@seed(12)
@settings(max_examples=60, deadline=None)
@given(M=st.integers(2, 8), data=st.data())
def test_ar_predictor_is_exact_on_polynomials_of_degree_up_to_N(M, data):
    """x_k+1 = sum a_i x_k+1-i with zero error on noise-free polynomials of degree <= N,
    for the least-squares (P = I) and the filter-weighted (random P) coefficients."""
    N = data.draw(st.integers(0, M - 1))
    degree = data.draw(st.integers(0, N))
    coef = np.array(data.draw(st.lists(st.floats(-10, 10), min_size=degree + 1, max_size=degree + 1)))
    t0 = data.draw(st.floats(-20, 20))
    lags = t0 - np.arange(M, dtype=float)                    # times k, k-1, ..., k-M+1
    x = np.polyval(coef, lags)
    target = np.polyval(coef, t0 + 1.0)
    rng = np.random.default_rng(M * 10 + N)
    for a in (ar_coefficients(M, N), ar_coefficients(M, N, _random_pd(rng, M)[None])[0]):
        scale = 1.0 + np.abs(a).sum() * (1.0 + np.abs(x).max())
        assert abs(a @ x - target) <= 1e-9 * scale


def test_first_order_coefficients_as_derived():
    np.testing.assert_allclose(ar_coefficients(2, 1), [2.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(ar_coefficients(3, 2), [3.0, -3.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(ar_coefficients(4, 1), [1.0, 0.5, 0.0, -0.5], atol=1e-12)
    np.testing.assert_allclose(exactness_constraints(4, 1).T @ ar_coefficients(4, 1), [1.0, 0.0], atol=1e-12)


def test_kinematic_map_is_exact_on_quadratics():
    dt = 0.5
    p, v, a = 100.0, -3.0, 0.7
    lags = lag_map(5, dt) @ np.array([p, v, a])
    np.testing.assert_allclose(kinematic_map(5, dt) @ lags, [p, v, a], rtol=1e-10)


@seed(13)
@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e8, 1e8), min_size=1, max_size=40), st.integers(1, 5))
def test_covariance_matched_q_is_psd_for_any_input(samples, n):
    """Whatever the innovations and predicted variances, Q_k = q e0 e0' has no negative eigenvalue."""
    excess = np.tile(np.asarray(samples, float), (n, 1))
    q = matched_noise(excess)
    assert np.all(q >= 0.0)
    Q = q[:, None, None] * np.diag([1.0, 0, 0, 0])
    assert np.all(np.linalg.eigvalsh(Q) >= 0.0)
    assert np.all(q >= excess.mean(axis=1)) and np.allclose(q[excess.mean(axis=1) >= 0],
                                                            excess.mean(axis=1)[excess.mean(axis=1) >= 0])


def _quiet_matched(n, K, dt, sigma, seed_):
    """Constant-velocity truths drawn from a prior with no acceleration; the filter's prior is
    the same, Q = 0 (the window never fills), so every AR order used is exact and the NIS
    of each tested step is chi2(1), independent of the past."""
    rng = np.random.default_rng(seed_)
    x0 = np.array([1000.0, -20.0, 0.0])
    P0 = np.diag([30.0, 5.0, 0.0]) ** 2
    p = x0[0] + 30.0 * rng.standard_normal(n)
    v = x0[1] + 5.0 * rng.standard_normal(n)
    truth = p[:, None] + v[:, None] * dt * np.arange(K)
    return truth + sigma * rng.standard_normal((n, K)), x0, P0


@pytest.mark.parametrize("switching", ["per-step", "latched"])
@pytest.mark.parametrize("coefficients", ["filter", "min-norm"])
def test_false_switch_rate_equals_alpha(switching, coefficients):
    """Switches on a quiet matched target ~ Binomial(tests, alpha): the count of tests is the
    number of steps actually tested (per-step: every step from M on; latched: the low-order
    steps only); the observed rate lies in the 99% Clopper-Pearson interval at a fixed seed."""
    alpha, n, K, sigma = 0.02, 400, 120, 10.0
    z, x0, P0 = _quiet_matched(n, K, 1.0, sigma, 7)
    params = SimpleNamespace(state_dim=4, window=1000, order_low=1, order_high=2, alpha=alpha, q0_m2=0.0,
                             coefficients=coefficients, switching=switching, state_noise="matching")
    res = ar_adaptive_filter(z, 1.0, sigma ** 2, x0, P0, params)
    tests = int(np.isfinite(res.nis).sum())
    switches = int(res.switch.sum())
    if switching == "per-step":
        assert tests == n * (K - 4)                            # every step from M = 4 on
    assert tests > 100 / alpha                                 # enough tests to resolve alpha
    ci = stats.binomtest(switches, tests, alpha).proportion_ci(0.99, method="exact")
    assert ci.low <= alpha <= ci.high, (switches, tests)
    # and the tested NIS is chi2(1): its mean is 1 within 4 standard errors (var 2 / tests)
    assert abs(np.nanmean(res.nis) - 1.0) < 4.0 * np.sqrt(2.0 / tests)
