"""Maneuver detectors `innovation` and `cumulant`: outputs, thresholds, params."""

import numpy as np
import pytest
import scipy.stats

from radarbench.bench.core import DetectionOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.registry import get_method
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.models.windows import sliding_sum
from radarbench.methods.maneuver.cumulant import Cumulant, window_third_moment
from radarbench.methods.maneuver.innovation import Innovation, fading_sum, fading_valid_from
from radarbench.models.kalman import innovations
from radarbench.scenarios.cv_turn_cv import CvTurnCv

CONFIGS = [
    (Innovation, {}),
    (Innovation, {"window": 1}),
    (Innovation, {"window": 1, "delta": 0.7}),
    (Cumulant, {}),
    (Cumulant, {"moment": "raw", "combine": "max", "normalisation": "paper", "window": 8}),
]


@pytest.fixture(scope="module")
def batch():
    rng = TrialRNG(seed=1, domain=0, scenario_key=0, trials=range(6))
    return CvTurnCv().generate(CvTurnCv.default_params(), 10.0, 6, rng)


def run(cls, values, batch):
    return cls().run(batch, build_params(cls.Params, values))


def test_registered():
    assert get_method("innovation") is Innovation
    assert get_method("cumulant") is Cumulant


@pytest.mark.parametrize("cls, values", CONFIGS)
def test_shapes_no_nan_deterministic(cls, values, batch):
    out = run(cls, values, batch)
    assert isinstance(out, DetectionOutput)
    assert out.statistic.shape == (batch.n, batch.steps)
    assert np.all(np.isfinite(out.statistic))
    assert 0 <= out.valid_from < batch.steps
    for trace in out.traces.values():
        assert trace.shape == (batch.n, batch.steps) and np.all(np.isfinite(trace))
    np.testing.assert_array_equal(out.statistic, run(cls, values, batch).statistic)


def test_window_one_is_nis(batch):
    out = run(Innovation, {"window": 1}, batch)
    # equal up to the rounding of the cumulative-sum differences
    nis = innovations(batch.scene.reference_filter, batch.z).nis
    np.testing.assert_allclose(out.statistic, nis, rtol=1e-9, atol=1e-9)
    assert out.valid_from == 0


def test_sliding_and_fading_sums():
    x = np.random.default_rng(3).random((3, 30))
    s = sliding_sum(x, 4)
    np.testing.assert_allclose(s[:, 10], x[:, 7:11].sum(axis=1))
    np.testing.assert_allclose(s[:, 2], x[:, :3].sum(axis=1))        # partial window
    e = fading_sum(x, 0.6)
    ref = np.zeros(3)
    for k in range(30):
        ref = 0.6 * ref + x[:, k]
    np.testing.assert_allclose(e[:, -1], ref)
    assert fading_valid_from(0.5) == 6          # 0.5^7 < 0.01 <= 0.5^6
    assert fading_valid_from(0.1) == 2          # 0.1^2 is not < 0.01


def test_nominal_thresholds(batch):
    def thr(cls, values, pfa=0.01):
        return cls().nominal_threshold(build_params(cls.Params, values), pfa, batch)

    assert thr(Innovation, {"window": 5}) == pytest.approx(scipy.stats.chi2.ppf(0.99, 10))
    assert thr(Innovation, {"window": 1}) == pytest.approx(scipy.stats.chi2.ppf(0.99, 2))
    d = 0.8
    assert thr(Innovation, {"window": 1, "delta": d}) == pytest.approx(
        scipy.stats.chi2.ppf(0.99, 2 * (1 + d) / (1 - d)) / (1 + d))
    for norm in ("consistent", "paper"):
        assert thr(Cumulant, {"normalisation": norm}) == pytest.approx(scipy.stats.chi2.ppf(0.99, 2))
        assert thr(Cumulant, {"normalisation": norm, "combine": "max"}) == pytest.approx(
            scipy.stats.chi2.ppf(0.99 ** 0.5, 1))


@pytest.mark.parametrize("cls, values, field", [
    (Innovation, {"window": 0}, "window"),
    (Innovation, {"delta": 0.5}, "delta"),                    # window defaults to 5
    (Innovation, {"delta": 1.0, "window": 1}, "delta"),
    (Cumulant, {"window": 2}, "window"),
    (Cumulant, {"moment": "central"}, "moment"),
    (Cumulant, {"normalisation": "printed"}, "normalisation"),
])
def test_bad_params_name_the_field(cls, values, field):
    with pytest.raises(ConfigError) as err:
        build_params(cls.Params, values)
    assert err.value.field == field


@pytest.mark.parametrize("moment", ["centred", "raw"])
@pytest.mark.parametrize("combine", ["sum", "max"])
def test_paper_statistic_is_consistent_over_M(batch, moment, combine):
    M = 16
    common = {"window": M, "moment": moment, "combine": combine}
    consistent = run(Cumulant, {**common, "normalisation": "consistent"}, batch)
    paper = run(Cumulant, {**common, "normalisation": "paper"}, batch)
    np.testing.assert_allclose(paper.statistic[:, M - 1:], consistent.statistic[:, M - 1:] / M,
                               rtol=1e-12)
    assert paper.valid_from == consistent.valid_from == M - 1


def test_window_third_moment_matches_direct_sums():
    x = np.random.default_rng(5).standard_normal((4, 40))
    M = 7
    raw = window_third_moment(x, M, centred=False)
    cen = window_third_moment(x, M, centred=True)
    for k in (0, 3, M - 1, 25, 39):
        w = x[:, max(0, k - M + 1):k + 1]
        np.testing.assert_allclose(raw[:, k], np.mean(w ** 3, axis=1), rtol=1e-10)
        centred = np.mean((w - w.mean(axis=1, keepdims=True)) ** 3, axis=1)
        np.testing.assert_allclose(cen[:, k], centred, rtol=1e-8, atol=1e-12)


def test_detectors_respond_to_the_turn(batch):
    """At 10 dB the turn raises both statistics well above their null level."""
    on = batch.scene.onset_step
    for cls in (Innovation, Cumulant):
        s = run(cls, {}, batch).statistic
        assert np.mean(s[:, on:on + 20]) > 3 * np.mean(s[:, 40:on])


# ------------------------------------------------------------------ the paper's Steps 1-4

def paper_steps_loop(x: np.ndarray, M: int) -> np.ndarray:
    """Song, Ji & Gao (2004), sec. 3, Steps 1-4, one scalar series, plain loops:
    the value at step k is the paper's c̄⁽ⁱ⁾ for i = k + 1 (window x̃(k-M+1..k))."""
    K = len(x)
    xbar = [sum(x[k - M:k]) / M if k >= M else None for k in range(K)]
    for k in range(M):
        xbar[k] = sum(x[0:M]) / M                      # x̄(k) = x̄(M), k < M
    xt = [x[k] - xbar[k] for k in range(K)]
    out = np.zeros(K)
    for k in range(M - 1, K):
        i = k + 1
        cubes = [xt[j] ** 3 for j in range(i - M, i)]
        c = sum(cubes) / M                             # eq. (9)
        var = sum((v - c) ** 2 for v in cubes) / M     # eq. (10)
        out[k] = c ** 2 / var                          # eq. (11)
    return out


from hypothesis import given, settings, strategies as st  # noqa: E402

from radarbench.methods.maneuver.cumulant import lagged_deviation, sample_normalised_cumulant  # noqa: E402


@settings(max_examples=40, deadline=None, derandomize=True)
@given(M=st.integers(3, 12), extra=st.integers(0, 30), seed=st.integers(0, 2**32 - 1),
       bias=st.floats(-3, 3), normalisation=st.sampled_from(["paper", "consistent"]))
def test_lagged_cumulant_equals_loop_over_paper_steps(M, extra, seed, bias, normalisation):
    rng = np.random.default_rng(seed)
    K = M + extra
    x = rng.standard_normal((3, K)) + bias * (np.arange(K) >= K // 2)
    got = sample_normalised_cumulant(x, M, "lagged", normalisation)
    scale = M if normalisation == "consistent" else 1.0
    want = np.stack([scale * paper_steps_loop(list(row), M) for row in x])
    np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9)


def test_lagged_deviation_step_one():
    x = np.arange(10.0)[None, :] ** 2
    d = lagged_deviation(x, 4)
    np.testing.assert_allclose(d[0, :4], x[0, :4] - x[0, :4].mean())
    np.testing.assert_allclose(d[0, 7], x[0, 7] - x[0, 3:7].mean())


def test_sample_variance_centred_and_raw_equal_direct_windows():
    rng = np.random.default_rng(5)
    x = rng.standard_normal((2, 40)) * 2 + 1
    M = 7
    for moment in ("centred", "raw"):
        got = sample_normalised_cumulant(x, M, moment, "consistent")
        for k in range(2, 40):
            w = x[:, max(0, k - M + 1):k + 1]
            y = w - w.mean(axis=1, keepdims=True) if moment == "centred" else w
            c = (y ** 3).mean(axis=1)
            var = ((y ** 3 - c[:, None]) ** 2).mean(axis=1)
            np.testing.assert_allclose(got[:, k], w.shape[1] * c ** 2 / var, rtol=1e-8)


def test_paper_config_runs_and_valid_from(batch):
    out = run(Cumulant, {"moment": "lagged", "variance": "sample", "normalisation": "paper",
                         "combine": "max", "window": 32}, batch)
    assert out.valid_from == 31
    assert np.all(out.statistic[:, :31] == 0) and np.all(np.isfinite(out.statistic))
    x = innovations(batch.scene.reference_filter, batch.z).whitened
    want = np.maximum(*(sample_normalised_cumulant(x[..., i], 32, "lagged", "paper") for i in range(2)))
    np.testing.assert_array_equal(out.statistic, want)


def test_lagged_needs_sample_variance():
    with pytest.raises(ConfigError, match="variance"):
        build_params(Cumulant.Params, {"moment": "lagged"})


def test_lagged_sees_a_constant_bias_the_centred_misses():
    """A step bias: the same-window centred cumulant vanishes once the window
    is fully biased, the lagged one does not while the lagged mean lags."""
    x = np.zeros((1, 100))
    x[:, 60:] = 3.0
    x += np.random.default_rng(0).standard_normal(x.shape) * 0.1
    lagged = sample_normalised_cumulant(x, 16, "lagged", "consistent")
    centred = sample_normalised_cumulant(x, 16, "centred", "consistent")
    assert lagged[0, 60:76].mean() > 5 * centred[0, 76:90].mean()


def test_nominal_threshold_chi2_one_per_component(batch):
    p = build_params(Cumulant.Params, {"combine": "max", "moment": "lagged", "variance": "sample"})
    t = Cumulant().nominal_threshold(p, 0.01, batch)
    assert t == pytest.approx(scipy.stats.chi2.isf(1 - 0.99 ** 0.5, 1))
