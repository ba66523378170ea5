"""The multi-target trackers' parts against oracles: the UKF against FilterPy's,
JPDA-UKF against a plain UKF on one target, the JPDA marginals against brute
force, the compiled measurement model against models/hfswr.py, M/N
confirmation timing, GNN's assignment, and the Stone Soup peer on a small case.

Hypothesis draws the cases with ``derandomize=True``; every random array comes
from ``numpy.random.default_rng`` seeded by the drawn integer."""

from __future__ import annotations

import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.methods.multitarget import kernels as kern
from radarbench.methods.multitarget.jpda import jpda_marginals
from radarbench.methods.multitarget.track_management import (
    CONFIRMATIONS,
    EkfTrackerParams,
    TrackerParams,
    TrialBuffers,
    UkfTrackerParams,
    tracker_models,
)
from radarbench.methods.multitarget.trackers import GnnEkf, JpdaUkf, gnn_assignment
from radarbench.models.hfswr import measure, measure_jacobian, measurement_residual, plot_to_cartesian

FIXED = settings(derandomize=True, deadline=None, max_examples=8)
SIGMA = np.array([300.0, math.radians(1.0), 0.2])


def _scene(pd=1.0, clutter_density=0.0, accel=0.01, T=60.0):
    return SimpleNamespace(scan_period_s=T, measurement_std=SIGMA, pd=pd, clutter_density=clutter_density,
                           speed_bounds_m_s=(1.0, 15.0), sensor_xy=np.zeros(2), accel_std_m_s2=accel)


def _target(seed, K, T=60.0, accel=0.01):
    """One CV ship (K, 4) at 60-120 km, 3-12 m/s, and its plots (K, 3)."""
    rng = np.random.default_rng(seed)
    r, az, heading, speed = rng.uniform(60e3, 120e3), rng.uniform(-0.4, 0.4), rng.uniform(0, 2 * np.pi), \
        rng.uniform(3.0, 12.0)
    x = np.array([r * np.sin(az), speed * np.sin(heading), r * np.cos(az), speed * np.cos(heading)])
    F = np.array([[1, T, 0, 0], [0, 1, 0, 0], [0, 0, 1, T], [0, 0, 0, 1]], float)
    G = np.array([[T * T / 2, 0], [T, 0], [0, T * T / 2], [0, T]])
    xs = []
    for _ in range(K):
        xs.append(x)
        x = F @ x + G @ (accel * rng.standard_normal(2))
    xs = np.array(xs)
    z = measure(xs, np.zeros(2)) + SIGMA * rng.standard_normal((K, 3))
    return xs, z


def _run_jpda(z, n_plots, scene, params, capacity=16):
    models = tracker_models(scene, params, kern.UKF, CONFIRMATIONS[getattr(params, "confirmation", "frame-n+2")])
    tab = kern.new_table(capacity, z.shape[1])
    buf = TrialBuffers.empty(z.shape[0], capacity)
    kern.jpda_trial(z, n_plots, models.F, models.Q, models.R, models.Wm, models.Wc, models.cfg, models.icfg,
                    tab, buf.state, buf.track_id, buf.status, buf.cov)
    return buf, tab


def _filterpy_ukf(params, scene):
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    models = tracker_models(scene, params, kern.UKF)
    points = MerweScaledSigmaPoints(4, alpha=params.alpha, beta=params.beta, kappa=params.kappa)

    def z_mean(sigmas, Wm):
        mean = Wm @ sigmas
        mean[1] = sigmas[0, 1] + Wm @ measurement_residual(sigmas, sigmas[0])[:, 1]
        return measurement_residual(mean[None], np.zeros(3))[0]

    ukf = UnscentedKalmanFilter(dim_x=4, dim_z=3, dt=scene.scan_period_s, points=points,
                                fx=lambda x, dt: models.F @ x, hx=lambda x: measure(x, np.zeros(2)),
                                z_mean_fn=z_mean, residual_z=lambda a, b: measurement_residual(a, b))
    ukf.Q, ukf.R = models.Q, models.R
    return ukf, points


def _filterpy_step(ukf, points, z):
    """The chapter's UKF step with FilterPy: predict, redraw the sigma points
    around (x⁻, P⁻) (FilterPy would reuse the propagated ones), update."""
    ukf.predict()
    ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)
    ukf.update(z)


@FIXED
@given(seed=st.integers(0, 2 ** 31))
def test_ukf_equals_filterpy_step_by_step(seed):
    """models/ukf.py through the compiled prediction and a one-plot update equals
    FilterPy's UnscentedKalmanFilter (MerweScaledSigmaPoints) at every step."""
    scene, params = _scene(), TrackerParams()
    truth, z = _target(seed, 12)
    rng = np.random.default_rng(seed + 1)
    x0 = truth[0] + np.array([300.0, 1.0, 300.0, 1.0]) * rng.standard_normal(4)
    P0 = np.diag([500.0 ** 2, 4.0, 500.0 ** 2, 4.0])
    ukf, points = _filterpy_ukf(params, scene)
    ukf.x, ukf.P = x0.copy(), P0.copy()
    models = tracker_models(scene, params, kern.UKF)
    tab = kern.new_table(1, 1)
    tab.x[0], tab.P[0], tab.status[0] = x0, P0, kern.CONFIRMED
    for k in range(1, 12):
        kern.predict_all(tab, models.F, models.Q, models.R, models.Wm, models.Wc, models.cfg, models.icfg)
        kern.mixture_update(tab, 0, z[k:k + 1], np.zeros(1, np.int64), 0.0, np.ones(1))
        _filterpy_step(ukf, points, z[k])
        np.testing.assert_allclose(tab.x[0], ukf.x, rtol=1e-9, atol=1e-6)
        np.testing.assert_allclose(tab.P[0], ukf.P, rtol=1e-7, atol=1e-6)


@FIXED
@given(seed=st.integers(0, 2 ** 31))
def test_jpda_ukf_on_one_target_is_a_plain_ukf(seed):
    """One target, Pd = 1, no clutter: JPDA-UKF's track (started from the first
    two plots by two-point differencing) equals FilterPy's UKF started from the
    same state, scan by scan (every marginal is 1 for the one plot; a gate of
    P_G = 1 - 1e-6 keeps the plot inside)."""
    K = 15
    scene = _scene()
    params = TrackerParams(gate_probability=0.999999, max_speed_m_s=1000.0, max_position_std_m=1e6)
    truth, z = _target(seed, K)
    buf, tab = _run_jpda(z[:, None, :], np.ones(K, np.int64), scene, params)
    assert tab.counters[kern.K_NEXT_ID] == 1
    ukf, points = _filterpy_ukf(params, scene)
    ukf.x, ukf.P = buf.state[1, 0].copy(), _two_point_covariance(z[0], z[1], scene.scan_period_s)
    for k in range(2, K):
        _filterpy_step(ukf, points, z[k])
        np.testing.assert_allclose(buf.state[k, 0], ukf.x, rtol=1e-9, atol=1e-6)
        np.testing.assert_allclose(buf.cov[k, 0], ukf.P[np.ix_((0, 2), (0, 2))], rtol=1e-7, atol=1e-6)
    np.testing.assert_allclose(buf.state[1, 0, [0, 2]], plot_to_cartesian(z[1], np.zeros(2)))


def _two_point_covariance(z1, z2, T):
    """P_pp = R2, P_vv = (R1 + R2)/T², P_pv = R2/T in [x, vx, y, vy] order."""
    def cart(z):
        J = np.array([[np.sin(z[1]), z[0] * np.cos(z[1])], [np.cos(z[1]), -z[0] * np.sin(z[1])]])
        return J @ np.diag(SIGMA[:2] ** 2) @ J.T
    R1, R2 = cart(z1), cart(z2)
    P = np.zeros((4, 4))
    idx = np.array([0, 2])
    P[np.ix_(idx, idx)] = R2
    P[np.ix_(idx, idx + 1)] = P[np.ix_(idx + 1, idx)] = R2 / T
    P[np.ix_(idx + 1, idx + 1)] = (R1 + R2) / T ** 2
    return P


def _brute_force_marginals(valid, loglik, pd, miss, lam):
    """Every assignment of plots to tracks or clutter by itertools; the event
    weight λ^φ ∏ P_D N ∏ (1 − P_D P_G)."""
    t, m = valid.shape
    beta = np.zeros((t, m + 1))
    for choice in itertools.product(*[[-1] + [j for j in range(t) if valid[j, i]] for i in range(m)]):
        used = [c for c in choice if c >= 0]
        if len(used) != len(set(used)):
            continue
        w = lam ** (m - len(used)) * miss ** (t - len(used))
        for i, c in enumerate(choice):
            if c >= 0:
                w *= pd * math.exp(loglik[c, i])
        for i, c in enumerate(choice):
            if c >= 0:
                beta[c, 1 + i] += w
        for j in set(range(t)) - set(used):
            beta[j, 0] += w
    return beta / beta[0].sum()


@settings(derandomize=True, deadline=None, max_examples=40)
@given(seed=st.integers(0, 2 ** 31), t=st.integers(1, 4), m=st.integers(1, 5))
def test_jpda_marginals_equal_brute_force_and_sum_to_one(seed, t, m):
    rng = np.random.default_rng(seed)
    valid = rng.random((t, m)) < 0.7
    loglik = rng.normal(-12.0, 2.0, (t, m))
    pd, pg, lam = rng.uniform(0.5, 1.0), 0.99, 10.0 ** rng.uniform(-7, -4)
    miss = 1.0 - pd * pg
    beta = np.zeros((t, m + 1))
    exact = jpda_marginals(valid, np.where(valid, loglik, -np.inf), math.log(pd), math.log(miss),
                           math.log(lam), 64, beta)
    assert exact
    np.testing.assert_allclose(beta.sum(axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(beta, _brute_force_marginals(valid, loglik, pd, miss, lam), rtol=1e-9, atol=1e-300)
    assert np.all(beta[:, 1:][~valid] == 0.0)


@settings(derandomize=True, deadline=None, max_examples=10)
@given(seed=st.integers(0, 2 ** 31))
def test_beyond_the_cluster_limit_each_track_gets_its_pda(seed):
    """A cluster above max_size falls back to single-target PDA per track:
    marginals still sum to 1, and equal brute force on the track alone."""
    rng = np.random.default_rng(seed)
    t, m = 3, 4
    valid = np.ones((t, m), bool)
    loglik = rng.normal(-12.0, 2.0, (t, m))
    beta = np.zeros((t, m + 1))
    exact = jpda_marginals(valid, loglik, math.log(0.9), math.log(1 - 0.9 * 0.99), math.log(1e-5), t * m - 1, beta)
    assert not exact
    np.testing.assert_allclose(beta.sum(axis=1), 1.0, rtol=1e-12)
    for j in range(t):
        alone = _brute_force_marginals(valid[j:j + 1], loglik[j:j + 1], 0.9, 1 - 0.9 * 0.99, 1e-5)
        np.testing.assert_allclose(beta[j], alone[0], rtol=1e-9)


@pytest.mark.parametrize("M, N", [(1, 1), (2, 3), (3, 3), (3, 5), (4, 6)])
def test_mn_confirms_a_true_target_at_frame_n_plus_2(M, N):
    """Pd = 1, no clutter: the head at frame 1, the initial track at frame 2,
    confirmed at frame N + 2 (scan index N + 1), tentative before."""
    K = N + 4
    _, z = _target(7, K)
    params = TrackerParams(confirm_m=M, confirm_n=N, gate_probability=0.999999)
    buf, _ = _run_jpda(z[:, None, :], np.ones(K, np.int64), _scene(), params)
    status = buf.status[:, 0]
    assert status[0] == kern.EMPTY
    assert np.all(status[1:N + 1] == kern.TENTATIVE)
    assert np.all(status[N + 1:] == kern.CONFIRMED)


@pytest.mark.parametrize("M, N", [(1, 1), (2, 3), (3, 3), (3, 5), (4, 6)])
def test_kth_plot_confirms_a_true_target_on_its_m_plus_2_th_plot(M, N):
    """Pd = 1, no clutter, ``confirmation = "kth-plot"``: the initial track at
    frame 2, confirmed with its (M + 2)-th plot at frame M + 2 whatever N."""
    K = N + 4
    _, z = _target(7, K)
    params = UkfTrackerParams(confirm_m=M, confirm_n=N, gate_probability=0.999999, confirmation="kth-plot")
    buf, _ = _run_jpda(z[:, None, :], np.ones(K, np.int64), _scene(), params)
    status = buf.status[:, 0]
    assert status[0] == kern.EMPTY
    assert np.all(status[1:M + 1] == kern.TENTATIVE)
    assert np.all(status[M + 1:] == kern.CONFIRMED)


def _first_decision(rule, hits, M, N):
    """(frame after the initial plots, confirmed?) at which ``rule`` first
    decides on the hit sequence ``hits``, or None; the rules see what
    ``kern.manage`` gives them (hits so far, frames so far, miss history)."""
    n_hits, history = 0, 0
    for frame, hit in enumerate(hits, start=1):
        n_hits += hit
        history = (history << 1) | (1 - hit)
        confirm, drop = (kern.mn_rule(n_hits, frame, M, N) if rule == "frame-n+2"
                         else kern.kth_plot_rule(n_hits, history, M, N))
        if confirm or drop:
            return frame, confirm
    return None


@pytest.mark.parametrize("M, N", [(1, 1), (1, 3), (2, 3), (3, 5), (2, 6)])
def test_confirmation_rules_against_their_definitions(M, N):
    """Every hit sequence of N + 3 frames: frame-n+2 decides by frame N and
    confirms exactly with M hits in the first N frames; kth-plot confirms on
    the M-th hit unless N − M + 1 misses in a row came first (then drops), so
    it confirms every sequence frame-n+2 confirms, no later."""
    run = N - M + 1
    for hits in itertools.product((0, 1), repeat=N + 3):
        frame, confirmed = _first_decision("frame-n+2", hits, M, N)
        assert frame <= N and confirmed == (sum(hits[:N]) >= M)
        if confirmed:
            assert frame == N
        text = "".join(map(str, hits))
        mth_hit = [i for i, h in enumerate(hits) if h][M - 1] + 1 if sum(hits) >= M else None
        missed_run = text.find("0" * run) + run if "0" * run in text else None
        expected = (None if mth_hit is None and missed_run is None else
                    (mth_hit, True) if missed_run is None or (mth_hit is not None and mth_hit < missed_run)
                    else (missed_run, False))
        assert _first_decision("kth-plot", hits, M, N) == expected
        if confirmed:
            assert expected[1] and expected[0] <= frame


def test_the_filter_is_a_parameter_of_both_trackers_with_each_method_s_default():
    """JPDA-EKF and GNN-UKF (our ablation) run through the methods: each
    method's default filter is its name's, and the crossed filter changes the
    estimates yet still follows the lone target."""
    assert JpdaUkf.Params().filter == "ukf" and GnnEkf.Params().filter == "ekf"
    batch, truth = _peer_batch()
    for method, params, crossed in ((JpdaUkf(), UkfTrackerParams, "ekf"), (GnnEkf(), EkfTrackerParams, "ukf")):
        base = method.run(batch, params(gate_probability=0.999))
        other = method.run(batch, params(gate_probability=0.999, filter=crossed))
        confirmed = other.status[0, -1] == kern.CONFIRMED
        assert confirmed.sum() == 1
        assert not np.allclose(base.state[0, -1][confirmed], other.state[0, -1][confirmed], rtol=0, atol=1e-6)
        err = np.linalg.norm(other.state[0, -1][confirmed][0, [0, 2]] - truth[-1, [0, 2]])
        assert err < 3 * 100e3 * SIGMA[1]


def test_a_trial_keeps_the_slots_it_used_and_the_working_buffer_is_emptied():
    """``TrialBuffers.take``: a copy of the used slots; those slots empty again, the rest untouched."""
    buf, empty = TrialBuffers.empty(3, 8), TrialBuffers.empty(3, 8)
    rng = np.random.default_rng(3)
    buf.state[:], buf.cov[:] = rng.normal(size=buf.state.shape), rng.normal(size=buf.cov.shape)
    buf.track_id[:], buf.status[:] = rng.integers(0, 9, buf.track_id.shape), kern.CONFIRMED
    before = TrialBuffers(*(np.copy(a) for a in (buf.state, buf.track_id, buf.status, buf.cov)))
    kept = buf.take(5)
    for name in ("state", "track_id", "status", "cov"):
        np.testing.assert_array_equal(getattr(kept, name), getattr(before, name)[:, :5])
        np.testing.assert_array_equal(getattr(buf, name)[:, :5], getattr(empty, name)[:, :5])
        np.testing.assert_array_equal(getattr(buf, name)[:, 5:], getattr(before, name)[:, 5:])
        assert not np.shares_memory(getattr(kept, name), getattr(buf, name))


@pytest.mark.parametrize("method", [JpdaUkf, GnnEkf])
def test_a_runs_memory_does_not_grow_with_the_table_capacity_per_trial(method):
    """The outputs of a run hold the slots its trials used, not ``max_tracks`` per trial: the traced
    peak at a 32-fold capacity grows by about one working buffer, not one per trial."""
    import tracemalloc

    from radarbench.bench import registry
    from radarbench.bench.params import build_params
    from radarbench.bench.sweep.rng import TrialRNG

    scenario = registry.get_scenario("hfswr-targets")
    batch = scenario().generate(build_params(scenario.Params, scenario.small_params), 10.0, 12,
                                TrialRNG(4, 0, 0, range(12)))
    runs, peaks = [], []
    for capacity in (64, 2048):
        params = method.Params(max_tracks=capacity)
        method().run(batch, params)                                   # compiled before it is traced
        tracemalloc.start()
        runs.append(method().run(batch, params))
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    for name in ("state", "track_id", "status", "position_covariance"):
        np.testing.assert_array_equal(getattr(runs[0], name), getattr(runs[1], name))
    one_buffer = TrialBuffers.empty(batch.z.shape[1], 2048)
    per_capacity = sum(a.nbytes for a in (one_buffer.state, one_buffer.track_id, one_buffer.status, one_buffer.cov))
    assert peaks[1] - peaks[0] < 2 * per_capacity < batch.n * per_capacity


def test_compiled_measurement_model_equals_models_hfswr():
    rng = np.random.default_rng(5)
    x = np.column_stack([rng.uniform(-1e5, 1e5, 50), rng.normal(0, 10, 50), rng.uniform(1e4, 1e5, 50),
                         rng.normal(0, 10, 50)])
    sensor = np.array([1000.0, -2000.0])
    z, H = np.empty(3), np.empty((3, 4))
    for xi, zi, Hi in zip(x, measure(x, sensor), measure_jacobian(x, sensor)):
        kern.measure_one(xi, sensor[0], sensor[1], z)
        kern.jacobian_one(xi, sensor[0], sensor[1], H)
        np.testing.assert_allclose(z, zi, rtol=1e-14)
        np.testing.assert_allclose(H, Hi, rtol=1e-12, atol=1e-18)
        p = np.empty(2)
        kern.plot_position(zi, sensor[0], sensor[1], p)
        np.testing.assert_allclose(p, xi[[0, 2]], rtol=1e-12)


def test_gnn_assignment_minimises_the_gated_distance_and_leaves_ungated_tracks_empty():
    inf = np.inf
    d2 = np.array([[1.0, 2.0, inf], [1.5, inf, inf], [inf, inf, inf]])
    assert gnn_assignment(d2).tolist() == [1, 0, -1]
    assert gnn_assignment(np.zeros((0, 0))).tolist() == []


def test_stonesoup_peer_tracks_a_lone_target():
    """The peer confirms one target in no clutter and follows it within the noise."""
    pytest.importorskip("stonesoup")
    from radarbench.methods.multitarget.stonesoup_peer import StoneSoupJpda
    from tests.test_mtt_trackers import _peer_batch

    batch, truth = _peer_batch()
    out = StoneSoupJpda().run(batch, TrackerParams(gate_probability=0.999))
    confirmed = out.status[0] == kern.CONFIRMED
    assert confirmed[-1].sum() == 1
    err = np.linalg.norm(out.state[0, -1][confirmed[-1]][0, [0, 2]] - truth[-1, [0, 2]])
    assert err < 3 * 100e3 * SIGMA[1]


def _peer_batch():
    from radarbench.bench.core import Batch
    from radarbench.bench.tasks.multitarget import MultiTargetScene

    K = 12
    truth, z = _target(11, K)
    region = np.array([[1e3, 2e5], [-1.5, 1.5], [-30.0, 30.0]])
    scene = MultiTargetScene(n_plots=np.ones((1, K), np.int64), plot_origin=np.zeros((1, K, 1), np.int64),
                             scan_period_s=60.0, sensor_xy=np.zeros(2), measurement_std=SIGMA,
                             clutter_density=0.0, surveillance_region=region, pd=1.0,
                             speed_bounds_m_s=(1.0, 15.0), accel_std_m_s2=0.01)
    return Batch(t=np.arange(K) * 60.0, truth=truth[None, :, None], z=z[None, :, None], scene=scene,
                 trials=np.arange(1)), truth
