"""Scenario hfswr-targets and models.hfswr: geometry, targets, plots, clutter,
draws (chunking, common random numbers), scene checks."""

import math

import numpy as np
import pytest
from scipy import stats

from radarbench.bench.core import SceneError
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.registry import get_scenario
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.tasks.multitarget import CLUTTER, PADDING, MultiTargetScene
from radarbench.models.hfswr import (cv_process_noise, cv_transition, measure, measure_jacobian, measurement_residual,
                          plot_to_cartesian)
from radarbench.scenarios.hfswr_targets import HFSWRTargets, swerling1_pd


def make(snr_db=15.0, n=8, seed=3, trials=None, **values):
    params = build_params(HFSWRTargets.Params, values)
    trials = range(n) if trials is None else trials
    return HFSWRTargets().generate(params, snr_db, len(trials), TrialRNG(seed, 0, 0, trials))


def target_plots(b):
    """(origin, plot, true state) of every target-originated plot."""
    i, k, p = np.nonzero(b.scene.plot_origin >= 0)
    t = b.scene.plot_origin[i, k, p]
    return t, b.z[i, k, p], b.truth[i, k, t]


# ------------------------------------------------------------------ models.hfswr

def test_measure_and_jacobian():
    rng = np.random.default_rng(0)
    x = np.column_stack([rng.uniform(-5e4, 5e4, 50), rng.normal(0, 10, 50),
                         rng.uniform(2e4, 1e5, 50), rng.normal(0, 10, 50)])
    sensor = np.array([1000.0, -2000.0])
    z = measure(x, sensor)
    dx, dy = x[:, 0] - sensor[0], x[:, 2] - sensor[1]
    np.testing.assert_allclose(z[:, 0], np.hypot(dx, dy))
    np.testing.assert_allclose(z[:, 1], np.arctan2(dx, dy))                      # clockwise from north
    np.testing.assert_allclose(plot_to_cartesian(z, sensor), x[:, [0, 2]], rtol=1e-12, atol=1e-6)
    # receding target: positive radial velocity
    assert measure(np.array([0.0, 0.0, 1e4, 5.0]), np.zeros(2))[2] == pytest.approx(5.0)
    H = measure_jacobian(x, sensor)
    eps = np.array([1e-3, 1e-5, 1e-3, 1e-5])
    for j in range(4):
        step = np.zeros(4)
        step[j] = eps[j]
        num = measurement_residual(measure(x + step, sensor), measure(x - step, sensor)) / (2 * eps[j])
        np.testing.assert_allclose(H[..., j], num, rtol=1e-5, atol=1e-12)


def test_cv_model():
    F = cv_transition(60.0)
    np.testing.assert_allclose(F @ np.array([0.0, 2.0, 0.0, -1.0]), [120.0, 2.0, -60.0, -1.0])
    np.testing.assert_allclose(cv_transition(-60.0) @ F, np.eye(4), atol=1e-12)
    Q = cv_process_noise(2.0, 0.5)
    np.testing.assert_allclose(Q[:2, :2], 0.25 * np.array([[4.0, 4.0], [4.0, 4.0]]))   # T^4/4, T^3/2, T^2
    assert np.all(Q[:2, 2:] == 0)


def test_swerling1_pd():
    assert swerling1_pd(10.0, 1e-3) == pytest.approx(1e-3 ** (1 / 11))
    assert swerling1_pd(-100.0, 1e-3) == pytest.approx(1e-3, rel=1e-6)
    assert swerling1_pd(20.0, 1e-3) > swerling1_pd(15.0, 1e-3) > swerling1_pd(10.0, 1e-3)


# ------------------------------------------------------------------ the scenario

def test_shapes_and_scene():
    b = make(n=5, scans=30, targets=4)
    sc = b.scene
    assert type(sc) is MultiTargetScene
    assert b.t.shape == (30,) and b.truth.shape == (5, 30, 4, 4)
    assert b.z.ndim == 4 and b.z.shape[:2] == (5, 30) and b.z.shape[3] == 3
    np.testing.assert_allclose(b.t, 60.0 * np.arange(30))
    assert sc.position_index == (0, 2)
    np.testing.assert_array_equal(sc.n_plots, (sc.plot_origin != PADDING).sum(axis=2))
    pad = sc.plot_origin == PADDING
    assert np.isnan(b.z[pad]).all() and np.isfinite(b.z[~pad]).all()
    # plots first, padding after
    assert np.all(np.diff(pad.astype(int), axis=2) >= 0)
    assert sc.pd == pytest.approx(swerling1_pd(15.0, 1e-3))
    assert sc.clutter_per_scan == pytest.approx(20.0)
    inside = (b.z[~pad] >= sc.surveillance_region[:, 0]) & (b.z[~pad] <= sc.surveillance_region[:, 1])
    assert inside.all()


def test_targets_present_and_speeds_bounded():
    b = make(n=20, scans=60, targets=6, speed_bounds_m_s=(2.0, 12.0))
    present = np.isfinite(b.truth[..., 0])
    assert np.array_equal(present, np.isfinite(b.truth).all(axis=-1))
    speed = np.hypot(b.truth[..., 1], b.truth[..., 3])[present]
    assert speed.min() >= 2.0 - 1e-9 and speed.max() <= 12.0 + 1e-9
    # appearing and disappearing: some targets are absent at the start or at the end
    assert (~present[:, 0]).any() and (~present[:, -1]).any()
    # consecutive states follow the CV model up to the small accelerations
    F = cv_transition(60.0)
    both = present[:, 1:] & present[:, :-1]
    pred = b.truth[:, :-1] @ F.T
    jump = np.abs(pred[..., [0, 2]] - b.truth[:, 1:][..., [0, 2]])[both]
    assert jump.max() < 60.0 * 60.0 * 0.002 * 8 + 60.0 * 15                   # 8 sigma, or a speed clip


def test_crossing_targets_meet_with_equal_measurements():
    b = make(n=10, scans=40, targets=3, crossing=True, crossing_targets=2)
    mid = 20
    a, c = b.truth[:, mid, 0], b.truth[:, mid, 1]
    ok = np.isfinite(a[:, 0]) & np.isfinite(c[:, 0])
    assert ok.sum() >= 8
    np.testing.assert_allclose(a[ok][:, [0, 2]], c[ok][:, [0, 2]])
    za, zc = measure(a[ok], np.zeros(2)), measure(c[ok], np.zeros(2))
    np.testing.assert_allclose(za, zc, atol=1e-9)                        # same range, azimuth, radial velocity
    heading = np.degrees(np.arctan2(a[ok][:, 1], a[ok][:, 3]) - np.arctan2(c[ok][:, 1], c[ok][:, 3]))
    np.testing.assert_allclose(np.abs((heading + 180) % 360 - 180), 20.0, atol=1e-6)


def test_detection_rate_noise_and_clutter_statistics():
    b = make(n=40, detection="fixed", pd=0.7, clutter_per_scan=15.0)
    sc = b.scene
    present = np.isfinite(b.truth[..., 0])
    detected = (sc.plot_origin >= 0).sum()
    m = present.sum()
    # a plot may fall outside the region (rare: the targets are inside it), so at most Pd, barely less
    se = math.sqrt(0.7 * 0.3 / m)
    assert 0.7 - 4 * se - 0.01 < detected / m < 0.7 + 4 * se
    t, z, x = target_plots(b)
    e = measurement_residual(z, measure(x, sc.sensor_xy)) / sc.measurement_std
    lo, hi = stats.chi2.ppf([1e-4, 1 - 1e-4], len(e)) / len(e)
    for j in range(3):
        assert abs(e[:, j].mean()) < 4 / math.sqrt(len(e))
        assert lo < (e[:, j] ** 2).mean() < hi
    clutter = (sc.plot_origin == CLUTTER).sum(axis=2)                     # Poisson(15) per scan
    assert abs(clutter.mean() - 15.0) < 4 * math.sqrt(15.0 / clutter.size)
    cz = b.z[sc.plot_origin == CLUTTER]
    u = (cz - sc.surveillance_region[:, 0]) / np.diff(sc.surveillance_region, axis=1)[:, 0]
    for j in range(3):                                                   # uniform over the region
        assert stats.kstest(u[:, j], "uniform").pvalue > 1e-4
    assert sc.clutter_density == pytest.approx(15.0 / np.prod(np.diff(sc.surveillance_region, axis=1)))


def test_chunking_and_common_random_numbers():
    whole = make(n=6, seed=9)
    part = make(seed=9, trials=[2, 3, 4, 5])
    for i in range(4):
        P = part.z.shape[2]
        np.testing.assert_array_equal(part.truth[i], whole.truth[i + 2])
        np.testing.assert_array_equal(part.scene.plot_origin[i], whole.scene.plot_origin[i + 2][:, :P])
        np.testing.assert_array_equal(part.z[i], whole.z[i + 2][:, :P])
    lo, hi = make(detection="fixed", pd=0.5, seed=9), make(detection="fixed", pd=0.9, seed=9)
    np.testing.assert_array_equal(lo.truth, hi.truth)
    for i in range(lo.n):                                                # a higher Pd only adds target plots
        for k in range(lo.steps):
            a = set(lo.scene.plot_origin[i, k][lo.scene.plot_origin[i, k] >= 0])
            c = set(hi.scene.plot_origin[i, k][hi.scene.plot_origin[i, k] >= 0])
            assert a <= c
    null = make(None, seed=9)
    assert np.isnan(null.truth).all() and not (null.scene.plot_origin >= 0).any()
    np.testing.assert_array_equal(null.scene.plot_origin == CLUTTER, null.scene.plot_origin != PADDING)
    # the same clutter as under a target
    for i in range(whole.n):
        np.testing.assert_array_equal(np.sort(null.z[i][null.scene.plot_origin[i] == CLUTTER], axis=0),
                                      np.sort(whole.z[i][whole.scene.plot_origin[i] == CLUTTER], axis=0))


def test_bad_params_and_scene():
    with pytest.raises(ConfigError, match="crossing_targets"):
        build_params(HFSWRTargets.Params, {"targets": 2, "crossing_targets": 3})
    with pytest.raises(ConfigError, match="range_bounds_m"):
        build_params(HFSWRTargets.Params, {"range_bounds_m": [9e4, 5e4]})
    p = build_params(HFSWRTargets.Params, {"noise_scales_with_snr": True})
    assert HFSWRTargets().check_snr(p, 15.0) is None
    assert "range noise" in HFSWRTargets().check_snr(p, 80.0)
    b = make(n=2, scans=10)
    with pytest.raises(SceneError, match="MultiTargetScene.pd"):
        MultiTargetScene(**{**b.scene.__dict__, "pd": 1.5})
    assert get_scenario("hfswr-targets") is HFSWRTargets
