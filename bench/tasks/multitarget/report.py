"""Report sections of the multi-target task (docs/architecture.md, 'Outputs of a run').

GOSPA with its localisation / missed / false decomposition and OSPA per cell
with 95 % bootstrap intervals; GOSPA, false-track rate and initiation delay
against the detection probability and the clutter density; the track-level
metrics; paired differences of GOSPA between the trackers on the same trials
(the first config of the sweep against each other one); GOSPA per scan.
Imported only when a report is written (matplotlib).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from radarbench.bench import figures
from radarbench.bench.markdown import code, fmt, fmt_interval, table
from radarbench.bench.metrics import bootstrap_mean_interval
from radarbench.bench.recording.paths import entity_name as slug
from radarbench.bench.tasks.base import ReportContext

#: the two axes a multi-target sweep varies, as summary columns, with their words
AXES = {"scene_pd": ("Pd", "detection probability Pd", False),
        "clutter_per_scan": ("clutter/scan", "expected clutter plots per scan (lambda x region volume)", True)}


def _interval(r, name: str) -> str:
    return fmt_interval(getattr(r, f"{name}_mean"), getattr(r, f"{name}_low"), getattr(r, f"{name}_high"))


def _cell(r) -> list[str]:
    return [code(r.scenario), fmt(r.snr_db), fmt(r.scene_pd), fmt(r.clutter_per_scan), code(r.config)]


CELL_HEADER = ["scenario config", "SNR (dB)", "Pd", "clutter/scan", "config"]


def _gospa_table(summary: pd.DataFrame, cutoff_text: str) -> list[str]:
    rows = [_cell(r) + [_interval(r, "gospa"), _interval(r, "gospa_loc"), _interval(r, "gospa_missed"),
                        _interval(r, "gospa_false"), _interval(r, "ospa")] for r in summary.itertuples()]
    return ["## Multi-target tracking: GOSPA",
            "*GOSPA* (alpha = 2, " + cutoff_text + ") between the true positions and the confirmed tracks' "
            "positions at each scan, averaged over the scans of a trial as (mean of d^p)^(1/p), then over trials "
            "(metres, 95 % bootstrap interval over trials). Its decomposition: *localisation* = (mean over scans "
            "of the sum of d^p over assigned pairs)^(1/p) (m), *missed* and *false* = mean number per scan of "
            "targets without a track and of confirmed tracks without a target; at p = 2, GOSPA^2 = "
            "localisation^2 + c^2/2 (missed + false) trial by trial. *OSPA*: mean over scans. Every tracker "
            "runs on the same trials.",
            table(CELL_HEADER + ["GOSPA (m)", "localisation (m)", "missed / scan", "false / scan", "OSPA (m)"],
                  rows)]


def _track_table(summary: pd.DataFrame) -> list[str]:
    rows = [_cell(r) + [_interval(r, "init_delay"), fmt(r.initiated_fraction), _interval(r, "false_track_rate"),
                        _interval(r, "track_breaks"), _interval(r, "id_switches"), _interval(r, "purity")]
            for r in summary.itertuples()]
    return ["## Multi-target tracking: track initiation, false tracks, continuity",
            "*Initiation delay*: scans from a target's first presence to the first scan a confirmed track is "
            "assigned to it (GOSPA's assignment, pairs closer than the cut-off), pooled over the initiated "
            "targets; *initiated*: the fraction of targets that ever get one. *False tracks*: confirmed tracks "
            "never assigned to a target, per hour of the run. *Breaks*: scans at which a target tracked at the "
            "previous scan loses its track while present; *switches*: scans at which a target's track "
            "identity changes; *purity*: the fraction of a non-false track's confirmed scans on its most "
            "frequent target (per trial, mean over tracks). Means per trial with 95 % bootstrap intervals.",
            table(CELL_HEADER + ["initiation delay (scans)", "initiated", "false tracks / h", "breaks / trial",
                                 "id switches / trial", "purity"], rows)]


def _versus_axes(summary: pd.DataFrame, fig_dir, title: str) -> list[str]:
    """Figures of GOSPA, false-track rate and initiation delay against Pd (one per clutter level)
    and against the clutter (one per Pd), where the sweep has two levels or more."""
    parts = []
    for axis, (short, words, logx) in AXES.items():
        other = next(a for a in AXES if a != axis)
        for level, g in summary.groupby([other, "snr_db"], sort=True):
            if g[axis].nunique() < 2:
                continue
            at = f"{AXES[other][0]} = {fmt(level[0])}, SNR {fmt(level[1])} dB"
            for column, ylabel in (("gospa_mean", "GOSPA (m)"), ("false_track_rate_mean", "false tracks per hour"),
                                   ("init_delay_mean", "initiation delay (scans)")):
                name = f"mtt_{column[:-5]}_vs_{slug(short)}_{slug(fmt(level[0]))}_{slug(fmt(level[1]))}.png"
                figures.metric_vs(g, axis, fig_dir / name, f"{title}: {ylabel} at {at}", column, ylabel, words,
                                  logx=logx)
                parts.append(f"![{ylabel} vs {short} at {at}](figures/{name})")
    if parts:
        parts.insert(0, "## Multi-target tracking: against Pd and clutter\n\nEach curve is a tracker, the band "
                        "its 95 % interval over trials.")
    return parts


def paired_differences(trials: pd.DataFrame, reference: str, column: str = "gospa_m") -> pd.DataFrame:
    """Per cell (scenario config, SNR) and other config: the mean over common
    trials of ``column``(other) - ``column``(reference) with a 95 % bootstrap
    interval (the trials are paired: same plots, same truths)."""
    rows = []
    keys = ["scenario", "snr_db"]
    for (scenario, snr), g in trials.groupby(keys, sort=False):
        ref = g[g.config == reference].set_index("trial")[column]
        if ref.empty:
            continue
        for config, h in g[g.config != reference].groupby("config", sort=False):
            d = (h.set_index("trial")[column] - ref).dropna().to_numpy(float)
            if len(d) == 0:
                continue
            lo, hi = bootstrap_mean_interval(d)
            rows.append({"scenario": scenario, "snr_db": snr, "config": config, "n": len(d),
                         "diff_mean": float(d.mean()), "diff_low": lo, "diff_high": hi,
                         "ref_mean": float(ref.loc[h.set_index("trial").index.intersection(ref.index)].mean())})
    return pd.DataFrame(rows)


def _paired(ctx: ReportContext) -> list[str]:
    summary, trials = ctx.summary, ctx.trials
    configs = list(dict.fromkeys(summary.config))
    if len(configs) < 2:
        return []
    ref = configs[0]
    diffs = paired_differences(trials, ref)
    if diffs.empty:
        return []
    axes = summary.drop_duplicates("scenario").set_index("scenario")[list(AXES)]
    rows, verdicts = [], {}
    for r in diffs.itertuples():
        if r.diff_low > 0:
            verdict = f"{code(ref)} better"
        elif r.diff_high < 0:
            verdict = f"{code(r.config)} better"
        else:
            verdict = "no significant difference"
        verdicts.setdefault(r.config, []).append((verdict, r))
        rel = r.diff_mean / r.ref_mean if r.ref_mean > 0 else np.nan
        rows.append([code(r.scenario), fmt(r.snr_db), fmt(axes.scene_pd.get(r.scenario)),
                     fmt(axes.clutter_per_scan.get(r.scenario)), code(r.config), r.n,
                     fmt_interval(r.diff_mean, r.diff_low, r.diff_high), fmt(100 * rel), verdict])
    lines = []
    for config, vs in verdicts.items():
        better = [r for v, r in vs if v.startswith(code(ref))]
        worse = [r for v, r in vs if v.startswith(code(config))]
        text = (f"- {code(ref)} against {code(config)}: lower GOSPA in {len(better)} of {len(vs)} cells, higher in "
                f"{len(worse)}, no significant difference in {len(vs) - len(better) - len(worse)}")
        if better:
            best = max(better, key=lambda r: r.diff_mean)
            text += (f"; the largest gain is {fmt(best.diff_mean)} m ({fmt(100 * best.diff_mean / best.ref_mean)} % "
                     f"of {code(ref)}'s GOSPA) at Pd = {fmt(axes.scene_pd.get(best.scenario))}, clutter/scan = "
                     f"{fmt(axes.clutter_per_scan.get(best.scenario))}")
        lines.append(text + ".")
    return ["## Multi-target tracking: paired comparison",
            f"GOSPA of each config minus that of {code(ref)} (the sweep's first config) on the same trials, mean "
            "over trials with a 95 % bootstrap interval of the paired differences; positive: "
            f"{code(ref)} has the lower (better) GOSPA. A difference whose interval holds 0 is within sampling "
            "error.", "\n".join(lines),
            table(CELL_HEADER[:4] + ["config", "trials", "GOSPA(config) - GOSPA(ref) (m)", "% of ref",
                                     "verdict"], rows)]


def _per_scan(ctx: ReportContext) -> list[str]:
    steps, summary = ctx.steps, ctx.summary
    if steps.empty or "gospa" not in steps:
        return []
    ref = summary.config.iloc[0]
    hardest = summary[summary.config == ref].sort_values("gospa_mean").iloc[-1]
    at = steps[(steps.scenario == hardest.scenario) & (steps.snr_db == hardest.snr_db)]
    curves = {c: (s.step.to_numpy(), s.gospa.to_numpy()) for c, s in at.groupby("config", sort=False)}
    name = f"mtt_gospa_per_scan_{slug(hardest.scenario)}.png"
    figures.rmse_per_step(curves, ctx.fig_dir / name, f"{ctx.title}: {hardest.scenario}", xlabel="scan",
                          ylabel="GOSPA (m), mean over trials")
    return ["## Multi-target tracking: GOSPA per scan",
            f"Mean GOSPA across trials at each scan on {code(hardest.scenario)} (SNR {fmt(hardest.snr_db)} dB), "
            f"the scenario config where {code(ref)} has its largest GOSPA; `steps.csv` has every cell, with the "
            "missed and false counts and the numbers of targets and confirmed tracks per scan.",
            f"![GOSPA per scan](figures/{name})"]


def sections(ctx: ReportContext) -> list[str]:
    summary = ctx.summary
    if summary.empty:
        return []
    cutoff = ctx.trials.get("gospa_cutoff_m")
    order = ctx.trials.get("gospa_order")
    cutoff_text = ("cut-off c = " + ", ".join(f"{fmt(v)} m" for v in sorted(cutoff.unique())) +
                   ", order p = " + ", ".join(fmt(v) for v in sorted(order.unique()))) if cutoff is not None \
        else "the scenario's cut-off c and order p"
    return (_gospa_table(summary, cutoff_text) + _paired(ctx) + _versus_axes(summary, ctx.fig_dir, ctx.title)
            + _track_table(summary) + _per_scan(ctx))
