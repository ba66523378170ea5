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


def test_each_method_is_timed_on_a_scenario_it_accepts(monkeypatch):
    """``bench perf`` times a method on the first scenario of its task whose perf size its
    ``check_scenario`` accepts, never on one it refuses (generic: no scenario is named)."""
    from dataclasses import dataclass

    from bench.core import TRACKING, Method
    from bench.params import build_params
    from bench.perf import jobs

    registry.discover()
    tracking = [s for s in registry.scenarios().values() if TRACKING in s.tasks]
    assert len(tracking) >= 2
    refused_name = tracking[0].name

    class RefusesTheFirst(Method):
        name, task = "refuses-the-first", TRACKING

        @dataclass(frozen=True)
        class Params:
            pass

        def check_scenario(self, params, scenario_params):
            return "not this one" if type(scenario_params) is tracking[0].Params else None

    monkeypatch.setitem(registry._METHODS, RefusesTheFirst.name, RefusesTheFirst)
    picked = {job.scenario for job, _ in jobs([RefusesTheFirst.name])}
    assert picked == {tracking[1].name} != {refused_name}
    for job, _ in jobs():
        cls = registry.get_method(job.method)
        scenario = registry.get_scenario(job.scenario)
        assert cls.serves(scenario.name, scenario.tasks)
        assert cls().check_scenario(build_params(cls.Params, {}), build_params(scenario.Params,
                                                                               job.scenario_params)) is None
