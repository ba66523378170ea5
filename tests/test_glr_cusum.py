"""Maneuver detectors `glr` and `cusum`: the textbook formulas by plain loops, the
signature matrices by brute force, the nominal threshold by simulation."""

import numpy as np
import pytest
import scipy.stats
from hypothesis import given, settings, strategies as st

from radarbench.bench.core import DetectionOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.registry import get_method, get_task
from radarbench.bench.sweep.rng import CALIBRATION, TrialRNG
from radarbench.methods.maneuver.cusum import Cusum, page_cusum, reference_cusum
from radarbench.methods.maneuver import glr as glr_module
from radarbench.methods.maneuver.glr import JUMPS, Glr, glr_statistic, jump_response, reference_glr, signatures
from radarbench.models.kalman import (LinearGaussianModel, covariance_sequence, filterpy_innovations, kalman_filter,
                           steady_state)
from radarbench.scenarios.cv_turn_cv import CvTurnCv, cv_model, dwna_gain
from tests.test_detectors import batch, run  # noqa: F401 - the 10 dB batch fixture, shared
from tests.test_kalman import random_model


def test_registered():
    assert get_method("glr") is Glr
    assert get_method("cusum") is Cusum


# ------------------------------------------------------------------ GLR: the textbook formula

def brute_force_signatures(model: LinearGaussianModel, P0: np.ndarray, K: int, jump: str) -> np.ndarray:
    """G[theta, t] (m, m): column c is the innovation at step t of the filter run, from a zero
    state, on the noise-free measurements of a unit jump of component c with onset theta
    (filterpy, one deterministic "trial" per onset and component)."""
    m = model.dim_z
    z = np.zeros((K, m, K, m))                       # (onset, component, step, measured)
    for theta in range(K):
        for c in range(m):
            z[theta, c, theta:, c] = [jump_response(jump, t - theta) for t in range(theta, K)]
    nu, _ = filterpy_innovations(model, z.reshape(K * m, K, m), np.zeros(model.dim_x), P0)
    return nu.reshape(K, m, K, m).transpose(0, 2, 3, 1)          # (theta, t, measured, component)


def textbook_glr(nu: np.ndarray, S: np.ndarray, G: np.ndarray, window: int) -> np.ndarray:
    """l(t) = max over theta in (t - M, t] of d' C^-1 d, d = sum G' S^-1 nu, C = sum G' S^-1 G over
    j = theta .. t, for one trial's innovations nu (K, m): the sums written out, no recursion."""
    K = nu.shape[0]
    out = np.zeros(K)
    for t in range(K):
        for theta in range(max(0, t - window + 1), t + 1):
            d = sum(G[theta, j].T @ np.linalg.solve(S[j], nu[j]) for j in range(theta, t + 1))
            C = sum(G[theta, j].T @ np.linalg.solve(S[j], G[theta, j]) for j in range(theta, t + 1))
            out[t] = max(out[t], d @ np.linalg.solve(C, d))
    return out


def _random_case(seed, K, cv):
    """A model (a CV model, or a random linear one), a prior far from steady state (so the
    gains vary over time), three trials of random measurements."""
    rng = np.random.default_rng(seed)
    if cv:
        model = cv_model(rng.uniform(0.1, 3.0), rng.uniform(0.5, 20.0), rng.uniform(0.01, 2.0))
    else:
        model = random_model(rng)
    A = rng.standard_normal((4, 4))
    P0 = rng.uniform(0.1, 30.0) * A @ A.T + np.eye(4)
    z = rng.standard_normal((3, K, 2)) * rng.uniform(0.5, 5.0) + rng.standard_normal(2)
    return model, P0, z, rng.standard_normal((3, 4))


@settings(max_examples=30, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), K=st.integers(1, 14), window=st.integers(1, 16),
       jump=st.sampled_from(JUMPS), cv=st.booleans())
def test_glr_equals_the_textbook_sums(seed, K, window, jump, cv):
    model, P0, z, x0 = _random_case(seed, K, cv)
    res = kalman_filter(model, z, x0, P0)
    got, _ = glr_statistic(res.nu, res.S, signatures(model, res.gain, res.S, window, jump))
    G = brute_force_signatures(model, P0, K, jump)
    want = np.stack([textbook_glr(res.nu[i], res.S, G, window) for i in range(z.shape[0])])
    np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9)
    online = reference_glr(model, z, x0, P0, window, jump)         # the bench perf reference
    np.testing.assert_allclose(online, want, rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize("jump", JUMPS)
@pytest.mark.parametrize("steady", [False, True])
def test_signatures_equal_the_filter_on_a_unit_jump(jump, steady):
    """G(t; theta) from the recursion = the filter's innovations on the noise-free unit jump,
    and C(t; theta)^-1 = (sum G' S^-1 G)^-1, at every lag and onset: from a prior far from
    steady state (gains varying) and from the steady state (one onset stands for all)."""
    rng = np.random.default_rng(4)
    model = random_model(rng)
    P0 = steady_state(model)[0] if steady else 5.0 * np.eye(4)
    K, window = 12, 7
    _, _, S, gains = covariance_sequence(model, P0, K)
    assert glr_module._constant(gains) == steady
    G = brute_force_signatures(model, P0, K, jump)
    lags = list(signatures(model, gains, S, window, jump))
    assert [sig.lag for sig in lags] == list(range(window))
    for sig in lags:
        for theta in range(K - sig.lag):
            t = theta + sig.lag
            np.testing.assert_allclose(sig.G[theta], G[theta, t], rtol=1e-9, atol=1e-12)
            C = sum(G[theta, j].T @ np.linalg.inv(S[j]) @ G[theta, j] for j in range(theta, t + 1))
            np.testing.assert_allclose(sig.info_inverse[theta], np.linalg.inv(C), rtol=1e-8)


@pytest.mark.parametrize("jump", JUMPS)
def test_signature_is_the_cv_models_own_jump(jump):
    """On the DWNA CV model, psi is the measured response of the model's own jump: a constant
    acceleration input through its noise gain [T^2/2, T]' (in units of T^2), or a velocity
    step (in units of T) between two measurements."""
    T, onset, K = 2.0, 3, 15
    model = cv_model(T, 5.0, 0.3)
    P0 = np.eye(4)
    x = np.zeros((K, 4))
    step = (np.array([1.0, -0.5]) if jump == "acceleration" else np.array([0.7, 0.2]))
    for k in range(1, K):
        x[k] = model.F @ x[k - 1]
        if k >= onset and jump == "acceleration":
            x[k] += dwna_gain(T) @ step / T ** 2
        if k == onset and jump == "velocity":
            x[k] += np.kron(step, [T, 1.0]) / T              # the velocity moves by step/T just after k-1
    z = (x @ model.H.T)[None]
    nu = kalman_filter(model, z, np.zeros(4), P0).nu[0]
    _, _, S, gains = covariance_sequence(model, P0, K)
    for sig in signatures(model, gains, S, K - onset, jump):
        np.testing.assert_allclose(nu[onset + sig.lag], sig.G[onset] @ step, rtol=1e-9, atol=1e-12)


def test_run_is_the_batched_statistic_with_traces(batch):
    out = run(Glr, {"window": 9}, batch)
    assert isinstance(out, DetectionOutput) and out.valid_from == 8
    filt = batch.scene.reference_filter
    want = reference_glr(filt.model, batch.z, filt.x0, filt.P0, 9, "acceleration")
    np.testing.assert_allclose(out.statistic, want, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(Glr().reference_run(batch, build_params(Glr.Params, {"window": 9})).statistic,
                               want)
    assert set(out.traces) == {"onset_lag", "nis"}
    assert out.traces["onset_lag"].min() >= 0 and out.traces["onset_lag"].max() <= 8


def test_onset_estimate_follows_the_turn():
    """At high SNR the maximising lag counts the steps since the turn began."""
    params = build_params(CvTurnCv.Params, {"onset_jitter_steps": 0})
    b = CvTurnCv().generate(params, 25.0, 3, TrialRNG(2, 0, 0, range(3)))
    lag = run(Glr, {"window": 30}, b).traces["onset_lag"]
    since = np.arange(5, 25)
    steps = b.scene.onset_step + since
    assert np.all(np.abs(lag[:, steps] - since) <= 2), lag[:, steps]


def test_detectors_respond_to_the_turn(batch):
    on = batch.scene.onset_step
    for cls, values in ((Glr, {}), (Glr, {"jump": "velocity"}), (Cusum, {}), (Cusum, {"score": "glr",
                                                                                        "drift": 12.0})):
        s = run(cls, values, batch).statistic
        assert np.mean(s[:, on:on + 20]) > 3 * np.mean(s[:, 40:on]) + 1.0, (cls.name, values)


# ------------------------------------------------------------------ GLR: the nominal threshold

NULL_TRIALS = 2000


@pytest.fixture(scope="module")
def null_batch():
    return CvTurnCv().generate(CvTurnCv.default_params(), None, NULL_TRIALS,
                               TrialRNG(17, CALIBRATION, 5, range(NULL_TRIALS)))


def _null_statistic(null_batch, window):
    out = run(Glr, {"window": window}, null_batch)
    return out.statistic[:, get_task(Glr.task).null_start(null_batch, out):]


def test_a_single_onset_is_exactly_chi2(null_batch):
    """M = 1: d(t; t)' C^-1 d(t; t) is chi2(n_z), white over steps, so its exceedances of the
    nominal threshold are Bernoulli(pfa): the count lies in the exact binomial 99.9% interval."""
    pfa = 0.01
    stat = _null_statistic(null_batch, 1)
    threshold = Glr().nominal_threshold(build_params(Glr.Params, {"window": 1}), pfa, null_batch)
    assert threshold == pytest.approx(scipy.stats.chi2.isf(pfa, 2))
    low, high = scipy.stats.binom.interval(0.999, stat.size, pfa)
    assert low <= np.sum(stat >= threshold) <= high


@pytest.mark.parametrize("window", [5, 20, 40])
def test_bonferroni_threshold_bounds_the_pfa(null_batch, window):
    """The maximum over M onsets at the chi2 quantile of pfa / M: its per-step false-alarm rate
    is at most pfa (Bonferroni). One-sided, with the standard error of the rate over trials
    (alarms cluster within a trial; trials are independent): 4.5 standard errors above."""
    pfa = 0.01
    stat = _null_statistic(null_batch, window)
    threshold = Glr().nominal_threshold(build_params(Glr.Params, {"window": window}), pfa, null_batch)
    assert threshold == pytest.approx(scipy.stats.chi2.isf(pfa / window, 2))
    counts = (stat >= threshold).sum(axis=1)
    rate = counts.sum() / stat.size
    se = counts.std(ddof=1) / np.sqrt(len(counts)) / stat.shape[1]
    assert rate <= pfa + 4.5 * se, (rate, se)
    assert 4.5 * se < pfa / 2                  # power: a rate of 1.5 pfa would be seen


# ------------------------------------------------------------------ CUSUM

@settings(max_examples=40, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), K=st.integers(1, 60), drift=st.floats(0.0, 10.0),
       scale=st.floats(0.1, 10.0))
def test_page_cusum_equals_the_recursion_loop(seed, K, drift, scale):
    score = np.random.default_rng(seed).chisquare(2, (4, K)) * scale
    np.testing.assert_allclose(page_cusum(score, drift), reference_cusum(score, drift), rtol=1e-12, atol=1e-12)


def test_page_cusum_by_hand():
    g = page_cusum(np.array([[1.0, 5.0, 0.0, 4.0, 3.0]]), 2.0)
    np.testing.assert_array_equal(g, [[0.0, 3.0, 1.0, 3.0, 4.0]])


@pytest.mark.parametrize("values", [{}, {"drift": 2.5}, {"score": "glr", "drift": 10.0, "window": 8},
                                    {"score": "glr", "drift": 8.0, "jump": "velocity"}])
def test_cusum_run_equals_its_reference(batch, values):
    params = build_params(Cusum.Params, values)
    out, ref = Cusum().run(batch, params), Cusum().reference_run(batch, params)
    np.testing.assert_allclose(out.statistic, ref.statistic, rtol=1e-9, atol=1e-9)
    assert out.valid_from == ref.valid_from == (params.window - 1 if params.score == "glr" else 0)
    source = out.traces[params.score]
    np.testing.assert_array_equal(out.statistic, page_cusum(source, params.drift))
    if params.score == "glr":
        np.testing.assert_array_equal(source, Glr().run(batch, params).statistic)


def test_cusum_has_no_nominal_threshold(batch):
    assert not Cusum.has_nominal_threshold()
    assert np.isnan(Cusum().nominal_threshold(Cusum.Params(), 0.01, batch))


# ------------------------------------------------------------------ parameters

@pytest.mark.parametrize("cls, values, field", [
    (Glr, {"window": 0}, "window"),
    (Glr, {"window": 1001}, "window"),
    (Glr, {"jump": "position"}, "jump"),
    (Cusum, {"drift": -1.0}, "drift"),
    (Cusum, {"score": "cumulant"}, "score"),
    (Cusum, {"window": 5}, "window"),                  # a GLR parameter with the NIS score
    (Cusum, {"jump": "velocity"}, "jump"),
])
def test_bad_params_name_the_field(cls, values, field):
    with pytest.raises(ConfigError) as err:
        build_params(cls.Params, values)
    assert err.value.field == field


def test_window_longer_than_the_scene_is_refused():
    short = build_params(CvTurnCv.Params, {"steps": 120})
    assert "120 steps" in Glr().check_scenario(build_params(Glr.Params, {"window": 200}), short)
    assert Glr().check_scenario(build_params(Glr.Params, {"window": 100}), short) is None
    assert "120 steps" in Cusum().check_scenario(build_params(Cusum.Params, {"score": "glr", "window": 200}), short)
    assert Cusum().check_scenario(build_params(Cusum.Params, {}), short) is None
