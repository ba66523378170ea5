"""Report sections of the track-before-detect task (docs/architecture.md, 'Outputs of a run').

Pd against SNR at the calibrated scene Pfa, the SNR at Pd = 0.5 and each
config's gain over the first one, the null scene scores against the law fitted
to them (:mod:`bench.calibration`: Gumbel, or a generalized Pareto tail), the per-frame position RMSE over detected trials and its average, and
the papers' RMSE over all Monte Carlo runs with the percentage reduction of
each config against the first config of its scenario config (the multi-frame
DP-TBD paper's figure of merit). Imported only when a report is written
(matplotlib).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd

from radarbench.bench import figures
from radarbench.bench.calibration import fitted_survival, gumbel_fit
from radarbench.bench.markdown import code, crossing_difference, crossing_text, fmt, fmt_db, fmt_interval, snr50, table
from radarbench.bench.tasks.base import ReportContext


def _rmse_level(summary: pd.DataFrame) -> float | None:
    """The lowest SNR at which every config has Pd >= 0.5 (RMSE over enough
    detected trials to mean something); else the highest SNR."""
    if summary.empty:
        return None
    worst = summary.groupby("snr_db").pd.min()
    ok = worst[worst >= 0.5]
    return float(ok.index.min()) if len(ok) else float(worst.index.max())


def _per_scenario_tables(summary: pd.DataFrame, cell, caption: str) -> list[str]:
    """One table per scenario config: a row per method config, a column per
    SNR level (levels may differ between scenario configs), ``cell(row)``
    in each entry."""
    out = []
    for sc, scene in summary.groupby("scenario", sort=False):
        wide = scene.assign(_cell=[cell(r) for r in scene.itertuples()])
        wide = wide.pivot_table(index="config", columns="snr_db", values="_cell", aggfunc="first", sort=False)
        wide = wide[sorted(wide.columns)]
        out.append(f"{caption}, {code(sc)}:\n\n" + table(["config"] + [fmt_db(s) for s in wide.columns],
                                                    [[code(c)] + list(r) for c, r in zip(wide.index,
                                                                                          wide.to_numpy())]))
    return out


def _section_detection(summary: pd.DataFrame, fig_dir: Path, title: str, pfa: float) -> str:
    figures.pd_vs_snr(summary, fig_dir / "tbd_pd_vs_snr.png", pfa, f"{title} (TBD, per-scene Pfa)")
    crossings = snr50(summary)
    rows = []
    for _sc, scene in crossings.groupby("scenario", sort=False):   # gains within a scenario config
        lead = scene.crossing.iloc[0]
        for i, c in enumerate(scene.itertuples()):
            rows.append([code(c.config), code(c.scenario), *crossing_text(c.crossing),
                         "–" if i == 0 else crossing_difference(c.crossing, lead)])
    detail = _per_scenario_tables(summary, lambda r: fmt(r.pd), "Pd against SNR (dB)")
    return "\n\n".join([
        "## Track-before-detect: detection probability",
        "A scene is a *track detection* when its score reaches the threshold calibrated at the requested "
        "per-scene Pfa **and** the backtracked track lies on the true target cells (within the scenario's "
        "tolerance) in at least two frames.",
        "![TBD Pd vs SNR](figures/tbd_pd_vs_snr.png)",
        "SNR at Pd = 0.5: a probit fit to the track detections of every level (no floor), its 95% interval the "
        "profile likelihood's; *between a and b* where Pd jumps across 0.5 between adjacent levels (from ≤ 0.1 "
        "to ≥ 0.9), which the levels cannot resolve.",
        table(["config", "scenario", "SNR at Pd = 0.5 (dB)", "95% interval (dB)",
               f"gain over the scenario's first config, {code(crossings.config.iloc[0])} (dB)"], rows),
        "<details><summary>Pd per SNR level</summary>\n\n" + "\n\n".join(detail) + "\n\n</details>",
    ])


def _section_null(cals, store, fig_dir: Path, title: str, pfa: float, configs: set[str]) -> str:
    fits, rows = {}, []
    mine = [c for c in cals if c.method in configs]
    several = len({c.scenario for c in mine}) > 1
    for c in mine:
        values, _peaks, _nominal = store.null_values(c.scenario, c.method)
        if not np.isfinite(c.fit_loc):      # no law fitted (empirical, nominal): a Gumbel fit, for reference
            loc, scale = gumbel_fit(values)
            c = dataclasses.replace(c, mode="gumbel", fit_loc=loc, fit_scale=scale, fit_shape=0.0)
        law = "generalized Pareto tail" if c.mode == "pot" else "Gumbel"
        grid = np.linspace(values.min(), max(values.max(), c.used) + c.fit_scale, 300)
        fits[f"{c.method} ({c.scenario})" if several else c.method] = (values, grid, fitted_survival(c, grid),
                                                                        c.used, law)
        rows.append([code(c.method), code(c.scenario), c.mode, f"{c.null_values:,}", law, fmt(c.fit_loc, 4),
                     fmt(c.fit_scale, 4), fmt(c.fit_shape, 3), fmt(c.used, 4),
                     fmt_interval(c.used_pfa, c.used_pfa_low, c.used_pfa_high),
                     fmt_interval(c.cell_pfa, c.cell_pfa_low, c.cell_pfa_high), fmt(c.cell_threshold, 4),
                     fmt(c.cell_threshold_scene_pfa)])
    if not fits:
        return ""
    figures.null_score_fits(fits, fig_dir / "tbd_null_scores.png", pfa, f"{title}: null scene scores")
    return "\n\n".join([
        "## Track-before-detect: null scenes and the scene threshold",
        "Each null scene (no target) gives one score, the largest merit at the last frame. The figure "
        "shows their empirical survival function (steps), the law fitted to them by maximum likelihood "
        "(dashed: a Gumbel law, or in `pot` mode a generalized Pareto law for the excesses of the largest "
        "tenth over the next score, the tail start u; for a mode that fits none, the Gumbel fit for "
        "reference) and the threshold used (dotted); the requested Pfa is the horizontal line. *Scene Pfa* is the "
        "fraction of null scenes at or above the threshold used, with its 95% Wilson interval: with N "
        "null scenes it cannot resolve Pfa much below 3/N.",
        "*Per-cell Pfa* reads the same threshold per cell, as a DP-TBD detector that declares every cell "
        "whose final merit reaches V_T a candidate track end: the fraction of all null cells at or above "
        "it, with a 95% interval counted over scenes (each null scene keeps its value map's 64 largest "
        "values exactly and coarser order statistics below them; a count that falls between two kept "
        "ranks is taken at the middle of its bracket). The last two columns give the other reading: the "
        f"threshold whose per-cell Pfa is {fmt(pfa)}, and the fraction of null scenes that reach it (their "
        "scene Pfa).",
        "![null scene scores](figures/tbd_null_scores.png)",
        table(["config", "scenario", "mode", "null scenes", "law fitted", "location (Gumbel) or tail start u",
               "scale", "shape ξ", "threshold used",
               "scene Pfa [95% CI]", "per-cell Pfa [95% CI]", f"threshold at per-cell Pfa {fmt(pfa)}",
               "its scene Pfa"], rows),
    ])


def _section_rmse(summary: pd.DataFrame, steps: pd.DataFrame, fig_dir: Path, title: str) -> str:
    level = _rmse_level(summary)
    at = steps[(steps.snr_db == level)] if not steps.empty else steps
    several = summary.scenario.nunique() > 1
    curves = {f"{cfg} ({sc})" if several else cfg: (g.step.to_numpy() + 1, g.rmse_position.to_numpy())
              for (sc, cfg), g in at.groupby(["scenario", "config"], sort=False)}
    parts = ["## Track-before-detect: position error",
             "Position error = distance between the centre of the backtracked cell and the true position, per "
             "frame, over **detected** trials only. *Average RMSE* is the mean over frames of the per-frame "
             "RMSE (the papers' figure of merit), with a 95% bootstrap interval over trials."]
    if curves:
        figures.rmse_per_step(curves, fig_dir / "tbd_rmse_per_frame.png",
                              f"{title}: per-frame RMSE of detected tracks at {fmt_db(level)} dB")
        parts += [f"Per-frame RMSE at {fmt_db(level)} dB, the lowest SNR where every config has Pd ≥ 0.5 "
                  "(all levels are in `steps.csv`):", "![RMSE per frame](figures/tbd_rmse_per_frame.png)"]
    detail = _per_scenario_tables(summary, lambda r: fmt_interval(r.rmse_mean, r.rmse_low, r.rmse_high) +
                                  f" ({fmt(r.pd * r.n_trials)} det.)", "Average RMSE (m) against SNR (dB)")
    parts.append("<details><summary>Average RMSE (m) per SNR level [95% CI] (detected trials)</summary>\n\n" +
                 "\n\n".join(detail) + "\n\n</details>")
    return "\n\n".join(parts)


def _reductions(summary: pd.DataFrame) -> list[str]:
    """One line per method config after the first of each scenario config (the
    sweep's order: the first is the baseline): its percentage reduction of the
    all-runs average RMSE against the baseline at each SNR,
    100 (1 − RMSE / RMSE_baseline), and the mean over SNR levels."""
    lines = []
    for scenario, g in summary.groupby("scenario", sort=False):
        configs = list(dict.fromkeys(g.config))
        if len(configs) < 2:
            continue
        base_cfg = configs[0]
        ref = g[g.config == base_cfg].set_index("snr_db").rmse_all_mean
        for cfg in configs[1:]:
            red = 100.0 * (1.0 - g[g.config == cfg].set_index("snr_db").rmse_all_mean / ref).dropna()
            if red.empty:
                continue
            per = ", ".join(f"{fmt_db(snr)} dB: {v:+.1f} %" for snr, v in red.items())
            lines.append(f"- {code(cfg)} vs {code(base_cfg)} ({code(scenario)}): {per}; mean over SNR {red.mean():+.1f} %")
    return lines


def _section_rmse_all(summary: pd.DataFrame, steps: pd.DataFrame, fig_dir: Path, title: str) -> str:
    if "rmse_all_mean" not in summary or summary.rmse_all_mean.isna().all():
        return ""
    parts = ["## Track-before-detect: position error over all Monte Carlo runs",
             "The papers' RMSE: RMSE(k) = sqrt(mean over **all** Monte Carlo runs, detected or not, of the "
             "squared distance between the backtracked cell's centre and the true position at frame k); "
             "*average RMSE* is its mean over frames, with a 95% bootstrap interval over trials. Unlike the "
             "detected-only RMSE above, it penalises a method for the trials it loses."]
    figures.metric_vs_snr(summary, fig_dir / "tbd_rmse_all_vs_snr.png", f"{title}: average RMSE over all runs",
                          column="rmse_all_mean", ylabel="average position RMSE over all runs (m)")
    parts.append("![average RMSE over all runs vs SNR](figures/tbd_rmse_all_vs_snr.png)")
    level = 6.0 if (summary.snr_db == 6.0).any() else _rmse_level(summary)
    if not steps.empty and "rmse_position_all" in steps:
        at = steps[steps.snr_db == level]
        curves = {f"{cfg} ({sc})" if summary.scenario.nunique() > 1 else cfg:
                  (g.step.to_numpy() + 1, g.rmse_position_all.to_numpy())
                  for (sc, cfg), g in at.groupby(["scenario", "config"], sort=False)}
        if curves:
            figures.rmse_per_step(curves, fig_dir / "tbd_rmse_all_per_frame.png",
                                  f"{title}: per-frame RMSE over all runs at {fmt_db(level)} dB")
            parts.append("![RMSE per frame, all runs](figures/tbd_rmse_all_per_frame.png)")
    parts += _per_scenario_tables(summary, lambda r: fmt_interval(r.rmse_all_mean, r.rmse_all_low, r.rmse_all_high),
                                  "Average RMSE (m) over all runs against SNR (dB) [95% CI]")
    reductions = _reductions(summary)
    if reductions:
        parts.append("Reduction of the all-runs average RMSE of each config against the first config of its "
                     "scenario config (positive = smaller error):\n\n" + "\n".join(reductions))
    return "\n\n".join(parts)


def _section_snr_reference(summary: pd.DataFrame) -> str:
    """Our SNR axis against one whose noise scale is a unit-variance AR innovation."""
    if "snr_offset_unit_innovation_db" not in summary or summary.snr_offset_unit_innovation_db.isna().all():
        return ""
    rows = []
    for sc, g in summary.groupby("scenario", sort=False):
        off = float(g.snr_offset_unit_innovation_db.iloc[0])
        snrs = sorted(g.snr_db.unique())
        rows.append([code(sc), f"{10 ** (off / 10):.2f}", f"{off:+.1f}", ", ".join(fmt_db(s) for s in snrs),
                     ", ".join(fmt_db(s + off) for s in snrs)])
    return "\n\n".join([
        "## Track-before-detect: SNR reference",
        "Our SNR is s² over the *stationary* variance of the per-cell noise (scaled to 1). An AR model "
        "v_k + a1 v_(k-1) + ... + aP v_(k-P) = w_k written with w_k ~ N(0, 1), as the DP-TBD paper writes "
        "its noise, has stationary variance γ(0)/σ_w² (first Yule-Walker equation σ_w² = γ(0) + Σ a_i γ(i)); "
        "if its SNR is s² over σ_w² = 1, it reads higher than ours by the offset below (0 dB for white "
        "noise). Our SNR levels on that axis:",
        table(["scenario", "stationary variance at σ_w = 1", "offset (dB)", "our SNR levels (dB)",
               "the same on the unit-innovation axis (dB)"], rows),
    ])


def sections(ctx: ReportContext) -> list[str]:
    summary, steps, fig_dir, title, pfa = ctx.summary, ctx.steps, ctx.fig_dir, ctx.title, ctx.pfa
    if summary.empty:
        return []
    return [_section_snr_reference(summary),
            _section_detection(summary, fig_dir, title, pfa),
            _section_null(ctx.calibrations, ctx.store, fig_dir, title, pfa, set(summary.config)),
            _section_rmse(summary, steps, fig_dir, title),
            _section_rmse_all(summary, steps, fig_dir, title)]
