"""Maneuver detector ``wavelet``: outputs, causality, Haar closed form, thresholds, params."""

import numpy as np
import pytest
import pywt
import scipy.stats

from radarbench.bench import registry
from radarbench.bench.core import DetectionOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.models.windows import sliding_sum
from radarbench.methods.maneuver.wavelet import (Wavelet, causal_coefficients, first_step, null_threshold, support,
                             valid_from, wavelet_statistic)
from radarbench.models.kalman import innovations

CONFIGS = [
    {},
    {"mode": "sliding"},
    {"coefficients": "approximation"},
    {"coefficients": "detail", "levels": 3, "coarsest": 1},
    {"wavelet": "db2"},
    {"wavelet": "sym4", "mode": "sliding", "levels": 3, "coarsest": 3},
]


def cv_batch(snr_db, n, seed=1):
    scenario = registry.get_scenario("cv-turn-cv")
    return scenario().generate(scenario.Params(), snr_db, n, TrialRNG(seed, 0, 0, range(n)))


@pytest.fixture(scope="module")
def batch():
    return cv_batch(10.0, 6)


def run(values, batch):
    return Wavelet().run(batch, build_params(Wavelet.Params, values))


def test_registered():
    assert registry.get_method("wavelet") is Wavelet


@pytest.mark.parametrize("values", CONFIGS)
def test_shapes_no_nan_deterministic(values, batch):
    out = run(values, batch)
    assert isinstance(out, DetectionOutput)
    assert out.statistic.shape == (batch.n, batch.steps) and out.statistic.dtype == np.float64
    assert np.all(np.isfinite(out.statistic))
    assert 0 <= out.valid_from < batch.steps
    assert np.all(out.statistic[:, :out.valid_from] == 0.0)
    p = build_params(Wavelet.Params, values)
    levels = [f"level_{j}" for j in range(p.levels - p.coarsest + 1, p.levels + 1)]
    assert set(out.traces) == {"innovation_0", "innovation_1", *levels}
    for trace in out.traces.values():
        assert trace.shape == (batch.n, batch.steps) and np.all(np.isfinite(trace))
    stacked = np.max([out.traces[name] for name in levels], axis=0)
    np.testing.assert_array_equal(out.statistic[:, out.valid_from:], stacked[:, out.valid_from:])
    whitened = innovations(batch.scene.reference_filter, batch.z).whitened
    np.testing.assert_array_equal(out.traces["innovation_1"], whitened[..., 1])
    np.testing.assert_array_equal(out.statistic, run(values, batch).statistic)


def test_valid_from():
    assert Wavelet().run(cv_batch(None, 2), Wavelet.Params()).valid_from == 15
    for mode in ("decimated", "sliding"):
        for J in range(1, 9):
            assert valid_from("haar", J, 1, mode) == 2 ** J - 1
    # db2 (filter length 4): a level-j coefficient spans 3 (2^j - 1) + 1 samples
    assert [support("db2", j) for j in (1, 2, 3, 4)] == [4, 10, 22, 46]
    assert valid_from("db2", 4, 2, "sliding") == 45
    assert valid_from("db2", 4, 2, "decimated") == 47        # first block end k + 1 = 48 >= 46
    assert first_step("db2", 3, "decimated") == 23


@pytest.mark.parametrize("wavelet", ["haar", "db2", "sym4"])
@pytest.mark.parametrize("mode", ["decimated", "sliding"])
def test_causal(wavelet, mode):
    """Changing the samples after step k leaves the statistic (and every
    coefficient) up to step k unchanged."""
    rng = np.random.default_rng(7)
    x = rng.standard_normal((4, 120, 2))
    base = wavelet_statistic(x, wavelet, 4, 3, "both", mode)
    coefs = causal_coefficients(x, wavelet, 4, mode)
    for k in (0, 5, 16, 31, 47, 60, 100, 118):
        y = x.copy()
        y[:, k + 1:] = 10.0 * rng.standard_normal(y[:, k + 1:].shape) + 3.0
        other = wavelet_statistic(y, wavelet, 4, 3, "both", mode)
        np.testing.assert_array_equal(other.statistic[:, :k + 1], base.statistic[:, :k + 1])
        for j, T in base.per_level.items():
            np.testing.assert_array_equal(other.per_level[j][:, :k + 1], T[:, :k + 1])
        for j, c in causal_coefficients(y, wavelet, 4, mode).items():
            np.testing.assert_array_equal(c.approximation[:, :k + 1], coefs[j].approximation[:, :k + 1])
            np.testing.assert_array_equal(c.detail[:, :k + 1], coefs[j].detail[:, :k + 1])


def haar_closed_form(x, j):
    """At each step k >= L - 1 (L = 2^j): approximation = sum of the last L
    samples / sqrt(L); detail = (sum of the older L/2 - sum of the newer L/2)
    / sqrt(L) (PyWavelets' sign: dec_hi = [-1, 1]/sqrt 2 in correlation order)."""
    L, h = 2 ** j, 2 ** (j - 1)
    A = sliding_sum(x, L) / np.sqrt(L)
    half = sliding_sum(x, h)
    D = np.zeros_like(x)
    D[:, h:] = (half[:, :-h] - half[:, h:]) / np.sqrt(L)
    A[:, :L - 1] = D[:, :L - 1] = 0.0
    return A, D


def test_haar_closed_form():
    x = np.random.default_rng(3).standard_normal((5, 100))
    K = x.shape[1]
    sliding = causal_coefficients(x, "haar", 5, "sliding")
    decimated = causal_coefficients(x, "haar", 5, "decimated")
    dwt = pywt.wavedec(x[:, :96], "haar", level=5, axis=1)   # [cA5, cD5, cD4, ..., cD1]
    for j in range(1, 6):
        L = 2 ** j
        A, D = haar_closed_form(x, j)
        np.testing.assert_allclose(sliding[j].approximation, A, rtol=0, atol=1e-12)
        np.testing.assert_allclose(sliding[j].detail, D, rtol=0, atol=1e-12)
        # decimated: the closed form at the last block end, held
        last_end = (np.arange(K) + 1) // L * L - 1
        held = np.where(last_end >= 0, last_end, 0)
        np.testing.assert_allclose(decimated[j].approximation, A[:, held], rtol=0, atol=1e-12)
        np.testing.assert_allclose(decimated[j].detail, D[:, held], rtol=0, atol=1e-12)
        # ... which are the DWT coefficients of consecutive blocks
        ends = np.arange(L - 1, 96, L)
        np.testing.assert_allclose(decimated[j].detail[:, ends], dwt[6 - j], rtol=0, atol=1e-12)
        assert np.flatnonzero(decimated[j].release).tolist() == list(range(L - 1, K, L))
    np.testing.assert_allclose(decimated[5].approximation[:, np.arange(31, 96, 32)], dwt[0],
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize("wavelet", ["haar", "db2", "sym4", "coif1"])
def test_decimated_coefficients_are_orthonormal(wavelet):
    """The released coefficients, as linear functionals of x (rows found by
    feeding unit impulses as trials), are orthonormal: approximation and
    detail of one level together, so i.i.d. N(0, 1) for white N(0, 1) input.
    In sliding mode each coefficient still has unit norm."""
    K = 128
    for mode in ("decimated", "sliding"):
        for j, c in causal_coefficients(np.eye(K), wavelet, 4, mode).items():
            rel = np.flatnonzero(c.release)
            A, D = c.approximation[:, rel].T, c.detail[:, rel].T
            if mode == "decimated":
                G = np.vstack([A, D])
                np.testing.assert_allclose(G @ G.T, np.eye(len(G)), atol=1e-10)
            else:
                np.testing.assert_allclose(np.sum(A ** 2, axis=1), 1.0, atol=1e-10)
                np.testing.assert_allclose(np.sum(D ** 2, axis=1), 1.0, atol=1e-10)
                np.testing.assert_allclose(np.sum(A * D, axis=1), 0.0, atol=1e-10)


def test_input_of_one_component_is_accepted():
    x = np.random.default_rng(4).standard_normal((3, 64))
    one = wavelet_statistic(x)
    two = wavelet_statistic(x[..., None])
    np.testing.assert_array_equal(one.statistic, two.statistic)
    assert one.statistic.shape == (3, 64)


def test_nominal_thresholds(batch):
    def thr(values, pfa=0.01):
        return Wavelet().nominal_threshold(build_params(Wavelet.Params, values), pfa, batch)

    assert thr({}) == pytest.approx(scipy.stats.chi2.ppf(0.99 ** 0.5, 4))
    assert thr({"coefficients": "approximation"}) == pytest.approx(scipy.stats.chi2.ppf(0.99 ** 0.5, 2))
    assert thr({"coefficients": "detail", "coarsest": 1}) == pytest.approx(scipy.stats.chi2.ppf(0.99, 2))
    assert thr({"coarsest": 3, "mode": "sliding"}, pfa=0.05) == pytest.approx(
        scipy.stats.chi2.ppf(0.95 ** (1 / 3), 4))
    assert null_threshold(0.01, 2, 1) == pytest.approx(-2 * np.log(0.01))    # chi2(2) tail exp(-t/2)


@pytest.mark.parametrize("values, field", [
    ({"levels": 0}, "levels"),
    ({"levels": 9}, "levels"),
    ({"coarsest": 0}, "coarsest"),
    ({"levels": 3, "coarsest": 4}, "coarsest"),
    ({"levels": 1}, "coarsest"),                      # coarsest defaults to 2
    ({"wavelet": "daubechies"}, "wavelet"),
    ({"wavelet": "bior2.2"}, "wavelet"),              # biorthogonal
    ({"wavelet": "dmey"}, "wavelet"),                 # orthogonal only to ~2e-3
    ({"wavelet": "morl"}, "wavelet"),                 # continuous
    ({"wavelet": 2}, "wavelet"),
    ({"mode": "undecimated"}, "mode"),
    ({"coefficients": "all"}, "coefficients"),
])
def test_bad_params_name_the_field(values, field):
    with pytest.raises(ConfigError) as err:
        build_params(Wavelet.Params, values)
    assert err.value.field == field


def test_too_deep_for_the_scenario_names_levels(batch):
    params = build_params(Wavelet.Params, {"levels": 8})     # 2^8 - 1 = 255 >= 160 steps
    with pytest.raises(ConfigError) as err:
        Wavelet().run(batch, params)
    assert err.value.field == "levels"


def test_accepted_wavelets():
    for name in ("haar", "db1", "db2", "sym4", "coif1"):
        assert build_params(Wavelet.Params, {"wavelet": name}).wavelet == name


@pytest.mark.parametrize("mode", ["decimated", "sliding"])
def test_detector_responds_to_the_turn(batch, mode):
    """At 10 dB the turn raises the statistic well above its null level."""
    on = batch.scene.onset_step
    s = run({"mode": mode}, batch).statistic
    assert np.mean(s[:, on:on + 20]) > 3 * np.mean(s[:, 20:on])
