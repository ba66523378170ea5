"""The posterior Cramér-Rao bound (models.pcrb) and the scenes that carry it."""

import numpy as np
import pytest

from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.models.glint import glint_fisher_information, glint_variance
from radarbench.models.kalman import LinearGaussianModel, steady_state
from radarbench.models.kinematics import cv, per_axis, position_measurement
from radarbench.models.pcrb import (linear_dynamics_pcrb, measurement_information, pcrb_recursion,
                                    position_mse_bound)
from radarbench.scenarios.glint import Glint
from radarbench.scenarios.maneuvering import Maneuvering


def _cv_scene(dt=1.0, sigma_a=2.0, sigma_z=30.0):
    F, Q = (per_axis(M, 2) for M in cv(dt, sigma_a))
    H = position_measurement(2, 2)
    return LinearGaussianModel(F=F, H=H, Q=Q, R=sigma_z ** 2 * np.eye(2))


def test_linear_gaussian_bound_is_the_kalman_filters_steady_state_covariance():
    """On a linear-Gaussian scene the PCRB is the Kalman filter's covariance: after enough
    steps, the trace of its position block equals the steady-state posterior's."""
    model = _cv_scene()
    K = 400
    Jz = np.broadcast_to(measurement_information(model.H, 1.0 / np.diag(model.R)), (1, K, 4, 4))
    bound = linear_dynamics_pcrb(np.diag([1e4, 400.0, 1e4, 400.0]), model.F, model.Q, Jz)[0]
    P_post = steady_state(model)[1]
    expected = P_post[0, 0] + P_post[2, 2]
    assert position_mse_bound(bound[-1], (0, 2)) == pytest.approx(expected, rel=1e-9)
    assert position_mse_bound(bound[0], (0, 2)) > 1.5 * expected          # it converges from above


def test_general_recursion_agrees_with_the_linear_gaussian_form():
    """With an invertible Q, D11 = F'Q^-1F, D12 = -F'Q^-1, D22 = Q^-1 + J_z in Tichavský's
    recursion give the covariance form's bound step for step."""
    rng = np.random.default_rng(0)
    d, K = 3, 30
    F = np.eye(d) + 0.1 * rng.standard_normal((d, d))
    A = rng.standard_normal((d, d))
    Q = A @ A.T + 0.5 * np.eye(d)
    H = rng.standard_normal((K, 2, d))
    Jz = measurement_information(H, np.array([2.0, 0.5]))
    P0 = np.diag([4.0, 1.0, 9.0])
    Qi = np.linalg.inv(Q)
    D11 = np.broadcast_to(F.T @ Qi @ F, (K - 1, d, d))
    D12 = np.broadcast_to(-F.T @ Qi, (K - 1, d, d))
    J = pcrb_recursion(np.linalg.inv(P0) + Jz[0], D11, D12, Qi + Jz[1:])
    np.testing.assert_allclose(np.linalg.inv(J), linear_dynamics_pcrb(P0, F, Q, Jz[None])[0], rtol=1e-9)


def test_glint_fisher_information():
    """1/sigma^2 without glint; above 1/variance with it (the Cramér-Rao inequality for the
    location of any density, equality for the Gaussian only), below the core's 1/sigma^2."""
    sigma, eta = np.array([1.0, 2e-3]), np.array([5.0, 1e-2])
    np.testing.assert_allclose(glint_fisher_information(sigma, eta, 0.0), 1.0 / sigma ** 2, rtol=1e-6)
    for model in ("mixture", "additive"):
        info = glint_fisher_information(sigma, eta, 0.1, model)
        assert np.all(info > 1.0 / glint_variance(sigma, eta, 0.1, model)) and np.all(info < 1.0 / sigma ** 2)


def test_scenes_carry_a_bound_below_the_kalman_filters_error():
    """maneuvering-1d without a maneuver is linear-Gaussian: the bound is the CV filter's
    covariance, so its RMSE over many trials meets the bound to sampling error."""
    from radarbench.methods.kinematic.kinematic_kf import ConstantVelocityKF
    p = build_params(Maneuvering.Params, {"maneuver_duration_s": 0.0, "process_noise_m_s2": 1.0})
    b = Maneuvering().generate(p, 0.0, 400, TrialRNG(5, 0, 0, range(400)))
    bound = b.scene.position_bound
    assert bound.shape == (400, 100) and np.all(bound == bound[0])
    out = ConstantVelocityKF().run(b, build_params(ConstantVelocityKF.Params, {"accel_noise_m_s2": 1.0}))
    mse = ((out.estimate[..., 0] - b.truth[..., 0]) ** 2).mean(axis=0)
    # the filter is matched: per-step MSE / bound is a chi-square(400)/400 mean; its time average within 3 %
    assert np.mean(mse / bound[0]) == pytest.approx(1.0, abs=0.03)


def test_glint_bound_rises_with_glint():
    """The glint scene's bound uses its density's Fisher information, less than the core's
    1/sigma^2: on the same trajectories it is positive and at least the Gaussian scene's."""
    b0 = Glint().generate(build_params(Glint.Params, {"sensor": "active", "epsilon": 0.0}), 0.0, 4,
                          TrialRNG(1, 0, 0, range(4)))
    b2 = Glint().generate(build_params(Glint.Params, {"sensor": "active", "epsilon": 0.2}), 0.0, 4,
                          TrialRNG(1, 0, 0, range(4)))
    assert b0.scene.position_bound.shape == b0.truth.shape[:2] and np.all(b0.scene.position_bound > 0)
    # the same trajectories (common random numbers); the glint's information is less than the core's
    np.testing.assert_array_equal(b0.truth, b2.truth)
    assert np.all(b2.scene.position_bound >= b0.scene.position_bound * (1 - 1e-12))
