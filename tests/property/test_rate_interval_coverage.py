"""Coverage of the per-step false-alarm-rate interval on null trials of a window statistic.

The statistic is the sliding sum of M chi-square(1) values: each sum is exactly
chi-square(M), so the true per-step rate at threshold chi2.isf(p, M) is p, while
alarms come in clusters. Over R = 400 replications (fixed seeds) the number of
intervals covering p is Binomial(400, 0.95) for an exact 95 % interval: the
99.9 % acceptance band of that law is the tolerance. The naive Wilson interval
on steps must fall below the band for the same statistic.
"""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from radarbench.bench.metrics import binomial_interval, clustered_rate_interval

R = 400
BAND = stats.binom.ppf([0.0005, 0.9995], R, 0.95) / R


def _alarm_counts(seed, trials, steps, window, rate):
    x = np.random.default_rng(seed).standard_normal((R, trials, steps + window - 1)) ** 2
    c = np.concatenate([np.zeros((R, trials, 1)), np.cumsum(x, axis=-1)], axis=-1)
    sums = c[..., window:] - c[..., :-window]
    return (sums >= stats.chi2.isf(rate, window)).sum(axis=-1)


@settings(derandomize=True, deadline=None, max_examples=4)
@given(window=st.sampled_from([16, 32]), rate=st.sampled_from([0.01, 0.02]), seed=st.integers(0, 2**32 - 1))
def test_interval_over_trials_covers_the_true_rate(window, rate, seed):
    trials, steps = 200, 100
    counts = _alarm_counts(seed, trials, steps, window, rate)
    opp = np.full(trials, steps)
    clustered = np.array([clustered_rate_interval(e, opp) for e in counts])
    naive = np.array([binomial_interval(int(e.sum()), trials * steps) for e in counts])
    cover = np.mean((clustered[:, 0] <= rate) & (rate <= clustered[:, 1]))
    naive_cover = np.mean((naive[:, 0] <= rate) & (rate <= naive[:, 1]))
    assert BAND[0] <= cover <= BAND[1], (cover, BAND)
    assert naive_cover < BAND[0], naive_cover


def test_degenerate_cases():
    lo, hi = clustered_rate_interval(np.zeros(50), np.full(50, 100))
    assert lo < 1e-12 and hi == binomial_interval(0, 50)[1]   # [0, bound on the trials], not on steps
    lo, hi = clustered_rate_interval([3.0], [100])
    assert 0 < lo <= 0.03 <= hi <= 1   # one trial: the assumption-free bracket [q_low / 100, 1]
    e = np.r_[np.ones(10), np.zeros(40)]
    assert clustered_rate_interval(e, np.ones(50)) == binomial_interval(10, 50)
