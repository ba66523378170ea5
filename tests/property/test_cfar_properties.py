"""CFAR detectors on homogeneous exponential noise (models/cfar/__init__.py): the
measured Pfa at the nominal threshold factor equals the closed form, the
decisions are scale-invariant, and the kernels equal a direct loop.

Cells of one map share reference windows, so their decisions are
correlated; the Pfa tests count only cells whose windows and cells under
test are disjoint (one cell per line, or cells 2(g + L) + 1 apart along a
line), whose exceedances are independent Bernoulli(pfa) draws: the binomial
law is exact. The band is the binomial interval at level 1 - 1e-6 (no
chance failure over every example tried), and each test checks it is
narrow enough to see a 25 % error in the Pfa.
"""

import math

import numpy as np
import pytest
import scipy.stats
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.models import cfar

LEVEL = 1.0 - 1e-6
PFA = 0.01
#: independent cells per Pfa test: the 1 - 1e-6 binomial interval is then +-17 % of n pfa
CELLS = 80_000
LINE = 400


def _noise(seed: int, shape: tuple, scale: float = 1.0) -> np.ndarray:
    return (scale * np.random.default_rng(seed).exponential(size=shape)).astype(np.float32)


def _assert_binomial(exceed: np.ndarray, pfa: float) -> None:
    n = exceed.size
    lo, hi = scipy.stats.binom.interval(LEVEL, n, pfa)
    assert lo <= exceed.sum() <= hi, (exceed.sum(), n * pfa, lo, hi)
    assert hi - lo < 0.5 * n * pfa, "too few cells to see a 25 % error"


def _independent_cells(M: int, L: int, g: int) -> np.ndarray:
    """Interior positions along a line, 2(g + L) + 1 apart: disjoint windows."""
    stride = 2 * (g + L) + 1
    return np.arange(g + L, M - g - L, stride)


window = st.tuples(st.integers(1, 16), st.integers(0, 3))


@settings(derandomize=True, deadline=None, max_examples=12)
@given(w=window, seed=st.integers(0, 2**31))
def test_ca_pfa_at_nominal_k_is_the_closed_form(w, seed):
    L, g = w
    cells = _independent_cells(LINE, L, g)
    maps = _noise(seed, (-(-CELLS // cells.size), 1, LINE), scale=3.7)
    _, sig = cfar.ca_cfar(maps, L, g, "doppler")
    _assert_binomial(sig[:, :, cells] > -math.log10(PFA), PFA)
    # the map's first cell has a one-sided window: N' = L, its own closed form
    _assert_binomial(cfar.ca_cfar(_noise(seed + 1, (CELLS, 1, 2 * (g + L) + 1)), L, g, "doppler")[1][:, :, 0]
                     > -math.log10(PFA), PFA)


@pytest.mark.slow                     # enough null maps per example for the binomial tolerance
@settings(derandomize=True, deadline=None, max_examples=12)
@given(w=window, k_fraction=st.floats(0.05, 1.0), seed=st.integers(0, 2**31))
def test_os_pfa_at_nominal_k_is_the_closed_form(w, k_fraction, seed):
    L, g = w
    k = max(1, math.ceil(k_fraction * 2 * L))
    cells = _independent_cells(LINE, L, g)
    maps = _noise(seed, (-(-CELLS // cells.size), LINE, 1), scale=0.02)
    mu, sig = cfar.os_cfar(maps, L, g, k, "range")
    exceed = sig[:, cells, :] > -math.log10(PFA)
    _assert_binomial(exceed, PFA)
    # the same decision by U0 = K mu with K from the closed form
    K = cfar.os_threshold_factor(PFA, 2 * L, k)
    by_factor = maps[:, cells, :] > K * mu[:, cells, :]
    assert np.mean(exceed != by_factor) < 1e-4
    assert math.isclose(float(cfar.os_pfa(K, 2 * L, k)), PFA, rel_tol=1e-9)


@settings(derandomize=True, deadline=None, max_examples=10)
@given(w=window, k=st.integers(1, 32), c=st.floats(1e-6, 1e6), seed=st.integers(0, 2**31))
def test_ca_and_os_decisions_are_scale_invariant(w, k, c, seed):
    L, g = w
    k = min(k, 2 * L)
    maps = _noise(seed, (4, 48, 64))
    threshold = -math.log10(PFA)
    for axis in ("range", "doppler"):
        for run in (lambda m: cfar.ca_cfar(m, L, g, axis), lambda m: cfar.os_cfar(m, L, g, k, axis)):
            sig = run(maps)[1]
            exact = run(maps * np.float32(2.0 ** round(math.log2(c))))[1]      # a power of 2: no rounding
            np.testing.assert_array_equal(sig, exact)
            scaled = run((maps * c).astype(np.float32))[1]                     # c's rounding moves S by ~1e-6
            decided_apart = np.abs(sig - threshold) > 1e-4 * threshold
            np.testing.assert_array_equal((sig > threshold)[decided_apart], (scaled > threshold)[decided_apart])


def _direct(maps: np.ndarray, L: int, g: int, k: int | None, axis: str):
    """mu and S by a Python loop over cells: the window gathered, averaged or sorted."""
    x = maps.astype(np.float64) if axis == "doppler" else maps.astype(np.float64).transpose(0, 2, 1)
    mu, sig = np.empty_like(x), np.empty_like(x)
    M = x.shape[-1]
    for p in range(x.shape[0]):
        for r in range(x.shape[1]):
            for i in range(M):
                idx = [a for a in range(i - g - L, i - g) if a >= 0] + \
                      [a for a in range(i + g + 1, i + g + L + 1) if a < M]
                window = x[p, r, idx]
                N = len(idx)
                if k is None:
                    mu[p, r, i] = window.mean()
                    pfa = (1 + x[p, r, i] / mu[p, r, i] / N) ** -N
                else:
                    kk = math.ceil(k * N / (2 * L))
                    mu[p, r, i] = np.sort(window)[kk - 1]
                    t = x[p, r, i] / mu[p, r, i]
                    pfa = np.prod([(N - j) / (N - j + t) for j in range(kk)])
                sig[p, r, i] = -math.log10(pfa)
    if axis == "range":
        mu, sig = mu.transpose(0, 2, 1), sig.transpose(0, 2, 1)
    return mu, sig


@settings(derandomize=True, deadline=None, max_examples=8)
@given(w=window, seed=st.integers(0, 2**31))
def test_ca_and_os_with_k_equal_n_agree_with_a_direct_loop(w, seed):
    L, g = w
    maps = _noise(seed, (2, 2 * (g + L) + 7, 2 * (g + L) + 9))
    for axis in ("range", "doppler"):
        for k in (None, 2 * L, max(1, L)):
            mu, sig = cfar.ca_cfar(maps, L, g, axis) if k is None else cfar.os_cfar(maps, L, g, k, axis)
            mu_loop, sig_loop = _direct(maps, L, g, k, axis)
            np.testing.assert_allclose(mu, mu_loop, rtol=1e-6)
            np.testing.assert_allclose(sig, np.minimum(sig_loop, cfar.MAX_SIGNIFICANCE), rtol=2e-5, atol=1e-5)


def test_threshold_factors_invert_their_closed_forms():
    for pfa in (0.1, 1e-3, 1e-8, 1e-300):
        for N in (1, 2, 16, 64):
            assert math.isclose(float(cfar.ca_pfa(cfar.ca_threshold_factor(pfa, N), N)), pfa, rel_tol=1e-9)
            for k in {1, max(1, N // 2), N}:
                assert math.isclose(float(cfar.os_pfa(cfar.os_threshold_factor(pfa, N, k), N, k)), pfa, rel_tol=1e-7)
    # OS with k = 1 on N = 1 cell and CA on N = 1 are the same detector
    assert math.isclose(cfar.os_threshold_factor(0.01, 1, 1), cfar.ca_threshold_factor(0.01, 1), rel_tol=1e-9)


def test_a_strong_target_is_detected_by_every_detector():
    """A cell 30 dB above homogeneous noise passes CA and OS at Pfa 1e-6 (the
    regression CFAR: tests/property/test_cfar_regression_properties.py),
    in both dimensions, and survives the peak detection."""
    maps = _noise(11, (3, 64, 128))
    maps[:, 30, 70] = 1000.0
    threshold = 6.0
    results = {"ca": {a: cfar.ca_cfar(maps, 8, 2, a) for a in ("range", "doppler")},
               "os": {a: cfar.os_cfar(maps, 8, 2, 12, a) for a in ("range", "doppler")}}
    for name, per_axis in results.items():
        statistic, _ = cfar.fold(maps, per_axis, "both", 1, 1)
        assert np.all(statistic[:, 30, 70] > threshold), name
