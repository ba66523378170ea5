"""Method pf-tbd: the kernel against its NumPy reference, existence under H0 and H1,
convergence of its track to the DP's as particles grow, the counter-based draws."""

import math

import numpy as np
import pytest

from radarbench.bench.core import TBD
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.registry import get_method
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.methods.tbd import pf_kernels
from radarbench.methods.tbd.dp_tbd import DpTbd
from radarbench.methods.tbd.pf_tbd import PfTbd, particle_split, residual_predictors
from radarbench.scenarios.tbd_grid import TbdGrid


def scene(snr_db, n=3, seed=11, **values):
    params = build_params(TbdGrid.Params, {"cells": 32, **values})
    return TbdGrid().generate(params, snr_db, n, TrialRNG(seed, 0, 7, range(n)))


def pf(**values):
    return build_params(PfTbd.Params, values)


def existence(score):
    """P(E_(K-1) = 1 | Z) from the score, the log-odds."""
    return 1.0 / (1.0 + np.exp(-np.asarray(score)))


def test_registered_with_the_tbd_task_and_its_parameters_checked():
    assert get_method("pf-tbd") is PfTbd and PfTbd.task == TBD
    assert math.isnan(PfTbd().nominal_threshold(pf(), 1e-3, scene(None, n=1, frames=4)))
    with pytest.raises(ConfigError, match="snr_max_db"):
        pf(snr_min_db=5.0, snr_max_db=5.0)
    with pytest.raises(ConfigError, match="particles"):
        pf(particles=5)
    assert particle_split(pf(particles=10, birth_fraction=0.99)) == (9, 1)
    assert particle_split(pf(particles=1000, birth_fraction=0.25)) == (250, 750)


def test_residual_predictors_of_white_and_ar_noise():
    betas, var = residual_predictors(scene(None, n=1, noise="white"))
    assert np.array_equal(betas, np.zeros((3, 2))) and np.allclose(var, 1.0)
    betas, var = residual_predictors(scene(None, n=1))
    # the default AR(3): beta = (1.545, -0.711), sigma_c^2 = 0.0915 (methods.tbd.dp_tbd.DpTbdMf)
    assert betas[2] == pytest.approx([1.545, -0.711], abs=1e-3) and var[2] == pytest.approx(0.0915, abs=1e-4)
    assert betas[0].tolist() == [0.0, 0.0] and var[0] == pytest.approx(1.0) and betas[1, 1] == 0.0


@pytest.mark.parametrize("values", [{}, {"birth_proposal": "uniform"}, {"resampling": "stratified"},
                                    {"birth_threshold": 9.0, "accel_std_m_s2": 0.0, "amplitude_walk_db": 0.0}])
@pytest.mark.parametrize("noise", ["ar", "white"])
def test_kernel_equals_the_numpy_per_trial_loop(values, noise):
    """Two implementations of the same equations on the same draws: the numba kernel (a
    scalar loop over particles) and the reference (NumPy over particles, a loop over
    trials and frames). Transcendentals may round differently in numba and NumPy, so
    the score, a sum over ~10^3 particle terms of magnitude <= 10^3, is compared to
    1e-9 relative; the tracks (cells) exactly."""
    batch = scene(4.0, n=3, frames=8, noise=noise)
    params = pf(particles=300, **values)
    fast, slow = PfTbd().run(batch, params), PfTbd().reference_run(batch, params)
    np.testing.assert_allclose(fast.score, slow.score, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(fast.track, slow.track)


def test_existence_stays_low_under_the_null_and_high_under_a_strong_target():
    """Under H0 the data pull the existence probability from the chain's stationary
    P_b / (P_b + P_d) = 0.5 towards 0; a 12 dB target (per-frame LLR ~ 10^2 nats in the
    residual) drives it to 1. Deterministic (fixed seeds); the margins are wide."""
    params = pf(particles=2000)
    null = existence(PfTbd().run(scene(None, n=20, seed=2), params).score)
    strong = existence(PfTbd().run(scene(12.0, n=20, seed=2), params).score)
    assert null.max() < 0.1
    assert strong.min() > 0.99


def test_track_converges_to_the_dp_track_as_particles_grow():
    """High SNR (15 dB, straight track, white noise): the DP's backtracked track is the
    true cell path. The PF's track is the cell of its posterior mean position; the
    posterior of the position within the true cell is spread over that cell, so its
    mean can fall in a neighbour near a cell edge: a 1-cell Chebyshev tolerance. With
    the particles, the mean distance to the DP's track must not grow, and at 20 000
    particles every frame after the first (the first has only births, uniform over the
    cells above the threshold) is within 1 cell."""
    batch = scene(15.0, n=6, seed=5, noise="white", turn_rate_rad_s=0.0)
    dp = DpTbd().run(batch, DpTbd.Params()).track
    assert np.array_equal(dp, batch.scene.target_cells)
    distance = {}
    for n_particles in (200, 2000, 20000):
        track = PfTbd().run(batch, pf(particles=n_particles)).track
        distance[n_particles] = np.abs(track - dp).max(axis=-1)
    means = [distance[n].mean() for n in (200, 2000, 20000)]
    assert means[2] <= means[1] <= means[0], means
    assert distance[20000][:, 1:].max() <= 1


def test_draws_are_uniform_and_shared_by_kernel_and_reference():
    """The counter-based uniforms (SplitMix64 outputs) are the same in NumPy and numba,
    lie in (0, 1) and are uniform: a chi-square test on 10 bins of 10^5 draws
    (9 degrees of freedom: 27.9 is the 0.999 quantile)."""
    key = pf_kernels.trial_keys(3, [17])[0]
    index = np.arange(100_000, dtype=np.uint64)
    u = pf_kernels.draws(key, 4, index, 2, 100_000)
    assert 0.0 < u.min() and u.max() < 1.0
    counts = np.bincount((u * 10).astype(int), minlength=10)
    chi2 = ((counts - 10_000) ** 2 / 10_000).sum()
    assert chi2 < 27.9
    compiled = [pf_kernels._draw(key, 4, int(i), 2, 100_000) for i in (0, 1, 99_999)]
    assert compiled == [u[0], u[1], u[99_999]]
    assert len(set(pf_kernels.trial_keys(0, range(1000)).tolist())) == 1000
