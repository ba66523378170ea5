"""Every detector's empirical threshold holds its per-step Pfa on fresh null trials.

Window statistics are correlated from step to step, so exceedances are not
independent Bernoulli draws and the binomial interval on steps would be too
narrow. Trials are independent, though: the per-step Pfa is a ratio of sums of
i.i.d. per-trial exceedance counts, whose variance the CLT over trials gives,
var = var(count per trial) / (n * steps^2). The threshold's own sampling error
(fitted on one set) adds the same kind of term for the fitting set. The test
allows 4.5 combined standard errors: never failing by chance over the examples
tried, while a threshold whose Pfa is off by a factor 2 fails.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.bench import registry
from radarbench.bench.calibration import empirical_threshold
from radarbench.bench.sweep.rng import CALIBRATION, EVALUATION, TrialRNG
from radarbench.bench.registry import get_task

DETECTORS = [
    ("innovation", {"window": 5}),
    ("innovation", {"window": 1, "delta": 0.8}),
    ("cumulant", {"window": 32}),
    ("cumulant", {"window": 16, "moment": "raw", "combine": "max"}),
    ("wavelet", {}),
    ("glr", {"window": 20}),
    ("cusum", {"drift": 4.0}),
]
TRIALS = 1000


def _null_statistics(name, params, seed, domain):
    scenario = registry.get_scenario("cv-turn-cv")
    method = registry.get_method(name)
    batch = scenario().generate(scenario.Params(), None, TRIALS, TrialRNG(seed, domain, 3, range(TRIALS)))
    out = method().run(batch, method.Params(**params))
    start = get_task(method.task).null_start(batch, out)
    return out.statistic[:, start:]


def _pfa_and_se(stat: np.ndarray, threshold: float) -> tuple[float, float]:
    counts = (stat >= threshold).sum(axis=1)
    steps = stat.shape[1]
    return counts.sum() / stat.size, counts.std(ddof=1) / np.sqrt(len(counts)) / steps


@pytest.mark.parametrize("name, params", DETECTORS)
@settings(derandomize=True, deadline=None, max_examples=3)
@given(pfa=st.sampled_from([0.01, 0.02, 0.05]), seed=st.integers(0, 2**31))
def test_empirical_threshold_holds_on_fresh_null_trials(name, params, pfa, seed):
    fit = _null_statistics(name, params, seed, CALIBRATION)
    threshold = empirical_threshold(fit.ravel(), pfa)
    fit_pfa, fit_se = _pfa_and_se(fit, threshold)
    fresh_pfa, fresh_se = _pfa_and_se(_null_statistics(name, params, seed, EVALUATION), threshold)
    assert fit_pfa <= pfa
    tolerance = 4.5 * np.hypot(fit_se, fresh_se)
    assert abs(fresh_pfa - pfa) < tolerance, (name, params, fresh_pfa, pfa, tolerance)
    assert tolerance < pfa              # power: a Pfa off by a factor 2 would be seen
