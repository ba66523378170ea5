"""Methods dp-tbd and dp-tbd-mf: interface, window, turn prior, LLR, agreement with the reference."""

import math

import numpy as np
import pytest
import scipy.integrate

from bench.core import TBD, Batch, TBDOutput
from bench.params import build_params
from bench.registry import get_method
from bench.rng import TrialRNG
from methods._tbd_reference import reference_dp_tbd
from methods.dp_tbd import (
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
from scenarios.tbd_grid import TbdGrid


def scene(snr_db, n=2, seed=3, **values):
    params = build_params(TbdGrid.Params, {"cells": 32, **values})
    return TbdGrid().generate(params, snr_db, n, TrialRNG(seed, 0, 7, range(n)))


def frames_batch(z, gamma=(1.0, 0.0, 0.0), cell_m=100.0, period_s=1.0):
    z = np.asarray(z, np.float32)
    n, K, H, W = z.shape
    meta = {"grid": {"rows": H, "cols": W, "cell_m": cell_m, "x_min_m": 0.0, "y_min_m": 0.0},
            "frame_period_s": period_s, "noise_std": math.sqrt(gamma[0]),
            "noise_autocovariance": np.asarray(gamma, float)}
    return Batch(t=period_s * np.arange(K), truth=np.zeros((n, K, 4)), z=z, meta=meta, trials=np.arange(n))


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
    cells = scene(6.0, n=1).meta["target_cells"][0]
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
    off = np.abs(out.track - b.meta["target_cells"]).max(axis=-1)
    assert np.all((off <= 1).sum(axis=1) >= 18)


def test_mf_finds_a_weak_target_in_correlated_noise():
    """The whitening LLR sees a target the raw-merit DP cannot: at 0 dB in the
    default AR(3) noise the MF track sits on the target."""
    b = scene(0.0, n=2)
    out = DpTbdMf().run(b, DpTbdMf.Params())
    off = np.abs(out.track - b.meta["target_cells"]).max(axis=-1)
    assert np.all((off <= 1).sum(axis=1) >= 15)


@pytest.mark.parametrize("q", [1, 2, 3])
def test_numba_dp_tbd_equals_scipy_reference_on_scene_frames(q):
    b = scene(4.0, n=2, frames=8)
    out = DpTbd().run(b, DpTbd.Params(max_speed_m_s=100.0 * q))
    score, track = reference_dp_tbd(b.z, q)
    np.testing.assert_array_equal(out.score, score)
    np.testing.assert_array_equal(out.track, track)


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
    gamma = np.asarray(scene(None, n=1, frames=4).meta["noise_autocovariance"])[:3]
    llr = ConditionalLLR.from_autocovariance(gamma, 1.0)
    assert (llr.beta1, llr.beta2) == pytest.approx((1.544715, -0.711382), abs=1e-6)
    assert llr.var == pytest.approx(0.0915213, abs=1e-6)
    np.testing.assert_allclose(llr.c_frame2(), [1.0, 1.711382, -0.544715, 0.166667], atol=1e-6)
    assert llr.beta_first == pytest.approx(gamma[1])
    with pytest.raises(ValueError, match="singular"):
        ConditionalLLR.from_autocovariance((1.0, 1.0, 1.0), 1.0)
