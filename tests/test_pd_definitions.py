"""The three Pd definitions of the detection task: any alarm, per-step average, equal chance Pd."""

import numpy as np
import pandas as pd

from radarbench.bench.calibration import EQUAL_CHANCE_PD, calibrate
from radarbench.bench.tasks.detection.metrics import detection_trial_metrics, equal_chance_pd, summarise_detection


def test_window_alarm_fraction_and_step_average_pd():
    statistic = np.zeros((3, 10))
    statistic[0, 4:6] = 5.0          # two of the four window steps alarm
    statistic[1, 4:8] = 5.0          # all four
    m = detection_trial_metrics(statistic, 1.0, onset=4, detect_window=4, null_start=0)
    np.testing.assert_allclose(m["window_alarm_fraction"], [0.5, 1.0, 0.0])
    rows = pd.DataFrame({"scenario": "s", "method": "m", "config": "c", "params": "", "snr_db": 0.0,
                         "threshold": 1.0, "realised_snr_db": 0.0, **m})
    s = summarise_detection(rows).iloc[0]
    assert s.pd == 2 / 3 and abs(s.pd_step - 0.5) < 1e-12 and s.pd_step_low <= 0.5 <= s.pd_step_high


def test_equal_chance_threshold_gives_every_detector_the_same_chance_pd():
    """On fresh null trials, the window threshold's chance Pd is EQUAL_CHANCE_PD within the
    binomial interval, for a white statistic and for a strongly correlated one."""
    rng = np.random.default_rng(7)
    n, K, onset, window = 4000, 80, 40, 30
    white = rng.chisquare(2, (2, n, K))
    correlated = np.cumsum(rng.standard_normal((2, n, K)), axis=2) ** 2 / np.arange(1, K + 1)
    for stat in (white, correlated):
        peaks = [detection_trial_metrics(s, np.inf, onset=onset, detect_window=window,
                                         null_start=10)["peak_statistic"] for s in stat]
        cal = calibrate("s", "m", stat[0][:, 10:].ravel(), np.nan, 0.01, "empirical", peaks[0])
        fresh = equal_chance_pd(peaks[1], cal.equal_chance_threshold)
        # Binomial(4000, 0.05): sd 0.0034; 4.5 sd is never reached by chance
        assert abs(fresh["pd_equal_chance"] - EQUAL_CHANCE_PD) < 4.5 * np.sqrt(0.05 * 0.95 / n)
