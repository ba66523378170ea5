"""The tracking task's maneuver metrics (bench/tasks/tracking/metrics.py) on hand-made
errors, masks and switch traces whose values are known exactly."""

import numpy as np

from radarbench.bench.tasks.tracking.metrics import ONSET_WINDOW_STEPS, maneuver_trial_metrics


def _case():
    K, onset, end = 40, 10, 25
    mask = np.zeros((2, K), bool)
    mask[0, onset:end] = True                               # trial 1: no maneuver
    onsets = np.array([[onset], [K]])[:, :1]
    sq = np.ones((2, K))
    sq[0, onset:onset + ONSET_WINDOW_STEPS] = 16.0          # the onset transient: 4 m
    switch = np.zeros((2, K))
    switch[0, [3, onset + 2]] = 1.0                         # one false switch, one 2 steps late
    switch[1, 7] = 1.0
    return maneuver_trial_metrics(sq, mask, onsets, {"switch": switch}), onset, end, K


def test_onset_window_rmse_is_taken_over_the_steps_after_the_onset():
    out, onset, end, K = _case()
    assert np.isclose(out["rmse_onset_m"][0], 4.0)
    assert np.isnan(out["rmse_onset_m"][1])                 # no onset inside the trial
    assert out["onset_window"][0].sum() == ONSET_WINDOW_STEPS
    assert out["onset_window"][0, onset] == 1.0 and out["onset_window"][0, onset - 1] == 0.0
    expected = np.sqrt((16.0 * ONSET_WINDOW_STEPS + (end - onset - ONSET_WINDOW_STEPS)) / (end - onset))
    assert np.isclose(out["rmse_maneuver_m"][0], expected)
    assert np.isclose(out["rmse_quiet_m"][0], 1.0)


def test_switches_are_scored_against_the_onset():
    out, onset, end, K = _case()
    assert out["switch_detected"][0] == 1.0 and np.isnan(out["switch_detected"][1])
    assert out["switch_delay_steps"][0] == 2.0
    assert list(out["false_switches"]) == [1.0, 1.0]
    assert list(out["quiet_steps"]) == [onset, K]
