"""Maneuver detectors `innovation` and `cumulant`: outputs, thresholds, params."""

import numpy as np
import pytest
import scipy.stats

from bench.core import DetectionOutput
from bench.errors import ConfigError
from bench.kalman import innovations
from bench.params import build_params
from bench.registry import get_method
from bench.rng import TrialRNG
from methods.cumulant import Cumulant, window_third_moment
from bench.windows import sliding_sum
from methods.innovation import Innovation, fading_sum, fading_valid_from
from scenarios.cv_turn_cv import CvTurnCv

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
    np.testing.assert_allclose(out.statistic, innovations(batch).nis, rtol=1e-9, atol=1e-9)
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
    on = batch.meta["onset_step"]
    for cls in (Innovation, Cumulant):
        s = run(cls, {}, batch).statistic
        assert np.mean(s[:, on:on + 20]) > 3 * np.mean(s[:, 40:on])
