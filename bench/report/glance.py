"""Results at a glance and paired comparisons (docs/architecture.md, 'Report').

Both are driven by what a task declares (:class:`bench.tasks.base.Task`):
``ranking_metric`` (a per-trial column of trials.csv), ``ranking_higher_is_better``,
``ranking_label`` and ``ranking_binary``. Nothing here names a task.

*Paired comparisons* (``comparisons.csv``): every method config of a scenario
config sees the same trials (common random numbers), so for each pair of
configs (a, b) the per-trial difference b − a of the ranking metric cancels
the noise they share. Per SNR level and over all levels (each level weighing
the same), the mean difference has a 95% paired-bootstrap interval (trials
resampled within each level, :func:`bench.metrics.paired_difference`); for a
0/1 metric McNemar's exact test of the discordant pairs is added. A pair is
*significant* when its interval excludes 0 and, for a 0/1 metric, McNemar's
test rejects at 5% too (the percentile bootstrap is anti-conservative with few
discordant pairs; the exact test is not).

*At a glance*: per (task, scenario config) the configs ranked by the ranking
metric averaged over the SNR levels (each level weighing the same), with
bootstrap intervals; a config whose metric is undefined (no value, or what its task
finds undefined, :meth:`~bench.tasks.base.Task.unranked_reason`) is listed unranked with
the reason; the winner's margin over the runner-up is their paired comparison over all
levels, "tie" when it is not significant, "not enough
trials to rank" when the comparison has a single pair or a zero-width interval
away from 0. A task whose detectors differ in chance Pd (a single-step test
alarms by chance far more often than a window statistic) declares
``equal_chance_metric``, the per-trial 0/1 outcome at thresholds that give every
config the same chance Pd: the configs are ranked on it (McNemar's test
applies), with the ranking metric as a secondary column.
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd

from radarbench.bench.metrics import (CONFIDENCE, RELATIVE_RESOLUTION, bootstrap_mean_ci, mcnemar_exact,
                                      paired_difference, resolved_differences)
from radarbench.bench.results.figure_cache import reused

COMPARISON_COLUMNS = ["scenario", "task", "metric", "snr_db", "config_a", "config_b", "n_pairs", "mean_a", "mean_b",
                      "difference", "difference_low", "difference_high", "only_a", "only_b", "mcnemar_p",
                      "significant", "better", "degenerate"]
#: ``snr_db`` of the comparison over every level of a scenario config (blank in the CSV)
ALL_LEVELS = np.nan


def metric_values(column: pd.Series) -> pd.Series:
    """A trials.csv metric column as floats (a 0/1 indicator stored as bool: 0.0/1.0; missing: NaN)."""
    return pd.to_numeric(column.map(lambda v: float(v) if isinstance(v, (bool, np.bool_)) else v), errors="coerce")


def _wide(g: pd.DataFrame, metric: str) -> pd.DataFrame:
    """``metric`` with one row per (snr_db, trial) and one column per config, pivoted once
    for every pair of configs."""
    return g.assign(_v=metric_values(g[metric])).pivot_table(index=["snr_db", "trial"], columns="config", values="_v",
                                                             aggfunc="first", dropna=False)


def compare_pair(a: np.ndarray, b: np.ndarray, snr_db: np.ndarray, binary: bool, higher_is_better: bool) -> dict:
    """The paired comparison of two configs' per-trial values ``a`` and ``b`` (NaN where
    a config has none), trial by trial, ``snr_db`` each trial's level."""
    ok = np.isfinite(a) & np.isfinite(b)
    mean_a, mean_b = _mean(a[ok]), _mean(b[ok])
    diff, low, high = _snapped(paired_difference(a, b, snr_db), mean_a, mean_b)
    only_a, only_b, p = mcnemar_exact(a, b) if binary else (np.nan, np.nan, np.nan)
    significant = bool(np.isfinite(low) and (low > 0 or high < 0) and (not binary or p < 1 - CONFIDENCE))
    better = "tie"
    if significant:
        better = "b" if (diff > 0) == higher_is_better else "a"
    return {"n_pairs": int(ok.sum()), "mean_a": mean_a, "mean_b": mean_b,
            "difference": diff, "difference_low": low, "difference_high": high, "only_a": only_a, "only_b": only_b,
            "mcnemar_p": p, "significant": significant, "better": better,
            "degenerate": _degenerate(a[ok], b[ok], low, high)}


def _snapped(values, mean_a: float, mean_b: float) -> tuple[float, ...]:
    """``values`` (a difference and its interval) with those within the metric's
    resolution of 0 (:data:`~bench.metrics.RELATIVE_RESOLUTION` of the larger mean) set to
    exactly 0: an average over levels of equal values leaves float noise (-2e-17) that
    would read as an interval excluding 0."""
    scale = RELATIVE_RESOLUTION * max(abs(mean_a), abs(mean_b)) if np.isfinite(mean_a + mean_b) else 0.0
    return tuple(0.0 if np.isfinite(v) and abs(v) <= scale else float(v) for v in values)


def _degenerate(a: np.ndarray, b: np.ndarray, low: float, high: float) -> str:
    """Why an interval is a single point, for comparisons.csv: "identical" (every pair
    equal: the two configs gave the same values on every trial), "zero-width" (every
    pair differs by the same amount, so resampling changes nothing), else ""."""
    if a.size and not np.any(resolved_differences(a, b)):
        return "identical"
    return "zero-width" if np.isfinite(low) and low == high else ""


def _mean(values: np.ndarray) -> float:
    return float(values.mean()) if values.size else np.nan


def _groups(trials: pd.DataFrame, task_of: dict):
    """(scenario, task, its trials) per scenario config and task with a ranking metric."""
    tasks = trials.config.map(lambda c: task_of[c].name if c in task_of else "")
    for (scenario, name), g in trials.groupby([trials.scenario, tasks], sort=False):
        task = next((t for t in task_of.values() if t.name == name), None)
        if task is not None and task.ranking_metric and task.ranking_metric in g:
            yield scenario, task, g


def equal_chance_metric(task, g: pd.DataFrame) -> str:
    """The task's :attr:`~bench.tasks.base.Task.equal_chance_metric` where every config of
    ``g`` has it (a 0/1 outcome at equal chance Pd), else ""."""
    column = task.equal_chance_metric
    if not column or column not in g:
        return ""
    return column if metric_values(g[column]).notna().groupby(g.config).all().all() else ""


def _metrics(task, g: pd.DataFrame) -> list[tuple[str, bool]]:
    """(per-trial column, whether 0/1) the configs of ``g`` are compared on: the ranking
    metric and, where the run has it, the outcome at equal chance Pd."""
    fair = equal_chance_metric(task, g)
    return [(task.ranking_metric, task.ranking_binary)] + ([(fair, True)] if fair else [])


def comparisons_frame(trials: pd.DataFrame, task_of: dict) -> pd.DataFrame:
    """Every pair of method configs of each (scenario config, task), per SNR
    level and over all levels, on each of the task's metrics: :data:`COMPARISON_COLUMNS`."""
    rows = []
    for scenario, task, g in _groups(trials, task_of):
        configs = list(dict.fromkeys(g.config))
        for metric, binary in _metrics(task, g):
            wide = _wide(g, metric)
            snr_db = wide.index.get_level_values("snr_db").to_numpy(float)
            levels = [ALL_LEVELS, *np.unique(snr_db)]                  # the rows of _pair_rows, in order
            for a, b in itertools.combinations(configs, 2):
                va, vb = wide[a].to_numpy(float), wide[b].to_numpy(float)
                key = {"scenario": scenario, "task": task.name, "metric": metric, "config_a": a, "config_b": b}
                for snr, row in zip(levels, reused(_pair_rows, va, vb, snr_db, binary, task.ranking_higher_is_better),
                                    strict=True):
                    row["better"] = {"a": a, "b": b}.get(row["better"], "tie")
                    rows.append({**key, "snr_db": snr, **row})
    return pd.DataFrame(rows, columns=COMPARISON_COLUMNS)


def _pair_rows(a: np.ndarray, b: np.ndarray, snr_db: np.ndarray, binary: bool, higher_is_better: bool) -> list[dict]:
    """:func:`compare_pair` of two configs over all levels, then level by level (in order): a pure
    function of their values, reused where an earlier report compared the same values
    (:func:`bench.results.figure_cache.reused`), so an edit of one config recomputes only its pairs."""
    subsets = [slice(None)] + [snr_db == level for level in np.unique(snr_db)]
    return [compare_pair(a[at], b[at], snr_db[at], binary, higher_is_better) for at in subsets]


def _mean_by_config(g: pd.DataFrame, column: str) -> dict[str, tuple[float, float, float]]:
    """config -> (mean over the levels, each weighing the same; its bootstrap interval)."""
    values = g.assign(_v=metric_values(g[column]))
    return {config: bootstrap_mean_ci(c._v, c.snr_db) for config, c in values.groupby("config", sort=False)}


def enough_trials(row) -> bool:
    """Whether a paired comparison can rank: more than one pair, and an interval that is
    not a single point away from 0 (one trial per level, or identical trials, give the
    bootstrap nothing to resample: a zero-width interval says nothing about the spread)."""
    degenerate = row.difference_low == row.difference_high and row.difference != 0
    return bool(row.n_pairs >= 2 and not degenerate)


def unranked_reasons(task, g: pd.DataFrame, means: dict) -> dict[str, str]:
    """config -> why it is never ranked: no value of the ranking metric (the task's
    ``ranking_undefined``), or what the task finds undefined in its trials
    (:meth:`~bench.tasks.base.Task.unranked_reason`, e.g. a Pfa with no false-alarm step)."""
    reasons, no_value = {}, task.ranking_undefined or "no value"
    for config, c in g.groupby("config", sort=False):
        reason = no_value if not np.isfinite(means[config][0]) else task.unranked_reason(c)
        if reason:
            reasons[config] = reason
    return reasons


def _common_reason(reasons) -> str:
    """The reasons no config is ranked, each once, in order."""
    return "; ".join(dict.fromkeys(reasons))


def glance(trials: pd.DataFrame, task_of: dict, comparisons: pd.DataFrame, chance: dict) -> list[dict]:
    """Per (scenario config, task): the configs ranked (mean of the ranking
    metric over the levels with its interval, the chance Pd where calibrated),
    the winner, its margin over the runner-up and whether it is a tie. Where the
    task has an outcome at equal chance Pd (:func:`equal_chance_metric`), the configs
    are ranked on it and the ranking metric is a secondary column (``secondary``)."""
    out = []
    for scenario, task, g in _groups(trials, task_of):
        fair = equal_chance_metric(task, g)
        metric = fair or task.ranking_metric
        means = _mean_by_config(g, metric)
        secondary = _mean_by_config(g, task.ranking_metric) if fair else {}
        unranked = unranked_reasons(task, g, means)
        ranking = [{"config": config, "mean": mean, "low": low, "high": high, "unranked": unranked.get(config, ""),
                    "chance": chance.get((scenario, config), np.nan), "secondary": secondary.get(config)}
                   for config, (mean, low, high) in means.items()]
        sign = -1.0 if task.ranking_higher_is_better else 1.0
        ranking.sort(key=lambda r: np.inf if r["unranked"] else sign * r["mean"])
        ranked = sum(not r["unranked"] for r in ranking)
        entry = {"scenario": scenario, "task": task, "ranking": ranking, "levels": int(g.snr_db.nunique()),
                 "winner": ranking[0]["config"], "runner_up": None, "margin": None, "equal_chance": bool(fair),
                 "undefined": "" if ranked else _common_reason(unranked.values())}
        if ranked > 1:
            a, b = ranking[0]["config"], ranking[1]["config"]
            pick = comparisons[(comparisons.scenario == scenario) & (comparisons.task == task.name)
                               & (comparisons.metric == metric) & comparisons.snr_db.isna()]
            row = pick[((pick.config_a == a) & (pick.config_b == b)) | ((pick.config_a == b) & (pick.config_b == a))]
            r = row.iloc[0]
            flip = 1.0 if r.config_b == a else -1.0      # the rows hold b − a: as winner − runner-up
            low, high = sorted((flip * r.difference_low, flip * r.difference_high))
            entry.update(runner_up=b, margin={"difference": flip * r.difference, "low": low, "high": high,
                                              "tie": not r.significant, "mcnemar_p": r.mcnemar_p,
                                              "enough": enough_trials(r)})
        out.append(entry)
    return out


#: Curves in a glance figure: the top-ranked configs, legible at a glance (every config is
#: in the report's sections)
GLANCE_CURVES = 6


def draw_glance_figures(entries: list[dict], summary: pd.DataFrame, fig_dir) -> None:
    """Per glance entry with two or more SNR levels, its metric against SNR for its
    :data:`GLANCE_CURVES` top-ranked configs, in rank order (``figures/glance-K.png``,
    K from 1 in the glance's order); the entry gets the figure's name as ``figure``."""
    from radarbench.bench import figures

    for k, g in enumerate(entries, start=1):
        task = g["task"]
        column = task.equal_chance_column if g["equal_chance"] else task.ranking_column
        top = [r["config"] for r in g["ranking"] if not r["unranked"]][:GLANCE_CURVES]
        rows = summary[(summary.scenario == g["scenario"]) & summary.config.isin(top)] if column in summary else None
        if rows is None or rows.snr_db.nunique() < 2:
            continue
        rows = pd.concat([rows[rows.config == config] for config in top])       # in rank order
        label = task.equal_chance_label if g["equal_chance"] else task.ranking_label
        title = f"{g['scenario']}: the top {len(top)} of {len(g['ranking'])} configs"
        name = f"glance-{k}.png"
        if task.ranking_binary:
            figures.pd_vs_snr(rows, fig_dir / name, float("nan"), title, column=column, ylabel=label,
                              condition="at equal chance $P_D$" if g["equal_chance"] else "as ranked at a glance")
        else:
            figures.metric_vs_snr(rows, fig_dir / name, title, column=column, ylabel=label, log=True)
        g["figure"] = name
