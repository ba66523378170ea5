"""Report sections of the cell-detection task (docs/architecture.md, 'Outputs of a run').

Per scenario config (one background mix): Pd against SNR per clutter region
with the ideal known-noise detector's curve, the Pd table at a reference SNR,
the measured per-cell Pfa per region against the requested one, the CFAR loss
per region, the masking of paired targets, ROC curves at the reference SNR,
which detector wins where (with intervals), a paired comparison of every
config with the others over the whole map, and one RD map with each
detector's detections (the HFSWR chapter's Fig. 6.24). Definitions in
:mod:`bench.tasks.cells.metrics`. Imported only when a report is written.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from radarbench.bench.calibration import cell_exceedances
from radarbench.bench.markdown import code, fmt, fmt_crossing, fmt_interval, table, text
from radarbench.bench.metrics import bootstrap_mean_interval, snr_at_pd
from radarbench.bench.recording.record import TrialRecord
from radarbench.bench.tasks.base import ReportContext
from radarbench.bench.tasks.cells.figures import map_detections, pd_panels, roc_panels
from radarbench.bench.tasks.cells.metrics import (PAIRED_GROUP, REGION_NAMES, ideal_pd, ideal_snr_at_pd, ratio_with_interval,
                                       slug)

#: the reference SNR is the lowest level at which the ideal detector reaches this Pd
REFERENCE_IDEAL_PD = 0.9
#: the groups the report shows: the regions, then the paired targets
GROUPS = (*REGION_NAMES, "paired")


def _column(group: str) -> str:
    return "pd_paired" if group == "paired" else f"pd_{slug(group)}"


def _present(scene: pd.DataFrame) -> list[str]:
    """The target groups with targets in this scenario config."""
    return [g for g in GROUPS if scene[_column(g)].notna().any()]


def reference_snr(scene: pd.DataFrame, pfa: float) -> float:
    """The lowest SNR level where the ideal detector's Pd reaches
    :data:`REFERENCE_IDEAL_PD` (else the highest level): where a CFAR's loss
    shows as a drop in Pd."""
    levels = np.sort(scene.snr_db.unique())
    swerling = int(scene.swerling.iloc[0])
    ok = levels[ideal_pd(levels, pfa, swerling) >= REFERENCE_IDEAL_PD]
    return float(ok[0]) if ok.size else float(levels[-1])


def _at(scene: pd.DataFrame, snr: float) -> pd.DataFrame:
    return scene[np.isclose(scene.snr_db, snr)]


def _interval(row, column: str) -> str:
    return fmt_interval(row[column], row[f"{column}_low"], row[f"{column}_high"])


def _section_pd(scene: pd.DataFrame, sc: str, snr: float, ctx: ReportContext, fig: Path) -> str:
    groups = _present(scene)
    if not groups:
        return f"### {code(sc)}: no targets\n\nThe maps of this scenario config hold no target: Pfa only."
    swerling = int(scene.swerling.iloc[0])
    pd_panels(scene, groups, [_column(g) for g in groups], ctx.pfa, swerling, fig, f"{ctx.title}: {sc}")
    rows = [[code(r.config), *(_interval(r._asdict(), _column(g)) for g in groups), _interval(r._asdict(), "pd")]
            for r in _at(scene, snr).itertuples()]
    ideal = fmt(float(ideal_pd(snr, ctx.pfa, swerling)))
    return "\n\n".join([
        f"### {code(sc)}: Pd by clutter region",
        f"![Pd vs SNR by region, {text(sc)}]({fig.relative_to(ctx.fig_dir.parent)})",
        f"Pd [95% CI, clustered by map] at the reference SNR {fmt(snr)} dB (Swerling {swerling}); the ideal "
        f"known-noise detector's Pd there is {ideal}:",
        table(["config", *groups, "all targets"], rows)])


def _pooled_pfa(trials: pd.DataFrame, config: str, events: str, cells: str) -> tuple[float, float, float]:
    """A config's per-cell Pfa pooled over the scenario config's SNR levels,
    clustered by map (trial i has the same noise at every level)."""
    g = trials[trials.config == config].groupby("trial")[[events, cells]].sum()
    return ratio_with_interval(g[events], g[cells])


def _section_pfa(scene_trials: pd.DataFrame, configs: list[str], sc: str, pfa: float, cals: list) -> str:
    regions = [r for r in REGION_NAMES if scene_trials[f"clear_cells_{slug(r)}"].sum() > 0]
    null = {c.method: c for c in cals if c.scenario == sc}
    rows = []
    for config in configs:
        cells = [_pooled_pfa(scene_trials, config, f"false_alarms_{slug(r)}", f"clear_cells_{slug(r)}")
                 for r in regions]
        whole = _pooled_pfa(scene_trials, config, "false_alarms", "clear_cells")
        cal = null.get(config)
        nominal = "–" if cal is None else fmt_interval(cal.nominal_pfa, cal.nominal_pfa_low, cal.nominal_pfa_high)
        rows.append([code(config), nominal, *(fmt_interval(*c) for c in cells), fmt_interval(*whole),
                     fmt(whole[0] / pfa)])
    mode = _threshold_mode(cals, sc)
    return "\n\n".join([
        f"### {code(sc)}: measured per-cell Pfa by clutter region",
        f"Requested Pfa {pfa:g} per cell. *Null maps, nominal K*: the per-cell Pfa of the detector's closed-form "
        f"threshold on the whole null maps (the calibration's). The other columns: false alarms over the cells "
        f"outside the targets' guard boxes on the evaluation maps at the threshold used ({mode}), pooled over "
        f"the SNR levels, per region; 95% intervals clustered by map.",
        table(["config", "null maps, nominal K", *regions, "whole map", "whole map / requested"], rows)])


def _section_loss(scene: pd.DataFrame, sc: str, pfa: float) -> str:
    groups = _present(scene)
    if not groups or scene.snr_db.nunique() < 2:    # a crossing needs two SNR levels
        return ""
    swerling = int(scene.swerling.iloc[0])
    ideal = ideal_snr_at_pd(pfa, swerling)
    rows = []
    for config, g in scene.groupby("config", sort=False):
        g = g.sort_values("snr_db")
        entries = []
        for group in groups:
            col = _column(group)
            mid, low, high = snr_at_pd(g.snr_db, g[col], g[f"{col}_low"], g[f"{col}_high"])
            loss = f"{mid - ideal:+.2f}" if np.isfinite(mid) else "–"
            entries.append(f"{loss} ({fmt_crossing(mid, g.snr_db)} [{fmt_crossing(low, g.snr_db)}, "
                           f"{fmt_crossing(high, g.snr_db)}])")
        rows.append([code(config), *entries])
    return "\n\n".join([
        f"### {code(sc)}: CFAR loss",
        f"CFAR loss (dB) = SNR at which the detector's Pd reaches 0.5 minus that of the ideal known-noise "
        f"detector at the same per-cell Pfa ({pfa:g}; {ideal:.2f} dB for Swerling {swerling}); in brackets the "
        f"SNR at Pd = 0.5 and its interval from the Pd bands (dB).",
        table(["config", *groups], rows)])


def _section_masking(scene: pd.DataFrame, sc: str) -> str:
    if "paired" not in _present(scene) or "homogeneous" not in _present(scene):
        return ""
    levels = sorted(scene.snr_db.unique())
    rows = []
    for config, g in scene.groupby("config", sort=False):
        g = g.set_index("snr_db")
        rows.append([code(config), *(f"{fmt(g.pd_paired[s])} vs {fmt(g.pd_homogeneous[s])}" for s in levels)])
    return "\n\n".join([
        f"### {code(sc)}: masking by a close neighbour",
        "Pd of a target with a close neighbour (paired) vs an isolated target in the homogeneous region, per "
        "SNR level (dB): a CFAR whose reference window holds the neighbour raises its noise estimate.",
        table(["config", *(fmt(s) for s in levels)], rows)])


def _roc_curves(ctx: ReportContext, sc: str, configs: list[str], snr: float, groups: list[str]) -> dict:
    """Per group, per config: (per-cell Pfa on the null maps, Pd of the group's targets) over thresholds."""
    out: dict = {g: {} for g in groups}
    for config in configs:
        null_cells = ctx.store.null_cells(sc, config)
        series = next((v for k, v in ctx.series.items() if k[0] == sc and k[1] == config and np.isclose(k[2], snr)),
                      None)
        if null_cells is None or series is None:
            continue
        # fine steps where nominal significance is usual, then geometric up to the largest value seen
        top = max(float(null_cells[:, 1].max()), float(np.max(series["target_statistic"], initial=0.0)), 12.0)
        thresholds = np.concatenate([np.linspace(0.0, 12.0, 121), np.geomspace(12.0, top * 1.01, 80)[1:]])
        total = null_cells[:, 0, -1].sum()
        pfa = np.array([np.add(*cell_exceedances(null_cells, t)).sum() / 2 / total for t in thresholds])
        stat, group = series["target_statistic"], series["target_group"]
        for g in groups:
            index = PAIRED_GROUP if g == "paired" else REGION_NAMES.index(g)
            values = stat[group == index]
            if values.size:
                out[g][config] = (pfa, (values[None, :] >= thresholds[:, None]).mean(axis=1))
    return out


def _section_roc(ctx: ReportContext, scene: pd.DataFrame, sc: str, snr: float, fig: Path) -> str:
    groups = _present(scene)
    configs = list(dict.fromkeys(scene.config))
    curves = _roc_curves(ctx, sc, configs, snr, groups) if groups else {}
    if not any(curves.values()):
        return ""
    roc_panels(curves, ctx.pfa, fig, f"{ctx.title}: {sc}, ROC at {fmt(snr)} dB")
    return "\n\n".join([
        f"### {code(sc)}: ROC at {fmt(snr)} dB",
        "Pd of each region's targets against the per-cell Pfa over the whole null map, as the threshold on the "
        "statistic moves (from the stored statistics, no re-run; the null maps' order statistics bound the "
        "per-cell Pfa exactly below 64 exceedances a map).",
        f"![ROC, {text(sc)}]({fig.relative_to(ctx.fig_dir.parent)})"])


def _paired_difference(trials: pd.DataFrame, a: str, b: str) -> tuple[float, float, float]:
    """Pd(a) − Pd(b) over the same maps (common random numbers): the mean over
    maps of the difference in hit fractions, with a bootstrap interval over maps."""
    ha = trials[trials.config == a].set_index("trial").hit_fraction
    hb = trials[trials.config == b].set_index("trial").hit_fraction
    diff = (ha - hb).dropna().to_numpy(float)
    if diff.size == 0:
        return (np.nan, np.nan, np.nan)
    mean = float(diff.mean())
    return (0.0 if abs(mean) < 1e-12 else mean,          # hit fractions that cancel leave float noise, not a gain
            *bootstrap_mean_interval(diff))


def _threshold_mode(cals: list, sc: str) -> str:
    """The calibration mode of a scenario config's thresholds (nominal when none was calibrated)."""
    return next((c.mode for c in cals if c.scenario == sc), "nominal")


def _section_winners(scene: pd.DataFrame, scene_trials: pd.DataFrame, sc: str, snr: float, mode: str) -> str:
    if not _present(scene):                 # no targets: Pd is not defined, nothing to win ("no targets" above)
        return ""
    at = _at(scene, snr)
    rows = []
    for group in _present(scene):
        col = _column(group)
        ranked = at.sort_values(col, ascending=False)
        if ranked.empty or not np.isfinite(ranked[col].iloc[0]):
            continue
        best = ranked.iloc[0]
        runner = ranked.iloc[1] if len(ranked) > 1 else None
        clear = runner is not None and best[f"{col}_low"] > runner[f"{col}_high"]
        verdict = "alone (intervals apart)" if clear else (
            "tied within intervals with " + ", ".join(code(c) for c in ranked.config[1:][
                ranked[f"{col}_high"].iloc[1:] >= best[f"{col}_low"]]) if runner is not None else "only config")
        pfa_col = "pfa" if group == "paired" else f"pfa_{slug(group)}"
        rows.append([group, code(best.config), _interval(best, col), _interval(best, pfa_col), verdict])
    configs = list(dict.fromkeys(at.config))
    at_trials = scene_trials[np.isclose(scene_trials.snr_db, snr)]
    pairs = [[f"{code(a)} − {code(b)}", fmt_interval(*_paired_difference(at_trials, a, b))]
             for i, a in enumerate(configs) for b in configs[i + 1:]]
    return "\n\n".join([
        f"### {code(sc)}: which detector wins where (at {fmt(snr)} dB)",
        "Per region, the config with the highest Pd, its Pd and its measured per-cell Pfa in that region on "
        "the same maps (95% intervals, clustered by map); a win is *alone* when its Pd interval lies above "
        "every other config's. " + (
            "Read the Pd beside the Pfa: at nominal thresholds the detectors do not share a per-cell Pfa (the "
            "ROC above compares them at equal Pfa)." if mode == "nominal" else
            f"The thresholds ({mode}) give every config the same per-cell Pfa over the whole map, not in each "
            "region: read the Pd beside the region's Pfa."),
        table(["region", "best config", "Pd [95% CI]", "Pfa in the region [95% CI]", "verdict"], rows),
        "Over the whole map (every target), paired over the same maps: the difference in Pd with a bootstrap "
        "interval over maps (an interval above 0: the first config detects more).",
        table(["configs", "Pd difference [95% CI]"], pairs)])


def _section_map(ctx: ReportContext, configs: set[str], reference: dict[str, float]) -> str:
    """The HFSWR chapter's Fig. 6.24: one RD map with each detector's detections:
    a map with the most clutter regions, at its scenario config's reference SNR
    (or the nearest level recorded)."""
    records = [TrialRecord.from_bytes(r) if isinstance(r, bytes) else r for r in ctx.records]
    ours = [r for r in records if "rd_map_db" in r.images and set(r.methods) & configs and r.snr_db is not None]
    if not ours:
        return ""
    rec = min(ours, key=lambda r: (-len(np.unique(r.arrays["regions"])) if "regions" in r.arrays else 0,
                                   abs(r.snr_db - reference.get(r.scenario, r.snr_db)), r.trial))
    fig = map_detections(rec, sorted(set(rec.methods) & configs, key=list(rec.methods).index),
                         ctx.fig_dir / "cells_rd_map_detections.png", f"{ctx.title}: {rec.scenario}")
    return "\n\n".join([
        "### One RD map with each detector's detections (cf. the HFSWR chapter's Fig. 6.24)",
        f"Map {rec.trial} of {code(rec.scenario)} at {fmt(rec.snr_db)} dB: the map in dB with the true targets "
        "(white circles), the clutter regions, and each detector's declared cells (dots) at its threshold in "
        "force.",
        f"![RD map with detections]({fig.relative_to(ctx.fig_dir.parent)})"])


def sections(ctx: ReportContext) -> list[str]:
    summary = ctx.summary
    if summary.empty:
        return []
    parts = ["## Cell detection (CFAR on range-Doppler maps)",
             "Definitions: a target is detected when its cell's statistic reaches the threshold; a false alarm "
             "is a declared cell outside every target's guard box; Pd per clutter region counts isolated "
             "targets, *paired* the targets with a close neighbour; the ideal detector knows each cell's noise "
             "power (bench/tasks/cells/metrics.py)."]
    reference = {}
    for sc, scene in summary.groupby("scenario", sort=False):
        scene = scene.sort_values(["config", "snr_db"], kind="stable")
        scene_trials = ctx.trials[ctx.trials.scenario == sc]
        snr = reference[sc] = reference_snr(scene, ctx.pfa)
        name = "".join(ch if ch.isalnum() else "_" for ch in sc)
        configs = list(dict.fromkeys(scene.config))
        parts += [_section_pd(scene, sc, snr, ctx, ctx.fig_dir / f"cells_pd_{name}.png"),
                  _section_pfa(scene_trials, configs, sc, ctx.pfa, ctx.calibrations),
                  _section_loss(scene, sc, ctx.pfa),
                  _section_masking(scene, sc),
                  _section_roc(ctx, scene, sc, snr, ctx.fig_dir / f"cells_roc_{name}.png"),
                  _section_winners(scene, scene_trials, sc, snr, _threshold_mode(ctx.calibrations, sc))]
    parts.append(_section_map(ctx, set(ctx.configs), reference))
    return [p for p in parts if p]
