"""Empirical calibration holds its Pfa on fresh null trials.

The innovation statistic with window 1 (the NIS) is white under the matched
model, so its per-step exceedances are independent Bernoulli draws and the
binomial law is exact: the threshold is fitted on N0 null steps, the Pfa
measured on N1 fresh ones, and the measured Pfa differs from the requested one
by sampling error of variance about pfa (1 - pfa) (1/N0 + 1/N1) (the fitted
quantile's own error plus the measurement's). A 4.5-sigma band keeps the test
from ever failing by chance across the examples tried, while a threshold off
by 20% of the Pfa would fail it.
"""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.bench import registry
from radarbench.bench.calibration import calibrate
from radarbench.bench.sweep.rng import CALIBRATION, EVALUATION, TrialRNG
from radarbench.bench.registry import get_task


def _null_values(seed: int, domain: int, n: int) -> np.ndarray:
    scenario = registry.get_scenario("cv-turn-cv")
    method = registry.get_method("innovation")
    batch = scenario().generate(scenario.Params(), None, n, TrialRNG(seed, domain, 5, range(n)))
    params = method.Params(window=1)
    out = method().run(batch, params)
    return get_task(method.task).null_values(batch, out)


@settings(derandomize=True, deadline=None, max_examples=6)
@given(pfa=st.sampled_from([0.005, 0.01, 0.02, 0.05]), seed=st.integers(0, 2**32 - 1))
def test_empirical_threshold_holds_its_pfa_on_fresh_trials(pfa, seed):
    fit = _null_values(seed, CALIBRATION, 1500)      # 1500 x 150 steps: see the power check below
    fresh = _null_values(seed, EVALUATION, 1500)
    threshold = calibrate("s", "m", fit, np.inf, pfa, "empirical").used
    measured = np.mean(fresh >= threshold)
    sigma = np.sqrt(pfa * (1 - pfa) * (1 / fit.size + 1 / fresh.size))
    assert abs(measured - pfa) < 4.5 * sigma, (measured, pfa, sigma)
    assert 4.5 * sigma < 0.2 * pfa      # the test has the power to see a 20% miscalibration
