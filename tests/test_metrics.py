"""Metric definitions and calibration."""

import numpy as np
import pytest
from scipy import stats

from radarbench.bench.calibration import calibrate, empirical_threshold
from radarbench.bench.metrics import crossing, snr_at_pd
from radarbench.bench.tasks.detection.metrics import detection_trial_metrics


def test_detection_metrics_follow_the_definitions():
    K = 12
    stat = np.zeros((3, K))
    stat[0, [2, 7]] = 5        # a false alarm at 2, detection at onset 6 + 1
    stat[1, 11] = 5            # alarm after the detection window: missed
    stat[2, [6, 8]] = 5        # detection at the onset itself
    m = detection_trial_metrics(stat, 5.0, onset=6, detect_window=4, null_start=1)
    assert m["detected"].tolist() == [True, False, True]
    assert np.array_equal(m["delay"], [1, np.nan, 0], equal_nan=True)
    assert m["false_alarms"].tolist() == [1, 0, 0]
    assert m["null_steps"].tolist() == [5, 5, 5]
    assert m["peak_statistic"].tolist() == [5, 0, 5]


def test_empirical_threshold_exceedance_never_above_pfa():
    rng = np.random.default_rng(0)
    for n in (10, 99, 1000, 12345):
        v = rng.standard_normal(n)
        for pfa in (0.001, 0.01, 0.1, 0.37):
            t = empirical_threshold(v, pfa)
            assert np.mean(v >= t) <= pfa
            # and it is the smallest such threshold: any value below t would exceed pfa
            below = v[v < t]
            if below.size:
                assert np.mean(v >= below.max()) > pfa


def test_calibration_reports_the_nominal_thresholds_measured_pfa():
    v = np.random.default_rng(1).chisquare(2, 200_000)
    nominal = stats.chi2.ppf(0.99, 2)
    c = calibrate("s", "m", v, nominal, 0.01, "empirical")
    assert c.nominal_exceedances == np.count_nonzero(v >= nominal) and c.null_values == v.size
    assert c.nominal_pfa_low < c.nominal_pfa < c.nominal_pfa_high
    # the nominal threshold is exact here: its measured Pfa is 0.01 up to binomial sampling (4 sigma)
    assert abs(c.nominal_pfa - 0.01) < 4 * np.sqrt(0.01 * 0.99 / v.size)
    assert np.mean(v >= c.used) <= 0.01
    assert calibrate("s", "m", v, nominal, 0.01, "nominal").used == nominal


def test_crossing_interpolates_and_reports_missing():
    assert crossing([0, 1, 2], [0.0, 0.4, 0.8]) == pytest.approx(1.25)
    assert np.isnan(crossing([0, 1], [0.1, 0.2]))
    assert crossing([0, 1], [0.6, 0.9]) == -np.inf
    mid, low, high = snr_at_pd([0, 1, 2], [0.0, 0.4, 0.8], [0.0, 0.2, 0.6], [0.1, 0.6, 0.9])
    assert low < mid < high


def test_wilson_interval_matches_scipy_on_integer_counts():
    from radarbench.bench.metrics import binomial_interval, wilson_interval
    for k, n in [(0, 50), (3, 50), (10, 1000), (999, 1000)]:
        np.testing.assert_allclose(wilson_interval(k / n, n), binomial_interval(k, n), rtol=1e-12, atol=1e-15)


def test_clustered_rate_interval_widens_for_clustered_alarms():
    from radarbench.bench.metrics import binomial_interval, clustered_rate_interval
    steps = np.full(200, 50)
    spread = np.r_[np.ones(100), np.zeros(100)]          # 100 alarms, one per trial
    clustered = np.r_[np.full(10, 10.0), np.zeros(190)]  # 100 alarms in 10 trials
    independent = binomial_interval(100, steps.sum())
    np.testing.assert_allclose(clustered_rate_interval(spread, steps), independent, rtol=0.02)
    lo, hi = clustered_rate_interval(clustered, steps)
    assert hi - lo > 2 * (independent[1] - independent[0])


def test_calibration_pfa_intervals_are_counted_over_trials():
    """A window statistic's exceedances cluster within a trial: the calibration table's
    interval over trials is wider than Wilson's on pooled steps; with one value per
    trial (TBD scene scores) it is Wilson's exactly."""
    from radarbench.bench.calibration import exceedance_interval
    from radarbench.bench.metrics import binomial_interval
    rng = np.random.default_rng(3)
    n, K, M = 300, 100, 16
    x = rng.chisquare(1, (n, K + M))
    windowed = np.lib.stride_tricks.sliding_window_view(x, M, axis=1).sum(axis=-1)[:, :K]
    values = windowed.ravel()
    threshold = np.quantile(values, 0.99)
    low, high = exceedance_interval(values, threshold, np.full(n, K))
    w_low, w_high = binomial_interval(int((values >= threshold).sum()), values.size)
    assert high - low > 2 * (w_high - w_low)
    scenes = rng.gumbel(size=1000)
    assert exceedance_interval(scenes, 2.0, np.ones(1000, int)) == \
        binomial_interval(int((scenes >= 2.0).sum()), 1000)


def test_the_bootstrap_draws_a_fresh_generator_would_whatever_came_before():
    """The resampling indices are kept per strata sizes: every interval must still be the
    one a fresh generator seeded with BOOTSTRAP_SEED gives, in any order of calls, and the
    memo stays bounded."""
    from radarbench.bench import metrics
    rng = np.random.default_rng(5)
    cases = [(rng.standard_normal(n * k), np.repeat(np.arange(k), n)) for n, k in [(7, 3), (20, 1), (7, 3), (5, 6),
                                                                                   (3, 2), (9, 2), (4, 4), (7, 3)]]
    for values, strata in cases:
        fresh = metrics._stratified_means(values, strata, 300, np.random.default_rng(metrics.BOOTSTRAP_SEED))
        np.testing.assert_array_equal(metrics._stratified_means(values, strata, 300), fresh)
    assert len(metrics._resamples_memo) <= metrics.RESAMPLES_MEMO_SIZE
