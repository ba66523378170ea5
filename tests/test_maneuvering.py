"""Scenario ``maneuvering-1d``: shapes, the documented profile, the null, the SNR mapping."""

import numpy as np
import pytest
from scipy import stats

from radarbench.bench.core import SceneError
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.tasks.tracking import TrackingScene
from radarbench.models.kinematics import KinematicModel, singer
from radarbench.scenarios.maneuvering import Maneuvering

#: two-sided probability outside the sampling intervals (never flaky at fixed seeds, still tight)
P_OUT = 1e-6


def _batch(snr_db=0.0, n=200, seed=5, **kw):
    p = build_params(Maneuvering.Params, kw)
    return Maneuvering().generate(p, snr_db, n, TrialRNG(seed, 0, 3, range(n))), p


def _variance_interval(dof: int) -> tuple[float, float]:
    """Interval of s^2 / sigma^2 for a sum of ``dof`` independent squared N(0, 1) / dof."""
    return stats.chi2.ppf(P_OUT / 2, dof) / dof, stats.chi2.isf(P_OUT / 2, dof) / dof


@pytest.mark.parametrize("dims", [1, 2])
def test_shapes_labels_and_scene(dims):
    b, p = _batch(dims=dims, n=7)
    K = p.steps
    assert b.truth.shape == (7, K, 3 * dims) and b.z.shape == (7, K, dims) and b.t.shape == (K,)
    assert b.scene.state_labels == ("x", "vx", "ax", "y", "vy", "ay")[:3 * dims]
    assert b.scene.position_index == (0, 3)[:dims]
    assert isinstance(b.scene.model, KinematicModel) and b.scene.model.dims == dims
    assert b.scene.maneuver_mask.shape == (7, K) and b.scene.maneuver_onset_steps.shape == (7, 1)
    assert (b.scene.measurements_xy is None) == (dims == 2)


def test_default_profile_is_the_documented_one():
    """Quiet to 40 s, 20 m/s^2 from 40 s to 60 s, quiet to 100 s; range 12 km at 40 s and 60 s, 20 km at the end."""
    b, p = _batch(n=3)
    a = b.truth[..., 2]
    assert (a[:, :40] == 0).all() and (a[:, 40:60] == 20.0).all() and (a[:, 60:] == 0).all()
    np.testing.assert_array_equal(b.scene.maneuver_onset_steps, 40)
    np.testing.assert_array_equal(b.scene.maneuver_mask, a != 0)
    # the mean target (prior mean initial state) by the documented kinematics
    mean0 = Maneuvering.model(p).x0
    offset = b.truth[:, 0, :2] - mean0[:2]              # each trial's initial draw
    x = b.truth[:, :, 0] - offset[:, :1] - offset[:, 1:2] * b.t
    np.testing.assert_allclose(x[:, [40, 60, 99]], np.tile([12_000.0, 12_000.0, 19_800.0], (3, 1)), atol=1e-6)
    v = b.truth[:, :, 1] - offset[:, 1:2]
    np.testing.assert_allclose(v[:, 60], 200.0)


def test_truth_obeys_the_exact_kinematics():
    b, p = _batch(n=4, dims=2, process_noise_m_s2=3.0)
    T = p.dt_s
    for axis in (0, 3):
        pos, vel, acc = (b.truth[..., axis + c] for c in range(3))
        np.testing.assert_allclose(pos[:, 1:], pos[:, :-1] + vel[:, :-1] * T + acc[:, :-1] * T * T / 2, rtol=1e-12)
        np.testing.assert_allclose(vel[:, 1:], vel[:, :-1] + acc[:, :-1] * T, rtol=1e-12, atol=1e-9)


def test_null_has_no_maneuver_and_the_same_noise():
    null, _ = _batch(snr_db=None, n=5)
    ref, _ = _batch(snr_db=0.0, n=5)
    assert (null.truth[..., 2] == 0).all() and not null.scene.maneuver_mask.any()
    assert null.scene.maneuver_onset_steps.shape == (5, 0)
    np.testing.assert_allclose(null.z - null.truth[..., :1], ref.z - ref.truth[..., :1], atol=1e-9)   # noise at 0 dB
    zero, _ = _batch(n=5, maneuver_accel_m_s2=(0.0,))
    assert zero.scene.maneuver_onset_steps.shape == (5, 0)


@pytest.mark.parametrize("snr_db", [-10.0, 0.0, 12.0])
def test_noise_std_matches_the_snr_mapping(snr_db):
    """s^2 / sigma^2 of the measurement noise within its chi-square interval, sigma = 50 m x 10^(-SNR/20)."""
    b, p = _batch(snr_db=snr_db, n=100, dims=2)
    sigma = p.noise_std_m * 10 ** (-snr_db / 20)
    assert b.scene.model.noise_std_m == pytest.approx(sigma)
    noise = b.z - b.truth[..., [0, 3]]
    lo, hi = _variance_interval(noise.size)
    assert lo < np.mean(noise ** 2) / sigma ** 2 < hi


def test_singer_profile_is_stationary_with_its_sigma():
    """Across trials (independent), the acceleration at the last step has variance sigma_m^2."""
    b, p = _batch(n=4000, profile="singer", steps=30, singer_sigma_m_s2=7.0, singer_alpha_per_s=0.3)
    assert b.scene.maneuver_mask is None and b.scene.maneuver_onset_steps is None
    a = b.truth[:, -1, 2]
    lo, hi = _variance_interval(a.size)
    assert lo < np.mean(a ** 2) / 7.0 ** 2 < hi
    F, Q = singer(p.dt_s, 0.3, 7.0)
    assert F[2, 2] == pytest.approx(np.exp(-0.3)) and Q[2, 2] == pytest.approx(49 * (1 - np.exp(-0.6)))


def test_bad_input_names_the_field():
    with pytest.raises(ConfigError, match="maneuver_start_s"):
        build_params(Maneuvering.Params, {"steps": 10, "maneuver_start_s": 10.0})
    assert "below 0.001 m" in Maneuvering().check_snr(build_params(Maneuvering.Params, {}), 100.0)
    with pytest.raises(SceneError, match="maneuver_mask"):
        TrackingScene(maneuver_mask=np.zeros((2, 3)))
    with pytest.raises(SceneError, match="maneuver_onset_steps"):
        TrackingScene(maneuver_onset_steps=np.full((2, 1), -1))
