"""The summary of a run in a recording: each task's charts against SNR, and a table.

Static entities (they show on any timeline)::

    /summary/{task}/{chart}/{method}              BarChart of a summary column against SNR (dB)
    /summary/{task}/{chart}/{scenario}/{method}   the same, one chart per scenario config
                                                  when the task ran on several
    /summary/table                                TextDocument (Markdown, :mod:`bench.markdown`)

Which charts a task has is its own business (``Task.recording_charts``: the summary
column and the axis title with its unit, e.g. ``("rmse_mean", "RMSE (m)")``): charts
are split by task and by scenario config, so a detector's Pd never shares an axis
with a tracker's RMSE in metres, nor a 2 m RMSE with a 100 m one
(docs/architecture.md, 'Recordings'). ``tasks`` maps each config label (the
summary's ``method`` column) to its task; a config without a task has no chart.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from bench.markdown import code, frame_table
from bench.recording.layout import PALETTE, method_colors
from bench.recording.paths import entity_name, method_entity_names, rerun_path

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pandas as pd

__all__ = ["Chart", "informative_snr", "log_summary", "summary_charts", "summary_markdown"]

@dataclass(frozen=True)
class Chart:
    """One bar chart of the summary: its entity root, title and bars."""

    root: str
    title: str
    column: str
    bars: tuple  # (entity path, colour, rows sorted by SNR) per method


#: Names of the PALETTE colours (tab10), for the colour key.
COLOUR_NAMES = ("blue", "orange", "green", "red", "purple", "brown", "pink", "grey", "olive", "cyan")


def _task_name(task) -> str:
    return str(getattr(task, "name", "") or "results")


def _charts_of(task) -> tuple:
    return tuple(getattr(task, "recording_charts", ()))


def _by_task(summary: pd.DataFrame, tasks: Mapping[str, Any]) -> list[tuple[Any, pd.DataFrame]]:
    """(task, its rows) in the order tasks first appear among the sorted config labels."""
    task_of = {label: tasks.get(label) for label in summary["method"].astype(str).unique()}
    groups: dict = {}
    for label in sorted(task_of):
        groups.setdefault(_task_name(task_of[label]), (task_of[label], []))[1].append(label)
    return [(task, summary[summary["method"].astype(str).isin(labels)]) for task, labels in groups.values()]


def summary_charts(summary: pd.DataFrame | None, tasks: Mapping[str, Any] | None = None) -> list[Chart] | None:
    """None for no/empty summary, else every chart with data (possibly none: the
    table alone). ValueError when ``method`` or ``snr_db`` is missing."""
    if summary is None or summary.empty:
        return None
    missing = {"method", "snr_db"} - set(summary.columns)
    if missing:
        raise ValueError(f"summary: missing column(s) {', '.join(sorted(missing))}")
    tasks = tasks or {}
    colors = method_colors(set(tasks) | set(summary["method"].astype(str)))
    several_tasks = len(_by_task(summary, tasks)) > 1
    out = []
    for task, rows in _by_task(summary, tasks):
        scenarios = sorted(rows["scenario"].astype(str).unique()) if "scenario" in rows.columns else [None]
        for column, title in _charts_of(task):
            if column not in rows.columns:
                continue
            key = column.removesuffix("_mean")
            for scenario in scenarios:
                part = rows if scenario is None else rows[rows["scenario"].astype(str) == scenario]
                root = f"/summary/{entity_name(_task_name(task))}/{key}_vs_snr"
                if len(scenarios) > 1:
                    root += f"/{entity_name(scenario)}"
                bars = _bars(part, column, root, colors)
                if bars:
                    words = ([_task_name(task)] if several_tasks else []) + \
                        ([scenario] if len(scenarios) > 1 else [])
                    # what tells the chart apart first: a view's header cuts a long title
                    words = list(reversed(words))
                    out.append(Chart(root, (f"{', '.join(words)} · " if words else "") + f"{title} vs SNR (dB)",
                                     column, tuple(bars)))
    return out


def _bars(rows: pd.DataFrame, column: str, root: str, colors: Mapping[str, tuple]) -> list[tuple[str, tuple, pd.DataFrame]]:
    """(entity path, colour, rows sorted by SNR) per method with data in ``column``;
    ``colors``: the run's colour of each config (:func:`~bench.recording.layout.method_colors`),
    as in the trial plots."""
    df = rows.dropna(subset=["snr_db", column])
    labels = sorted(df["method"].astype(str).unique())
    names = method_entity_names(labels)
    return [(f"{root}/{names[label]}", colors[label],
             df[df["method"].astype(str) == label].sort_values("snr_db")) for label in labels]


def informative_snr(summary: pd.DataFrame | None, tasks: Mapping[str, Any] | None = None) -> dict[str, float]:
    """Per scenario config, its most informative SNR level: where a task's
    ``informative_column`` (e.g. Pd) averaged over the configs is nearest its
    ``informative_target`` (0.5: the methods differ most there). Scenario configs
    whose tasks declare none are left out (the caller picks the middle level)."""
    if summary is None or summary.empty or "scenario" not in summary.columns:
        return {}
    out = {}
    for task, rows in _by_task(summary, tasks or {}):
        column = getattr(task, "informative_column", "")
        if not column or column not in rows.columns:
            continue
        target = float(getattr(task, "informative_target", 0.5))
        for scenario, g in rows.dropna(subset=["snr_db", column]).groupby("scenario"):
            level = g.groupby("snr_db")[column].mean()
            if not level.empty and str(scenario) not in out:
                out[str(scenario)] = float((level - target).abs().idxmin())
    return out


def log_bars(stream, bars: list, column: str) -> None:
    """Grouped bars: one BarChart per method of a chart, shifted so bars sit side by side.

    A BarChart is static and needs no timeline; its legend entry is the entity
    name (BarChart has no series name).
    """
    import rerun as rr

    if not bars:
        return
    snrs = np.unique(np.concatenate([rows["snr_db"].to_numpy(float) for _, _, rows in bars]))
    step = float(np.min(np.diff(snrs))) if snrs.size > 1 else 1.0
    width = 0.8 * step / len(bars)
    for i, (path, color, rows) in enumerate(bars):
        x = rows["snr_db"].to_numpy(float) + (i - (len(bars) - 1) / 2) * width
        stream.log(
            rerun_path(path),
            rr.BarChart(rows[column].to_numpy(float), abscissa=x,
                        widths=np.full(x.size, width, np.float32), color=color),
            static=True,
        )


def summary_markdown(summary: pd.DataFrame, tasks: Mapping[str, Any] | None = None) -> str:
    """Per chart a compact pivot (SNR x method), then every row."""
    import pandas as pd

    parts = ["# Summary"]
    charts = summary_charts(summary, tasks) or []
    colors = {rows["method"].iloc[0]: color for chart in charts for _, color, rows in chart.bars}
    if colors:       # one colour per config in every chart and trial (layout.method_colors)
        parts += ["Colours of the methods, in every chart and trial:",
                  "\n".join(f"- {COLOUR_NAMES[PALETTE.index(color)]}: {code(label)}"
                            for label, color in sorted(colors.items()))]
    for chart in charts:
        df = pd.concat([rows for _, _, rows in chart.bars])
        pivot = df.pivot_table(index="snr_db", columns="method", values=chart.column, sort=False)
        parts += [f"## {chart.title}", frame_table(pivot.sort_index().reset_index())]
    parts += ["## All rows", frame_table(summary)]
    return "\n\n".join(parts) + "\n"


def log_summary(stream, summary: pd.DataFrame | None, tasks: Mapping[str, Any] | None = None) -> list[Chart] | None:
    """Each task's charts against SNR and a Markdown table; returns the charts
    logged (see :func:`summary_charts`), None when there is no summary."""
    import rerun as rr

    charts = summary_charts(summary, tasks)
    if charts is None:
        return None
    for chart in charts:
        log_bars(stream, list(chart.bars), chart.column)
    stream.log("/summary/table", rr.TextDocument(summary_markdown(summary, tasks),
                                                 media_type=rr.MediaType.MARKDOWN), static=True)
    return charts
