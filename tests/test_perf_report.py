"""``bench perf`` report layout: the scene-generation table (no speed is asserted)."""

import re

import pandas as pd

from bench import registry
from bench.perf import PERF_COLUMNS, SCENE_COLUMNS, Job, scene_jobs, write_report


def test_scene_jobs_one_per_scenario_size():
    jobs = [Job("dp-tbd", "tbd-grid", "small", {"cells": 100}, 20, False),
            Job("dp-tbd-mf", "tbd-grid", "small", {"cells": 100}, 20, False),
            Job("dp-tbd", "tbd-grid", "paper", {}, 4, False)]
    assert [(j.scenario, j.size, j.trials) for j in scene_jobs(jobs)] == \
        [("tbd-grid", "small", 20), ("tbd-grid", "paper", 4)]


def test_report_has_scene_generation_table_and_csv(tmp_path):
    registry.discover()
    scenes = pd.DataFrame([["tbd-grid", "paper", 4, 0.0123, 400.0]], columns=SCENE_COLUMNS)
    report = write_report(tmp_path, pd.DataFrame(columns=PERF_COLUMNS), [], None, scenes=scenes)
    text = report.read_text()
    assert "## Scene generation" in text
    assert "| `tbd-grid` | paper | 4 | 12.3 | 400 | ≤ 0.02 s/trial: 0.0123 ✓ |" in re.sub(" +", " ", text)   # padded cells
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "scene.csv"), scenes)
