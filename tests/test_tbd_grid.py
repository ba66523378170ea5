"""Scenario tbd-grid: geometry, noise model, SNR definition, null, per-trial streams."""

import dataclasses

import numpy as np
import pytest

from radarbench.bench.core import TBD, SceneError
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.registry import get_scenario
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.tasks.tbd import Grid, TBDScene
from radarbench.models.ar_noise import ar_autocovariance, ar_innovation_std, ar_roots, stationary_predictors
from radarbench.scenarios.tbd_grid import EDGE_MARGIN_CELLS, TbdGrid, generate_noise, scene_geometry, true_track

DEFAULT = build_params(TbdGrid.Params, {})


def make(snr_db, n=3, seed=1, trials=None, **values):
    params = build_params(TbdGrid.Params, {"cells": 32, **values})
    rng = TrialRNG(seed=seed, domain=0, scenario_key=0, trials=range(n) if trials is None else trials)
    return TbdGrid().generate(params, snr_db, rng.n, rng)


def test_registered():
    assert get_scenario("tbd-grid") is TbdGrid
    assert TbdGrid.tasks == (TBD,)
    assert TbdGrid.summary().startswith("DP track-before-detect surveillance scene")
    assert (DEFAULT.cells, DEFAULT.frames, DEFAULT.noise, DEFAULT.ar_coefficients) == \
        (500, 20, "ar", (-2.0, 1.7, -0.64))


def test_shapes_and_scene():
    b = make(6.0, n=3, frames=12)
    assert b.t.shape == (12,) and np.allclose(np.diff(b.t), 1.0)
    assert b.z.shape == (3, 12, 32, 32) and b.z.dtype == np.float32
    assert b.truth.shape == (3, 12, 4)
    np.testing.assert_array_equal(b.trials, np.arange(3))
    sc = b.scene
    assert type(sc) is TBDScene and type(sc.grid) is Grid
    assert set(sc.grid.as_dict()) == {"rows", "cols", "cell_m", "x_min_m", "y_min_m"}
    assert (sc.grid.rows, sc.grid.cols, sc.grid.cell_m) == (32, 32, 100.0)
    cells = sc.target_cells
    assert cells.shape == (3, 12, 2) and np.issubdtype(cells.dtype, np.integer)
    assert sc.target_present is True
    assert sc.position_index == (0, 1)
    assert sc.hit_tolerance_cells == 1 and sc.frame_period_s == 1.0
    assert sc.ar_coefficients == DEFAULT.ar_coefficients
    np.testing.assert_allclose(sc.realised_snr_db, 6.0)
    gamma = sc.noise_autocovariance
    assert gamma.shape == (12,) and gamma[0] == pytest.approx(sc.noise_std ** 2)
    np.testing.assert_allclose(gamma[1:4], [0.902613, 0.682898, 0.471354], atol=1e-6)
    assert "stationary" in sc.snr_definition


def _scene_fields(b) -> dict:
    return {f.name: getattr(b.scene, f.name) for f in dataclasses.fields(b.scene)}


def test_a_misspelt_or_misshapen_scene_field_fails_naming_it():
    """The scene is built in generate(): a misspelt keyword, a missing field or
    a wrong shape fails there, naming the field."""
    b = make(6.0, n=2, frames=10)
    fields = _scene_fields(b)
    TBDScene(**fields)                                                  # as generated: fine
    with pytest.raises(TypeError, match="target_cell"):
        TBDScene(**{k: v for k, v in fields.items() if k != "target_cells"}, target_cell=fields["target_cells"])
    with pytest.raises(TypeError, match="frame_period_s"):
        TBDScene(**{k: v for k, v in fields.items() if k != "frame_period_s"})
    for field, bad in (("target_cells", fields["target_cells"].astype(float)), ("noise_std", 0.0),
                       ("grid", fields["grid"].as_dict()), ("ar_coefficients", [-2.0, 1.7, -0.64]),
                       ("hit_tolerance_cells", -1), ("noise_autocovariance", np.ones((2, 3)))):
        with pytest.raises(SceneError, match=f"TBDScene.{field}: expected") as err:
            TBDScene(**{**fields, field: bad})
        assert err.value.field == field
    with pytest.raises(SceneError, match="Grid.cell_m: expected a number > 0"):
        Grid(rows=32, cols=32, cell_m=0.0, x_min_m=0.0, y_min_m=0.0)
    for field, bad in (("target_cells", fields["target_cells"][:, :4]), ("amplitude", fields["amplitude"][:1]),
                       ("grid", dataclasses.replace(fields["grid"], rows=16))):
        with pytest.raises(SceneError, match=f"TBDScene.{field}"):
            dataclasses.replace(b, scene=TBDScene(**{**fields, field: bad}))


def test_cell_convention_matches_truth():
    """The target cell contains the true position: centre within half a cell."""
    b = make(6.0, n=1)
    g = b.scene.grid.as_dict()
    rc = b.scene.target_cells[0]
    centre_x = g["x_min_m"] + (rc[:, 1] + 0.5) * g["cell_m"]
    centre_y = g["y_min_m"] + (rc[:, 0] + 0.5) * g["cell_m"]
    assert np.all(np.abs(centre_x - b.truth[0, :, 0]) <= 0.5 * g["cell_m"])
    assert np.all(np.abs(centre_y - b.truth[0, :, 1]) <= 0.5 * g["cell_m"])


def test_paper_scale_geometry():
    truth, grid, cells = scene_geometry(DEFAULT)
    assert (grid["x_min_m"], grid["y_min_m"], grid["rows"]) == (150e3, 120e3, 500)
    np.testing.assert_allclose(truth[0], [180e3, 160e3, 100.0, 100.0])
    np.testing.assert_array_equal(cells[0], [400, 300])             # row <-> y, col <-> x
    np.testing.assert_array_equal(cells[:10] - cells[0], np.arange(10)[:, None] * [1, 1])


@pytest.mark.parametrize("side", [24, 32, 40, 64, 200, 500])
def test_true_track_stays_inside_every_grid(side):
    p = build_params(TbdGrid.Params, {"cells": side})
    cells = scene_geometry(p)[2]
    assert cells.min() >= EDGE_MARGIN_CELLS and cells.max() <= side - 1 - EDGE_MARGIN_CELLS
    # the same cell path, relative to its start, at every grid size
    np.testing.assert_array_equal(cells - cells[0], scene_geometry(DEFAULT)[2] - scene_geometry(DEFAULT)[2][0])


def test_too_small_grid_is_rejected_naming_cells():
    with pytest.raises(ConfigError) as err:
        build_params(TbdGrid.Params, {"cells": 16})
    assert err.value.field == "cells" and "needs cells >= 24" in str(err.value)


def test_turn_is_clockwise_at_the_given_rate():
    truth = true_track(20, 1.0, 0.35)
    heading = np.unwrap(np.arctan2(truth[:, 3], truth[:, 2]))
    dh = np.diff(heading)                                  # change on the transition into frame k
    np.testing.assert_allclose(dh[9:14], -0.35, atol=1e-12)     # frames 11..15 (1-based): clockwise
    np.testing.assert_allclose(np.delete(dh, np.s_[9:14]), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.hypot(truth[:, 2], truth[:, 3]), 100 * np.sqrt(2), rtol=1e-12)
    # positions follow the velocities of the exact constant-turn motion
    assert np.all(np.diff(truth[:, 0]) > 0)


def test_paper_printed_ar_set_is_rejected_with_the_reason():
    with pytest.raises(ConfigError) as err:
        build_params(TbdGrid.Params, {"ar_coefficients": [-2.0, 1.7, 0.64]})
    assert err.value.field == "ar_coefficients"
    assert "explosive" in str(err.value) and "flips the sign of a3" in str(err.value)


def test_snr_definition_and_target_amplitude():
    """z(snr) - z(null) is exactly s in the target cells (same noise: common
    random numbers) and 0 elsewhere; s = sigma 10^(snr/20) with sigma = 1."""
    null, sig = make(None, n=2), make(9.0, n=2)
    diff = sig.z.astype(np.float64) - null.z
    s = 10 ** (9.0 / 20)
    cells = sig.scene.target_cells
    n_idx, k_idx = np.meshgrid(range(2), range(DEFAULT.frames), indexing="ij")
    np.testing.assert_allclose(diff[n_idx, k_idx, cells[..., 0], cells[..., 1]], s, rtol=1e-6)
    diff[n_idx, k_idx, cells[..., 0], cells[..., 1]] = 0.0
    assert np.all(np.abs(diff) < 1e-5)
    np.testing.assert_allclose(sig.scene.amplitude, s)


def test_null_has_no_target():
    b = make(None, n=2)
    assert b.scene.target_cells is None and b.scene.target_present is False
    assert np.all(np.isnan(b.scene.realised_snr_db))
    assert np.all(b.scene.amplitude == 0)
    np.testing.assert_array_equal(b.truth, make(3.0, n=2).truth)      # truth kept for reference


def test_swerling1_amplitude():
    """A_k = s sqrt(E_k), E_k ~ Exp(1) per frame: the realised SNR is that of
    the trial's mean power; over many frames E[A^2] = s^2 (the mean of N
    Exp(1) draws has standard error 1 / sqrt(N); 5 standard errors)."""
    b = make(3.0, n=40, amplitude="swerling1", cells=24)
    s2 = 10 ** 0.3
    amp = b.scene.amplitude
    assert amp.shape == (40, 20) and np.all(amp > 0) and np.std(amp) > 0
    np.testing.assert_allclose(b.scene.realised_snr_db, 10 * np.log10(np.mean(amp ** 2, axis=1)))
    assert abs(np.mean(amp ** 2) / s2 - 1.0) < 5 / np.sqrt(amp.size)
    # the same noise as with a constant amplitude: only the target cells differ
    const = make(3.0, n=40, cells=24)
    assert np.count_nonzero(b.z != const.z) <= 40 * 20
    off_target = np.ones(b.z.shape, bool)
    cells = b.scene.target_cells
    n_idx, k_idx = np.meshgrid(range(40), range(20), indexing="ij")
    off_target[n_idx, k_idx, cells[..., 0], cells[..., 1]] = False
    np.testing.assert_array_equal(b.z[off_target], const.z[off_target])


def test_trial_is_identical_whatever_its_batch():
    whole = make(4.0, n=4)
    alone = make(4.0, trials=[2])
    part = make(4.0, trials=[1, 3])
    np.testing.assert_array_equal(whole.z[2], alone.z[0])
    np.testing.assert_array_equal(whole.z[[1, 3]], part.z)
    np.testing.assert_array_equal(whole.scene.realised_snr_db[[1, 3]], part.scene.realised_snr_db)


def test_white_noise_option():
    b = make(None, n=4, noise="white")
    assert b.scene.ar_coefficients is None
    np.testing.assert_array_equal(b.scene.noise_autocovariance, np.r_[1.0, np.zeros(19)])
    v = b.z.astype(np.float64)
    lag1 = np.mean(v[:, 1:] * v[:, :-1])
    assert abs(lag1) < 5 / np.sqrt(v[:, 1:].size)            # white: uncorrelated over frames
    assert abs(np.mean(v ** 2) - 1.0) < 5 * np.sqrt(2 / v.size)


def test_paper_scale_generation_is_float32_and_stationary():
    b = TbdGrid().generate(DEFAULT, None, 1, TrialRNG(5, 0, 0, [0]))
    assert b.z.shape == (1, 20, 500, 500) and b.z.dtype == np.float32
    v = b.z[0].reshape(20, -1).astype(np.float64)
    # per-frame variance, 250 000 cells each: standard error sqrt(2 / N)
    assert np.all(np.abs(v.var(axis=1) - 1.0) < 5 * np.sqrt(2 / v.shape[1]))


def numpy_noise(gen, shape_hw, frames, a, sigma):
    """The noise law of ``generate_noise`` written out in plain numpy: e =
    gen.standard_normal((K, H, W)), then v_k = sqrt(nu_k) e_k + sum phi_k v_(k-j)
    for k < P and v_k = sigma_w e_k - sum a_i v_(k-i) from k = P on, in float64,
    each lag subtracted in turn (the compiled kernel's order of operations)."""
    e = gen.standard_normal((frames, *shape_hw))
    if not a:
        return (sigma * e).astype(np.float32)
    P = len(a)
    steps = [(-phi, np.sqrt(nu)) for phi, nu in stationary_predictors(a, sigma)]
    v = np.empty_like(e)
    for k in range(frames):
        coeffs, scale = steps[k] if k < P else (np.asarray(a), ar_innovation_std(a, sigma ** 2))
        v[k] = scale * e[k]
        for i, c in enumerate(coeffs, start=1):
            v[k] -= c * v[k - i]
    return v.astype(np.float32)


@pytest.mark.parametrize("a", [None, (-2.0, 1.7, -0.64), (-0.5,), (-0.5, 0.1, 0.05, -0.02, 0.01)])
def test_noise_is_the_trials_numpy_normals_through_the_recursion(a):
    """The compiled path draws exactly each trial's numpy standard normals, in
    (frame, row, column) order, and applies the documented recursion: equal,
    bit for bit, to the numpy transcription above; each trial's Generator ends
    in the same state (what it draws next, the Swerling powers, is unchanged)."""
    trials = [0, 3, 11]
    z = generate_noise(TrialRNG(4, 0, 2, trials), (9, 13), 7, a, 1.3)
    ref_rng, rng = TrialRNG(4, 0, 2, trials), TrialRNG(4, 0, 2, trials)
    generate_noise(rng, (9, 13), 7, a, 1.3)
    for t, gen in enumerate(ref_rng.generators):
        np.testing.assert_array_equal(z[t], numpy_noise(gen, (9, 13), 7, a, 1.3))
        assert gen.bit_generator.state == rng.generators[t].bit_generator.state


def _lag_product_variance(gamma, h, m):
    """Var of (1/m) sum_(k<m) v_k v_(k+h) in one cell, v zero-mean Gaussian
    stationary with autocovariance gamma (Isserlis: Cov(v_k v_(k+h), v_l v_(l+h))
    = gamma(k-l)^2 + gamma(k-l+h) gamma(k-l-h))."""
    d = np.abs(np.subtract.outer(np.arange(m), np.arange(m)))
    g = np.r_[gamma, np.zeros(2 * len(gamma))]
    return float(np.sum(g[d] ** 2 + g[np.abs(d + h)] * g[np.abs(d - h)])) / m ** 2


def test_ar_noise_has_the_models_variance_and_autocorrelations():
    """Fixed seed, 8 trials x 150 x 150 independent cells x 20 frames. (1) the
    lag-h covariance pooled over frames (per cell, then averaged over cells)
    equals gamma(h) of the AR model (gamma(0) = 1: variance 1, lags 1..3: the
    autocorrelations) within 5 standard errors of its exact Gaussian sampling
    law; (2) every frame pair (k, k + h), including the start-up frames,
    matches gamma(h) within 5 standard errors, sqrt((gamma(0)^2 +
    gamma(h)^2) / cells): stationary from frame 0."""
    b = make(None, n=8, cells=150)
    v = b.z.astype(np.float64).transpose(1, 0, 2, 3).reshape(DEFAULT.frames, -1)   # (K, cells)
    K, cells = v.shape
    gamma = ar_autocovariance(DEFAULT.ar_coefficients, K - 1)
    for h in range(4):
        per_pair = np.mean(v[:K - h] * v[h:], axis=1)                            # (K - h,)
        se_pooled = np.sqrt(_lag_product_variance(gamma, h, K - h) / cells)
        assert abs(per_pair.mean() - gamma[h]) < 5 * se_pooled, (h, per_pair.mean(), gamma[h])
        se_pair = np.sqrt((gamma[0] ** 2 + gamma[h] ** 2) / cells)
        assert np.all(np.abs(per_pair - gamma[h]) < 5 * se_pair), (h, per_pair - gamma[h])
