"""Units handed out longest first, from the seconds per trial earlier runs kept
(bench.run.runner.longest_first): the order changes when a phase ends, never a number."""

from __future__ import annotations

from radarbench.bench.run import runner
from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.run.identity import content_keys
from radarbench.bench.run.units import UnitTask, plan_units

SWEEP = {"name": "order", "trials": 20, "chunk": 10, "seed": 1, "snr_db": [0, 10],
         "scenarios": [{"name": "cv-turn-cv", "params": {"steps": 120, "onset_step": 60}},
                       {"name": "maneuvering-1d", "params": {"steps": 60}}],
         "methods": [{"name": "innovation"}, {"name": "cv-kf"}], "calibration": {"h0_trials": 20}}


def test_the_longest_units_go_first_and_unknown_ones_keep_their_order(monkeypatch):
    plan = parse_sweep(SWEEP)
    keys = content_keys(plan)
    tracking = keys["scenarios"]["maneuvering-1d"]
    monkeypatch.setattr(runner, "_known_seconds", lambda: {f"{tracking}/{keys['methods']['cv-kf']}": 0.5})
    _, evaluation = plan_units(plan)
    tasks = [UnitTask(plan, u) for u in evaluation]
    ordered = runner.longest_first(plan, tasks)
    assert [t.unit.scenario_label for t in ordered[:4]] == ["maneuvering-1d"] * 4
    assert ordered[4:] == [t for t in tasks if t.unit.scenario_label == "cv-turn-cv"]    # unknown: as they were
    monkeypatch.setattr(runner, "_known_seconds", dict)
    assert runner.longest_first(plan, tasks) == tasks


def test_a_run_keeps_its_seconds_per_trial_by_content(tmp_path):
    plan = parse_sweep(SWEEP)
    store = runner.run_sweep(plan, tmp_path, plan_record=runner.plan_record(plan, "t"), executor="serial", quiet=True)
    store.close()
    known, keys = runner._known_seconds(), content_keys(plan)
    for label, scenario in keys["scenarios"].items():
        assert known[scenario] >= 0
        assert f"{scenario}/{keys['methods']['cv-kf' if label == 'maneuvering-1d' else 'innovation']}" in known
