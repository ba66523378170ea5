"""Outputs of a run, all rebuilt from ``results.sqlite`` (``bench report DIR``).

Writes ``trials.csv``, ``summary.csv``, ``calibration.csv``, ``steps.csv``
(per-step RMSE of trackers and TBD methods), ``report.md``, ``figures/*.png``
and ``recording.rrd``. The sections of each task live with it: detection
here, :mod:`bench.report_tbd`, :mod:`bench.report_tracking`. Every file is written to a temporary
name and renamed, so no reader ever sees a half-written output.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from bench import figures, report_tbd, report_tracking
from bench.core import MANEUVER_DETECTION, TBD, TRACKING
from bench.errors import ConfigError
from bench.calibration import EQUAL_CHANCE_PD
from bench.markdown import fmt as _fmt
from bench.markdown import fmt_crossing as _fmt_crossing
from bench.markdown import snr50 as _snr50
from bench.markdown import table as _table
from bench.metrics import equal_chance_pd, per_step_rmse, roc_curve, tracking_steps
from bench.provenance import provenance
from bench.recording import TrialRecord, write_recording
from bench.runner import calibrations
from bench.store import Store
from bench.tasks import handler

TRIAL_KEYS = ["scenario", "method", "config", "params", "snr_db", "trial", "seed", "realised_snr_db",
              "threshold"]
SUMMARY_COLUMNS = ["scenario", "method", "config", "params", "snr_db", "n_trials", "pd", "pd_low", "pd_high",
                   "pfa", "pfa_low", "pfa_high", "delay_mean", "delay_low", "delay_high", "delay_median",
                   "rmse_mean", "rmse_low", "rmse_high", "seconds_per_trial", "threshold", "realised_snr_db",
                   "divergence_rate", "divergence_low", "divergence_high", "nees_mean",
                   "pd_step", "pd_step_low", "pd_step_high",
                   "pd_equal_chance", "pd_equal_chance_low", "pd_equal_chance_high",
                   "rmse_all_mean", "rmse_all_low", "rmse_all_high", "snr_offset_unit_innovation_db"]


def _write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def _write_csv(df: pd.DataFrame, path: Path) -> None:
    _write_text(path, df.to_csv(index=False, float_format=None, lineterminator="\n"))


def _scenario_order(record: dict) -> dict[str, int]:
    """Scenario config label -> its position in the sweep (tables follow the sweep's order)."""
    return {sc["label"]: i for i, sc in enumerate(record["scenarios"])}


def trials_frame(store: Store, record: dict) -> tuple[pd.DataFrame, dict]:
    """One row per (scenario config, method config, SNR, trial), in a fixed
    order, and the series: ``{(scenario, config, snr_db): {name: (n, K)}}``
    with rows in trial order."""
    info = {m["label"]: m for m in record["methods"]}
    frames = []
    parts: dict[tuple, list] = {}
    for _unit, label, scenario, snr, cols in store.iter_metrics():
        two_d = {k: v for k, v in cols.items() if np.ndim(v) == 2}
        if two_d:
            parts.setdefault((scenario, label, snr), []).append((cols["trial"], two_d))
        df = pd.DataFrame({k: v for k, v in cols.items() if np.ndim(v) == 1})
        df.insert(0, "scenario", scenario)
        df.insert(1, "method", info[label]["name"])
        df.insert(2, "config", label)
        df.insert(3, "params", info[label]["params"])
        df.insert(4, "snr_db", snr)
        frames.append(df)
    series = {}
    for key, chunks in parts.items():
        order = np.argsort(np.concatenate([t for t, _ in chunks]), kind="stable")
        series[key] = {name: np.concatenate([c[name] for _, c in chunks])[order] for name in chunks[0][1]}
    if not frames:
        return pd.DataFrame(columns=TRIAL_KEYS), series
    df = pd.concat(frames, ignore_index=True)
    order = {m["label"]: i for i, m in enumerate(record["methods"])}
    df = df.assign(_s=df.scenario.map(_scenario_order(record)), _o=df.config.map(order))
    df = df.sort_values(["_s", "_o", "snr_db", "trial"])
    rest = [c for c in df.columns if c not in TRIAL_KEYS and c not in ("_o", "_s")]
    return df[TRIAL_KEYS + rest].reset_index(drop=True), series


def _add_equal_chance_pd(summary: pd.DataFrame, trials: pd.DataFrame, cal) -> None:
    """Pd of each SNR level at the calibration's window threshold (same chance Pd for every detector)."""
    mine = trials[(trials.scenario == cal.scenario) & (trials.config == cal.method)]
    for snr, g in mine.groupby("snr_db"):
        rows = (summary.scenario == cal.scenario) & (summary.config == cal.method) & (summary.snr_db == snr)
        for col, value in equal_chance_pd(g["peak_statistic"], cal.equal_chance_threshold).items():
            summary.loc[rows, col] = value


def summary_frame(trials: pd.DataFrame, series: dict, runs: pd.DataFrame, record: dict,
                  cals=()) -> pd.DataFrame:
    """One row per (scenario config, method config, SNR). For TBD configs the
    Pfa columns are the scene Pfa of the threshold used, measured on the
    calibration null scenes."""
    tasks = {m["label"]: m["task"] for m in record["methods"]}
    parts = [handler(task).summarise(g, series) for task, g in trials.groupby(trials.config.map(tasks))] \
        if len(trials) else []
    summary = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=SUMMARY_COLUMNS)
    summary = summary.reindex(columns=list(dict.fromkeys([*SUMMARY_COLUMNS, *summary.columns])))
    for c in cals:
        rows = (summary.scenario == c.scenario) & (summary.config == c.method)
        if tasks.get(c.method) == TBD and rows.any():
            summary.loc[rows, ["pfa", "pfa_low", "pfa_high"]] = [c.used_pfa, c.used_pfa_low, c.used_pfa_high]
        if tasks.get(c.method) == MANEUVER_DETECTION and rows.any():
            _add_equal_chance_pd(summary, trials, c)
    ev = runs[(runs.phase == "evaluation") & runs.error.isna()]
    speed = ev.groupby(["scenario", "method", "snr_db"]).agg(s=("seconds", "sum"), n=("n", "sum"))
    speed = (speed.s / speed.n).rename("seconds_per_trial").reset_index().rename(columns={"method": "config"})
    summary = summary.drop(columns="seconds_per_trial").astype({"scenario": str, "config": str, "snr_db": float})
    summary = summary.merge(speed.astype({"scenario": str, "config": str, "snr_db": float}),
                            on=["scenario", "config", "snr_db"], how="left")
    order = {m["label"]: i for i, m in enumerate(record["methods"])}
    summary = summary.assign(_s=summary.scenario.map(_scenario_order(record)), _o=summary.config.map(order))
    summary = summary.sort_values(["_s", "_o", "snr_db"])
    return summary[SUMMARY_COLUMNS].reset_index(drop=True)


def steps_frame(trials: pd.DataFrame, series: dict, record: dict, t_of: dict) -> pd.DataFrame:
    """Per (scenario, config, SNR, step): position RMSE (TBD: over detected
    trials, and ``rmse_position_all`` over every trial) and, for trackers,
    RMSE and mean estimate vs truth per component."""
    tasks = {m["label"]: m["task"] for m in record["methods"]}
    rows = []
    for (scenario, config, snr), cols in series.items():
        g = trials[(trials.scenario == scenario) & (trials.config == config) & (trials.snr_db == snr)]
        if tasks.get(config) == TBD:
            detected = g["detected"].to_numpy(bool)
            df = pd.DataFrame({"rmse_position": per_step_rmse(cols["sq_err_m2"][detected]),
                               "n_trials": int(detected.sum()),
                               "rmse_position_all": per_step_rmse(cols["sq_err_m2"])})
        elif tasks.get(config) == TRACKING:
            labels = [k[len("est_"):] for k in cols if k.startswith("est_")]
            df = tracking_steps(cols, labels).assign(n_trials=len(g))
        else:
            continue
        t = t_of.get(scenario)
        df.insert(0, "t", t[:len(df)] if t is not None and len(t) >= len(df) else np.nan)
        df.insert(0, "step", np.arange(len(df)))
        for i, (k, v) in enumerate([("scenario", scenario), ("method", g.method.iloc[0] if len(g) else ""),
                                    ("config", config), ("snr_db", snr)]):
            df.insert(i, k, v)
        rows.append(df)
    if not rows:
        return pd.DataFrame()
    order = {m["label"]: i for i, m in enumerate(record["methods"])}
    out = pd.concat(rows, ignore_index=True)
    out = out.assign(_s=out.scenario.map(_scenario_order(record)), _o=out.config.map(order))
    return out.sort_values(["_s", "_o", "snr_db", "step"]).drop(columns=["_s", "_o"]).reset_index(drop=True)


# ------------------------------------------------------------------ report sections

def _snr_text(snr: list) -> str:
    if len(snr) > 2:
        return f"{_fmt(snr[0])} to {_fmt(snr[-1])} dB ({len(snr)} levels)"
    return ", ".join(f"{_fmt(x)} dB" for x in snr)


def _section_plan(record: dict, store: Store) -> str:
    sweep = record["sweep"]
    cal = sweep["calibration"]
    rows = [["seed", sweep["seed"]], ["trials per unit (chunk)", sweep["chunk"]],
            ["calibration", f"{cal['mode']}, requested Pfa {cal['pfa']:g} (per step for detectors, per scene "
                            f"for TBD), {cal['h0_trials']} null trials per scenario config"]]
    scenarios = [[f"`{sc['label']}`", sc["name"], ", ".join(sc.get("tasks", [])), sc["params"] or "defaults",
                  _snr_text(sc.get("snr_db", sweep.get("snr_db", []))), sc.get("trials", sweep.get("trials"))]
                 for sc in record["scenarios"]]
    methods = [[f"`{m['label']}`", m["name"], m["task"],
                ", ".join(f"{k}={v}" for k, v in sweep["methods"][i]["params"].items())]
               for i, m in enumerate(record["methods"])]
    definition = store.meta("snr_definition") or "see the scenario's documentation"
    return "\n\n".join([
        "## What was run",
        _table(["scenario config", "scenario", "tasks", "parameters set", "SNR", "trials per level"], scenarios),
        _table(["", ""], rows),
        f"**SNR definition.** {definition}",
        "Every method config runs on the same generated trials of each scenario config that serves its "
        "task (common random numbers); trial *i* sees the same noise at every SNR level. The resolved "
        "sweep is `plan.toml` next to this report.",
        _table(["config", "method", "task", "resolved parameters"], methods),
    ])


def _section_calibration(cals, summary: pd.DataFrame, tasks: dict[str, str]) -> str:
    if not cals:
        return ""
    measured = summary.groupby("config").agg(fa_pfa=("pfa", "mean"))
    rows = []
    for c in cals:
        in_eval = measured.fa_pfa.get(c.method, np.nan) if tasks.get(c.method) == MANEUVER_DETECTION else np.nan
        rows.append([f"`{c.method}`", c.mode, f"{c.pfa:g} {handler(tasks[c.method]).pfa_unit}",
                     _fmt(c.nominal, 4),
                     f"{_fmt(c.nominal_pfa)} [{_fmt(c.nominal_pfa_low)}, {_fmt(c.nominal_pfa_high)}]",
                     _fmt(c.used, 4), f"{_fmt(c.used_pfa)} [{_fmt(c.used_pfa_low)}, {_fmt(c.used_pfa_high)}]",
                     _fmt(in_eval), f"{_fmt(c.chance_pd)} [{_fmt(c.chance_pd_low)}, {_fmt(c.chance_pd_high)}]",
                     f"{c.null_values:,}"])
    header = ["config", "mode", "requested Pfa", "nominal threshold", "measured Pfa of nominal [95% CI]",
              "threshold used", "measured Pfa of the threshold used [95% CI]", "Pfa in evaluation",
              "chance Pd [95% CI]", "null values"]
    empty = {"–", "– [–, –]"}
    keep = [j for j in range(len(header)) if any(r[j] not in empty for r in rows)]
    detectors = any(tasks.get(c.method) == MANEUVER_DETECTION for c in cals)
    return "\n\n".join([
        "## Calibration",
        "Thresholds are applied by the harness, so every method is compared at the same false-alarm "
        "rate: per step for detectors, per scene for track-before-detect. *Measured Pfa of nominal* is "
        "the fraction of null-hypothesis values (separate calibration trials; detectors: all steps after "
        "warm-up; TBD: one scene score per null scene) at or above the method's own analytic threshold "
        "(– where the method has none), with its 95% interval; *empirical* thresholds are the "
        "(1 − Pfa) quantile of the same values, *gumbel* ones the quantile of a Gumbel law fitted to them. "
        "*Measured Pfa of the threshold used* is on the same null values (by construction at most the "
        "requested Pfa for *empirical*; an honest check of the tail fit for *gumbel*). *Pfa in "
        "evaluation* is the per-step false-alarm rate measured before the maneuver onset in the "
        "evaluation trials, averaged over SNR levels. *Chance Pd* is how often the detection rule fires "
        "on null trials (no maneuver) within the detection window: the floor Pd falls to as SNR goes "
        "down, drawn as a dotted line in the Pd figure.",
        _table([header[j] for j in keep], [[r[j] for j in keep] for r in rows]),
        "Per-step Pfa intervals (here and in summary.csv) are counted over trials, the independent "
        "units: a window statistic's alarms cluster within a trial, so its interval is wider than one "
        "that treats steps as independent (ratio-estimator variance over trials, Student's quantile on "
        "the trials that alarmed). Scene Pfa (TBD) has one value per scene: Wilson's interval." if detectors else "",
    ])


def _section_detection(summary: pd.DataFrame, fig_dir: Path, title: str, pfa: float,
                       chance: dict[str, float]) -> str:
    if summary.empty:
        return "## Detection\n\nNo results."
    figures.pd_vs_snr(summary, fig_dir / "pd_vs_snr.png", pfa, title, chance)
    figures.delay_vs_snr(summary, fig_dir / "delay_vs_snr.png", title)
    snr = summary.snr_db
    rows = []
    for c in _snr50(summary).itertuples():
        last = summary[summary.config == c.config].sort_values("snr_db").iloc[-1]
        rows.append([f"`{c.config}`", _fmt_crossing(c.mid, snr), f"[{_fmt_crossing(c.low, snr)}, "
                     f"{_fmt_crossing(c.high, snr)}]", f"{_fmt(last.pd)} at {_fmt(last.snr_db)} dB",
                     _fmt(last.delay_mean)])
    detail = summary.pivot_table(index="snr_db", columns="config", values="pd", sort=False)
    detail_rows = [[_fmt(s)] + [_fmt(v) for v in r] for s, r in zip(detail.index, detail.to_numpy())]
    return "\n\n".join([
        "## Detection probability",
        "![Pd vs SNR](figures/pd_vs_snr.png)",
        "SNR at which Pd = 0.5, interpolated linearly between levels; the interval is where the 95% "
        "Pd band crosses 0.5. `< x` / `> x`: the crossing lies outside the swept range.",
        _table(["config", "SNR at Pd = 0.5 (dB)", "interval (dB)", "Pd at the highest SNR",
                "mean delay there (steps)"], rows),
        "<details><summary>Pd per SNR level</summary>\n\n" +
        _table(["SNR (dB)"] + [f"`{c}`" for c in detail.columns], detail_rows) + "\n\n</details>",
        "## Detection delay",
        "![delay vs SNR](figures/delay_vs_snr.png)",
        "Delay = first alarm at or after the onset minus the onset, over detected trials only.",
    ])


def _section_ranking(summary: pd.DataFrame) -> str:
    """Method families ordered by the lowest SNR at which any of their configs reaches Pd = 0.5."""
    best = _snr50(summary).sort_values("order", kind="stable").drop_duplicates("method")
    lead = best.order.iloc[0]
    table = [[f"{rank}", f"`{b.method}`", f"`{b.config}`", _fmt_crossing(b.mid, summary.snr_db),
              f"{b.order - lead:+.2g}" if np.isfinite(b.order) and np.isfinite(lead) else "–"]
             for rank, b in enumerate(best.itertuples(), start=1)]
    return "\n\n".join([
        "## Ranking of methods",
        "Each method at its best config in this sweep, by the SNR at which Pd reaches 0.5 "
        "(all at the same calibrated per-step Pfa).",
        _table(["rank", "method", "best config", "SNR at Pd = 0.5 (dB)", "dB behind the first"], table),
    ])


PD_DEFINITIONS = (("pd", "any alarm in the window"), ("pd_step", "per-step average"),
                  ("pd_equal_chance", "equal chance Pd"))


def _section_pd_definitions(summary: pd.DataFrame, chance_pd: float) -> str:
    """SNR at Pd = 0.5 and the rank of every config under each Pd definition."""
    if summary.empty or summary.pd_step.isna().all():
        return ""
    cells, ranks = {}, {}
    for column, _ in PD_DEFINITIONS:
        s = _snr50(summary, column)
        ranks[column] = dict(zip(s.config, s.order.rank(method="min")))
        cells[column] = {b.config: _fmt_crossing(b.mid, summary.snr_db) for b in s.itertuples()}
    configs = list(dict.fromkeys(summary.config))
    rows = [[f"`{c}`"] + [f"{cells[col][c]} (#{int(ranks[col][c])})" for col, _ in PD_DEFINITIONS]
            for c in configs]
    return "\n\n".join([
        "## Pd under three definitions",
        "SNR at Pd = 0.5 (dB) and rank, per config. *Any alarm in the window*: a trial is detected if "
        "any step of the detection window after the onset alarms at the per-step threshold (the columns "
        "`pd*` of summary.csv). *Per-step average*: the fraction of the window's steps that alarm, "
        "averaged over trials (`pd_step*`; the cumulant paper's 平均检测概率, \"average detection "
        "probability\", Fig. 3, reads most naturally this way). *Equal chance Pd*: every detector's "
        f"threshold is set on the null trials' window peaks so that it alarms in {chance_pd:g} of "
        "null trials' windows (a per-trial false-alarm rate), then a trial is detected if its window peak "
        "reaches it (`pd_equal_chance*`). The first definition favours statistics that are white from step "
        "to step (a single-step test gets about one chance per step, see the chance Pd above); the other two "
        "do not.",
        _table(["config"] + [name for _, name in PD_DEFINITIONS], rows),
    ])


def _section_roc(store: Store, trials: pd.DataFrame, summary: pd.DataFrame, fig_dir: Path, title: str,
                 pfa: float) -> str:
    """ROC at the SNR level where the configs' mean Pd is closest to 0.5."""
    if summary.empty or "peak_statistic" not in trials:
        return ""
    mean_pd = summary.groupby("snr_db").pd.mean()
    snr = float((mean_pd - 0.5).abs().idxmin())
    curves = {}
    for (scenario, label), g in trials[trials.snr_db == snr].groupby(["scenario", "config"], sort=False):
        null, _peaks, _nominal = store.null_values(scenario, label)
        if null.size:
            curves[label] = roc_curve(null, g.peak_statistic.to_numpy())
    if not curves:
        return ""
    figures.roc(curves, fig_dir / "roc.png", snr, pfa, title)
    return "\n\n".join([
        "## ROC",
        f"Pd against per-step Pfa at {_fmt(snr)} dB, the level where the configs' mean Pd is closest to "
        "0.5, computed from the stored statistics without re-running: Pfa from the calibration null "
        "values, Pd from each trial's peak statistic in the detection window.",
        "![ROC](figures/roc.png)",
    ])


def _section_runtime(runs: pd.DataFrame, units: pd.DataFrame, fig_dir: Path, record: dict) -> str:
    ev = runs[runs.error.isna()]
    if ev.empty:
        return "## Runtime\n\nNo successful runs."
    per = ev.groupby("method").agg(seconds=("seconds", "sum"), n=("n", "sum")).reset_index()
    per["seconds_per_trial"] = per.seconds / per.n
    order = {m["label"]: i for i, m in enumerate(record["methods"])}
    per = per.rename(columns={"method": "config"}).assign(_o=lambda d: d.config.map(order)).sort_values("_o")
    figures.runtime(per, fig_dir / "runtime.png")
    gen = units.generate_seconds.sum() / units.n.sum()
    rows = [[f"`{r.config}`", f"{r.seconds_per_trial * 1e3:.3g}", f"{r.n:,}", f"{r.seconds:.3g}"]
            for r in per.itertuples()]
    return "\n\n".join([
        "## Runtime",
        "![runtime](figures/runtime.png)",
        _table(["config", "ms per trial", "trials run", "total seconds"], rows),
        f"Scenario generation: {gen * 1e3:.3g} ms per trial. Times are per unit, on one core each.",
    ])


def _section_failures(runs: pd.DataFrame) -> str:
    bad = runs[runs.error.notna()]
    if bad.empty:
        return "## Failures\n\nNone: every method config ran on every unit."
    rows = [[f"`{r.method}`", r.phase, "null" if pd.isna(r.snr_db) else _fmt(r.snr_db), f"`{r.unit}`",
             str(r.error).replace("|", "\\|")[:300]] for r in bad.head(50).itertuples()]
    more = f"\n\n… and {len(bad) - 50} more (see `results.sqlite`, table `runs`)." if len(bad) > 50 else ""
    return "## Failures\n\n" + _table(["config", "phase", "SNR (dB)", "unit", "error"], rows) + more


def _section_provenance(record: dict, store: Store, prov: dict) -> str:
    rows = [["command", f"`{record.get('command', '')}`"], ["sweep file", f"`{record.get('source', '')}`"],
            ["plan fingerprint", f"`{store.meta('fingerprint')}`"]]
    wall = store.meta("last_wall_seconds")
    if wall:
        rows.append(["wall time of the units in the last `bench run` (before report and recording)",
                     f"{float(wall):.1f} s"])
    rows += [[k, v] for k, v in prov.items()]
    return "## Provenance\n\n" + _table(["", ""], rows)


RECORDING_TEXT = """## Recording

`recording.rrd` holds the first {n} trial(s) of every SNR level of each scenario config, on the
timelines `step` and `time`: the true and measured positions (2D, y negated so north is up); per
detector the statistic, the threshold in force and the alarms; per tracker the estimated trajectory
and its error per state component, with glint-corrupted measurements marked; per TBD method the
frames as heatmaps with the true and backtracked tracks, the last-frame value map and the scene
score against its threshold. Pd and RMSE against SNR per config are under `/summary`. Open it with
`bench view {out}` or `rerun {out}/recording.rrd`."""


def preset_notes(source: str) -> str:
    """The packaged notes of a preset (``bench/presets/NAME.md``), if any."""
    import importlib.resources
    if not source.startswith("preset "):
        return ""
    path = importlib.resources.files("bench") / "presets" / f"{source.split(' ', 1)[1]}.md"
    return path.read_text(encoding="utf-8").strip() if path.is_file() else ""


def build_outputs(out_dir: Path, *, recording: bool = True) -> Path:
    """(Re)build every output of a run folder from its store; returns report.md's path."""
    out_dir = Path(out_dir)
    db = out_dir / "results.sqlite"
    if not db.exists():
        raise ConfigError("", f"{out_dir} has no results.sqlite (not a bench run folder)")
    store = Store(db)
    try:
        return _build(store, out_dir, recording)
    finally:
        store.close()


def _detection_parts(store, trials, summary, cals, fig_dir, title, pfa, chance_pd) -> list[str]:
    if summary.empty:
        return []
    return [_section_detection(summary, fig_dir, title, pfa, {c.method: c.chance_pd for c in cals}),
            _section_ranking(summary), _section_pd_definitions(summary, chance_pd), _section_roc(store, trials, summary, fig_dir, title, pfa)]


def _timeline_parts(records, fig_dir: Path, title: str, snr_db: float | None = None) -> list[str]:
    """The statistic of each detector on one recorded trial: at the recorded SNR level
    nearest ``snr_db`` (the sweep's ``[record] timeline_snr_db``), else the highest."""
    records = [r for r in records if r.methods and all(m.statistic is not None for m in r.methods.values())]
    if not records:
        return []
    if snr_db is None:
        top = max(records, key=lambda r: (r.snr_db if r.snr_db is not None else -np.inf, -r.trial))
    else:
        top = min(records, key=lambda r: (abs(r.snr_db - snr_db) if r.snr_db is not None else np.inf, r.trial))
    figures.trial_timeline(top, fig_dir / "trial_timeline.png",
                           f"{title}: trial {top.trial} at {_fmt(top.snr_db)} dB")
    return ["## One trial over time",
            f"Statistic, threshold in force and alarms of each method on trial {top.trial} at "
            f"{_fmt(top.snr_db)} dB (symmetric-log scale).",
            "![one trial](figures/trial_timeline.png)"]


def _build(store: Store, out_dir: Path, recording: bool) -> Path:
    record = store.plan()
    sweep = record["sweep"]
    runs, units = store.runs(), store.units()
    trials, series = trials_frame(store, record)
    cals = calibrations(store, [s["label"] for s in record["scenarios"]], [m["label"] for m in record["methods"]],
                        sweep["calibration"]["pfa"], sweep["calibration"]["mode"],
                        sweep["calibration"].get("chance_pd", EQUAL_CHANCE_PD))
    summary = summary_frame(trials, series, runs, record, cals)
    t_of = {key[0]: cols["t_s"][0] for key, cols in series.items() if "t_s" in cols}
    steps = steps_frame(trials, series, record, t_of)
    _write_csv(trials, out_dir / "trials.csv")
    _write_csv(summary, out_dir / "summary.csv")
    _write_csv(pd.DataFrame([c.as_row() for c in cals]), out_dir / "calibration.csv")
    if not steps.empty:
        _write_csv(steps, out_dir / "steps.csv")
    fig_dir = out_dir / "figures"
    title = sweep["name"]
    pfa = sweep["calibration"]["pfa"]
    tasks = {m["label"]: m["task"] for m in record["methods"]}
    of_task = {task: summary[summary.config.map(tasks) == task] for task in (MANEUVER_DETECTION, TBD, TRACKING)}
    records = [TrialRecord.from_bytes(b) for b in store.records()]
    done, total = len(units), int(store.meta("units_total") or len(units))
    parts = [f"# {title}", sweep.get("description") or "",
             f"Reproduce with `{record.get('command', '')}`." +
             ("" if done >= total else f" **Incomplete run: {done} of {total} units stored.**"),
             preset_notes(record.get("source", "")),   # the paper-vs-ours table leads a preset's report
             _section_plan(record, store), _section_calibration(cals, summary, tasks)]
    parts += _detection_parts(store, trials, of_task[MANEUVER_DETECTION], cals, fig_dir, title, pfa,
                              sweep["calibration"].get("chance_pd", EQUAL_CHANCE_PD))
    parts += report_tbd.sections(of_task[TBD], steps, store, cals, fig_dir, title, pfa)
    parts += report_tracking.sections(of_task[TRACKING], steps, fig_dir, title)
    parts += _timeline_parts(records, fig_dir, title, sweep["record"].get("timeline_snr_db"))
    parts += [_section_runtime(runs, units, fig_dir, record), _section_failures(runs)]
    if recording and records:
        write_recording(out_dir / "recording.rrd", records, summary.assign(method=summary.config),
                        recording_id=f"{title}-{store.meta('fingerprint')}")
        parts.append(RECORDING_TEXT.format(n=sweep["record"]["trials"], out=out_dir))
    parts.append(_section_provenance(record, store, provenance()))
    report = out_dir / "report.md"
    _write_text(report, "\n\n".join(p for p in parts if p) + "\n")
    return report
