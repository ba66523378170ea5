"""huber-ekf: Huber's M-estimator EKF on the glint scenario."""

import numpy as np
import pytest
import scipy.stats

from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.methods.glint.ekf import EKF, ekf_filter, kalman_gain, noise_covariance
from radarbench.methods.glint.huber import HuberEKF, huber_reweigh, huber_weights, minimax_threshold
from radarbench.scenarios.glint import Glint


def _batch(eps, n, seed=11):
    params = build_params(Glint.Params, {"sensor": "active", "epsilon": eps})
    return Glint().generate(params, 0.0, n, TrialRNG(seed, 0, 0, range(n)))


def _rmse(out, batch):
    return np.sqrt(((out.estimate - batch.truth)[..., :3] ** 2).sum(-1).mean(axis=1))


def test_minimax_threshold_solves_hubers_equation():
    """Huber (1964): eps = 0.05 gives c = 1.399 (his table); the root satisfies the equation."""
    assert minimax_threshold(0.05) == pytest.approx(1.3984, abs=1e-4)
    for eps in (0.01, 0.2, 0.5):
        c = minimax_threshold(eps)
        lhs = 2 * scipy.stats.norm.pdf(c) / c - 2 * scipy.stats.norm.cdf(-c)
        assert lhs == pytest.approx(eps / (1 - eps), rel=1e-9)
    assert minimax_threshold(0.0) == np.inf


def test_without_contamination_it_is_the_ekf():
    """At eps = 0 the threshold is infinite, every weight 1: the EKF's numbers exactly."""
    b = _batch(0.0, 6)
    huber = HuberEKF().run(b, build_params(HuberEKF.Params, {}))
    ekf = EKF().run(b, build_params(EKF.Params, {}))
    np.testing.assert_array_equal(huber.estimate, ekf.estimate)
    np.testing.assert_array_equal(huber.covariance, ekf.covariance)


def test_update_is_the_m_estimate():
    """The weighted update solves the M-estimator's normal equations
    H' (psi(r) / sigma) = P^-1 d at the returned weights, clipped residuals among them."""
    rng = np.random.default_rng(3)
    n, m, d = 5, 3, 6
    H = rng.standard_normal((n, m, d))
    A = rng.standard_normal((n, d, d))
    P = A @ A.transpose(0, 2, 1) + np.eye(d)
    R = np.diag([0.5, 2.0, 1.0])
    nu = rng.standard_normal((n, m)) * 3.0
    nu[:, 1] += 40.0                                   # an outlier
    c = minimax_threshold(0.1)
    R_w = huber_reweigh(c)(nu, H, P, R)
    gain = kalman_gain(P, H, R_w)[0]
    delta = np.einsum("nij,nj->ni", gain, nu)
    r = (nu - np.einsum("nij,nj->ni", H, delta)) / np.sqrt(np.diag(R))
    psi = huber_weights(r, c) * r
    lhs = np.einsum("nji,nj->ni", H, psi / np.sqrt(np.diag(R)))
    rhs = np.linalg.solve(P, delta[..., None])[..., 0]
    np.testing.assert_allclose(lhs, rhs, rtol=1e-6, atol=1e-8)
    assert np.sum(np.abs(r) > c) >= 3                   # clipped residuals: the normal equations are Huber's


def test_beats_the_ekf_under_contamination():
    """eps = 0.2, 60 trials at a fixed seed: the paired per-trial RMSE difference huber - ekf
    lies below 0 by more than 3 standard errors of its mean (its sampling distribution)."""
    b = _batch(0.2, 60)
    huber = _rmse(HuberEKF().run(b, build_params(HuberEKF.Params, {})), b)
    ekf = _rmse(EKF().run(b, build_params(EKF.Params, {})), b)
    diff = huber - ekf
    assert diff.mean() + 3.0 * diff.std(ddof=1) / np.sqrt(len(diff)) < 0.0


def test_threshold_from_the_scene_or_given():
    b = _batch(0.05, 2)
    model = b.scene.model
    assert HuberEKF.threshold(model, build_params(HuberEKF.Params, {})) == minimax_threshold(0.05)
    assert HuberEKF.threshold(model, build_params(HuberEKF.Params, {"epsilon": 0.2})) == minimax_threshold(0.2)
    res = ekf_filter(b.z, model, noise_covariance(model, "core"), reweigh=huber_reweigh(1.0))
    assert np.all(np.isfinite(res.x_post))
