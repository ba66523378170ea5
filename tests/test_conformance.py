"""Every registered method on every compatible scenario: shapes, no NaN, determinism."""

import numpy as np
import pytest

from bench import registry
from bench.rng import TrialRNG
from bench.tasks import handler

PAIRS = [(s, m) for s, scls in registry.scenarios().items() for m, mcls in registry.methods().items()
         if mcls.task in scls.tasks]


def test_every_method_has_a_scenario_and_nothing_is_unavailable():
    assert registry.unavailable() == []
    runnable = {m for _, m in PAIRS}
    assert runnable == set(registry.methods())


def _batch(scenario, snr_db, seed=3):
    cls = registry.get_scenario(scenario)
    return cls().generate(cls.Params(), snr_db, 3, TrialRNG(seed, 0, 11, range(5, 8)))


@pytest.mark.parametrize("scenario, method", PAIRS)
def test_method_conforms(scenario, method):
    cls = registry.get_method(method)
    task = handler(cls.task)
    for snr in (None, 0.0, 10.0):
        batch = _batch(scenario, snr)
        out = task.check_output(cls().run(batch, cls.Params()), batch)      # shape and finiteness
        again = cls().run(_batch(scenario, snr), cls.Params())
        np.testing.assert_array_equal(out.statistic, again.statistic)       # pure and deterministic
        assert np.isfinite(cls().nominal_threshold(cls.Params(), 0.01, batch))


@pytest.mark.parametrize("scenario", list(registry.scenarios()))
def test_scenario_streams_are_per_trial(scenario):
    """A trial's draws do not depend on which other trials share its batch."""
    cls = registry.get_scenario(scenario)
    whole = cls().generate(cls.Params(), 5.0, 4, TrialRNG(9, 0, 1, range(4)))
    part = cls().generate(cls.Params(), 5.0, 2, TrialRNG(9, 0, 1, range(2, 4)))
    np.testing.assert_array_equal(whole.z[2:], part.z)
    np.testing.assert_array_equal(whole.truth[2:], part.truth)
