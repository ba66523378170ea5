"""Report sections of the maneuver-detection task (docs/architecture.md, 'Outputs of a run').

Pd against SNR at the calibrated per-step Pfa and the SNR at Pd = 0.5 per
config, the ranking of method families, Pd under three definitions (any
alarm in the window; the per-step average of the cumulant paper, Song, Ji &
Gao 2004; equal chance Pd), the detection delay, a ROC from the stored
statistics, and one recorded trial over time. Imported only when a report is
written (matplotlib).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from radarbench.bench import figures
from radarbench.bench.markdown import code, crossing_difference, crossing_floors, crossing_text, fmt, fmt_db, snr50, table
from radarbench.bench.results.store import Store
from radarbench.bench.tasks.base import ReportContext
from radarbench.bench.tasks.detection.metrics import roc_curve


def sections(ctx: ReportContext) -> list[str]:
    summary = ctx.summary
    if summary.empty:
        return []
    chance = {c.method: c.chance_pd for c in ctx.calibrations}
    floors = {k: v for k, v in chance.items() if np.isfinite(v)}
    return [_section_detection(summary, ctx.fig_dir, ctx.title, ctx.pfa, chance, floors, ctx.chance_pd),
            _section_ranking(summary, floors),
            _section_pd_definitions(summary, ctx.chance_pd, floors, ctx.fig_dir, ctx.title, ctx.pfa,
                                    {c.method: c.used_pfa for c in ctx.calibrations}),
            _section_roc(ctx.store, ctx.trials, summary, ctx.fig_dir, ctx.title, ctx.pfa)
            if getattr(ctx.task, "has_roc", False) else ""]


def _section_detection(summary: pd.DataFrame, fig_dir: Path, title: str, pfa: float,
                       chance: dict[str, float], floors: dict[str, float], chance_pd: float) -> str:
    """Pd against SNR: first at equal chance Pd (what the glance ranks on), then with any
    alarm in the window at the calibrated per-step Pfa (each detector's own chance Pd
    dotted), the SNR at Pd = 0.5 of the latter and the detection delay."""
    if summary.empty:
        return "## Detection\n\nNo results."
    fair = _equal_chance_figure(summary, fig_dir, title, chance_pd)
    figures.pd_vs_snr(summary, fig_dir / "pd_vs_snr.png", pfa, title, chance,
                      ylabel="$P_D$, any alarm in the window")
    figures.delay_vs_snr(summary, fig_dir / "delay_vs_snr.png", title)
    rows = []
    for c in snr50(summary, floors=floors).itertuples():
        last = summary[summary.config == c.config].sort_values("snr_db").iloc[-1]
        rows.append([code(c.config), *crossing_text(c.crossing), f"{fmt(last.pd)} at {fmt_db(last.snr_db)} dB",
                     fmt(last.delay_mean)])
    detail = summary.pivot_table(index="snr_db", columns="config", values="pd", sort=False)
    detail_rows = [[fmt_db(s)] + [fmt(v) for v in r] for s, r in zip(detail.index, detail.to_numpy())]
    return "\n\n".join([
        "## Detection probability",
        *fair,
        "![Pd vs SNR, any alarm in the window](figures/pd_vs_snr.png)",
        "Pd with any alarm in the window at the calibrated per-step Pfa; dotted: each detector's chance Pd "
        "(how often it alarms on null trials' windows).",
        SNR50_TEXT,
        table(["config", "SNR at Pd = 0.5 (dB)", "95% interval (dB)", "Pd at the highest SNR",
                "mean delay there (steps)"], rows),
        "<details><summary>Pd per SNR level</summary>\n\n" +
        table(["SNR (dB)"] + [code(c) for c in detail.columns], detail_rows) + "\n\n</details>",
        "## Detection delay",
        "![delay vs SNR](figures/delay_vs_snr.png)",
        "Delay = first alarm at or after the onset minus the onset, over detected trials only.",
    ])


def _equal_chance_figure(summary: pd.DataFrame, fig_dir: Path, title: str, chance_pd: float) -> list[str]:
    """The figure and caption of Pd at equal chance Pd against SNR; none where no config
    has that Pd (no null trials to set its thresholds on)."""
    if "pd_equal_chance" not in summary or summary.pd_equal_chance.isna().all():
        return []
    name = "pd_equal_chance_vs_snr.png"
    figures.pd_vs_snr(summary, fig_dir / name, float("nan"), title, {c: chance_pd for c in summary.config.unique()},
                      column="pd_equal_chance", ylabel="$P_D$ at equal chance $P_D$",
                      condition=f"at equal chance $P_D$ = {chance_pd:g}")
    return [f"![Pd at equal chance Pd vs SNR](figures/{name})",
            f"Pd with every detector's threshold set so that it alarms in {chance_pd:g} of null trials' windows "
            "(dotted): the basis *Results at a glance* ranks on."]


def _section_ranking(summary: pd.DataFrame, floors: dict[str, float]) -> str:
    """Method families ordered by the lowest SNR at which any of their configs reaches Pd = 0.5."""
    best = snr50(summary, floors=floors).sort_values("order", kind="stable").drop_duplicates("method")
    lead = best.crossing.iloc[0]
    rows = [[f"{rank}", code(b.method), code(b.config), *crossing_text(b.crossing),
              crossing_difference(lead, b.crossing),
              fmt(floors.get(b.config))]
            for rank, b in enumerate(best.itertuples(), start=1)]
    return "\n\n".join([
        "## Ranking of methods",
        "Each method at its best config in this sweep, by the SNR at which Pd reaches 0.5 "
        "(all at the same calibrated per-step Pfa).",
        table(["rank", "method", "best config", "SNR at Pd = 0.5 (dB)", "95% interval (dB)", "dB behind the first",
               "chance Pd"], rows),
    ])


SNR50_TEXT = (
    "SNR at which Pd = 0.5: a probit fit to the detections of every level, Pd(s) = c + (1 − c) Φ(b (s − s50) + z), "
    "with c the config's chance Pd (the floor; taken as known) and z placing Pd = 0.5 at s50; the 95% interval is "
    "the profile likelihood's. Where Pd jumps across 0.5 between two adjacent levels (from ≤ 10% to ≥ 90% of the "
    "way from the floor to 1) the levels do not resolve it: *between a and b*. `< x` / `> x`: the crossing lies "
    "outside the swept range.")

PD_DEFINITIONS = (("pd", "any alarm in the window"), ("pd_step", "per-step average"),
                  ("pd_equal_chance", "equal chance Pd"))


def _section_pd_definitions(summary: pd.DataFrame, chance_pd: float, floors: dict[str, float], fig_dir: Path,
                            title: str, pfa: float, step_chance: dict[str, float]) -> str:
    """SNR at Pd = 0.5 and the rank of every config under each Pd definition, and the
    per-step average Pd against SNR (the cumulant paper's Figs. 3-4, Song, Ji & Gao 2004;
    ``step_chance``: config -> measured per-step Pfa of its threshold, that Pd's level
    without a maneuver)."""
    if summary.empty or summary.pd_step.isna().all():
        return ""
    figures.pd_vs_snr(summary, fig_dir / "pd_step_vs_snr.png", pfa, f"{title}, per-step average", step_chance,
                      column="pd_step", ylabel="per-step average $P_D$ over the window")
    cells, ranks = {}, {}
    for column, _ in PD_DEFINITIONS:
        s = snr50(summary, column, crossing_floors(column, floors, chance_pd))
        ranks[column] = dict(zip(s.config, s.order.rank(method="min")))
        cells[column] = {b.config: crossing_text(b.crossing)[0] for b in s.itertuples()}
    configs = list(dict.fromkeys(summary.config))
    rows = [[code(c)] + [f"{cells[col][c]} (#{int(ranks[col][c])})" for col, _ in PD_DEFINITIONS]
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
        table(["config"] + [name for _, name in PD_DEFINITIONS], rows),
        "Per-step average Pd against SNR per config, with its 95% bootstrap band over trials; dotted, each "
        "config's per-step Pfa measured on null trials (this Pd's level without a maneuver).",
        "![per-step average Pd vs SNR](figures/pd_step_vs_snr.png)",
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
        f"Pd against per-step Pfa at {fmt_db(snr)} dB, of the {len(curves)} config(s) of the tasks that draw a ROC "
        f"({', '.join(code(c) for c in curves)}), the level where the configs' mean Pd is closest to "
        "0.5, computed from the stored statistics without re-running: Pfa from the calibration null "
        "values, Pd from each trial's peak statistic in the detection window.",
        "![ROC](figures/roc.png)",
    ])


def timeline(ctx: ReportContext) -> list[str]:
    """The statistic of each detector on one recorded trial whose methods are
    all detectors: at the recorded SNR level nearest ``[record] timeline_snr_db``,
    else the highest."""
    records = [r for r in ctx.records if r.methods and all(label in ctx.configs for label in r.methods)]
    if not records:
        return []
    snr_db = ctx.timeline_snr_db
    if snr_db is None:
        top = max(records, key=lambda r: (r.snr_db if r.snr_db is not None else -np.inf, -r.trial))
    else:
        top = min(records, key=lambda r: (abs(r.snr_db - snr_db) if r.snr_db is not None else np.inf, r.trial))
    series = {label: (tr.arrays["statistic"], tr.threshold, tr.arrays["alarms"]) for label, tr in top.methods.items()}
    figures.trial_timeline(top.t, series, ctx.fig_dir / "trial_timeline.png",
                           f"{ctx.title}: trial {top.trial} at {fmt_db(top.snr_db)} dB")
    return ["## One trial over time",
            f"Statistic, threshold in force and alarms of each method on trial {top.trial} at "
            f"{fmt_db(top.snr_db)} dB (symmetric-log scale).",
            "![one trial](figures/trial_timeline.png)"]
