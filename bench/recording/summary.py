"""The summary of a run in a recording: each task's charts against SNR, and a table.

Entities (docs/architecture.md, 'Recordings')::

    /summary/{task}/{chart}/{method}              Scalars: a summary column against SNR (dB)
    /summary/{task}/{chart}/{scenario}/{method}   the same, one chart per scenario config
                                                  when the task ran on several
    /summary/table                                static TextDocument (Markdown, :mod:`bench.markdown`)

A chart is a time-series plot with one named series per method config, in the config's
colour (:func:`~bench.recording.layout.method_colors`), so its legend names the methods:
a line through the SNR levels, or markers alone where the chart has one SNR level. The
viewer's time-series x axis is the selected timeline, which the time panel shares with
the trials (``step``): so a point is indexed by its SNR on ``step`` as well as on its own
timeline :data:`SNR_TIMELINE`. Both are sequences (integers): SNR levels that are not
whole dB are drawn in tenths or hundredths of a dB (:func:`snr_axis`), which the
titles say.

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
from radarbench.bench.recording.paths import entity_name, method_entity_names, rerun_path

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pandas as pd

__all__ = ["SNR_TIMELINE", "Chart", "Series", "informative_snr", "legend_corner", "log_summary", "snr_axis", "summary_charts",
           "summary_markdown"]

#: The timeline of the summary's curves (besides ``step``, the one the viewer opens on).
SNR_TIMELINE = "SNR"
#: Marker sizes (ui points) of a curve's points, and of a chart's points where it has one SNR level.
CURVE_MARKER, SINGLE_MARKER = 3.0, 6.0


@dataclass(frozen=True)
class Series:
    """One method config's values in a chart: its entity, colour and rows sorted by SNR."""

    path: str
    label: str
    color: tuple[int, int, int]
    rows: pd.DataFrame


@dataclass(frozen=True)
class Chart:
    """One chart of the summary: a task's column against SNR on one scenario config."""

    root: str
    task: str                        # the task's name: the summary's sub-tab the chart goes in
    title: str                       # the scenario config first: what tells charts apart
    column: str
    series: tuple[Series, ...]
    snr_scale: int                   # timeline value = SNR (dB) x snr_scale (snr_axis)

    def _column(self, name: str) -> np.ndarray:
        return np.concatenate([s.rows[name].to_numpy(float) for s in self.series])

    @property
    def snrs(self) -> np.ndarray:
        """The chart's SNR levels (dB), ascending."""
        return _levels(self.series)

    @property
    def single_level(self) -> bool:
        """One SNR level: a comparison of the configs at it, no curve."""
        return self.snrs.size == 1

    @property
    def legend_corner(self) -> str:
        """The plot corner (``rerun.blueprint.Corner2D`` name) whose legend box the series
        cross least (:func:`legend_corner`)."""
        return legend_corner([(s.rows["snr_db"].to_numpy(float), s.rows[self.column].to_numpy(float))
                              for s in self.series], max(len(s.label) for s in self.series))


#: The plot a legend is placed for (ui points): half a 1280-point window wide, a grid row
#: high; and a legend's size in it: an entry's height, its marker and margins, a character.
PLOT_SIZE, LEGEND_ENTRY, LEGEND_MARGIN, LEGEND_CHAR = (620.0, 400.0), 23.0, 30.0, 7.0
#: Corners in order of preference when several are as free.
CORNERS = ("LeftTop", "RightTop", "LeftBottom", "RightBottom")


def legend_corner(curves: list[tuple[np.ndarray, np.ndarray]], longest_label: int) -> str:
    """The corner of a plot of ``curves`` ((x, y) each, drawn as lines) whose legend box
    (one entry per curve, ``longest_label`` characters wide) covers the fewest points
    sampled along the lines, in coordinates scaled to the data's range."""
    x = np.concatenate([c[0] for c in curves])
    y = np.concatenate([c[1] for c in curves])
    (x0, x1), (y0, y1) = (x.min(), x.max()), (y.min(), y.max())
    t = np.linspace(0.0, 1.0, 20)[:, None]
    samples = np.concatenate([np.column_stack([(cx[:-1] + t * np.diff(cx)).ravel(), (cy[:-1] + t * np.diff(cy)).ravel()])
                              if cx.size > 1 else np.column_stack([cx, cy]) for cx, cy in curves])
    u = (samples[:, 0] - x0) / (x1 - x0) if x1 > x0 else np.full(len(samples), 0.5)
    v = (samples[:, 1] - y0) / (y1 - y0) if y1 > y0 else np.full(len(samples), 0.5)
    width = min(0.9, (LEGEND_MARGIN + LEGEND_CHAR * longest_label) / PLOT_SIZE[0])
    height = min(0.9, (LEGEND_MARGIN + LEGEND_ENTRY * len(curves)) / PLOT_SIZE[1])
    left, bottom = u <= width, v <= height
    right, top = u >= 1 - width, v >= 1 - height
    covered = [np.sum(a & b) for a, b in ((left, top), (right, top), (left, bottom), (right, bottom))]
    return CORNERS[int(np.argmin(covered))]


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


def snr_axis(snrs) -> tuple[int, str]:
    """(scale, unit): the SNR levels ``snrs`` (dB) times ``scale`` (1, 10 or 100, the
    smallest that makes them whole; finer levels are rounded to 0.01 dB) are the
    sequence timeline's values, in ``unit``."""
    snrs = np.asarray(snrs, float)
    for scale, unit in ((1, "dB"), (10, "0.1 dB")):
        if np.allclose(snrs * scale, np.rint(snrs * scale), rtol=0.0, atol=1e-6):
            return scale, unit
    return 100, "0.01 dB"


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
    scale, unit = snr_axis(summary["snr_db"].dropna().to_numpy(float))
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
                where = f"at {levels[0]:+g} dB" if levels.size == 1 else f"vs SNR ({unit})"
                out.append(Chart(root, _task_name(task), (f"{scenario} · " if scenario else "") + f"{title} {where}",
                                 column, tuple(series), scale))
    return out


def _levels(series) -> np.ndarray:
    return np.unique(np.concatenate([s.rows["snr_db"].to_numpy(float) for s in series]))


def _series(rows: pd.DataFrame, column: str, root: str, colors: Mapping[str, tuple]) -> list[Series]:
    """Per method config with data in ``column``, its series; ``colors``: the run's colour
    of each config (:func:`~bench.recording.layout.method_colors`), as in the trial plots."""
    df = rows.dropna(subset=["snr_db", column])
    labels = sorted(df["method"].astype(str).unique())
    names = method_entity_names(labels)
    return [Series(f"{root}/{names[label]}", label, colors[label],
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


def log_chart(stream, chart: Chart) -> None:
    """Each series of ``chart``: its style (static), then its values in one column indexed
    by SNR on ``step`` and on :data:`SNR_TIMELINE` (see the module docstring)."""
    import rerun as rr

    for s in chart.series:
        path = rerun_path(s.path)
        snr = np.rint(s.rows["snr_db"].to_numpy(float) * chart.snr_scale).astype(np.int64)
        points = rr.SeriesPoints(names=s.label, colors=[s.color], markers=["circle"],
                                 marker_sizes=[SINGLE_MARKER if chart.single_level else CURVE_MARKER])
        stream.log(path, points, static=True)
        if not chart.single_level:
            stream.log(path, rr.SeriesLines(names=s.label, colors=[s.color], widths=[2.0]), static=True)
        stream.send_columns(path, indexes=[rr.TimeColumn("step", sequence=snr),
                                           rr.TimeColumn(SNR_TIMELINE, sequence=snr)],
                            columns=rr.Scalars.columns(scalars=s.rows[chart.column].to_numpy(np.float64)))


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
