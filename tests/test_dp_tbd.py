"""Methods dp-tbd and dp-tbd-mf: interface, window, turn prior, LLR, agreement with the reference."""

import math

import numpy as np
import pytest
import scipy.integrate

from radarbench.bench.core import TBD, Batch, TBDOutput
from radarbench.bench.tasks.tbd import Grid, TBDScene
from radarbench.bench.params import build_params
from radarbench.bench.registry import get_method
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.methods.tbd.reference import numpy_dp_tbd, reference_dp_tbd
from radarbench.methods.tbd.dp_tbd import (
    LOG_UNIFORM_ANGLE,
    ConditionalLLR,
    DpTbd,
    DpTbdMf,
    displacements,
    transition_log_weights,
    turn_angle,
    turn_log_density,
    window_radius,
)
from radarbench.scenarios.tbd_grid import TbdGrid


def scene(snr_db, n=2, seed=3, **values):
    params = build_params(TbdGrid.Params, {"cells": 32, **values})
    return TbdGrid().generate(params, snr_db, n, TrialRNG(seed, 0, 7, range(n)))


def frames_batch(z, gamma=(1.0, 0.0, 0.0), cell_m=100.0, period_s=1.0):
    z = np.asarray(z, np.float32)
    n, K, H, W = z.shape
    sc = TBDScene(grid=Grid(rows=H, cols=W, cell_m=cell_m, x_min_m=0.0, y_min_m=0.0), frame_period_s=period_s,
                  noise_std=math.sqrt(gamma[0]), noise_autocovariance=np.asarray(gamma, float))
    return Batch(t=period_s * np.arange(K), truth=np.zeros((n, K, 4)), z=z, scene=sc, trials=np.arange(n))


def test_registered_with_the_tbd_task():
    assert get_method("dp-tbd") is DpTbd and get_method("dp-tbd-mf") is DpTbdMf
    assert DpTbd.task == TBD and DpTbdMf.task == TBD
    assert DpTbd.Params().max_speed_m_s == 150.0
    p = DpTbdMf.Params()
    assert (p.max_speed_m_s, p.turn_prior) == (150.0, "von-mises")


def test_nominal_threshold_is_nan():
    b = scene(None, n=1, frames=4)
    assert math.isnan(DpTbd().nominal_threshold(DpTbd.Params(), 1e-3, b))
    assert math.isnan(DpTbdMf().nominal_threshold(DpTbdMf.Params(), 1e-3, b))


def test_window_radius_from_max_speed():
    b = scene(None, n=1, frames=4)
    assert window_radius(150.0, b) == 2            # 1.5 cells per frame
    assert window_radius(100.0, b) == 1            # exactly one cell per frame
    assert window_radius(100 * math.sqrt(2), b) == 2
    assert window_radius(1.0, b) == 1
    with pytest.raises(ValueError, match="at most 5"):
        window_radius(600.0, b)


def test_paper_true_path_is_admissible_with_the_default_window():
    cells = scene(6.0, n=1).scene.target_cells[0]
    steps = np.abs(np.diff(cells, axis=0)).max(axis=1)
    assert steps.max() == 2                       # q = 1 would cut the turn
    assert window_radius(DpTbd.Params().max_speed_m_s, scene(None, n=1, frames=4)) == 2


@pytest.mark.parametrize("cls", [DpTbd, DpTbdMf])
def test_output_shapes_and_determinism(cls):
    b = scene(3.0, n=3, frames=6)
    out = cls().run(b, cls.Params())
    assert isinstance(out, TBDOutput)
    assert out.score.shape == (3,) and np.all(np.isfinite(out.score))
    assert out.track.shape == (3, 6, 2) and np.issubdtype(out.track.dtype, np.integer)
    assert out.track.min() >= 0 and out.track.max() < 32
    assert out.value.shape == (3, 32, 32) and out.value.dtype == np.float32
    np.testing.assert_allclose(out.value.reshape(3, -1).max(axis=1), out.score, rtol=1e-6)
    again = cls().run(scene(3.0, n=3, frames=6), cls.Params())
    np.testing.assert_array_equal(out.score, again.score)
    np.testing.assert_array_equal(out.track, again.track)


@pytest.mark.parametrize("cls", [DpTbd, DpTbdMf])
def test_strong_target_is_tracked(cls):
    """At 15 dB both methods follow the true cells (the turn included)."""
    b = scene(15.0, n=2)
    out = cls().run(b, cls.Params())
    off = np.abs(out.track - b.scene.target_cells).max(axis=-1)
    assert np.all((off <= 1).sum(axis=1) >= 18)


def test_mf_finds_a_weak_target_in_correlated_noise():
    """The whitening LLR sees a target the raw-merit DP cannot: at 0 dB in the
    default AR(3) noise the MF track sits on the target."""
    b = scene(0.0, n=2)
    out = DpTbdMf().run(b, DpTbdMf.Params())
    off = np.abs(out.track - b.scene.target_cells).max(axis=-1)
    assert np.all((off <= 1).sum(axis=1) >= 15)


@pytest.mark.parametrize("q", [1, 2, 3])
def test_numba_dp_tbd_equals_scipy_reference_on_scene_frames(q):
    b = scene(4.0, n=2, frames=8)
    out = DpTbd().run(b, DpTbd.Params(max_speed_m_s=100.0 * q))
    score, track = reference_dp_tbd(b.z, q)
    np.testing.assert_array_equal(out.score, score)
    np.testing.assert_array_equal(out.track, track)


@pytest.mark.parametrize("q", [1, 2, 3])
def test_numpy_peer_equals_scipy_reference_with_ties_and_edges(q):
    """The ``bench perf`` peer (the kernel's algorithm in NumPy) gives the oracle's score and
    track bit for bit: on scene frames, and on small-integer frames full of ties (the first
    maximum must win) over grids narrower than the window (the -inf edges)."""
    b = scene(4.0, n=2, frames=8)
    for frames in (b.z, np.random.default_rng(q).integers(0, 3, (3, 6, 4, 2 * q)).astype(np.float32)):
        score, track = numpy_dp_tbd(frames, q)
        ref_score, ref_track = reference_dp_tbd(frames, q)
        np.testing.assert_array_equal(score, ref_score)
        np.testing.assert_array_equal(track, ref_track)


def test_mf_with_white_noise_and_flat_prior_is_the_scaled_dp():
    """White noise: Lambda_k = s z / sigma^2 - s^2 / (2 sigma^2) in every case,
    and kappa = 0 makes every transition weigh log(1 / 2 pi); so the MF
    score is (s / sigma^2) DP + constant and both pick the same path."""
    rng = np.random.default_rng(11)
    z = rng.standard_normal((3, 6, 12, 10)).astype(np.float32)
    b = frames_batch(2.0 * z, gamma=(4.0, 0.0, 0.0))
    dp = DpTbd().run(b, DpTbd.Params())
    mf = DpTbdMf().run(b, DpTbdMf.Params(design_snr_db=3.0, turn_concentration=0.0))
    s, var, K = 2.0 * 10 ** (3 / 20), 4.0, 6
    expected = s / var * dp.score - K * s * s / (2 * var) + (K - 1) * LOG_UNIFORM_ANGLE
    np.testing.assert_allclose(mf.score, expected, rtol=1e-5, atol=1e-4)
    np.testing.assert_array_equal(mf.track, dp.track)


def test_single_frame():
    rng = np.random.default_rng(2)
    z = rng.standard_normal((2, 1, 5, 6)).astype(np.float32)
    b = frames_batch(z)
    for cls in (DpTbd, DpTbdMf):
        out = cls().run(b, cls.Params())
        flat = z[:, 0].reshape(2, -1).argmax(axis=1)
        np.testing.assert_array_equal(out.track[:, 0], np.stack(np.divmod(flat, 6), axis=1))


def test_non_finite_frames_are_rejected():
    z = np.zeros((1, 3, 4, 4), np.float32)
    z[0, 1, 2, 2] = np.nan
    for cls in (DpTbd, DpTbdMf):
        with pytest.raises(ValueError, match="finite"):
            cls().run(frames_batch(z), cls.Params())


@pytest.mark.parametrize("prior", ["von-mises", "laplace"])
@pytest.mark.parametrize("kappa", [0.0, 0.3, 2.0, 10.0, 60.0])
def test_turn_density_is_a_decreasing_density_on_the_circle(prior, kappa):
    total = scipy.integrate.quad(lambda t: math.exp(turn_log_density(t, prior, kappa)), -math.pi, math.pi,
                                 points=[0.0], limit=200)[0]
    assert total == pytest.approx(1.0, rel=1e-8)
    theta = np.linspace(0, math.pi, 50)
    lp = turn_log_density(theta, prior, kappa)
    assert np.all(np.diff(lp) <= 1e-12)
    np.testing.assert_allclose(turn_log_density(-theta, prior, kappa), lp)
    if kappa == 0.0:
        np.testing.assert_allclose(lp, LOG_UNIFORM_ANGLE)


def test_transition_weights_and_zero_displacement():
    q = 2
    disp = displacements(q)
    assert disp.shape == (25, 2) and tuple(disp[12]) == (0, 0)
    np.testing.assert_array_equal(disp[::-1], -disp)             # index of -d is D - 1 - j
    lp = transition_log_weights(q, "von-mises", 2.0)
    np.testing.assert_allclose(lp[12, :], LOG_UNIFORM_ANGLE)
    np.testing.assert_allclose(lp[:, 12], LOG_UNIFORM_ANGLE)
    np.testing.assert_allclose(lp, lp.T)                          # |theta| is symmetric
    straight = lp[13, 14]                                          # (0, 1) -> (0, 2): theta = 0
    assert straight == pytest.approx(turn_log_density(0.0, "von-mises", 2.0))
    assert lp[13, 11] == pytest.approx(turn_log_density(math.pi, "von-mises", 2.0))   # reversal
    assert turn_angle(np.array([1, 0]), np.array([0, 1])) == pytest.approx(math.pi / 2)
    assert turn_angle(np.array([1, 0]), np.array([-1, 0])) == pytest.approx(math.pi)


def test_conditional_llr_of_the_default_noise():
    """The numbers quoted in the DpTbdMf docstring."""
    gamma = np.asarray(scene(None, n=1, frames=4).scene.noise_autocovariance)[:3]
    llr = ConditionalLLR.from_autocovariance(gamma, 1.0)
    assert (llr.beta1, llr.beta2) == pytest.approx((1.544715, -0.711382), abs=1e-6)
    assert llr.var == pytest.approx(0.0915213, abs=1e-6)
    np.testing.assert_allclose(llr.c_frame2(), [1.0, 1.711382, -0.544715, 0.166667], atol=1e-6)
    assert llr.beta_first == pytest.approx(gamma[1])
    with pytest.raises(ValueError, match="singular"):
        ConditionalLLR.from_autocovariance((1.0, 1.0, 1.0), 1.0)


# ------------------------------------------------- ablation options (pre-whitening, priors, along-track)

def lag1_correlation(x):
    """Pooled lag-1 correlation over frames of (n, K, H, W) series."""
    x = np.asarray(x, float)
    return float((x[:, 1:] * x[:, :-1]).mean() / x.var())


def test_prewhiten_makes_the_ar_cells_white_with_unit_variance():
    from radarbench.methods.tbd.dp_tbd import prewhiten
    batch = scene(None, n=4, seed=11, frames=20)          # 4 x 20 x 32 x 32 null frames
    z = batch.z
    N = z[:, 1:].size                                      # 77 824 lag-1 pairs
    assert lag1_correlation(z) > 0.85                      # the raw AR(3) series is far from white
    eps = prewhiten(z, batch)
    # Under H0 the innovations are iid N(0, 1): the pooled lag-1 correlation has
    # standard error 1 / sqrt(N) and the sample variance sqrt(2 / N_all).
    assert abs(lag1_correlation(eps)) < 4.0 / math.sqrt(N)
    assert abs(eps.var() - 1.0) < 4.0 * math.sqrt(2.0 / eps.size)
    for k in range(4):                                     # the conditionally whitened first frames too
        assert abs(eps[:, k].var() - 1.0) < 4.0 * math.sqrt(2.0 / eps[:, k].size)


def test_prewhiten_of_white_noise_divides_by_sigma_and_default_is_unchanged():
    from radarbench.methods.tbd.dp_tbd import prewhiten
    batch = scene(6.0, n=2, seed=5, noise="white", frames=8)
    np.testing.assert_allclose(prewhiten(batch.z, batch), batch.z, rtol=1e-6)
    raw = DpTbd().run(batch, build_params(DpTbd.Params, {}))
    same = DpTbd().run(batch, build_params(DpTbd.Params, {"prewhiten": True}))
    np.testing.assert_allclose(raw.score, same.score, rtol=1e-5)


def test_concentration_zero_is_a_uniform_turn_prior():
    for prior in ("von-mises", "laplace"):
        lp = transition_log_weights(2, prior, 0.0)
        assert np.all(lp == LOG_UNIFORM_ANGLE)


@pytest.mark.parametrize("gamma", [(1.0, 0.903, 0.683), (2.0, -0.5, 0.3), (1.0, 0.0, 0.0)])
def test_along_track_term_is_the_3d_minus_2d_gaussian_log_ratio(gamma):
    from scipy.stats import multivariate_normal as mvn

    from radarbench.methods.tbd.dp_tbd import along_track_llr
    g = np.asarray(gamma)
    G3 = g[np.abs(np.subtract.outer(np.arange(3), np.arange(3)))]
    s = 1.7
    for v in ([0.3, -1.2, 2.0], [4.0, 4.0, 4.0], [-2.5, 0.1, 0.0], [1.0, 3.0, -3.0]):
        v = np.asarray(v)
        ratio = lambda mean: (mvn(mean * np.ones(3), G3).logpdf(v)               # noqa: E731
                              - mvn(mean * np.ones(2), G3[1:, 1:]).logpdf(v[1:]))
        assert along_track_llr(v, s, gamma) == pytest.approx(ratio(s) - ratio(0.0), rel=1e-9, abs=1e-9)
        two = lambda mean: (mvn(mean * np.ones(2), G3[:2, :2]).logpdf(v[:2])       # noqa: E731
                            - mvn(mean, g[0]).logpdf(v[1]))
        assert along_track_llr(v[:2], s, gamma) == pytest.approx(two(s) - two(0.0), rel=1e-9, abs=1e-9)
        one = mvn(s, g[0]).logpdf(v[0]) - mvn(0.0, g[0]).logpdf(v[0])
        assert along_track_llr(v[:1], s, gamma) == pytest.approx(one, rel=1e-9, abs=1e-9)


def brute_force_along_track(z, gamma, s, lp, q):
    """(best score, best track) by enumerating every path on a tiny scene."""
    from radarbench.methods.tbd.dp_tbd import along_track_llr
    K, H, W = z.shape
    disp = displacements(q)
    D = len(disp)
    best, best_track = -np.inf, None
    for x0 in np.ndindex(H, W):
        for ds in np.ndindex(*([D] * (K - 1))):
            cells = [np.array(x0)]
            for j in ds:
                cells.append(cells[-1] + disp[j])
            cells = np.array(cells)
            if cells.min() < 0 or (cells[:, 0] >= H).any() or (cells[:, 1] >= W).any():
                continue
            vals = z[np.arange(K), cells[:, 0], cells[:, 1]].astype(float)
            total = along_track_llr(vals[:1], s, gamma) + along_track_llr(vals[1::-1], s, gamma) + LOG_UNIFORM_ANGLE
            for k in range(2, K):
                total += along_track_llr(vals[k:k - 3 if k > 2 else None:-1], s, gamma) + lp[ds[k - 2], ds[k - 1]]
            if total > best:
                best, best_track = total, cells
    return best, best_track


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_along_track_kernel_equals_brute_force_on_tiny_scenes(seed):
    rng = np.random.default_rng(seed)
    gamma = (1.0, 0.903, 0.683)
    K, H = 4, 4
    z = rng.normal(size=(1, K, H, H)).astype(np.float32)
    z[0, np.arange(K), [0, 1, 2, 3], [0, 1, 1, 2]] += 2.0            # a target, so the best path is not noise
    batch = frames_batch(z, gamma)
    params = build_params(DpTbdMf.Params, {"max_speed_m_s": 100.0, "likelihood": "along-track"})
    out = DpTbdMf().run(batch, params)
    s = 10.0 ** (params.design_snr_db / 20.0)
    lp = transition_log_weights(1, params.turn_prior, params.turn_concentration).astype(np.float32)
    best, track = brute_force_along_track(z[0], gamma, s, lp.astype(float), 1)
    assert out.score[0] == pytest.approx(best, rel=1e-5, abs=1e-4)
    np.testing.assert_array_equal(out.track[0], track)


def test_along_track_differs_from_per_cell_and_default_is_per_cell():
    batch = scene(0.0, n=1, seed=4, cells=24, frames=8)
    per_cell = DpTbdMf().run(batch, build_params(DpTbdMf.Params, {}))
    explicit = DpTbdMf().run(batch, build_params(DpTbdMf.Params, {"likelihood": "per-cell"}))
    along = DpTbdMf().run(batch, build_params(DpTbdMf.Params, {"likelihood": "along-track"}))
    np.testing.assert_array_equal(per_cell.score, explicit.score)
    assert not np.allclose(per_cell.score, along.score)


@pytest.mark.parametrize("prewhiten", [False, True])
@pytest.mark.parametrize("n", [1, 3])
def test_the_bench_perf_peer_gives_the_methods_output(n, prewhiten):
    """``dp-tbd``'s ``bench perf`` reference (the vectorised NumPy twin) on one trial and on a
    batch, on the frames or their pre-whitened innovations: the method's scores and tracks, bit for bit."""
    method = get_method("dp-tbd")()
    b, params = scene(6.0, n=n), build_params(method.Params, {"prewhiten": prewhiten})
    fast, peer = method.run(b, params), method.reference_run(b, params)
    np.testing.assert_array_equal(fast.score, peer.score)
    np.testing.assert_array_equal(fast.track, peer.track)
