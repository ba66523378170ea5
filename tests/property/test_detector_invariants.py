"""Statistical invariants of the maneuver detectors.

Hypothesis draws the cases with ``derandomize=True`` and every random array
comes from a fixed seed, so the tests are deterministic; tolerances are set
from the sampling distribution of the checked quantity at a 1e-6 level (or 4
standard errors), never tuned to pass.
"""

import dataclasses

import numpy as np
import scipy.stats
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.bench.core import Batch
from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.methods.maneuver.cumulant import Cumulant, third_moment_null_variance, window_third_moment
from radarbench.methods.maneuver.innovation import Innovation
from radarbench.models.kalman import LinearGaussianFilter, LinearGaussianModel, innovations
from radarbench.scenarios.cv_turn_cv import CvTurnCv

FIXED = settings(derandomize=True, deadline=None, max_examples=4)


def cv_batch(snr_db, n, seed=1, **values):
    params = build_params(CvTurnCv.Params, values)
    rng = TrialRNG(seed=seed, domain=0, scenario_key=0, trials=range(n))
    return CvTurnCv().generate(params, snr_db, n, rng)


@FIXED
@given(tracking_index=st.floats(0.02, 2.0), seed=st.integers(0, 2 ** 16))
def test_nis_mean_is_n_z_under_matched_model(tracking_index, seed):
    """E[nu' S^-1 nu] = n_z = 2; the NIS values are independent chi2(2)
    (white innovations from a steady-state start), so the standard error of
    the mean over N values is sqrt(4 / N)."""
    b = cv_batch(None, 200, seed=seed, tracking_index=tracking_index)
    nis = innovations(b.scene.reference_filter, b.z).nis
    se = np.sqrt(4.0 / nis.size)
    assert abs(nis.mean() - 2.0) < 4 * se


def scaled(batch: Batch, c: float) -> Batch:
    """The same batch in units c times smaller: z, truth, x0 times c, the
    covariances times c^2. The whitened innovation is unchanged."""
    f = batch.scene.reference_filter
    m = f.model
    model = LinearGaussianModel(F=m.F, H=m.H, Q=c ** 2 * m.Q, R=c ** 2 * m.R)
    scene = dataclasses.replace(batch.scene, reference_filter=LinearGaussianFilter(model=model, x0=c * f.x0,
                                                                                   P0=c ** 2 * f.P0))
    return dataclasses.replace(batch, truth=c * batch.truth, z=c * batch.z, scene=scene)


@FIXED
@given(c=st.floats(1e-3, 1e3), moment=st.sampled_from(["centred", "raw"]),
       snr_db=st.sampled_from([None, 0.0, 10.0]))
def test_cumulant_invariant_to_scale(c, moment, snr_db):
    b = cv_batch(snr_db, 8)
    params = build_params(Cumulant.Params, {"moment": moment, "window": 16})
    s1 = Cumulant().run(b, params).statistic
    s2 = Cumulant().run(scaled(b, c), params).statistic
    np.testing.assert_allclose(s2, s1, rtol=1e-8, atol=1e-12)
    p_nis = build_params(Innovation.Params, {})
    np.testing.assert_allclose(Innovation().run(scaled(b, c), p_nis).statistic,
                               Innovation().run(b, p_nis).statistic, rtol=1e-8)


@FIXED
@given(a=st.floats(-50.0, 50.0), M=st.integers(3, 64))
def test_centred_moment_blind_to_constant(a, M):
    """The centred third moment of (whitened innovation + a) equals that of
    the whitened innovation; the tolerance is the float64 cancellation bound
    of the cumulative-sum expansion."""
    b = cv_batch(10.0, 4)
    x = innovations(b.scene.reference_filter, b.z).whitened[..., 0]
    m3 = window_third_moment(x, M, centred=True)
    m3_shifted = window_third_moment(x + a, M, centred=True)
    scale = (abs(a) + np.abs(x).max()) ** 3
    np.testing.assert_allclose(m3_shifted, m3, rtol=0, atol=1e-14 * x.shape[1] * scale)


@FIXED
@given(M=st.integers(3, 64), centred=st.booleans(), seed=st.integers(0, 2 ** 16))
def test_third_moment_null_variance(M, centred, seed):
    """Windows of white N(0, 1): the variance of c3 is 6(M-1)(M-2)/M^3
    (centred) or 15/M (raw).

    c3 has mean 0, so v_hat = mean(c3^2) over R windows. For a Gaussian c3,
    R v_hat / v ~ chi2(R); c3 is heavier-tailed (kurtosis kappa > 3 at small
    M), so the chi2 law is used with the Satterthwaite effective size
    R_eff = 2 R / (kappa_hat - 1), which matches Var(v_hat) = (kappa-1) v^2 / R.
    """
    R = 20000
    x = np.random.default_rng(seed).standard_normal((R, M))
    c3 = window_third_moment(x, M, centred)[:, -1]
    v = float(third_moment_null_variance(np.float64(M), centred))
    v_hat = np.mean(c3 ** 2)
    kappa = np.mean(c3 ** 4) / v_hat ** 2
    R_eff = 2 * R / (kappa - 1)
    lo, hi = scipy.stats.chi2.ppf([1e-6, 1 - 1e-6], R_eff) / R_eff
    assert lo < v_hat / v < hi
