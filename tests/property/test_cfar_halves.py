"""GO- and SO-CFAR (models/cfar/halves.py, models/cfar/__init__.py) on homogeneous
exponential noise: the measured Pfa at the nominal threshold factor is the
closed form's (independent cells, the exact binomial interval of
test_cfar_properties), the two implementations of the closed form agree
(the finite sum of the kernels, scipy.special.betainc) and reduce to the
equal-halves textbook form, T inverts them, and the kernels equal a direct
loop over cells."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.models import cfar
from radarbench.models.cfar import halves
from tests.property.test_cfar_properties import CELLS, LINE, PFA, _assert_binomial, _independent_cells, _noise

window = st.tuples(st.integers(1, 16), st.integers(0, 3))
detector = st.sampled_from(["go", "so"])


@settings(derandomize=True, deadline=None, max_examples=12)
@given(w=window, det=detector, seed=st.integers(0, 2**31))
def test_pfa_at_nominal_t_is_the_closed_form(w, det, seed):
    L, g = w
    cells = _independent_cells(LINE, L, g)
    maps = _noise(seed, (-(-CELLS // cells.size), 1, LINE), scale=2.3)
    mu, sig = cfar.halves_cfar(maps, det, L, g, "doppler")
    exceed = sig[:, :, cells] > -math.log10(PFA)
    _assert_binomial(exceed, PFA)
    # the same decision by U0 = T mu with T from the closed form
    T = halves.halves_threshold_factor(PFA, L, L, det == "go")
    assert np.mean(exceed != (maps[:, :, cells] > T * mu[:, :, cells])) < 1e-4
    # a cell near the map's edge: unequal halves (n_l < L), their own closed form
    i = g + max(L // 2, 1) if L > 1 else 0
    edge = cfar.halves_cfar(_noise(seed + 1, (CELLS, 1, 2 * (g + L) + 1)), det, L, g, "doppler")[1][:, :, i]
    _assert_binomial(edge > -math.log10(PFA), PFA)


def _textbook(T: float, n: int) -> tuple[float, float]:
    """(GO, SO) Pfa of equal halves: Pfa_SO = 2 sum_{k<n} C(n-1+k, k) (2 + T/n)^-(n+k), GO = 2 (1 + T/n)^-n - SO."""
    so = 2.0 * sum(math.comb(n - 1 + k, k) * (2.0 + T / n) ** -(n + k) for k in range(n))
    return 2.0 * (1.0 + T / n) ** -n - so, so


@settings(derandomize=True, deadline=None, max_examples=40)
@given(n_l=st.integers(0, 40), n_r=st.integers(1, 40), T=st.floats(0.0, 200.0), det=detector)
def test_the_two_closed_forms_agree_and_reduce_to_the_textbook(n_l, n_r, T, det):
    greatest = det == "go"
    by_sum = math.exp(-halves.halves_log_survival(T, n_l, n_r, greatest))
    by_beta = float(halves.halves_pfa(T, n_l, n_r, greatest))
    assert math.isclose(by_sum, by_beta, rel_tol=1e-9, abs_tol=1e-300)
    if n_l == n_r and T < 50.0:                # beyond, the textbook's GO cancels (our forms do not)
        assert math.isclose(by_sum, _textbook(T, n_l)[0 if greatest else 1], rel_tol=1e-8)
    if n_l == 0:                               # one half: CA of the other
        assert math.isclose(by_sum, float(cfar.ca_pfa(T, n_r)), rel_tol=1e-12)


def test_threshold_factors_invert_the_closed_forms_and_order_the_detectors():
    for pfa in (0.1, 1e-3, 1e-8, 1e-100):
        for n_l, n_r in ((1, 1), (8, 8), (3, 8), (64, 64), (256, 256)):
            t_go, t_so = (halves.halves_threshold_factor(pfa, n_l, n_r, g) for g in (True, False))
            for T, g in ((t_go, True), (t_so, False)):
                assert math.isclose(float(halves.halves_pfa(T, n_l, n_r, g)), pfa, rel_tol=1e-7)
            # mu_SO <= mu_CA <= mu_GO, so at equal Pfa T_GO < T_CA < T_SO
            assert t_go < cfar.ca_threshold_factor(pfa, n_l + n_r) < t_so


def _direct(maps: np.ndarray, L: int, g: int, det: str):
    """mu and S by a Python loop over cells along Doppler: the two halves gathered,
    their means compared, the closed form summed term by term."""
    x = maps.astype(np.float64)
    mu, sig = np.empty_like(x), np.empty_like(x)
    M = x.shape[-1]
    for p in range(x.shape[0]):
        for r in range(x.shape[1]):
            for i in range(M):
                left = [x[p, r, a] for a in range(i - g - L, i - g) if a >= 0]
                right = [x[p, r, a] for a in range(i + g + 1, i + g + L + 1) if a < M]
                means = [sum(h) / len(h) for h in (left, right) if h]
                mu[p, r, i] = (max if det == "go" else min)(means)
                T = x[p, r, i] / mu[p, r, i]
                if not (left and right):
                    n = len(left) + len(right)
                    pfa = (1 + T / n) ** -n
                else:
                    pfa = 0.0
                    for a, o in ((len(left), len(right)), (len(right), len(left))):
                        P, Q = (a + T) / (a + o + T), o / (a + o + T)
                        if det == "go":      # I_Q(o, a)
                            tail = sum(math.comb(o - 1 + j, j) * Q ** o * P ** j for j in range(a))
                        else:                # I_P(a, o)
                            tail = sum(math.comb(a - 1 + j, j) * P ** a * Q ** j for j in range(o))
                        pfa += (1 + T / a) ** -a * tail
                sig[p, r, i] = -math.log10(pfa) if pfa > 0 else math.inf
    return mu, sig


@settings(derandomize=True, deadline=None, max_examples=10)
@given(w=window, det=detector, seed=st.integers(0, 2**31))
def test_go_and_so_agree_with_a_direct_loop(w, det, seed):
    L, g = w
    maps = _noise(seed, (2, 2 * (g + L) + 7, 2 * (g + L) + 9))
    for axis in ("doppler", "range"):
        mu, sig = cfar.halves_cfar(maps, det, L, g, axis)
        if axis == "doppler":
            mu_loop, sig_loop = _direct(maps, L, g, det)
        else:                                  # the loop runs along the last axis
            mu_loop, sig_loop = (a.transpose(0, 2, 1) for a in _direct(maps.transpose(0, 2, 1), L, g, det))
        np.testing.assert_allclose(mu, mu_loop, rtol=1e-6)
        np.testing.assert_allclose(sig, np.minimum(sig_loop, cfar.MAX_SIGNIFICANCE), rtol=2e-5, atol=1e-5)
