"""Statistical invariants of the wavelet maneuver detector.

Hypothesis draws the cases with ``derandomize=True`` and every random array
comes from a fixed seed, so the tests are deterministic; tolerances are set
from the sampling distribution of the checked quantity (4 standard errors) or
are exact (noise-free input), never tuned to pass.
"""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.methods.maneuver.wavelet import causal_coefficients, null_threshold, wavelet_statistic

FIXED = settings(derandomize=True, deadline=None, max_examples=5)


@FIXED
@given(seed=st.integers(0, 2 ** 32 - 1), levels=st.integers(1, 6),
       m=st.integers(1, 2))
def test_haar_coefficients_of_white_noise_are_standard_normal(seed, levels, m):
    """Orthonormal Haar coefficients of i.i.d. N(0, 1) input are i.i.d.
    N(0, 1) at every level. The decimated coefficients (one per block, at the
    block ends) are independent, so over N of them the sample mean has
    standard error 1/sqrt(N) and the sample variance sqrt(2/(N-1)); both must
    lie within 4 standard errors of 0 and 1."""
    n, K = 200, 256
    x = np.random.default_rng(seed).standard_normal((n, K, m))
    for j, c in causal_coefficients(x, "haar", levels, "decimated").items():
        ends = np.flatnonzero(c.release)
        assert ends.tolist() == list(range(2 ** j - 1, K, 2 ** j))
        for coef in (c.approximation[:, ends], c.detail[:, ends]):
            values = coef.ravel()
            N = values.size
            assert abs(values.mean()) < 4.0 / np.sqrt(N), (j, values.mean())
            assert abs(values.var(ddof=1) - 1.0) < 4.0 * np.sqrt(2.0 / (N - 1)), (j, values.var(ddof=1))


@FIXED
@given(levels=st.integers(1, 6), coarsest=st.integers(1, 3), block=st.integers(1, 3),
       mu=st.floats(50.0, 1e3), sign=st.sampled_from([-1.0, 1.0]),
       coefficients=st.sampled_from(["approximation", "both"]), m=st.integers(1, 2),
       pfa=st.sampled_from([1e-3, 0.01, 0.05]))
def test_decimated_haar_delay_floor(levels, coarsest, block, mu, sign, coefficients, m, pfa):
    """Theory: in decimated mode a level-J coefficient (L = 2^J) is released
    only at the block ends k = b L - 1 and held. A noise-free step of size mu
    starting at onset = b0 L + phase first enters the level-J statistic at the
    end of its own block, k = (b0 + 1) L - 1, where the approximation is
    mu (L - phase) / sqrt(L) >= mu / sqrt(L) per component; with mu >= 50 and
    L <= 64 its square (>= 39) exceeds the nominal threshold (<= 25 here),
    and before onset the statistic is exactly 0. So the delay is
    L - 1 - phase, and its mean over the L phases 0..L-1 is exactly
    (L - 1)/2, the inherent delay floor of the decimated method."""
    coarsest = min(coarsest, levels)
    L = 2 ** levels
    threshold = null_threshold(pfa, m * (2 if coefficients == "both" else 1), coarsest)
    K = (block + 3) * L
    onsets = block * L + np.arange(L)                       # one trial per phase
    x = np.zeros((L, K, m))
    x[np.arange(K)[None, :] >= onsets[:, None]] = sign * mu
    out = wavelet_statistic(x, "haar", levels, coarsest, coefficients, "decimated")
    T = out.per_level[levels]
    alarms = (T >= threshold) & (np.arange(K)[None, :] >= onsets[:, None])
    assert np.all(alarms.any(axis=1))
    delays = np.argmax(alarms, axis=1) - onsets
    np.testing.assert_array_equal(delays, L - 1 - np.arange(L))
    assert delays.mean() == (L - 1) / 2
    assert np.all(T[np.arange(K)[None, :] < onsets[:, None]] == 0.0)   # no alarm before onset


@FIXED
@given(seed=st.integers(0, 2 ** 32 - 1), wavelet=st.sampled_from(["haar", "db2", "sym4"]),
       mode=st.sampled_from(["decimated", "sliding"]),
       coefficients=st.sampled_from(["approximation", "detail", "both"]),
       bias=st.floats(-5.0, 5.0))
def test_statistic_invariant_to_sign(seed, wavelet, mode, coefficients, bias):
    """The transform is linear, so -x has coefficients of opposite sign and
    the same squares: T(-x) = T(x) (exactly: negation is exact in floating
    point and rounding is symmetric)."""
    x = np.random.default_rng(seed).standard_normal((4, 96, 2)) + bias
    a = wavelet_statistic(x, wavelet, 3, 2, coefficients, mode)
    b = wavelet_statistic(-x, wavelet, 3, 2, coefficients, mode)
    np.testing.assert_array_equal(b.statistic, a.statistic)
    for j in a.per_level:
        np.testing.assert_array_equal(b.per_level[j], a.per_level[j])
