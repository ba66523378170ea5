"""``bench compare RUN_A RUN_B``: what changed between two runs (docs/architecture.md, 'Report').

Two run folders (before and after a change to a method, two machines, two
versions) are matched on scenario config label, method config label and SNR
level. For each match, the difference B − A of the task's ranking metric
(``Task.ranking_metric``: a per-trial column of trials.csv) with a 95%
bootstrap interval, per SNR level and over the common levels (each weighing
the same):

* *paired* when the two runs share their trials — the same per-trial seeds
  (``seed`` column) at every common level, which is what the same sweep seed
  and scenario config give — so trial-to-trial noise cancels
  (:func:`bench.metrics.paired_difference`; McNemar's exact test too for a
  0/1 metric, as in the paired comparisons of a report);
* *unpaired* otherwise (:func:`bench.metrics.unpaired_difference`).

The summary metrics (the task's ``headline_columns`` of summary.csv) are listed
side by side with their difference, without an interval. A difference is
*significant* when its interval excludes 0 (and McNemar rejects, paired 0/1).
``--fail-on-regression`` looks only at the rows over all common levels, one
per (scenario config, method config), with Bonferroni-adjusted intervals (level
1 − 0.05/m for m such rows) so that a CI gate over many configs does not fail
by chance: a significant change for the worse exits with
:data:`EXIT_REGRESSION`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from bench import registry
from bench.cli import EXIT_REGRESSION
from bench.errors import ConfigError
from bench.escapes import escape_controls
from bench.markdown import code, fmt, fmt_db, table, text
from bench.report.glance import metric_values
from bench.metrics import CONFIDENCE, mcnemar_exact, paired_difference, unpaired_difference

COLUMNS = ["scenario", "task", "config", "metric", "snr_db", "paired", "n_a", "n_b", "mean_a", "mean_b",
           "difference", "difference_low", "difference_high", "confidence", "mcnemar_p", "significant", "change"]


@dataclass
class Run:
    path: Path
    name: str
    trials: pd.DataFrame
    summary: pd.DataFrame
    task_of: dict


def load_run(path: str | Path) -> Run:
    """A run folder's trials (rebuilt from results.sqlite, as ``bench report`` does)
    and its summary.csv; ConfigError (exit 2) unless it is a bench run folder."""
    from bench import runfolder
    from bench.report import trials_frame
    from bench.store import Store
    root = Path(path)
    if not root.is_dir():
        raise ConfigError("", f"{root} is not a folder (expected a bench run folder)")
    db = root / runfolder.STORE
    if not db.exists():
        raise ConfigError("", f"{root} has no {runfolder.STORE} (not a bench run folder)")
    runfolder.check_store(db, need_plan=True)
    store = Store(db)
    try:
        record = store.plan()
        trials, _series = trials_frame(store, record)
    finally:
        store.close()
    summary_csv = root / "summary.csv"
    summary = pd.read_csv(summary_csv) if summary_csv.is_file() else pd.DataFrame()
    task_of = {m["label"]: registry.get_task(m["task"]) for m in record["methods"]}
    return Run(root, record["sweep"]["name"], trials, summary, task_of)


def _numeric(s: pd.Series) -> np.ndarray:
    return metric_values(s).to_numpy(float)


def _shares_trials(a: pd.DataFrame, b: pd.DataFrame) -> bool:
    key = ["snr_db", "trial", "seed"]
    return len(a) == len(b) and a[key].sort_values(key).to_numpy().tolist() == \
        b[key].sort_values(key).to_numpy().tolist()


def _difference(a: pd.DataFrame, b: pd.DataFrame, metric: str, paired: bool, binary: bool,
                level: float) -> dict:
    if paired:
        m = a[["snr_db", "trial", metric]].merge(b[["snr_db", "trial", metric]], on=["snr_db", "trial"])
        va, vb = _numeric(m[f"{metric}_x"]), _numeric(m[f"{metric}_y"])
        diff, low, high = paired_difference(va, vb, m.snr_db.to_numpy(), level)
        p = mcnemar_exact(va, vb)[2] if binary else np.nan
    else:
        va, vb = _numeric(a[metric]), _numeric(b[metric])
        diff, low, high = unpaired_difference(va, a.snr_db.to_numpy(), vb, b.snr_db.to_numpy(), level)
        p = np.nan
    significant = bool(np.isfinite(low) and (low > 0 or high < 0) and (not np.isfinite(p) or p < 1 - level))
    return {"n_a": int(np.isfinite(va).sum()), "n_b": int(np.isfinite(vb).sum()),
            "mean_a": float(np.nanmean(va)) if np.isfinite(va).any() else np.nan,
            "mean_b": float(np.nanmean(vb)) if np.isfinite(vb).any() else np.nan,
            "difference": diff, "difference_low": low, "difference_high": high, "confidence": level,
            "mcnemar_p": p, "significant": significant}


def compare_runs(a: Run, b: Run) -> pd.DataFrame:
    """:data:`COLUMNS`, one row per matched (scenario config, method config) over
    the common SNR levels (``snr_db`` NaN), then one per common level."""
    common = [(s, c) for (s, c) in dict.fromkeys(zip(a.trials.scenario, a.trials.config))
              if c in b.task_of and ((b.trials.scenario == s) & (b.trials.config == c)).any()]
    common = [(s, c) for s, c in common if a.task_of[c].name == b.task_of[c].name and a.task_of[c].ranking_metric]
    if not common:
        raise ConfigError("", f"{a.path} and {b.path} have no (scenario config, method config) in common "
                              "with a ranking metric")
    overall_level = 1 - (1 - CONFIDENCE) / len(common)     # Bonferroni over the rows the gate reads
    rows = []
    for scenario, config in common:
        task = a.task_of[config]
        ga = a.trials[(a.trials.scenario == scenario) & (a.trials.config == config)]
        gb = b.trials[(b.trials.scenario == scenario) & (b.trials.config == config)]
        levels = sorted(set(ga.snr_db) & set(gb.snr_db))
        ga, gb = ga[ga.snr_db.isin(levels)], gb[gb.snr_db.isin(levels)]
        paired = _shares_trials(ga, gb)
        key = {"scenario": scenario, "task": task.name, "config": config, "metric": task.ranking_metric,
               "paired": paired}
        cells = [(np.nan, ga, gb, overall_level)] + [(s, ga[ga.snr_db == s], gb[gb.snr_db == s], CONFIDENCE)
                                                      for s in levels]
        for snr, xa, xb, level in cells:
            row = {**key, "snr_db": snr, **_difference(xa, xb, task.ranking_metric, paired, task.ranking_binary,
                                                       level)}
            worse = (row["difference"] < 0) == task.ranking_higher_is_better
            row["change"] = ("worse" if worse else "better") if row["significant"] else "no significant change"
            rows.append(row)
    return pd.DataFrame(rows, columns=COLUMNS)


def summary_changes(a: Run, b: Run) -> pd.DataFrame:
    """The tasks' headline summary columns of the matched cells (their interval bounds
    left out), side by side: A, B, B − A."""
    if a.summary.empty or b.summary.empty:
        return pd.DataFrame()
    keys = ["scenario", "config", "snr_db"]
    m = a.summary.merge(b.summary, on=keys, suffixes=("_a", "_b"))
    rows = []
    for r in m.itertuples(index=False):
        r = r._asdict()
        task = a.task_of.get(r["config"])
        for col in (c for c in (task.headline_columns if task else ()) if not c.endswith(("_low", "_high"))):
            va, vb = r.get(f"{col}_a"), r.get(f"{col}_b")
            if va is None or vb is None or (pd.isna(va) and pd.isna(vb)):
                continue
            rows.append({**{k: r[k] for k in keys}, "column": col, "a": va, "b": vb, "difference": vb - va})
    return pd.DataFrame(rows)


def _interval(r) -> str:
    return f"{fmt(r.difference)} [{fmt(r.difference_low)}, {fmt(r.difference_high)}]"


def compare_text(a: Run, b: Run, diffs: pd.DataFrame) -> str:
    """What ``bench compare`` prints (and writes as compare.md): the rows over all
    levels, then the per-level rows that changed significantly."""
    overall = diffs[diffs.snr_db.isna()]
    paired = "paired (the runs share their trials)" if overall.paired.all() else \
        "unpaired (the runs do not share their trials)" if not overall.paired.any() else "paired where they share trials"
    head = ["scenario config", "config", "metric", "A", "B", "B − A [CI]", "paired", "change"]
    rows = [[r.scenario, r.config, r.metric, fmt(r.mean_a), fmt(r.mean_b), _interval(r), "yes" if r.paired else "no",
             f"**{r.change}**" if r.significant else r.change] for r in overall.itertuples()]
    level = overall.confidence.iloc[0]
    per = diffs[diffs.snr_db.notna() & diffs.significant]
    out = [f"# bench compare\n\nA = {code(a.path)} ({text(a.name)}), B = {code(b.path)} ({text(b.name)}); "
           f"{len(overall)} (scenario config, method config) matched, {paired}. Intervals over all common SNR levels at "
           f"{level:.4g} (95% Bonferroni-adjusted over the {len(overall)} rows); per level at 95%.",
           table(head, rows)]
    if len(per):
        out.append("Significant changes at single SNR levels:\n\n" + table(
            ["scenario config", "config", "SNR (dB)", "A", "B", "B − A [95% CI]", "change"],
            [[r.scenario, r.config, fmt_db(r.snr_db), fmt(r.mean_a), fmt(r.mean_b), _interval(r), r.change]
             for r in per.itertuples()]))
    else:
        out.append("No significant change at any single SNR level.")
    return "\n\n".join(out) + "\n"


def run_compare(path_a: str, path_b: str, out: str | None, fail_on_regression: bool) -> int:
    """The command: prints the comparison, writes it into ``out`` if given; the exit code."""
    a, b = load_run(path_a), load_run(path_b)
    diffs = compare_runs(a, b)
    shown = escape_controls(compare_text(a, b, diffs))     # a terminal obeys no escape from a store
    print(shown, end="")
    if out:
        from bench import runfolder
        folder = Path(out)
        folder.mkdir(parents=True, exist_ok=True)
        runfolder.write_text(folder / "compare.csv", diffs.to_csv(index=False, lineterminator="\n"))
        runfolder.write_text(folder / "compare_summary.csv",
                             summary_changes(a, b).to_csv(index=False, lineterminator="\n"))
        runfolder.write_text(folder / "compare.md", shown)
        print(f"wrote {folder / 'compare.csv'}, compare_summary.csv and compare.md")
    overall = diffs[diffs.snr_db.isna()]
    regressed = overall[overall.change == "worse"]
    if fail_on_regression and len(regressed):
        names = ", ".join(f"{r.config} on {r.scenario}" for r in regressed.itertuples())
        import sys
        print(f"regression: {names} got significantly worse", file=sys.stderr)
        return EXIT_REGRESSION
    return 0
