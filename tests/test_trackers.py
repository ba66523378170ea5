"""Trackers ekf and viterbi on the glint scenario: the batched EKF against FilterPy,
the Viterbi tracker's kernels, options and invariants.

Hypothesis draws the cases with ``derandomize=True`` and fixed seeds, so the
tests are deterministic.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import radarbench.methods.glint.trellis as trellis
import radarbench.methods.glint.viterbi as vit
from radarbench.bench.core import TrackingOutput
from radarbench.bench.params import build_params
from radarbench.bench.registry import get_method
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.methods.glint.ekf import EKF, ekf_filter, filterpy_ekf, noise_covariance
from radarbench.methods.glint.trellis import expand, max_plus_step, trellis_step
from radarbench.methods.glint.viterbi import Viterbi
from radarbench.scenarios.glint import Glint

FIXED = settings(derandomize=True, deadline=None, max_examples=4)


def make(snr_db=0.0, n=3, seed=2, **values):
    params = build_params(Glint.Params, values)
    return Glint().generate(params, snr_db, n, TrialRNG(seed, 0, 5, range(n)))


def test_registered():
    assert get_method("ekf") is EKF and get_method("viterbi") is Viterbi
    assert EKF.task == Viterbi.task == "tracking"


@FIXED
@given(seed=st.integers(0, 2 ** 32 - 1), sensor=st.sampled_from(["passive", "active"]),
       bearing=st.sampled_from([0.0, 179.9, -120.0]), eps=st.sampled_from([0.0, 0.2]),
       which=st.sampled_from(["core", "mixture"]))
def test_batched_ekf_equals_filterpy_step_by_step(seed, sensor, bearing, eps, which):
    """Same model, same measurements: the batched EKF and FilterPy's
    ExtendedKalmanFilter (update then predict with control B u, Joseph form,
    bearing residual wrapped) agree at every step to rounding. Bearing 179.9
    deg puts the target on the -pi/pi cut, so the wrap is exercised."""
    b = make(n=3, seed=seed % 1000, sensor=sensor, epsilon=eps, steps=40, initial_bearing_deg=bearing,
             initial_cross_range_std_m=40.0)
    model = b.scene.model
    R = noise_covariance(model, which)
    res = ekf_filter(b.z, model, R)
    for i in range(b.n):
        x, P = filterpy_ekf(b.z[i], model, R)
        np.testing.assert_allclose(res.x_post[i], x, rtol=1e-9, atol=1e-7)
        np.testing.assert_allclose(res.P_post[i], P, rtol=1e-7, atol=1e-9)


def test_ekf_output_and_noise_options():
    b = make(n=4, sensor="active", steps=60, epsilon=0.1)
    model = b.scene.model
    np.testing.assert_allclose(np.diag(noise_covariance(model, "core")), model.sigma ** 2)
    total = (1 - 0.1) * model.sigma ** 2 + 2 * 0.1 * model.eta ** 2
    np.testing.assert_allclose(np.diag(noise_covariance(model, "mixture")), total)
    out = EKF().run(b, build_params(EKF.Params, {}))
    assert isinstance(out, TrackingOutput)
    assert out.estimate.shape == b.truth.shape and out.covariance.shape == (4, 60, 6, 6)
    assert out.traces["nis"].shape == (4, 60)
    np.testing.assert_allclose(out.covariance, np.swapaxes(out.covariance, -1, -2))
    assert np.all(np.linalg.eigvalsh(out.covariance) > 0)
    mix = EKF().run(b, build_params(EKF.Params, {"noise_variance": "mixture"}))
    assert not np.allclose(mix.estimate, out.estimate)


def test_ekf_is_consistent_on_gaussian_noise():
    """eps = 0, active sensor, matched R: the mean NEES over trials and the
    second half of the run is near d = 6 (chi-square, 6 dof; 40 trials x 100
    correlated steps: a loose +-25 % band)."""
    b = make(n=40, sensor="active", steps=200, epsilon=0.0)
    out = EKF().run(b, build_params(EKF.Params, {}))
    err = (out.estimate - b.truth)[:, 100:]
    nees = np.einsum("nki,nki->nk", err, np.linalg.solve(out.covariance[:, 100:], err[..., None])[..., 0])
    assert 4.5 < nees.mean() < 7.5


@pytest.mark.parametrize("values", [{}, {"node_value": "centre"}, {"Lb": 1, "survivors": 1},
                                    {"sweeps": 2, "Lb": 7}, {"gate_noise": "total", "disturbance_levels": 1}])
@pytest.mark.parametrize("sensor", ["passive", "active"])
def test_viterbi_runs_and_is_deterministic(values, sensor):
    b = make(n=3, sensor=sensor, steps=30, epsilon=0.1)
    params = build_params(Viterbi.Params, {"position_levels": 11, "velocity_levels": 11, "survivors": 16,
                                           **values})
    out = Viterbi().run(b, params)
    assert isinstance(out, TrackingOutput) and out.covariance is None
    assert out.estimate.shape == b.truth.shape and np.all(np.isfinite(out.estimate))
    np.testing.assert_array_equal(out.estimate, Viterbi().run(b, params).estimate)
    # one trial alone gives the same estimate as inside a batch (trials are independent)
    one = make(n=3, sensor=sensor, steps=30, epsilon=0.1)
    one.z, one.truth = one.z[1:2], one.truth[1:2]
    np.testing.assert_allclose(Viterbi().run(one, params).estimate[0], out.estimate[1], rtol=1e-12, atol=1e-9)


def test_viterbi_passive_radial_axis_is_the_prediction():
    """A passive sensor does not observe the line of sight: the radial axis's
    estimate is the zero-disturbance prediction from the prior mean."""
    b = make(n=2, sensor="passive", steps=25, initial_bearing_deg=40.0, initial_elevation_deg=15.0)
    model = b.scene.model
    est = Viterbi().run(b, build_params(Viterbi.Params, {"position_levels": 11, "velocity_levels": 11}))
    x = model.x0.copy()
    pred = []
    for _ in range(25):
        pred.append(x)
        x = model.F @ x + model.Bu
    R = model.los_rotation
    np.testing.assert_allclose(est.estimate[..., :3] @ R[0], np.broadcast_to(np.array(pred)[:, :3] @ R[0], (2, 25)),
                               atol=1e-6)


def test_viterbi_tracks_and_resists_glint():
    """Active sensor, eps = 0.2: both trackers stay on the target, and the
    Viterbi tracker (true density) has a smaller cross-range RMSE than the EKF
    (Gaussian core variance), which takes the outliers with the full gain."""
    b = make(n=6, sensor="active", steps=150, epsilon=0.2, seed=11)
    R = b.scene.model.los_rotation
    cross = {}
    for cls in (EKF, Viterbi):
        err = (cls().run(b, build_params(cls.Params, {})).estimate - b.truth)[..., :3] @ R.T
        cross[cls.name] = np.sqrt(np.mean(err[:, 30:, 1:] ** 2))
        assert np.abs(err).max() < 100.0
    assert cross["viterbi"] < cross["ekf"]


def test_compiled_trellis_step_equals_numpy():
    rng = np.random.default_rng(4)
    n, N, Lp, Lv = 3, 50, 9, 7
    w, logpi = vit.disturbance_levels(5, 1.0, 2.0)
    ps, sc = rng.normal(size=(n, N, 2)), rng.normal(size=(n, N))
    sc[1, :10] = -np.inf
    F2, g2 = np.array([[1.0, 0.1], [0.0, 0.96]]), np.array([0.005, 0.098])
    centre, step, metric = 0.1 * rng.normal(size=(n, 2)), np.array([0.3, 0.2]), rng.normal(size=(n, Lp))
    for snap in (False, True):
        a = trellis._trellis_step_numpy(ps, sc, F2, g2, 0.3, w, logpi, centre, step, Lp, Lv, metric, snap)
        b = trellis_step(ps, sc, F2, g2, 0.3, w, logpi, centre, step, Lp, Lv, metric, snap)
        np.testing.assert_array_equal(a[1], b[1])
        np.testing.assert_allclose(a[0], b[0], rtol=1e-12)
        np.testing.assert_allclose(a[2], b[2], rtol=1e-12, atol=1e-14)
    cell, gain, _ = expand(ps, sc, F2, g2, 0.3, w, logpi, centre, step, Lp, Lv, metric, False)
    np.testing.assert_array_equal(max_plus_step(cell, gain, Lp * Lv)[1], trellis._max_plus_step_numpy(cell, gain, Lp * Lv)[1])


def test_disturbance_levels():
    w, logpi = vit.disturbance_levels(9, 2.0, 2.0)
    np.testing.assert_allclose(w, np.linspace(-4.0, 4.0, 9))
    assert np.exp(logpi).sum() == pytest.approx(1.0)
    np.testing.assert_allclose(logpi - logpi[4], -0.5 * (w / 2.0) ** 2)
    assert vit.disturbance_levels(1, 2.0, 2.0)[0].tolist() == [0.0]
    assert vit.disturbance_levels(9, 0.0, 2.0)[0].tolist() == [0.0]


def test_viterbi_params_validation():
    from radarbench.bench.errors import ConfigError
    with pytest.raises(ConfigError) as err:
        build_params(Viterbi.Params, {"velocity_levels": 20})
    assert err.value.field == "velocity_levels"
    with pytest.raises(ConfigError):
        build_params(Viterbi.Params, {"survivors": 0})


def test_numpy_fallback_gives_the_compiled_result(monkeypatch):
    """Without numba the tracker runs the NumPy versions of its kernels, with
    the same result (to rounding)."""
    b = make(n=2, sensor="active", steps=20, epsilon=0.2)
    params = build_params(Viterbi.Params, {"position_levels": 11, "velocity_levels": 11, "survivors": 16})
    compiled = Viterbi().run(b, params).estimate
    monkeypatch.setattr(trellis, "_trellis_step_jit", None)
    monkeypatch.setattr(trellis, "_max_plus_step_jit", None)
    np.testing.assert_allclose(Viterbi().run(b, params).estimate, compiled, rtol=1e-10, atol=1e-8)
