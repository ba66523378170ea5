"""``bench compare RUN_A RUN_B``: what changed between two runs (docs/architecture.md, 'Report').

Two run folders (before and after a change to a method, two machines, two
versions) are matched on scenario config label, method config label and SNR
level. For each match, the difference B − A of the task's ranking metric
(``Task.ranking_metric``: a per-trial column of trials.csv) with a 95%
bootstrap interval, per SNR level and over the common levels (each weighing
the same), on the trials both runs hold:

* *paired* when the two runs share trials — the same per-trial seeds (``seed``
  column) at the same (level, trial), which is what the same sweep seed and
  scenario config give — on those shared trials, so trial-to-trial noise cancels
  (:func:`bench.metrics.paired_difference`; McNemar's exact test too for a
  0/1 metric, as in the paired comparisons of a report); an incomplete run is so
  compared on the trials it holds, never on the other run's as well;
* *unpaired* otherwise (:func:`bench.metrics.unpaired_difference`).

Nothing is hidden. Before any ranking the two runs are checked for
comparability, and every difference is stated at the top: the calibration
(mode, Pfa, chance Pd, null trials), the SNR grids, the scenario configs'
parameters, a run that is incomplete, and the claims (``claims.csv``) whose
verdict differs. A calibrated config's ranking metric at two different
false-alarm levels (Pfa or calibration mode differ) is *not comparable*: no
interval, no "better". A method config that failed on every unit of a run is
listed as failed there; configs, scenario configs and SNR levels in one run
only are listed with their metrics (compare.csv, compare_summary.csv).

The summary metrics (the task's ``headline_columns`` of summary.csv) are listed
side by side with their difference, without an interval. A difference is
*significant* when its interval excludes 0 (and McNemar rejects, paired 0/1)
over at least two trials on each side. ``--fail-on-regression`` looks only at
the rows over all common levels, one per (scenario config, method config), with
Bonferroni-adjusted intervals (level 1 − 0.05/m for m such rows) so that a CI
gate over many configs does not fail by chance; it exits with
:data:`EXIT_REGRESSION` on a significant change for the worse, on a config
that ran in A and failed in B, and on a comparison that is not comparable.

Stores are opened read-only (:meth:`bench.results.store.Store` ``read_only``): compare
creates and changes no file in the run folders, which may be on read-only media.
"""

from __future__ import annotations

import sqlite3
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from radarbench.bench import registry
from radarbench.bench.calibration import EQUAL_CHANCE_PD
from radarbench.bench.errors import EXIT_REGRESSION, ConfigError
from radarbench.bench.escapes import escape_controls
from radarbench.bench.markdown import code, fmt, fmt_db, table, text
from radarbench.bench.metrics import CONFIDENCE, mcnemar_exact, paired_difference, stratified_mean, unpaired_difference
from radarbench.bench.report.glance import metric_values

COLUMNS = ["scenario", "task", "config", "metric", "snr_db", "paired", "n_a", "n_b", "mean_a", "mean_b",
           "difference", "difference_low", "difference_high", "confidence", "mcnemar_p", "significant", "change",
           "units_failed_a", "units_failed_b", "note"]
#: the calibration settings compared (the sweep's ``[calibration]``)
CALIBRATION_FIELDS = {"mode": "mode", "pfa": "Pfa", "chance_pd": "chance Pd", "h0_trials": "null trials"}
#: those that set the false-alarm level of a calibrated task's ranking metric: across a
#: difference in these, a Pd comparison is not comparable
LEVEL_FIELDS = ("mode", "pfa")
#: the changes of a pair compared with an interval
RANKED = ("better", "worse", "no significant change")
#: the changes ``--fail-on-regression`` fails on
REGRESSIONS = ("worse", "failed in B", "not comparable")


@dataclass
class Run:
    path: Path
    name: str
    record: dict               # the stored plan
    trials: pd.DataFrame
    summary: pd.DataFrame
    runs: pd.DataFrame         # per (unit, method config): error or not (Store.runs)
    done: int                  # units stored
    total: int                 # units of the plan
    task_of: dict
    claims: pd.DataFrame       # claims.csv's id, claim, verdict (empty without one)

    def pairs(self) -> list[tuple[str, str]]:
        """The (scenario config, method config) pairs of the plan, in the sweep's order
        (those the methods refused left out), and any the store holds besides."""
        skipped = {(p["scenario"], p["method"]) for p in self.record.get("skipped_pairs", [])}
        planned = [(sc["label"], m["label"]) for sc in self.record["scenarios"] for m in self.record["methods"]
                   if m["task"] in sc.get("tasks", [m["task"]]) and (sc["label"], m["label"]) not in skipped]
        stored = zip(self.runs.scenario, self.runs.method)
        return list(dict.fromkeys([*planned, *stored]))

    def failures(self, scenario: str, config: str) -> tuple[int, int, str]:
        """(units run, units failed, the first failure's error) of a pair in this run."""
        r = self.runs[(self.runs.scenario == scenario) & (self.runs.method == config)]
        bad = r[r.error.notna()]
        return len(r), len(bad), str(bad.error.iloc[0]) if len(bad) else ""

    def _scenario(self, scenario: str) -> dict:
        return next((s for s in self.record["scenarios"] if s["label"] == scenario), {})

    def levels(self, scenario: str) -> list[float]:
        return [float(x) for x in self._scenario(scenario).get("snr_db", self.record["sweep"].get("snr_db", []))]

    def trials_per_level(self, scenario: str):
        return self._scenario(scenario).get("trials", self.record["sweep"].get("trials"))

    def calibration(self) -> dict:
        cal = self.record["sweep"].get("calibration", {})
        return {k: cal.get(k, EQUAL_CHANCE_PD if k == "chance_pd" else None) for k in CALIBRATION_FIELDS}


def read_claims(root: Path) -> pd.DataFrame:
    """claims.csv's id, claim and verdict columns; empty when the folder has none (or an
    unreadable one): claims are compared only where both runs computed them."""
    try:
        df = pd.read_csv(root / "claims.csv", dtype=str, keep_default_na=False)
    except (OSError, ValueError):        # absent, empty or not CSV
        df = pd.DataFrame()
    if not {"id", "verdict"} <= set(df.columns):
        return pd.DataFrame(columns=["id", "claim", "verdict"])
    return df.reindex(columns=["id", "claim", "verdict"]).fillna("")


def load_run(path: str | Path) -> Run:
    """A run folder's trials, summary and failures, all rebuilt from results.sqlite (opened
    read-only): any run folder the harness wrote compares, whether or not its report was
    built (``previous/``, an interrupted run); ConfigError (exit 2) unless it is a bench
    run folder."""
    from radarbench.bench.results import runfolder
    from radarbench.bench.report import store_tables
    from radarbench.bench.results.store import Store, store_fault
    root = Path(path)
    if not root.is_dir():
        raise ConfigError("", f"{root} is not a folder (expected a bench run folder)")
    db = root / runfolder.STORE
    if not db.exists():
        raise ConfigError("", f"{root} has no {runfolder.STORE} (not a bench run folder)")
    runfolder.check_store(db, need_plan=True)
    store = Store(db, read_only=True)
    try:
        record = store.plan()
        runs, done = store.runs(), len(store.units())
        trials, _series, _cals, summary = store_tables(store, record, runs)
        total = int(store.meta("units_total") or done)
    except sqlite3.Error as exc:
        raise store_fault(db, exc) from None
    finally:
        store.close()
    task_of = {m["label"]: registry.get_task(m["task"]) for m in record["methods"]}
    return Run(root, record["sweep"]["name"], record, trials, summary, runs, done, total, task_of,
               read_claims(root))


# ------------------------------------------------------------------ comparability

def calibration_differences(a: Run, b: Run) -> dict[str, tuple]:
    """The calibration settings that differ: field -> (A's, B's)."""
    ca, cb = a.calibration(), b.calibration()
    return {k: (ca[k], cb[k]) for k in CALIBRATION_FIELDS if ca[k] != cb[k]}


def _scenario_params(run: Run) -> dict[str, dict]:
    """Scenario config label -> its resolved parameters (the stored ones as text when the
    scenario cannot be resolved here, e.g. a plugin that is not installed)."""
    from radarbench.bench.report import _resolved_scenario_params
    try:
        resolved = _resolved_scenario_params(run.record)
    except Exception:  # noqa: BLE001 - a plugin missing here: compare what the plan stored
        resolved = {}
    return {sc["label"]: {"scenario": sc["name"], **resolved.get(sc["label"], {"parameters": sc.get("params", "")})}
            for sc in run.record["scenarios"]}


def comparability_notes(a: Run, b: Run, matched: list[tuple[str, str]], calibrated: set) -> list[str]:
    """What differs between the runs besides the methods, one line each, for the top."""
    notes = []
    cal = calibration_differences(a, b)
    if cal and calibrated:
        text = "; ".join(f"{CALIBRATION_FIELDS[k]} {va} in A, {vb} in B" for k, (va, vb) in cal.items())
        level = set(cal) & set(LEVEL_FIELDS)
        notes.append(f"**Calibration differs**: {text}. " + (
            "The calibrated configs' ranking metric is at different false-alarm levels: **not comparable** "
            "(no interval, no ranking; `--fail-on-regression` fails)." if level else
            "The false-alarm level is the same; the thresholds are estimated from different null samples."))
    pa, pb = _scenario_params(a), _scenario_params(b)
    for scenario in dict.fromkeys(s for s, _ in matched):
        la, lb = a.levels(scenario), b.levels(scenario)
        if la != lb:
            common = len(set(la) & set(lb))
            notes.append(f"**SNR levels of {code(scenario)} differ**: A {_levels_text(la)}, B {_levels_text(lb)}; "
                         f"compared at the {_plural(common, 'common level')}, the others are listed as in one "
                         "run only.")
        ta, tb = a.trials_per_level(scenario), b.trials_per_level(scenario)
        if ta != tb:
            notes.append(f"**Trials per level of {code(scenario)} differ**: A {ta}, B {tb}; compared on the trials "
                         "both runs hold (n_a, n_b).")
        diff = {k: (pa[scenario].get(k), pb[scenario].get(k)) for k in {**pa[scenario], **pb[scenario]}
                if pa[scenario].get(k) != pb[scenario].get(k)}
        if diff:
            notes.append(f"**Scenario config {code(scenario)} differs**: " + ", ".join(
                f"{k} = {va} in A, {vb} in B" for k, (va, vb) in sorted(diff.items())) + ".")
    for side, run in (("A", a), ("B", b)):
        if run.done < run.total:
            notes.append(f"**{side} is incomplete**: {run.done} of {run.total} units stored; every comparison "
                         "is on the trials both runs hold (n_a, n_b).")
    return notes


def _plural(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _levels_text(levels: list[float]) -> str:
    return ", ".join(fmt_db(x) for x in levels) + " dB" if levels else "none"


def flipped_claims(a: Run, b: Run) -> pd.DataFrame:
    """The claims whose verdict differs between the runs (absent on one side counts), when
    both runs hold a claims.csv."""
    if a.claims.empty or b.claims.empty:
        return pd.DataFrame(columns=["id", "claim", "verdict_a", "verdict_b"])
    m = a.claims.merge(b.claims, on="id", how="outer", suffixes=("_a", "_b"))
    m = m.assign(claim=m.claim_a.fillna(m.claim_b), verdict_a=m.verdict_a.fillna("absent"),
                 verdict_b=m.verdict_b.fillna("absent"))
    return m[m.verdict_a != m.verdict_b][["id", "claim", "verdict_a", "verdict_b"]].reset_index(drop=True)


# ------------------------------------------------------------------ differences

def _numeric(s: pd.Series) -> np.ndarray:
    return metric_values(s).to_numpy(float)


def _shared_trials(a: pd.DataFrame, b: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame, bool]:
    """The trials both runs hold, paired: those with the same (level, trial, seed); if the
    runs share none (other seeds), all trials of the common levels, unpaired."""
    key = ["snr_db", "trial", "seed"]
    shared = a[key].merge(b[key], on=key)
    if len(shared):
        return a.merge(shared, on=key), b.merge(shared, on=key), True
    levels = set(a.snr_db) & set(b.snr_db)
    return a[a.snr_db.isin(levels)], b[b.snr_db.isin(levels)], False


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
    n_a, n_b = int(np.isfinite(va).sum()), int(np.isfinite(vb).sum())
    # one trial a side gives a bootstrap interval of zero width: no evidence of a change
    significant = bool(min(n_a, n_b) >= 2 and np.isfinite(low) and (low > 0 or high < 0)
                       and (not np.isfinite(p) or p < 1 - level))
    return {"n_a": n_a, "n_b": n_b, "mean_a": _mean(va), "mean_b": _mean(vb),
            "difference": diff, "difference_low": low, "difference_high": high, "confidence": level,
            "mcnemar_p": p, "significant": significant}


def _mean(values: np.ndarray) -> float:
    return float(np.nanmean(values)) if np.isfinite(values).any() else np.nan


def _one_side(g: pd.DataFrame, metric: str) -> tuple[int, float]:
    """(trials, mean over the levels, each weighing the same) of one run's trials."""
    values, snr = _numeric(g[metric]), g.snr_db.to_numpy()
    keep = np.isfinite(values)
    return int(keep.sum()), stratified_mean(values[keep], snr[keep]) if keep.any() else np.nan


def _side_means(a: Run, b: Run, scenario: str, config: str, metric: str) -> dict:
    """n_a, mean_a, n_b, mean_b of a pair not compared (each run on its own trials)."""
    out = {}
    for side, run in (("a", a), ("b", b)):
        g = _trials_of(run, scenario, config)
        out[f"n_{side}"], out[f"mean_{side}"] = _one_side(g, metric) if len(g) else (0, np.nan)
    return out


def _trials_of(run: Run, scenario: str, config: str) -> pd.DataFrame:
    return run.trials[(run.trials.scenario == scenario) & (run.trials.config == config)]


def _only_rows(run: Run, side: str, scenario: str, config: str, levels=None) -> list[dict]:
    """Rows of a pair (over its levels, then per level) or of some of its levels, in one run only."""
    task = run.task_of[config]
    g = _trials_of(run, scenario, config)
    key = {"scenario": scenario, "task": task.name, "config": config, "metric": task.ranking_metric,
           "paired": False, "change": f"only in {side}"}
    overall = levels is None
    cells = ([(np.nan, g)] if overall else []) + [(s, g[g.snr_db == s])
                                                  for s in (sorted(set(g.snr_db)) if overall else levels)]
    rows = []
    for snr, part in cells:
        n, mean = _one_side(part, task.ranking_metric) if len(part) else (0, np.nan)
        rows.append({**key, "snr_db": snr, f"n_{side.lower()}": n, f"mean_{side.lower()}": mean})
    return rows


def _status(run: Run, scenario: str, config: str, has_trials: bool) -> tuple[str, int, str]:
    """("ran" | "failed" | "not run", units failed, a note) of a pair in a run."""
    units, failed, error = run.failures(scenario, config)
    if has_trials:
        note = f"failed on {failed} of {units} units: {error}" if failed else ""
        return "ran", failed, note
    if failed:
        return "failed", failed, f"failed on every unit it ran ({failed}): {error}"
    return "not run", 0, "not run yet (the run is incomplete)" if run.done < run.total else "no trials"


def _failed_change(status_a: str, status_b: str) -> str:
    if status_a == status_b == "failed":
        return "failed in both"
    if "failed" in (status_a, status_b):
        return "failed in B" if status_b == "failed" else "failed in A"
    return "not run in " + ("A and B" if status_a == status_b else "B" if status_b == "not run" else "A")


def compare_runs(a: Run, b: Run) -> pd.DataFrame:
    """:data:`COLUMNS`: per (scenario config, method config) of either run, a row over
    the common SNR levels (``snr_db`` NaN), then one per level; pairs and levels in
    one run only as "only in A" / "only in B"; pairs that failed or did not run as such."""
    pairs_a, pairs_b = a.pairs(), b.pairs()
    same_task = (lambda c: c in a.task_of and c in b.task_of and a.task_of[c].name == b.task_of[c].name)
    ranked = (lambda run, c: bool(run.task_of[c].ranking_metric))
    matched = [p for p in pairs_a if p in pairs_b and same_task(p[1]) and ranked(a, p[1])]
    level_differs = bool(set(calibration_differences(a, b)) & set(LEVEL_FIELDS))
    status = {p: (_status(a, *p, len(_trials_of(a, *p)) > 0), _status(b, *p, len(_trials_of(b, *p)) > 0))
              for p in matched}
    compared = [p for p in matched if status[p][0][0] == status[p][1][0] == "ran"
                and not (level_differs and a.task_of[p[1]].calibrated)]
    overall_level = 1 - (1 - CONFIDENCE) / max(1, len(compared))  # Bonferroni over the rows the gate reads
    rows = []
    for scenario, config in pairs_a:
        if (scenario, config) not in matched and ranked(a, config):
            rows += _only_rows(a, "A", scenario, config)
    for scenario, config in pairs_b:
        if (scenario, config) not in matched and ranked(b, config):
            rows += _only_rows(b, "B", scenario, config)
    for p in matched:
        (sa, fa, note_a), (sb, fb, note_b) = status[p]
        failed = {"units_failed_a": fa, "units_failed_b": fb,
                  "note": "; ".join(f"{s}: {n}" for s, n in (("A", note_a), ("B", note_b)) if n)}
        if p in compared:
            rows += [{**r, **failed} for r in _matched_rows(a, b, *p, overall_level)]
        else:       # ran in both at different false-alarm levels, or failed / did not run in one
            task = a.task_of[p[1]]
            row = {"scenario": p[0], "task": task.name, "config": p[1], "metric": task.ranking_metric,
                   "snr_db": np.nan, "paired": False, **_side_means(a, b, *p, task.ranking_metric), **failed}
            if sa == sb == "ran":
                row.update(change="not comparable", note="; ".join(filter(None, [
                    "calibrated at different false-alarm levels", failed["note"]])))
            else:
                row["change"] = _failed_change(sa, sb)
            rows.append(row)
        if sa == sb == "ran":
            la, lb = set(_trials_of(a, *p).snr_db), set(_trials_of(b, *p).snr_db)
            rows += [{**r, "units_failed_a": fa, "units_failed_b": fb}
                     for side, run, only in (("A", a, la - lb), ("B", b, lb - la)) if only
                     for r in _only_rows(run, side, *p, sorted(only))]
    return pd.DataFrame(rows, columns=COLUMNS)


def _matched_rows(a: Run, b: Run, scenario: str, config: str, overall_level: float) -> list[dict]:
    task = a.task_of[config]
    ga, gb, paired = _shared_trials(_trials_of(a, scenario, config), _trials_of(b, scenario, config))
    key = {"scenario": scenario, "task": task.name, "config": config, "metric": task.ranking_metric,
           "paired": paired}
    levels = sorted(set(ga.snr_db) & set(gb.snr_db))
    cells = [(np.nan, ga, gb, overall_level)] + [(s, ga[ga.snr_db == s], gb[gb.snr_db == s], CONFIDENCE)
                                                  for s in levels]
    rows = []
    for snr, xa, xb, level in cells:
        row = {**key, "snr_db": snr, **_difference(xa, xb, task.ranking_metric, paired, task.ranking_binary, level)}
        worse = (row["difference"] < 0) == task.ranking_higher_is_better
        row["change"] = ("worse" if worse else "better") if row["significant"] else "no significant change"
        rows.append(row)
    return rows


def summary_changes(a: Run, b: Run) -> pd.DataFrame:
    """The tasks' headline summary columns (their interval bounds left out) of every
    (scenario config, method config, SNR) of either run, side by side: A, B, B − A (a
    row of one run only has the other side empty)."""
    if a.summary.empty and b.summary.empty:
        return pd.DataFrame()
    keys = ["scenario", "config", "snr_db"]
    m = a.summary.merge(b.summary, on=keys, how="outer", suffixes=("_a", "_b"))
    rows = []
    for r in m.itertuples(index=False):
        r = r._asdict()
        task = a.task_of.get(r["config"]) or b.task_of.get(r["config"])
        for col in (c for c in (task.headline_columns if task else ()) if not c.endswith(("_low", "_high"))):
            va, vb = r.get(f"{col}_a"), r.get(f"{col}_b")
            if va is None or vb is None or (pd.isna(va) and pd.isna(vb)):
                continue
            rows.append({**{k: r[k] for k in keys}, "column": col, "a": va, "b": vb, "difference": vb - va})
    return pd.DataFrame(rows)


# ------------------------------------------------------------------ text

def _interval(r) -> str:
    return f"{fmt(r.difference)} [{fmt(r.difference_low)}, {fmt(r.difference_high)}]"


def _change(r) -> str:
    return f"**{r.change}**" if r.change in ("better", *REGRESSIONS) else r.change


def compare_text(a: Run, b: Run, diffs: pd.DataFrame) -> str:
    """What ``bench compare`` prints (and writes as compare.md): what makes the runs
    differ (comparability, claims), the rows over all levels of the pairs compared,
    those that failed or did not run, those in one run only, then the per-level rows
    that changed significantly."""
    matched = [(r.scenario, r.config) for r in diffs[~diffs.change.str.startswith("only in")].itertuples()]
    notes = comparability_notes(a, b, matched, {c for _, c in matched if a.task_of[c].calibrated})
    out = [f"# bench compare\n\nA = {code(a.path)} ({text(a.name)}), B = {code(b.path)} ({text(b.name)})."]
    if notes:
        out.append("\n".join(f"- {n}" for n in notes))
    flipped = flipped_claims(a, b)
    if len(flipped):
        out.append(f"**Claims whose verdict differs** ({len(flipped)}):\n\n" + table(
            ["claim", "", "A", "B"], [[code(r.id), text(r.claim), text(r.verdict_a), text(r.verdict_b)] for r in flipped.itertuples()]))
    overall = diffs[diffs.snr_db.isna()]
    ranked = overall[overall.change.isin(RANKED)]
    out += _ranked_text(ranked)
    rest = overall[~overall.index.isin(ranked.index) & ~overall.change.str.startswith("only in")]
    if len(rest):
        out.append("Not compared (failed, not run, or not comparable):\n\n" + table(
            ["scenario config", "config", "A", "B", "change", "why"],
            [[code(r.scenario), code(r.config), fmt(r.mean_a), fmt(r.mean_b), _change(r), text(r.note)]
             for r in rest.itertuples()]))
    failing = ranked[(ranked.units_failed_a > 0) | (ranked.units_failed_b > 0)]
    if len(failing):
        out.append("Compared on the units that ran; failed units:\n\n" + table(
            ["scenario config", "config", "failed in A", "failed in B", "first error"],
            [[code(r.scenario), code(r.config), r.units_failed_a, r.units_failed_b, text(str(r.note)[:300])]
             for r in failing.itertuples()]))
    only = diffs[diffs.change.str.startswith("only in")]
    if len(only):
        out.append("In one run only (configs, scenario configs, SNR levels), with their metric:\n\n" + table(
            ["in", "scenario config", "config", "SNR (dB)", "metric", "mean", "trials"],
            [[r.change[len("only in "):], code(r.scenario), code(r.config), "all" if pd.isna(r.snr_db) else fmt_db(r.snr_db),
              r.metric, fmt(r.mean_a if r.change.endswith("A") else r.mean_b),
              int(r.n_a if r.change.endswith("A") else r.n_b)] for r in only.itertuples()]))
    per = diffs[diffs.snr_db.notna() & (diffs.significant == True)]  # noqa: E712 - NaN on rows never compared
    if len(per):
        out.append("Significant changes at single SNR levels:\n\n" + table(
            ["scenario config", "config", "SNR (dB)", "A", "B", "B − A [95% CI]", "change"],
            [[code(r.scenario), code(r.config), fmt_db(r.snr_db), fmt(r.mean_a), fmt(r.mean_b), _interval(r), r.change]
             for r in per.itertuples()]))
    elif len(ranked):
        out.append("No significant change at any single SNR level.")
    return "\n\n".join(out) + "\n"


def _ranked_text(ranked: pd.DataFrame) -> list[str]:
    if ranked.empty:
        return ["No (scenario config, method config) ran in both runs comparably: nothing to rank."]
    paired = "paired (the runs share their trials)" if ranked.paired.all() else \
        "unpaired (the runs do not share their trials)" if not ranked.paired.any() else "paired where they share trials"
    head = ["scenario config", "config", "metric", "A", "B", "B − A [CI]", "trials (A, B)", "paired", "change"]
    rows = [[code(r.scenario), code(r.config), r.metric, fmt(r.mean_a), fmt(r.mean_b), _interval(r), f"{int(r.n_a)}, {int(r.n_b)}",
             "yes" if r.paired else "no", _change(r)] for r in ranked.itertuples()]
    level = ranked.confidence.iloc[0]
    return [f"{len(ranked)} (scenario config, method config) compared, {paired}. Intervals over all common SNR "
            f"levels at {level:.4g} (95% Bonferroni-adjusted over {_plural(len(ranked), 'row')}); per level at 95%.",
            table(head, rows)]


def regressions(diffs: pd.DataFrame) -> pd.DataFrame:
    """The rows ``--fail-on-regression`` fails on: over all levels, worse, not comparable,
    failed in B; or ran in A on every unit and failed in B on some."""
    overall = diffs[diffs.snr_db.isna()]
    newly_failing = (overall.units_failed_a == 0) & (overall.units_failed_b > 0)
    return overall[overall.change.isin(REGRESSIONS) | newly_failing]


def run_compare(path_a: str, path_b: str, out: str | None, fail_on_regression: bool) -> int:
    """The command: prints the comparison, writes it into ``out`` if given; the exit code."""
    a, b = load_run(path_a), load_run(path_b)
    diffs = compare_runs(a, b)
    shown = escape_controls(compare_text(a, b, diffs))     # a terminal obeys no escape from a store
    print(shown, end="")
    if out:
        from radarbench.bench.results import runfolder
        folder = Path(out)
        folder.mkdir(parents=True, exist_ok=True)
        runfolder.write_text(folder / "compare.csv", diffs.to_csv(index=False, lineterminator="\n"))
        runfolder.write_text(folder / "compare_summary.csv",
                             summary_changes(a, b).to_csv(index=False, lineterminator="\n"))
        runfolder.write_text(folder / "compare.md", shown)
        print(f"wrote {folder / 'compare.csv'}, compare_summary.csv and compare.md")
    regressed = regressions(diffs)
    if fail_on_regression and len(regressed):
        names = ", ".join(f"{r.config} on {r.scenario} ({r.change if r.change in REGRESSIONS else 'failed units in B'})"
                          for r in regressed.itertuples())
        print(f"regression: {names}", file=sys.stderr)
        return EXIT_REGRESSION
    return 0
