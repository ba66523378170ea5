"""The summary of a run in a recording: each task's charts against SNR, and a table.

Entities (docs/architecture.md, 'Recordings')::

    /summary/{task}/{chart}/...                   a summary column against SNR (dB), drawn as a
                                                  plot in a 2-D view (:mod:`bench.recording.plot`):
                                                  axes with titles and units, a curve per method
                                                  config, the configs' names beside the plot
    /summary/{task}/{chart}/{scenario}/...        the same, one chart per scenario config
                                                  when the task ran on several
    /summary/table                                static TextDocument (Markdown, :mod:`bench.markdown`)

A chart has one curve per method config, in the config's colour
(:func:`~bench.recording.layout.method_colors`, as in the trial plots), or points alone
where the chart has one SNR level. A config whose values equal an earlier config's at
every level is named "(identical to ...)": its curve lies exactly under that one.

Which charts a task has is its own business (``Task.recording_charts``: the summary
column and the axis title with its unit, e.g. ``("rmse_mean", "RMSE (m)")``): charts
are split by task and by scenario config, so a detector's Pd never shares an axis
with a tracker's RMSE in metres, nor a 2 m RMSE with a 100 m one. ``tasks`` maps each
config label (the summary's ``method`` column) to its task; a config without a task has
no chart, and a chart only exists where some config has a value in its column.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from radarbench.bench.markdown import code, frame_table
from radarbench.bench.recording.layout import PALETTE, method_colors
from radarbench.bench.recording.paths import entity_name, method_entity_names
from radarbench.bench.recording.plot import Plot, log_plot
from radarbench.bench.results.tables import identical_curves

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pandas as pd

__all__ = ["SNR_AXIS_TITLE", "Chart", "Series", "informative_snr", "log_summary", "summary_charts", "summary_markdown"]

#: The x axis of every summary chart
SNR_AXIS_TITLE = "SNR (dB)"


@dataclass(frozen=True)
class Series:
    """One method config's values in a chart: its entity, colour and rows sorted by SNR."""

    path: str
    label: str
    color: tuple[int, int, int]
    rows: pd.DataFrame
    #: the legend's entry: the label, and "(identical to X)" where its values equal X's
    legend: str = ""


@dataclass(frozen=True)
class Chart:
    """One chart of the summary: a task's column against SNR on one scenario config."""

    root: str
    task: str                        # the task's name: the summary's sub-tab the chart goes in
    title: str                       # the scenario config first: what tells charts apart
    column: str
    series: tuple[Series, ...]
    y_title: str                     # the column's name with its unit ("RMSE (m)")

    @property
    def snrs(self) -> np.ndarray:
        """The chart's SNR levels (dB), ascending."""
        return _levels(self.series)

    @property
    def single_level(self) -> bool:
        """One SNR level: a comparison of the configs at it, no curve."""
        return self.snrs.size == 1

    def bounds(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The x and y ranges of the chart's 2-D view: its plot, labels and legend."""
        plot = Plot.covering(self.snrs, np.concatenate([s.rows[self.column].to_numpy(float) for s in self.series]))
        return plot.bounds(max(len(s.legend) for s in self.series))


#: Names of the PALETTE colours (tab10), for the colour key.
COLOUR_NAMES = ("blue", "orange", "green", "red", "purple", "brown", "pink", "grey", "olive", "cyan")


def _task_name(task) -> str:
    return str(getattr(task, "name", "") or "results")


def _charts_of(task) -> tuple:
    return tuple(getattr(task, "recording_charts", ()))


def _by_task(summary: pd.DataFrame, tasks: Mapping[str, Any]) -> list[tuple[Any, pd.DataFrame]]:
    """(task, its rows) in the order tasks first appear in the summary (the plan's order)."""
    task_of = {label: tasks.get(label) for label in summary["method"].astype(str).unique()}
    groups: dict = {}
    for label in task_of:
        groups.setdefault(_task_name(task_of[label]), (task_of[label], []))[1].append(label)
    return [(task, summary[summary["method"].astype(str).isin(labels)]) for task, labels in groups.values()]


def summary_charts(summary: pd.DataFrame | None, tasks: Mapping[str, Any] | None = None) -> list[Chart] | None:
    """None for no/empty summary, else every chart with data (possibly none: the
    table alone), task by task and scenario config by scenario config in the order
    they first appear in the summary. ValueError when ``method`` or ``snr_db`` is missing."""
    if summary is None or summary.empty:
        return None
    missing = {"method", "snr_db"} - set(summary.columns)
    if missing:
        raise ValueError(f"summary: missing column(s) {', '.join(sorted(missing))}")
    tasks = tasks or {}
    colors = method_colors({label: tasks.get(label) for label in set(tasks) | set(summary["method"].astype(str))})
    out = []
    for task, rows in _by_task(summary, tasks):
        scenarios = list(rows["scenario"].astype(str).unique()) if "scenario" in rows.columns else [None]
        for scenario in scenarios:
            part = rows if scenario is None else rows[rows["scenario"].astype(str) == scenario]
            for column, title in _charts_of(task):
                if column not in rows.columns:
                    continue
                root = f"/summary/{entity_name(_task_name(task))}/{column.removesuffix('_mean')}_vs_snr"
                if len(scenarios) > 1:
                    root += f"/{entity_name(scenario)}"
                series = _series(part, column, root, colors)
                if not series:
                    continue
                levels = _levels(series)
                where = f"at {levels[0]:+g} dB" if levels.size == 1 else "vs SNR"
                out.append(Chart(root, _task_name(task), (f"{scenario} · " if scenario else "") + f"{title} {where}",
                                 column, tuple(series), title))
    return out


def _levels(series) -> np.ndarray:
    return np.unique(np.concatenate([s.rows["snr_db"].to_numpy(float) for s in series]))


def _series(rows: pd.DataFrame, column: str, root: str, colors: Mapping[str, tuple]) -> list[Series]:
    """Per method config with data in ``column``, its series; ``colors``: the run's colour
    of each config (:func:`~bench.recording.layout.method_colors`), as in the trial plots."""
    df = rows.dropna(subset=["snr_db", column])
    labels = sorted(df["method"].astype(str).unique())
    names = method_entity_names(labels)
    same = identical_curves(df.assign(config=df["method"].astype(str)).sort_values("config", kind="stable"), column)
    return [Series(f"{root}/{names[label]}", label, colors[label], df[df["method"].astype(str) == label].sort_values("snr_db"),
                   label if label not in same else f"{label} (identical to {same[label]})") for label in labels]


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


def log_chart(stream, chart: Chart) -> None:
    """``chart`` as a plot in its 2-D view (:func:`bench.recording.plot.log_plot`)."""
    log_plot(stream, chart.root, chart.series, chart.column, SNR_AXIS_TITLE, chart.y_title)


def summary_markdown(summary: pd.DataFrame, tasks: Mapping[str, Any] | None = None) -> str:
    """Per chart a compact pivot (SNR x method), then every row."""
    import pandas as pd

    parts = ["# Summary"]
    charts = summary_charts(summary, tasks) or []
    colors: dict[str, dict[str, tuple]] = {}     # task -> config -> colour (layout.method_colors)
    for chart in charts:
        colors.setdefault(chart.task, {}).update({s.label: s.color for s in chart.series})
    if colors:
        parts += ["Colours of the methods, task by task, in every chart and trial (the charts' legends name them):",
                  "\n".join(f"- {task}: " + ", ".join(f"{COLOUR_NAMES[PALETTE.index(color)]} {code(label)}"
                                                    for label, color in sorted(mine.items()))
                            for task, mine in colors.items())]
    for chart in charts:
        df = pd.concat([s.rows for s in chart.series])
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
        log_chart(stream, chart)
    stream.log("/summary/table", rr.TextDocument(summary_markdown(summary, tasks),
                                                 media_type=rr.MediaType.MARKDOWN), static=True)
    return charts
