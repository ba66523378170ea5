"""Scenario cv-turn-cv: shapes, the maneuver innovation, the SNR definition."""

import dataclasses

import numpy as np
import pytest
import scipy.stats

from radarbench.bench.core import SceneError
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.registry import get_scenario
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.tasks.detection import DetectionScene
from radarbench.models.kalman import LinearGaussianFilter, innovations, steady_state
from radarbench.scenarios.cv_turn_cv import (CvTurnCv, cv_model, deterministic_track,
                                  filter_response, maneuver_power)

DEFAULT = build_params(CvTurnCv.Params, {})


def make(snr_db, n=20, seed=1, **values):
    params = build_params(CvTurnCv.Params, values)
    rng = TrialRNG(seed=seed, domain=0, scenario_key=0, trials=range(n))
    return CvTurnCv().generate(params, snr_db, n, rng)


def test_registered():
    assert get_scenario("cv-turn-cv") is CvTurnCv
    assert CvTurnCv.summary().startswith("Constant velocity, coordinated turn")


def test_shapes_and_scene():
    b = make(10.0, n=7)
    K = DEFAULT.steps
    assert b.t.shape == (K,) and b.truth.shape == (7, K, 4) and b.z.shape == (7, K, 2)
    sc = b.scene
    assert type(sc) is DetectionScene
    assert isinstance(sc.reference_filter, LinearGaussianFilter)
    assert sc.reference_filter.x0.shape == (7, 4) and sc.reference_filter.P0.shape == (4, 4)
    assert sc.realised_snr_db.shape == (7,)
    assert sc.measurements_xy is None                     # z is already the plane position
    assert sc.onset_step == 80 and sc.offset_step == 120 and sc.null_onset_step == 80
    assert sc.detect_window_steps == 40 and sc.warmup_steps == 10
    assert sc.position_index == (0, 2)
    assert isinstance(sc.snr_definition, str) and "S_11" in sc.snr_definition
    np.testing.assert_array_equal(b.trials, np.arange(7))
    assert np.all(np.isfinite(b.z))


def _scene_fields(b) -> dict:
    sc = b.scene
    return {"onset_step": sc.onset_step, "null_onset_step": sc.null_onset_step, "offset_step": sc.offset_step,
            "detect_window_steps": sc.detect_window_steps, "warmup_steps": sc.warmup_steps,
            "reference_filter": sc.reference_filter, "snr_definition": sc.snr_definition,
            "realised_snr_db": sc.realised_snr_db, "position_index": sc.position_index}


def test_a_misspelt_or_missing_scene_field_fails_naming_it():
    """The scene is built in generate(): a misspelt keyword, a missing field or
    a bad value fails there, naming the field."""
    fields = _scene_fields(make(10.0, n=3))
    DetectionScene(**fields)                                            # as generated: fine
    with pytest.raises(TypeError, match="onset_stp"):
        DetectionScene(**{**fields, "onset_stp": 80})
    missing = {k: v for k, v in fields.items() if k != "detect_window_steps"}
    with pytest.raises(TypeError, match="detect_window_steps"):
        DetectionScene(**missing)
    for field, bad in (("detect_window_steps", 0), ("onset_step", -1), ("warmup_steps", 2.5),
                       ("onset_step", np.zeros((3, 2), int)), ("realised_snr_db", np.zeros((3, 1)))):
        with pytest.raises(SceneError, match=f"DetectionScene.{field}: expected") as err:
            DetectionScene(**{**fields, field: bad})
        assert err.value.field == field


def test_a_scene_that_does_not_fit_the_batch_names_the_field():
    b = make(10.0, n=3)
    fields = _scene_fields(b)
    with pytest.raises(SceneError, match=r"DetectionScene.realised_snr_db: expected \(3,\)"):
        dataclasses.replace(b, scene=DetectionScene(**{**fields, "realised_snr_db": np.zeros(4)}))
    with pytest.raises(SceneError, match="DetectionScene.onset_step"):
        dataclasses.replace(b, scene=DetectionScene(**{**fields, "onset_step": np.array([80, 90, 95, 99])}))
    with pytest.raises(SceneError, match="DetectionScene.position_index"):
        dataclasses.replace(b, scene=DetectionScene(**{**fields, "position_index": (0, 4)}))


def test_deterministic_given_rng():
    a, b = make(5.0, n=4), make(5.0, n=4)
    np.testing.assert_array_equal(a.z, b.z)
    np.testing.assert_array_equal(a.scene.reference_filter.x0, b.scene.reference_filter.x0)


def test_maneuver_innovation_starts_at_onset():
    nu_m = filter_response(cv_model(DEFAULT.dt_s, 1.0, DEFAULT.tracking_index),
                           deterministic_track(DEFAULT, turn=True))
    assert np.max(np.abs(nu_m[:DEFAULT.onset_step])) < 1e-9
    assert np.linalg.norm(nu_m[DEFAULT.onset_step]) > 1.0
    assert maneuver_power(DEFAULT) > 0


def test_gain_independent_of_noise_level():
    K1 = steady_state(cv_model(1.0, 1.0, 0.1))[3]
    K2 = steady_state(cv_model(1.0, 37.0, 0.1))[3]
    np.testing.assert_allclose(K1, K2, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("snr_db", [0.0, 10.0])
def test_noise_innovation_power_matches_S(snr_db):
    """Pooled over trials and turn steps, the noise part of the innovation has
    power S_11, so the realised SNR matches the requested one.

    Each whitened noise component is N(0, 1), independent over components,
    steps and trials, so the pooled power / S_11 is chi2(N) / N with
    N = m * turn_steps * n; the tolerance is its 1e-6 two-sided quantile in dB.
    """
    n, p = 400, DEFAULT
    b = make(snr_db, n=n, seed=2004)
    nu = innovations(b.scene.reference_filter, b.z).nu
    nu_m = filter_response(b.scene.reference_filter.model, deterministic_track(p, turn=True))
    turn = slice(p.onset_step, p.onset_step + p.turn_steps)
    power = np.mean((nu - nu_m)[:, turn] ** 2)
    snr = 10 * np.log10(maneuver_power(p) / power)
    N = 2 * p.turn_steps * n
    lo, hi = scipy.stats.chi2.ppf([1e-6, 1 - 1e-6], N) / N
    assert -10 * np.log10(hi) < snr - snr_db < -10 * np.log10(lo)
    S11 = steady_state(b.scene.reference_filter.model)[2][0, 0]
    assert lo < power / S11 < hi
    # the per-trial realised SNR agrees with the pooled one on average
    assert abs(np.mean(b.scene.realised_snr_db) - snr_db) < 0.5


def test_null_has_no_turn():
    b0 = make(None, n=5, process_noise=False)
    assert b0.scene.onset_step is None and b0.scene.offset_step is None
    assert b0.scene.null_onset_step == DEFAULT.onset_step
    assert np.all(np.isnan(b0.scene.realised_snr_db))
    np.testing.assert_allclose(b0.truth[..., 2:], 0.0, atol=1e-9)       # y, vy stay 0
    np.testing.assert_allclose(b0.truth[..., 1], DEFAULT.speed_m_s)


def test_null_and_alternative_share_noise():
    """Null noise is the 0 dB level, so 0 dB minus null is the turn alone."""
    alt, null = make(0.0, n=5), make(None, n=5)
    diff = alt.truth - null.truth
    turn = deterministic_track(DEFAULT, True) - deterministic_track(DEFAULT, False)
    np.testing.assert_allclose(diff, np.broadcast_to(turn, diff.shape), atol=1e-6)
    np.testing.assert_allclose(alt.z - null.z, diff[..., [0, 2]], atol=1e-6)
    np.testing.assert_array_equal(alt.scene.reference_filter.model.R, null.scene.reference_filter.model.R)


@pytest.mark.parametrize("values, field", [
    ({"turn_rate_deg_s": 0.0}, "turn_rate_deg_s"),
    ({"onset_step": 150}, "turn_steps"),
    ({"warmup_steps": 80}, "warmup_steps"),
    ({"detect_window_steps": 100}, "detect_window_steps"),
    ({"steps": 1}, "steps"),
    ({"dt_s": 0}, "dt_s"),
    ({"tracking_index": -1.0}, "tracking_index"),
    ({"process_noise": 1}, "process_noise"),
])
def test_bad_params_name_the_field(values, field):
    with pytest.raises(ConfigError) as err:
        build_params(CvTurnCv.Params, values)
    assert err.value.field == field


def test_onset_jitter_draws_one_onset_per_trial_shared_by_every_snr_and_the_null():
    """Each trial's onset is uniform on onset_step .. onset_step + jitter, from the
    trial's own stream: the same at every SNR level and under the null (common
    random numbers), and spread over the whole range."""
    jitter, n = 15, 400
    onsets = [np.asarray(make(snr, n=n, onset_jitter_steps=jitter).scene.null_onset_step) for snr in (-5.0, 10.0, None)]
    np.testing.assert_array_equal(onsets[0], onsets[1])
    np.testing.assert_array_equal(onsets[0], onsets[2])
    o = onsets[0]
    assert o.shape == (n,) and o.min() >= DEFAULT.onset_step and o.max() <= DEFAULT.onset_step + jitter
    # uniform on 16 values: each value's count is Binomial(400, 1/16) (mean 25, sd 4.8)
    counts = np.bincount(o - DEFAULT.onset_step, minlength=jitter + 1)
    assert counts.min() > 5 and counts.max() < 45
    # the truth turns at each trial's own onset
    b = make(10.0, n=6, onset_jitter_steps=jitter)
    turn = np.abs(np.diff(np.arctan2(b.truth[..., 3], b.truth[..., 1]), axis=1))   # heading change per step
    rate = np.deg2rad(DEFAULT.turn_rate_deg_s) * DEFAULT.dt_s
    for i, onset in enumerate(np.asarray(b.scene.onset_step)):
        assert turn[i, onset - 1:onset + 7].mean() > 0.7 * rate > turn[i, onset - 9:onset - 1].mean()


def test_zero_jitter_keeps_the_single_onset():
    assert make(10.0, n=3, onset_jitter_steps=0).scene.onset_step == DEFAULT.onset_step
