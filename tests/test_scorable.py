"""A detection config is scored only where it can be: refused at plan time when its
statistic is formed only at or after the scenario's onset (no false-alarm step), alarms
before its ``valid_from`` never count, and a config whose Pfa is undefined is never
ranked (docs/architecture.md, 'Run folders and faults' and 'Report')."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from radarbench.bench import registry
from radarbench.bench.report.glance import comparisons_frame, glance
from radarbench.bench.report.render import glance_markdown
from radarbench.bench.tasks.detection.metrics import detection_trial_metrics
from tests.test_reliability_validation import refused

#: a 40-step scene whose turn starts at step 16
SHORT_SCENE = """
name = "unscorable"
trials = 2
snr_db = [10]
scenario = "cv-turn-cv"
[scenario_params]
steps = 40
onset_step = 16
turn_steps = 10
detect_window_steps = 10
warmup_steps = 5
[[methods]]
"""


@pytest.mark.parametrize("method", ['name = "glr"\nparams = {window = 40}',
                                    'name = "cusum"\nparams = {score = "glr", window = 40, drift = 5.0}'])
def test_a_statistic_formed_only_after_the_onset_is_refused_at_plan_time(method):
    """Was accepted (the window fits in the 40 steps), Pfa NaN, ranked first with Pd 1."""
    line = refused(SHORT_SCENE + method)
    assert "methods[0].params:" in line and "cv-turn-cv" in line
    assert "from step 39 (valid_from)" in line and "onset at step 16" in line and "no false-alarm step" in line


def test_a_statistic_formed_before_the_onset_is_accepted():
    from radarbench.bench.sweep.config import parse_sweep_text
    plan = parse_sweep_text((SHORT_SCENE + 'name = "glr"\nparams = {window = 16}').encode(), "s.toml")
    assert [m.label for m in plan.methods] == ["glr[window=16]"] and not plan.skipped


def test_alarms_before_valid_from_never_count_as_detections():
    statistic = np.full((1, 12), 10.0)                     # alarms everywhere, the onset at 4
    formed_late = detection_trial_metrics(statistic, 1.0, onset=4, detect_window=4, null_start=6, valid_from=6)
    assert formed_late["detected"].tolist() == [True] and formed_late["delay"].tolist() == [2.0]
    assert formed_late["window_alarm_fraction"].tolist() == [0.5]
    never = detection_trial_metrics(statistic, 1.0, onset=4, detect_window=4, null_start=8, valid_from=8)
    assert never["detected"].tolist() == [False] and never["peak_statistic"].tolist() == [-np.inf]
    assert never["null_steps"].tolist() == [0]


def _trials(null_steps: dict[str, int], detected: dict[str, list[int]]) -> pd.DataFrame:
    return pd.DataFrame([{"scenario": "cv-turn-cv", "config": c, "snr_db": snr, "trial": i,
                          "detected": bool(detected[c][i]), "null_steps": null_steps[c], "false_alarms": 0}
                         for c in detected for snr in (0.0, 10.0) for i in range(len(detected[c]))])


def _glance_text(trials: pd.DataFrame) -> str:
    task = registry.get_task("maneuver-detection")
    task_of = {c: task for c in trials.config.unique()}
    return glance_markdown(glance(trials, task_of, comparisons_frame(trials, task_of), {}))


def test_a_config_without_a_false_alarm_step_is_not_ranked_and_the_glance_says_why():
    """Pd 1 with no false-alarm step before the onset is a Pd at no known Pfa: listed, unranked
    (was ranked first, the winner)."""
    text = _glance_text(_trials({"innovation": 60, "late": 0, "cumulant": 60},
                                {"innovation": [1, 1, 1, 0, 1, 0, 1, 1], "late": [1] * 8,
                                 "cumulant": [0, 1, 0, 0, 1, 0, 0, 0]}))
    assert "winner **`innovation`**, by +0.5 [+0.25, +0.75] over `cumulant`" in text
    rows = [line.split("|")[1:3] for line in text.splitlines() if line.startswith("| ")]
    assert [(rank.strip(), config.strip()) for rank, config in rows[1:]] == [
        ("1", "`innovation`"), ("2", "`cumulant`"), ("–", "`late`")]
    assert "Not ranked: `late` (Pfa undefined: no false-alarm step before the onset)." in text


def test_beside_an_unranked_config_the_only_ranked_one_is_said_so():
    text = _glance_text(_trials({"innovation": 60, "late": 0},
                                {"innovation": [1, 1, 1, 0, 1, 0, 1, 1], "late": [1] * 8}))
    assert "only `innovation` is ranked." in text and "Not ranked: `late` (Pfa undefined" in text


def test_when_no_config_has_a_false_alarm_step_none_is_ranked():
    text = _glance_text(_trials({"a": 0, "b": 0}, {"a": [1] * 4, "b": [1, 0, 1, 1]}))
    assert "not defined on this scene (Pfa undefined: no false-alarm step before the onset): no config is " \
           "ranked." in text
    assert "winner **" not in text and "**tie**:" not in text
