"""Report sections of the detect-and-track task (docs/architecture.md, 'Outputs of a run'):
per cell the detector's cell Pd and Pfa beside the tracks' GOSPA and track metrics, and
the figure of detection quality against tracking quality. Imported only when a report is
written (matplotlib)."""

from __future__ import annotations

import pandas as pd

from radarbench.bench import figures
from radarbench.bench.markdown import code, fmt, fmt_interval, table
from radarbench.bench.recording.paths import entity_name as slug
from radarbench.bench.tasks.base import ReportContext


def _interval(r, name: str) -> str:
    return fmt_interval(getattr(r, f"{name}_mean"), getattr(r, f"{name}_low"), getattr(r, f"{name}_high"))


def _table(summary: pd.DataFrame) -> list[str]:
    rows = [[code(r.scenario), fmt(r.snr_db), code(r.config), _interval(r, "cell_pd"), _interval(r, "cell_pfa"),
             _interval(r, "gospa"), _interval(r, "gospa_missed"), _interval(r, "gospa_false"),
             _interval(r, "init_delay"), _interval(r, "false_track_rate"), _interval(r, "track_breaks"),
             _interval(r, "id_switches")] for r in summary.itertuples()]
    return ["## Detect and track: cells and tracks",
            "*Cell Pd*: the fraction of (scan, target) pairs with the target in the map whose echo has a declared "
            "cell within the guard box of its true cell; *cell Pfa*: declared cells outside every target's guard "
            "box over the cells left (intervals clustered by trial). The track columns are the multi-target "
            "task's: time-averaged GOSPA (m), missed targets and false tracks per scan, the initiation delay "
            "(time to confirm, scans), false tracks per hour, breaks and identity switches per trial (95 % "
            "bootstrap intervals over trials). Every chain runs on the same maps.",
            table(["scenario config", "SNR (dB)", "config", "cell Pd", "cell Pfa", "GOSPA (m)", "missed / scan",
                   "false / scan", "time to confirm (scans)", "false tracks / h", "breaks / trial",
                   "id switches / trial"], rows)]


def _detection_vs_tracking(summary: pd.DataFrame, fig_dir, title: str) -> list[str]:
    """GOSPA against the detector's cell Pd and against its cell Pfa, one curve per chain
    (its points: the SNR levels), per scenario config."""
    parts = []
    for scenario, g in summary.groupby("scenario", sort=False):
        if g.cell_pd_mean.notna().sum() < 2:
            continue
        parts.append(f"On {code(scenario)}:")
        for x, words, logx in (("cell_pd_mean", "detector cell Pd", False),
                               ("cell_pfa_mean", "detector cell Pfa", True)):
            name = f"chain_gospa_vs_{x[:-5]}_{slug(scenario)}.png"
            figures.metric_vs(g.sort_values(x), x, fig_dir / name, f"{title}: {scenario}", "gospa_mean",
                              "GOSPA (m)", words, logx=logx and bool((g[x] > 0).all()))
            parts.append(f"![GOSPA vs {words}](figures/{name})")
    if parts:
        parts.insert(0, "## Detect and track: detection quality against tracking quality\n\nEach curve is a "
                        "chain (detector and tracker), its points the SNR levels; the band is GOSPA's 95 % "
                        "interval over trials.")
    return parts


def sections(ctx: ReportContext) -> list[str]:
    summary = ctx.summary
    if summary.empty:
        return []
    return _table(summary) + _detection_vs_tracking(summary, ctx.fig_dir, ctx.title)
