"""ar-adaptive: the batched filter against its per-trial filterpy reference, and on the scenario."""

import numpy as np
import pytest

from radarbench.bench import registry
from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG


def _batch(n=6, snr=0.0, **params):
    cls = registry.get_scenario("maneuvering-1d")
    p = build_params(cls.Params, {"steps": 70, "maneuver_start_s": 25.0, "maneuver_duration_s": 15.0} | params)
    return cls().generate(p, snr, n, TrialRNG(5, 0, 3, range(n)))


@pytest.mark.parametrize("config", [{}, {"coefficients": "min-norm"}, {"switching": "latched", "coefficients": "min-norm"},
                                    {"order_low": 0, "order_high": 3, "state_dim": 5},
                                    {"state_noise": "fixed", "switching": "latched"}])
@pytest.mark.parametrize("dims", [1, 2])
def test_batched_equals_the_filterpy_reference(config, dims):
    cls = registry.get_method("ar-adaptive")
    params = build_params(cls.Params, config)
    batch = _batch(dims=dims)
    fast, slow = cls().run(batch, params), cls().reference_run(batch, params)
    np.testing.assert_allclose(fast.estimate, slow.estimate, rtol=1e-8, atol=1e-6)
    np.testing.assert_allclose(fast.covariance, slow.covariance, rtol=1e-6, atol=1e-6)
    for name in ("mode", "switch", "q_k"):
        np.testing.assert_allclose(fast.traces[name], slow.traces[name], rtol=1e-8, atol=1e-6, err_msg=name)


def test_switches_at_the_maneuver_and_q_grows_with_it():
    """On a 40 m/s^2 maneuver at 20 dB the chi2 test fires within a few steps of the onset
    in most trials, and Q_k during the maneuver is far above its quiet level."""
    cls = registry.get_method("ar-adaptive")
    batch = _batch(n=50, snr=20.0, maneuver_accel_m_s2=(40.0,))
    out = cls().run(batch, cls.Params())
    onset = 25
    first = np.argmax(out.traces["switch"][:, onset:] > 0, axis=1)
    assert np.mean(first <= 3) > 0.9
    q = out.traces["q_k"]
    assert np.median(q[:, onset + 5:onset + 15]) > 10 * np.median(q[:, 15:onset])


def test_fixed_state_noise_holds_q0_and_only_q_changes():
    """state_noise = "fixed" keeps Q_k = Q0 at every step; with W beyond the run's length
    the matching never starts either, so the two settings give the same track."""
    cls = registry.get_method("ar-adaptive")
    batch = _batch(n=8, snr=10.0)
    fixed = cls().run(batch, build_params(cls.Params, {"state_noise": "fixed", "q0_m2": 4.0}))
    assert np.all(fixed.traces["q_k"] == 4.0)
    matching = cls().run(batch, build_params(cls.Params, {"q0_m2": 4.0}))
    assert np.any(matching.traces["q_k"] != 4.0)
    never = cls().run(batch, build_params(cls.Params, {"q0_m2": 4.0, "window": 100}))
    np.testing.assert_array_equal(never.estimate, fixed.estimate)


def test_refuses_too_few_steps_and_bad_orders():
    cls = registry.get_method("ar-adaptive")
    scen = build_params(registry.get_scenario("maneuvering-1d").Params, {"steps": 4, "maneuver_start_s": 1.0})
    assert "steps" in cls().check_scenario(cls.Params(), scen)
    from radarbench.bench.errors import ConfigError
    with pytest.raises(ConfigError, match="order_high"):
        build_params(cls.Params, {"order_low": 2, "order_high": 2})
    with pytest.raises(ConfigError, match="order_high"):
        build_params(cls.Params, {"state_dim": 3, "order_high": 3})
