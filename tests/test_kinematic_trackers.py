"""The kinematic baselines (cv-kf, ca-kf, singer, current-statistical, vd-filter,
imm-cv-ca): batched == their per-trial filterpy reference; consistency (NIS, NEES)
of the Kalman baselines on matched targets within sampling error; IMM with one mode
is that mode's Kalman filter; the kinematic models' closed forms."""

import dataclasses
import math

import numpy as np
import pytest
from scipy import stats

from radarbench.bench import registry
from radarbench.bench.core import Batch
from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.tasks.tracking import TrackingScene
from radarbench.methods.kinematic.base import ca_model, cv_model, cv_prior, linear_model
from radarbench.methods.kinematic.imm import IMMCVCA, filterpy_imm, imm_filter
from radarbench.models.kalman import kalman_filter, whiten
from radarbench.models.kinematics import (KinematicModel, ca, current_statistical_input, current_statistical_variance,
                               per_axis, position_index, singer, state_labels)
from radarbench.scenarios.maneuvering import Maneuvering

BASELINES = ("cv-kf", "ca-kf", "singer", "current-statistical", "vd-filter", "imm-cv-ca")
#: two-sided probability outside the sampling intervals
P_OUT = 1e-6
Z_OUT = stats.norm.isf(P_OUT / 2)


def _scenario_batch(n=12, seed=4, snr_db=0.0, **kw):
    p = build_params(Maneuvering.Params, kw)
    return Maneuvering().generate(p, snr_db, n, TrialRNG(seed, 0, 2, range(n)))


@pytest.mark.parametrize("dims", [1, 2])
@pytest.mark.parametrize("method", BASELINES)
def test_batched_equals_the_filterpy_reference(method, dims):
    """Every estimate, covariance and trace of the batched tracker equals the per-trial filterpy loop's."""
    batch = _scenario_batch(dims=dims, steps=70)
    cls = registry.get_method(method)
    out, ref = cls().run(batch, cls.Params()), cls().reference_run(batch, cls.Params())
    scale = np.abs(batch.truth).max()
    np.testing.assert_allclose(out.estimate, ref.estimate, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(out.covariance, ref.covariance, rtol=1e-7, atol=1e-7)
    for name in ("mode", "switch"):
        np.testing.assert_allclose(out.traces[name], ref.traces[name], rtol=0, atol=1e-9, err_msg=name)
    assert set(out.traces) >= {"mode", "switch"}


def test_vd_filter_switches_on_the_maneuver_and_back():
    """At 10 dB on the default profile (20 m/s^2 from step 40 to 60) the VD filter switches
    to CA within 10 steps of the onset in every trial (its measurement first shows the
    maneuver at step 41) and is back in CV 15 steps after its end."""
    batch = _scenario_batch(n=30, snr_db=10.0)
    out = registry.get_method("vd-filter")().run(batch, registry.get_method("vd-filter").Params())
    after_onset = out.traces["switch"][:, 40:] > 0
    assert after_onset.any(axis=1).all()
    assert (np.argmax(after_onset, axis=1) <= 10).all()
    assert (out.traces["mode"][:, 75] == 0).all()
    assert set(np.unique(out.traces["mode"])) == {0.0, 1.0}


def test_imm_is_step_by_step_filterpy_imm_estimator():
    """Mode probabilities, combined estimate and covariance at every step."""
    batch = _scenario_batch(n=5, dims=2, snr_db=-5.0)
    model = batch.scene.model
    params = IMMCVCA.Params(transition=(0.9, 0.1, 0.2, 0.8), initial_probabilities=(0.6, 0.4))
    args = (IMMCVCA.modes(model, params), np.reshape(params.transition, (2, 2)),
            np.asarray(params.initial_probabilities), batch.z, model.x0, model.P0)
    ours, ref = imm_filter(*args), filterpy_imm(*args)
    np.testing.assert_allclose(ours.mu, ref.mu, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(ours.x, ref.x, rtol=0, atol=1e-7)
    np.testing.assert_allclose(ours.P, ref.P, rtol=1e-8, atol=1e-8)


def test_imm_with_one_mode_is_that_modes_kalman_filter():
    batch = _scenario_batch(n=6, dims=2)
    model = batch.scene.model
    ca_m = ca_model(model, 2.0)
    res = imm_filter([ca_m], np.ones((1, 1)), np.ones(1), batch.z, model.x0, model.P0)
    kf = kalman_filter(ca_m, batch.z, model.x0, model.P0)
    np.testing.assert_allclose(res.x, kf.x_post, rtol=0, atol=1e-8)
    np.testing.assert_allclose(res.P, np.broadcast_to(kf.P_post, res.P.shape), rtol=1e-10, atol=1e-10)
    np.testing.assert_array_equal(res.mu, 1.0)


# ------------------------------------------------------------------ consistency

def _simulated_batch(F_axis, Q_axis, dims, x0_axis, P0_axis, noise_std, n, K, seed):
    """Truth x_{k+1} = F x_k + w_k, w_k ~ N(0, Q), x_0 ~ N(x0, P0) per axis (the filter's
    own model), positions measured with N(0, noise_std^2) noise."""
    rng = np.random.default_rng(seed)
    F, Q = per_axis(F_axis, dims), per_axis(Q_axis, dims)
    x0, P0 = np.tile(x0_axis, dims), per_axis(P0_axis, dims)

    def root(C):
        lam, V = np.linalg.eigh(C)
        return V * np.sqrt(np.clip(lam, 0, None))

    truth = np.empty((n, K, len(x0)))
    x = x0 + rng.standard_normal((n, len(x0))) @ root(P0).T
    for k in range(K):
        truth[:, k] = x
        x = x @ F.T + rng.standard_normal((n, len(x0))) @ root(Q).T
    z = truth[..., list(position_index(dims))] + noise_std * rng.standard_normal((n, K, dims))
    model = KinematicModel(dt_s=1.0, noise_std_m=float(noise_std), dims=dims, x0=x0, P0=P0)
    scene = TrackingScene(model=model, position_index=position_index(dims), state_labels=state_labels(dims))
    return Batch(t=np.arange(K, dtype=float), truth=truth, z=z, scene=scene, trials=np.arange(n))


def _matched(name: str, dims: int, n=400, K=60):
    """(batch, the method's params, its filter model, prior) on a target drawn from its own model."""
    x0_axis, P0_axis = np.array([1000.0, 50.0, 0.0]), np.diag([30.0, 5.0, 2.0]) ** 2
    if name == "cv-kf":
        # the scenario with no maneuver and a white acceleration of sigma_a is the CV (DWNA) model
        batch = _scenario_batch(n=n, seed=11, steps=K, dims=dims, maneuver_accel_m_s2=(0.0,),
                                process_noise_m_s2=2.0, initial_accel_std_m_s2=2.0)
        params = registry.get_method(name).Params(accel_noise_m_s2=2.0)
        return batch, params, cv_model(batch.scene.model, 2.0), cv_prior(batch.scene.model)
    if name == "ca-kf":
        batch = _simulated_batch(*ca(1.0, 0.5), dims, x0_axis, P0_axis, 20.0, n, K, seed=12)
        params = registry.get_method(name).Params(accel_increment_m_s2=0.5)
        return batch, params, ca_model(batch.scene.model, 0.5), (batch.scene.model.x0, batch.scene.model.P0)
    F, Q = singer(1.0, 0.2, 4.0)
    batch = _simulated_batch(F, Q, dims, x0_axis, np.diag([30.0, 5.0, 4.0]) ** 2, 20.0, n, K, seed=13)
    params = registry.get_method(name).Params(alpha_per_s=0.2, sigma_m_s2=4.0)
    return batch, params, linear_model(batch.scene.model, F, Q), (batch.scene.model.x0, batch.scene.model.P0)


@pytest.mark.parametrize("dims", [1, 2])
@pytest.mark.parametrize("name", ["cv-kf", "ca-kf", "singer"])
def test_nis_and_nees_of_matched_kalman_baselines(name, dims):
    """On a target drawn from the filter's own model (no maneuver, matched noise):

    * NIS: the innovations of a matched filter are independent over steps and trials, so
      the sum of all n K NIS values is chi2(m n K): the mean is within its chi-square interval;
    * NEES: the errors are correlated over steps, so the n per-trial means (independent) give
      the interval, mean +- z sd / sqrt(n) (z at P_OUT); its mean is the state dimension, 3 dims
      (the CV tracker's padded acceleration, variance sigma_a^2, is independent of its error).
    """
    batch, params, filt, prior = _matched(name, dims)
    n, K, m = batch.z.shape
    res = kalman_filter(filt, batch.z, *prior)
    nis = whiten(res.nu, res.S)[1]
    lo, hi = stats.chi2.ppf(P_OUT / 2, m * n * K), stats.chi2.isf(P_OUT / 2, m * n * K)
    assert lo / (n * K) < nis.mean() < hi / (n * K), (nis.mean(), m)

    out = registry.get_method(name)().run(batch, params)
    err = out.estimate - batch.truth
    nees = np.einsum("nki,nki->nk", err, np.linalg.solve(out.covariance, err[..., None])[..., 0])
    trial_means = nees.mean(axis=1)
    half = Z_OUT * trial_means.std(ddof=1) / math.sqrt(n)
    assert abs(trial_means.mean() - 3 * dims) < half, (trial_means.mean(), 3 * dims, half)


# ------------------------------------------------------------------ kinematic models

def test_singer_closed_form_and_limits():
    dt, alpha, sigma = 0.7, 0.3, 5.0
    F, Q = singer(dt, alpha, sigma)
    e = math.exp(-alpha * dt)
    expected_F = [[1, dt, (alpha * dt - 1 + e) / alpha ** 2], [0, 1, (1 - e) / alpha], [0, 0, e]]
    np.testing.assert_allclose(F, expected_F, rtol=1e-12, atol=1e-15)
    assert np.linalg.eigvalsh(Q).min() > 0
    # alpha -> 0 with 2 alpha sigma^2 = q fixed: the CA model driven by white jerk of density q
    q = 2.0
    F0, Q0 = singer(dt, 1e-7, math.sqrt(q / 2e-7))
    cwpa = q * np.array([[dt ** 5 / 20, dt ** 4 / 8, dt ** 3 / 6], [dt ** 4 / 8, dt ** 3 / 3, dt ** 2 / 2],
                         [dt ** 3 / 6, dt ** 2 / 2, dt]])
    np.testing.assert_allclose(F0, ca(dt, 0.0)[0], atol=1e-6)
    np.testing.assert_allclose(Q0, cwpa, rtol=1e-5)


@pytest.mark.parametrize("alpha_dt", [0.2, 0.999, 1.001, 5.0])
def test_singer_van_loan_and_closed_form_agree(alpha_dt):
    """Van Loan (used up to alpha T = 1) and Singer's closed form (beyond) are the same Q."""
    from radarbench.models.kinematics import _singer_closed_form
    dt = 0.5
    F, Q = singer(dt, alpha_dt / dt, 3.0)
    F2, Q2 = _singer_closed_form(dt, alpha_dt / dt, 3.0)
    np.testing.assert_allclose(F, F2, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(Q, Q2, rtol=1e-9, atol=1e-12 * np.abs(Q).max())


def test_current_statistical_prediction_is_the_ca_prediction():
    """F(alpha) x + U a = the CA transition of x when the current mean is the state's acceleration."""
    dt, alpha = 0.5, 0.4
    F, _ = singer(dt, alpha, 1.0)
    U = current_statistical_input(dt, alpha)
    x = np.array([100.0, -20.0, 3.0])
    np.testing.assert_allclose(F @ x + U * x[2], ca(dt, 0.0)[0] @ x, rtol=1e-12)


def test_current_statistical_variance():
    c = (4 - math.pi) / math.pi
    var = current_statistical_variance(np.array([0.0, 10.0, -10.0, 60.0, -80.0]), 50.0, 40.0, 0.01)
    np.testing.assert_allclose(var, [c * 2500, c * 1600, c * 900, 0.01, 0.01])


@pytest.mark.parametrize("dims, transition, mu0, ragged", [
    (2, (0.9, 0.1, 0.2, 0.8), (0.6, 0.4), False),
    (1, (0.95, 0.05, 0.05, 0.95), (0.9, 0.1), True),
    (2, (0.5, 0.5, 1.0, 0.0), (0.5, 0.5), True),          # a zero transition: log 0 = -inf, its weight 0
])
def test_the_compiled_imm_is_the_batched_numpy_steps_bit_for_bit(dims, transition, mu0, ragged):
    """Every trial's numbers equal, not merely close: the committed results were made by
    the batched NumPy steps (tests/imm_oracle.py) the compiled kernel replaced."""
    from tests.kinematic_oracle import stepwise_imm_filter
    batch = _scenario_batch(n=9, dims=dims, snr_db=-3.0)
    model = batch.scene.model
    params = IMMCVCA.Params(transition=transition, initial_probabilities=mu0)
    valid = np.random.default_rng(dims).random(batch.z.shape[:2]) > 0.2 if ragged else None
    args = (IMMCVCA.modes(model, params), np.reshape(transition, (2, 2)), np.asarray(mu0), batch.z, model.x0,
            model.P0)
    ours, oracle = imm_filter(*args, valid=valid), stepwise_imm_filter(*args, valid=valid)
    for name in ("x", "P", "mu"):
        np.testing.assert_array_equal(getattr(ours, name), getattr(oracle, name), err_msg=name)


@pytest.mark.parametrize("dims, ragged, a_max", [(2, False, 50.0), (1, True, 50.0), (2, True, 0.5)])
def test_the_compiled_current_statistical_is_the_batched_numpy_steps_bit_for_bit(dims, ragged, a_max):
    """As the IMM's above; ``a_max`` 0.5 m/s^2 clips the acceleration and holds the floor."""
    from tests.kinematic_oracle import stepwise_current_statistical
    batch = _scenario_batch(n=9, dims=dims, snr_db=-3.0)
    if ragged:
        valid = np.random.default_rng(dims).random(batch.z.shape[:2]) > 0.2
        batch = dataclasses.replace(batch, z=np.where(valid[..., None], batch.z, np.nan),
                                    scene=dataclasses.replace(batch.scene, valid_steps=valid))
    method = registry.get_method("current-statistical")()
    params = build_params(type(method).Params, {"a_max_m_s2": a_max, "a_max_neg_m_s2": a_max,
                                                "accel_std_floor_m_s2": 0.1})
    ours, oracle = method.track(batch, batch.scene.model, params), stepwise_current_statistical(
        method, batch, batch.scene.model, params)
    np.testing.assert_array_equal(ours.estimate, oracle.estimate)
    np.testing.assert_array_equal(ours.covariance, oracle.covariance)
    np.testing.assert_array_equal(ours.traces["accel_std"], oracle.traces["accel_std"])
