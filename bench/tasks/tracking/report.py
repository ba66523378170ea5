"""Report sections of the tracking task (docs/architecture.md, 'Outputs of a run').

Time-averaged position RMSE with bootstrap intervals per scenario config and
SNR, divergence rate and NEES, RMSE against SNR, per-step RMSE and the mean
estimate against the truth per step (the usual figure of tracking papers, e.g.
the glint paper's Viterbi vs EKF comparison), and one recorded trial per scenario
config drawn in the plane (truth, measurements, estimates). Imported only when a report is
written (matplotlib).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from radarbench.bench import figures
from radarbench.bench.markdown import code, fmt, fmt_db, fmt_interval, table, text
from radarbench.bench.metrics import bootstrap_mean_interval
from radarbench.bench.recording.paths import entity_name as slug
from radarbench.bench.tasks.base import ReportContext
from radarbench.bench.tasks.tracking.metrics import ONSET_WINDOW_STEPS


def _reference_snr(g: pd.DataFrame) -> float:
    """The scenario config's SNR level closest to 0 dB (its reference level)."""
    levels = np.unique(g.snr_db.to_numpy(float))
    return float(levels[np.argmin(np.abs(levels))])


def _overview(summary: pd.DataFrame, fig_dir: Path, title: str) -> list[str]:
    configs = list(dict.fromkeys(summary.config))
    rows, ref = [], {}
    for scenario, g in summary.groupby("scenario", sort=False):
        ref[scenario] = snr = _reference_snr(g)
        at = g[g.snr_db == snr].set_index("config")
        rows.append([code(scenario), fmt_db(snr)] +
                    [fmt_interval(at.rmse_mean.get(c), at.rmse_low.get(c), at.rmse_high.get(c))
                     if c in at.index else "–" for c in configs])
    parts = ["## Tracking: position RMSE",
             "*Time-averaged RMSE* = mean over steps of the per-step position RMSE across trials (metres), "
             "with a 95% bootstrap interval over trials; every method runs on the same trials.",
             table(["scenario config", "SNR (dB)"] + [code(c) for c in configs], rows)]
    if summary.scenario.nunique() > 1:
        pick = pd.concat([g[g.snr_db == ref[s]] for s, g in summary.groupby("scenario", sort=False)])
        values = pick.pivot_table(index="scenario", columns="config", values="rmse_mean", sort=False)
        low = pick.pivot_table(index="scenario", columns="config", values="rmse_low", sort=False)
        high = pick.pivot_table(index="scenario", columns="config", values="rmse_high", sort=False)
        figures.grouped_bars(values, low, high, fig_dir / "tracking_rmse_by_scenario.png",
                             f"{title}: time-averaged position RMSE (95% CI)", "RMSE (m)", log=True)
        parts.append("![RMSE by scenario config](figures/tracking_rmse_by_scenario.png)")
    bounded = "efficiency" in summary and summary.efficiency.notna().any()
    health = [[code(r.scenario), fmt_db(r.snr_db), code(r.config),
               fmt_interval(r.divergence_rate, r.divergence_low, r.divergence_high), fmt(r.nees_mean)]
              + ([fmt(r.pcrb_rmse), fmt(r.efficiency)] if bounded else []) for r in summary.itertuples()]
    parts.append("<details><summary>Divergence rate, NEES and efficiency per cell</summary>\n\n"
                 "*Divergence*: the position error exceeded the scenario's `divergence_bound_m` at some step. "
                 "*NEES*: mean normalised estimation error squared (equals the state dimension for a "
                 "consistent filter; – without a covariance)." +
                 (" *PCRB*: the posterior Cramér–Rao bound on the position error, time-averaged like the "
                  "RMSE (m; – where the scene gives none); *efficiency*: PCRB / RMSE, 1 at the bound."
                  if bounded else "") + "\n\n" +
                 table(["scenario config", "SNR (dB)", "config", "divergence rate [95% CI]", "mean NEES"]
                       + (["PCRB (m)", "efficiency"] if bounded else []), health)
                 + "\n\n</details>")
    return parts


def _versus_snr(summary: pd.DataFrame, fig_dir: Path, title: str) -> list[str]:
    parts = []
    for scenario, g in summary.groupby("scenario", sort=False):
        if g.snr_db.nunique() < 2:
            continue
        name = f"tracking_rmse_vs_snr_{slug(scenario)}.png"
        figures.metric_vs_snr(g, fig_dir / name, f"{title}: {scenario}", log=True)
        parts.append(f"RMSE against SNR on {code(scenario)}:\n\n![RMSE vs SNR]({'figures/' + name})")
    return parts


def _per_step(summary: pd.DataFrame, steps: pd.DataFrame, fig_dir: Path, title: str) -> list[str]:
    parts = []
    for scenario, g in summary.groupby("scenario", sort=False):
        snr = _reference_snr(g)
        at = steps[(steps.scenario == scenario) & (steps.snr_db == snr)]
        if at.empty:
            continue
        curves = {c: (s.t.to_numpy(), s.rmse_position.to_numpy()) for c, s in at.groupby("config", sort=False)}
        first_config = at[at.config == at.config.iloc[0]]      # the bound is the scene's: one per config, equal
        bound = (first_config.t.to_numpy(), first_config.pcrb_position.to_numpy()) \
            if "pcrb_position" in at and at.pcrb_position.notna().any() else None
        name = f"tracking_rmse_per_step_{slug(scenario)}.png"
        figures.rmse_per_step(curves, fig_dir / name, f"{title}: {scenario} at {fmt_db(snr)} dB", xlabel="time (s)",
                              bound=bound)
        parts.append(f"![per-step RMSE on {text(scenario)}](figures/{name})")
    first = summary.scenario.iloc[0]
    snr = _reference_snr(summary[summary.scenario == first])
    at = steps[(steps.scenario == first) & (steps.snr_db == snr)]
    components = [c[len("mean_est_"):] for c in at.columns if c.startswith("mean_est_") and at[c].notna().any()]
    if not at.empty and components:
        one = at[at.config == at.config.iloc[0]]
        panels = {comp: (one[f"mean_true_{comp}"].to_numpy(),
                         {c: s[f"mean_est_{comp}"].to_numpy() for c, s in at.groupby("config", sort=False)})
                  for comp in components}
        figures.mean_estimates(one.t.to_numpy(), panels, fig_dir / "tracking_mean_estimate.png",
                               f"{title}: mean estimates on {first} at {fmt_db(snr)} dB ({int(one.n_trials.iloc[0])} trials)")
        parts.append(f"Mean estimate of every component across trials against the truth, per step, on {code(first)} "
                     "(state components, and the components the scenario derives from the state, e.g. range, "
                     "bearing and elevation):\n\n![mean estimates](figures/tracking_mean_estimate.png)")
    if parts:
        parts.insert(0, "## Tracking: error over time\n\nPer-step position RMSE across trials at each "
                        "scenario config's reference SNR (closest to 0 dB), under it (dashed) the posterior "
                        "Cramér–Rao bound where the scene gives one; `steps.csv` has every level "
                        "and component.")
    return parts


def _trial_in_plane(ctx: ReportContext) -> list[str]:
    """Per scenario config, its recorded trial closest to the reference SNR drawn in the
    plane with every tracker's estimate; scenes drawn against time (a range) are left to
    the per-step figures."""
    best = {}
    reference = 0.0 if ctx.timeline_snr_db is None else ctx.timeline_snr_db
    for rec in ctx.records:
        estimates = {label: tr.arrays["estimate_xy"] for label, tr in rec.methods.items()
                     if label in ctx.configs and "estimate_xy" in tr.arrays}
        if (rec.snr_db is None or rec.truth_xy is None or not estimates
                or np.array_equal(rec.truth_xy[:, 0], rec.t)):
            continue
        distance = abs(rec.snr_db - reference)
        if rec.scenario not in best or distance < best[rec.scenario][0]:
            best[rec.scenario] = (distance, rec, estimates)
    parts = []
    for scenario, (_, rec, estimates) in best.items():
        name = f"tracking_trial_plane_{slug(scenario)}.png"
        figures.trial_in_plane(rec.truth_xy, rec.measurements_xy, estimates, rec.arrays.get("maneuvering"),
                               ctx.fig_dir / name,
                               f"{ctx.title}: {scenario}, trial {rec.trial} at {fmt_db(rec.snr_db)} dB")
        parts.append(f"![one trial of {text(scenario)} in the plane](figures/{name})")
    if parts:
        parts.insert(0, "## Tracking: one trial in the plane\n\nOne recorded trial per scenario config (the "
                        "recording has them all), in metres: the truth, its maneuvering steps, the "
                        "measurements and every tracker's estimate.")
    return parts


def _maneuvers(summary: pd.DataFrame, steps: pd.DataFrame, fig_dir: Path, title: str) -> list[str]:
    """Scenes with a maneuver mask: the quiet / maneuvering split, the switches against
    the true onsets, and the RMSE of each component over time."""
    if "rmse_quiet" not in summary or summary.rmse_quiet.isna().all():
        return []
    parts = ["## Tracking: quiet and maneuvering segments",
             "*Quiet* / *maneuver* RMSE: time-averaged position RMSE over the steps outside / inside the true "
             f"maneuver, *onset window* over the first {ONSET_WINDOW_STEPS} steps from its onset "
             "(95% bootstrap interval over trials). For trackers that report their model switches: "
             "*switch Pd*, the fraction of trials with a chi-square switch between the onset and the end of "
             "the maneuver (Wilson); *delay*, steps from the onset to that switch (bootstrap); *false "
             "switches*, switches before the onset per step before the onset (ratio-estimator interval over "
             "trials); *Q quiet / maneuver*, the mean estimated state-noise scale (m²) of adaptive trackers."]
    rows = []
    for r in summary[summary.rmse_quiet.notna()].itertuples():
        rows.append([code(r.scenario), fmt(r.snr_db), code(r.config),
                     fmt_interval(r.rmse_quiet, r.rmse_quiet_low, r.rmse_quiet_high),
                     fmt_interval(r.rmse_maneuver, r.rmse_maneuver_low, r.rmse_maneuver_high),
                     fmt_interval(r.rmse_onset, r.rmse_onset_low, r.rmse_onset_high)
                     if pd.notna(r.rmse_onset) else "–", fmt(r.nees_mean),
                     fmt_interval(r.switch_pd, r.switch_pd_low, r.switch_pd_high) if pd.notna(r.switch_pd) else "–",
                     fmt_interval(r.switch_delay_mean, r.switch_delay_low, r.switch_delay_high)
                     if pd.notna(r.switch_delay_mean) else "–",
                     fmt_interval(r.false_switch_rate, r.false_switch_low, r.false_switch_high)
                     if pd.notna(r.false_switch_rate) else "–",
                     f"{fmt(r.q_quiet_mean)} / {fmt_interval(r.q_maneuver_mean, r.q_maneuver_low, r.q_maneuver_high)}"
                     if pd.notna(r.q_maneuver_mean) else "–"])
    parts.append(table(["scenario config", "SNR (dB)", "config", "quiet RMSE (m)", "maneuver RMSE (m)",
                        "onset-window RMSE (m)", "mean NEES",
                        "switch Pd", "delay (steps)", "false switches / step", "Q quiet / maneuver"], rows))
    for scenario, g in summary[summary.rmse_quiet.notna()].groupby("scenario", sort=False):
        snr = _reference_snr(g)
        at = steps[(steps.scenario == scenario) & (steps.snr_db == snr)]
        comps = [c[len("rmse_"):] for c in at.columns if c.startswith("rmse_") and c != "rmse_position"
                 and at[c].notna().any()][:2]
        for comp in comps:
            curves = {c: (s.t.to_numpy(), s[f"rmse_{comp}"].to_numpy()) for c, s in at.groupby("config", sort=False)}
            name = f"tracking_rmse_{slug(comp)}_{slug(scenario)}.png"
            figures.rmse_per_step(curves, fig_dir / name, f"{title}: {scenario} at {fmt(snr)} dB, RMSE of {comp}",
                                  xlabel="time (s)", ylabel=f"RMSE of {comp}")
            parts.append(f"![RMSE of {text(comp)} over time on {text(scenario)}](figures/{name})")
        break                                   # the first maneuvering scenario config: the papers' figures
    return parts


PAIRED_METRICS = (("rmse_maneuver_m", "maneuver"), ("rmse_onset_m", "onset window"))


def _paired(summary: pd.DataFrame, trials: pd.DataFrame) -> list[str]:
    """Every method config against the sweep's first, paired over the same trials (common
    random numbers): the mean per-trial difference of the maneuver and onset-window RMSE,
    at each maneuvering scenario config's reference SNR."""
    if "rmse_onset_m" not in trials or trials.rmse_onset_m.isna().all():
        return []
    configs = list(dict.fromkeys(summary.config))
    first, rows = configs[0], []
    for scenario, g in trials[trials.rmse_onset_m.notna()].groupby("scenario", sort=False):
        snr = _reference_snr(g)
        at = g[g.snr_db == snr]
        wide = {name: at.pivot_table(index="trial", columns="config", values=name) for name, _ in PAIRED_METRICS}
        if first not in wide["rmse_onset_m"]:
            continue
        for config in configs[1:]:
            if config not in wide["rmse_onset_m"]:
                continue
            cells = []
            for name, _ in PAIRED_METRICS:
                d = (wide[name][config] - wide[name][first]).to_numpy(float)
                cells.append(fmt_interval(float(np.nanmean(d)), *bootstrap_mean_interval(d)))
            rows.append([code(scenario), fmt(snr), code(config)] + cells)
    if not rows:
        return []
    return ["### Paired differences against the first method config",
            f"Per trial, a config's position RMSE minus {code(first)}'s on the same trial, averaged over trials "
            "(95% bootstrap interval over trials; positive: the first config is better), over the true "
            f"maneuver and over the first {ONSET_WINDOW_STEPS} steps from its onset (the *onset window*, where "
            "a switching tracker detects the maneuver and changes its model). Per-trial RMS, so the means "
            "differ slightly from the time-averaged RMSE above.",
            table(["scenario config", "SNR (dB)", "config"] + [f"Δ {label} RMSE (m)" for _, label in PAIRED_METRICS],
                  rows)]


def sections(ctx: ReportContext) -> list[str]:
    summary = ctx.summary
    if summary.empty:
        return []
    return _overview(summary, ctx.fig_dir, ctx.title) + _versus_snr(summary, ctx.fig_dir, ctx.title) + \
        _per_step(summary, ctx.steps, ctx.fig_dir, ctx.title) + _trial_in_plane(ctx) + \
        _maneuvers(summary, ctx.steps, ctx.fig_dir, ctx.title) + _paired(summary, ctx.trials)
