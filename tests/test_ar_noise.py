"""AR noise maths: stationarity, Yule-Walker autocovariance, exact predictors."""

import numpy as np
import pytest

from radarbench.models.ar_noise import (ar_autocovariance, ar_innovation_std, ar_roots, ar_stationarity_problem,
                             stationary_predictors)

DEFAULT_AR = (-2.0, 1.7, -0.64)      # the tbd-grid default
PAPER_PRINTED_AR = (-2.0, 1.7, 0.64)


def test_default_ar_is_stable_and_paper_printed_set_is_explosive():
    assert np.max(np.abs(ar_roots(DEFAULT_AR))) == pytest.approx(0.9018821, abs=1e-6)
    assert np.max(np.abs(ar_roots(PAPER_PRINTED_AR))) > 1.5
    assert np.max(np.abs(ar_roots((2.0, -1.7, -0.64)))) > 2.5          # the other sign convention
    assert ar_stationarity_problem(DEFAULT_AR) is None
    why = ar_stationarity_problem(PAPER_PRINTED_AR)
    assert why.startswith("not stationary: z^3 - 2 z^2 + 1.7 z + 0.64") and "1.525" in why


def test_autocovariance_solves_yule_walker():
    a = (-2.0, 1.7, -0.64)
    g = ar_autocovariance(a, 10)
    assert g[0] == pytest.approx(1.0)
    for h in range(1, 11):      # gamma(h) + a1 gamma(h-1) + a2 gamma(h-2) + a3 gamma(h-3) = 0, h >= 1
        assert g[h] + sum(ai * g[abs(h - i)] for i, ai in enumerate(a, 1)) == pytest.approx(0.0, abs=1e-12)


def test_innovation_std_gives_the_stationary_variance():
    for a in (DEFAULT_AR, (-0.5,), (0.3, -0.2)):
        sigma_w = ar_innovation_std(a, 4.0)
        gamma = ar_autocovariance(a, len(a), 4.0)
        # first Yule-Walker equation: sigma_w^2 = gamma(0) + sum_i a_i gamma(i)
        assert sigma_w ** 2 == pytest.approx(gamma[0] + np.dot(a, gamma[1:]), rel=1e-12)


def test_stationary_predictors_are_the_cholesky_factor_of_the_stationary_covariance():
    """v = L e with Gamma_P = L L': predictor k gives row k of L^-1 up to scale."""
    a, sigma = DEFAULT_AR, 2.0
    P = len(a)
    gamma = ar_autocovariance(a, P - 1, sigma ** 2)
    Gamma = gamma[np.abs(np.subtract.outer(np.arange(P), np.arange(P)))]
    L = np.linalg.cholesky(Gamma)
    for k, (phi, nu) in enumerate(stationary_predictors(a, sigma)):
        assert nu == pytest.approx(L[k, k] ** 2, rel=1e-12)
        row = np.zeros(P)
        row[k] = 1.0
        row[:k] = -phi[::-1]                       # v_k - sum_j phi_j v_(k-j)
        np.testing.assert_allclose(row @ L, np.r_[np.zeros(k), L[k, k], np.zeros(P - k - 1)], atol=1e-12)
