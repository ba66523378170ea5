"""Every figure's first view is what *Results at a glance* ranks on (docs/architecture.md,
'Report'): a task's first interactive curve and first recording chart are the summary
column of its glance metric, and on a run that column is that metric's mean over trials,
level by level, as the glance computes it."""

import numpy as np
import pandas as pd
import pytest

from radarbench.bench import registry
from radarbench.bench.report.glance import metric_values
from radarbench.bench.report.html import interactive_specs


def _tasks():
    return list(registry.tasks().values())


@pytest.mark.parametrize("task", _tasks(), ids=lambda t: t.name)
def test_a_tasks_first_figure_is_its_glance_metric(task):
    glance = task.glance_column()
    assert glance, f"{task.name}: no summary column for its ranking metric"
    assert glance in task.summary_columns
    assert task.curves and task.curves[0][0] == glance
    assert task.recording_charts[0][0] == glance
    assert all(title for _, title in task.curves)                 # a human title with its unit


def test_the_first_interactive_figure_plots_the_glance_metric_of_the_run(small_run):
    summary = pd.read_csv(small_run / "summary.csv")
    trials = pd.read_csv(small_run / "trials.csv")
    task = registry.tasks()["maneuver-detection"]
    task_of = {config: task for config in summary.config.unique()}
    specs = interactive_specs(summary, task_of)
    first = specs[0]
    assert first["column"] == "pd_equal_chance" and "equal chance" in first["title"]
    assert [s["column"] for s in specs] == ["pd_equal_chance", "pd"]    # any-alarm Pd second
    evaluated = trials[trials.config.isin(summary.config)]
    for trace in first["traces"]:
        config = trace["label"].split(" (identical to ")[0]
        mine = evaluated[evaluated.config == config]
        by_level = mine.assign(v=metric_values(mine[task.equal_chance_metric])).groupby("snr_db").v.mean()
        np.testing.assert_allclose(trace["y"], by_level.loc[list(trace["x"])].to_numpy(), rtol=0, atol=1e-12)


def test_a_glance_figure_draws_the_top_six_configs_in_rank_order(monkeypatch, tmp_path):
    from radarbench.bench import figures
    import importlib

    glance_module = importlib.import_module("radarbench.bench.report.glance")

    task = registry.tasks()["maneuver-detection"]
    configs = [f"c{i}" for i in range(8)]
    summary = pd.DataFrame([{"scenario": "s", "config": c, "snr_db": snr, "pd": 0.5, "pd_low": 0.4, "pd_high": 0.6,
                             "pd_equal_chance": i / 10, "pd_equal_chance_low": 0.0, "pd_equal_chance_high": 1.0}
                            for i, c in enumerate(configs) for snr in (0.0, 6.0)])
    ranking = [{"config": c, "unranked": "no Pfa" if c == "c7" else ""} for c in reversed(configs)]
    drawn = {}
    monkeypatch.setattr(figures, "pd_vs_snr", lambda rows, path, *a, column, **k: drawn.update(
        path=path.name, column=column, configs=list(dict.fromkeys(rows.config))))
    entries = [{"task": task, "scenario": "s", "equal_chance": True, "ranking": ranking}]
    glance_module.draw_glance_figures(entries, summary, tmp_path)
    assert drawn == {"path": "glance-1.png", "column": "pd_equal_chance",
                     "configs": ["c6", "c5", "c4", "c3", "c2", "c1"]}          # ranked, the unranked left out
    assert entries[0]["figure"] == "glance-1.png"
