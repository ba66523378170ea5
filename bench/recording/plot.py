"""A chart of the summary drawn as a plot in a 2-D view: titled axes with units, a legend
beside the data.

Rerun 0.41's time-series views take their x axis from the timeline the time panel
selects, which the trials' steps own: a curve against SNR drawn there reads its levels
as step numbers (``#-15``) with no title or unit, and its legend sits over the data.
So the harness draws each summary chart itself, static, in a 2-D view
(docs/architecture.md, 'Recordings'):

    {root}/axes            the axis lines and tick marks; ``axes/labels``: tick values and
                           the axes' titles ("SNR (dB)", the chart's metric with its unit)
    {root}/{method}        the config's curve (a line through its SNR levels) and its points
    {root}/legend          the configs' names right of the plot, each at the height its curve
                           ends, moved apart so that no two overlap

The plot area is :data:`PLOT_WIDTH` × :data:`PLOT_HEIGHT` view units whatever the data
(x right, y up: drawn with y negated, the 2-D view's y pointing down); ticks are
matplotlib's round steps, chosen per axis (:func:`ticks`).

rerun and matplotlib are imported inside the functions: importing this module stays cheap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from radarbench.bench.recording.axes import log_frame_lines
from radarbench.bench.recording.layout import NEUTRAL_COLOR
from radarbench.bench.recording.paths import rerun_path

__all__ = ["PLOT_HEIGHT", "PLOT_WIDTH", "Plot", "legend_heights", "log_plot", "ticks"]

#: The plot area, in view units (the view keeps one scale for x and y: a 5:3 plot)
PLOT_WIDTH, PLOT_HEIGHT = 100.0, 60.0
#: A tick mark's length, and the gap between the plot and its legend (view units)
TICK, LEGEND_GAP = 2.0, 4.0
#: Vertical room a legend entry needs (view units, about a line of text in a view some
#: 350 points high): entries closer than this are moved apart
LEGEND_LINE = 5.5
#: The width (points) of the view a chart is laid out for (a 1280-point window, two
#: charts side by side), and of a label's character in it (the viewer's font, measured)
VIEW_POINTS, CHAR_POINTS = 620.0, 7.5
#: Room around the plot for the tick values and the titles (view units)
ROOM = {"left": 16.0, "top": 12.0, "bottom": 14.0}
#: Intervals an axis is cut into at a round step (matplotlib's MaxNLocator)
MAX_INTERVALS = 5


def ticks(lo: float, hi: float) -> np.ndarray:
    """Round ticks (1, 2 or 5 × 10^k apart) from at or below ``lo`` to at or above ``hi``;
    a range of one value gets a unit span around it."""
    from matplotlib.ticker import MaxNLocator

    if not hi > lo:
        half = max(abs(lo) * 0.1, 0.5)
        lo, hi = lo - half, hi + half
    values = MaxNLocator(nbins=MAX_INTERVALS, steps=[1, 2, 2.5, 5, 10]).tick_values(lo, hi)
    step = float(values[1] - values[0])
    return np.arange(math.floor(lo / step + 1e-9), math.ceil(hi / step - 1e-9) + 1) * step


def tick_text(values: np.ndarray) -> list[str]:
    """Tick values with as many decimals as their step needs."""
    step = float(values[1] - values[0]) if values.size > 1 else 1.0
    decimals = max(0, math.ceil(-math.log10(step) - 1e-9))
    return [f"{v:.{decimals}f}".replace("-", "−") for v in values]


def legend_heights(ends: np.ndarray, line: float = LEGEND_LINE) -> np.ndarray:
    """Screen heights (y down) for legend entries wanted at ``ends`` (where each curve
    ends), at least ``line`` apart, each as near its wish as that allows: entries are
    placed in order of their wish, pushed down past the one above, then the block is
    shifted up by half its excess so that it stays centred on the wishes."""
    ends = np.asarray(ends, float)
    order = np.argsort(ends, kind="stable")
    placed = ends[order].copy()
    for i in range(1, placed.size):
        placed[i] = max(placed[i], placed[i - 1] + line)
    placed -= (placed - ends[order]).mean()
    out = np.empty_like(placed)
    out[order] = placed
    return out


@dataclass(frozen=True)
class Plot:
    """Where a chart's values land in its 2-D view: the ticks of both axes and the mapping."""

    x_ticks: np.ndarray
    y_ticks: np.ndarray

    @classmethod
    def covering(cls, x: np.ndarray, y: np.ndarray) -> Plot:
        x, y = np.asarray(x, float), np.asarray(y, float)
        x, y = x[np.isfinite(x)], y[np.isfinite(y)]
        return cls(ticks(float(x.min()), float(x.max())), ticks(float(y.min()), float(y.max())))

    def screen_x(self, x) -> np.ndarray:
        x0, x1 = self.x_ticks[[0, -1]]
        return (np.asarray(x, float) - x0) / (x1 - x0) * PLOT_WIDTH

    def screen_y(self, y) -> np.ndarray:
        """View heights of the values ``y``: negated, so that larger values are higher up."""
        y0, y1 = self.y_ticks[[0, -1]]
        return -(np.asarray(y, float) - y0) / (y1 - y0) * PLOT_HEIGHT

    def screen(self, x, y) -> np.ndarray:
        """(n, 2) view positions of the values ``x``, ``y``."""
        return np.column_stack([self.screen_x(x), self.screen_y(y)])

    def bounds(self, longest_label: int) -> tuple[tuple[float, float], tuple[float, float]]:
        """The view's x and y ranges: the plot, its labels and a legend of entries up to
        ``longest_label`` characters."""
        right = PLOT_WIDTH + LEGEND_GAP + char_width(longest_label) * (longest_label + 2)
        return ((-ROOM["left"], right), (-PLOT_HEIGHT - ROOM["top"], ROOM["bottom"]))


def char_width(longest_label: int) -> float:
    """A character's width in view units when the view (:data:`VIEW_POINTS` wide) shows
    the plot and a legend of entries up to ``longest_label`` characters: w solves
    w = CHAR_POINTS · (plot + w · (longest_label + 2)) / VIEW_POINTS; the legend takes at
    most half the view (longer names run past its edge)."""
    plot = ROOM["left"] + PLOT_WIDTH + LEGEND_GAP
    legend_points = min(CHAR_POINTS * (longest_label + 2), VIEW_POINTS / 2)
    return CHAR_POINTS * plot / (VIEW_POINTS - legend_points)


def log_plot(stream, root: str, series, column: str, x_title: str, y_title: str) -> Plot:
    """Draw a chart (``series``: each with ``path``, ``legend``, ``color`` and ``rows``, its
    values in ``column`` against ``snr_db``) under ``root`` as static entities."""
    import rerun as rr

    plot = Plot.covering(np.concatenate([s.rows["snr_db"].to_numpy(float) for s in series]),
                         np.concatenate([s.rows[column].to_numpy(float) for s in series]))
    xs, ys = plot.screen_x(plot.x_ticks), plot.screen_y(plot.y_ticks)
    log_frame_lines(stream, f"{root}/axes", xs, ys, TICK)
    longest = max(len(s.legend) for s in series)
    width = char_width(longest)
    # the y title over the axis, starting at the view's left edge
    places = ([(x, TICK, t) for x, t in zip(xs, tick_text(plot.x_ticks))]
              + [(-3.5 * TICK, y - TICK, t) for y, t in zip(ys, tick_text(plot.y_ticks))]
              + [(PLOT_WIDTH / 2, 4.5 * TICK, x_title),
                 (-ROOM["left"] + width * (len(y_title) + 2) / 2, -PLOT_HEIGHT - 4.5 * TICK, y_title)])
    stream.log(rerun_path(f"{root}/axes/labels"),
               rr.Points2D([p[:2] for p in places], labels=[p[2] for p in places], colors=[NEUTRAL_COLOR],
                           radii=[rr.components.Radius.ui_points(0.5)], show_labels=True), static=True)
    ends = []
    for s in series:
        xy = plot.screen(s.rows["snr_db"], s.rows[column])
        path = rerun_path(s.path)
        if len(xy) > 1:
            stream.log(path, rr.LineStrips2D([xy], colors=[s.color], radii=[rr.components.Radius.ui_points(1.0)]),
                       static=True)
        stream.log(f"{path}/points", rr.Points2D(xy, colors=[s.color], radii=[rr.components.Radius.ui_points(3.0)]),
                   static=True)
        ends.append(xy[-1, 1])
    heights = legend_heights(np.array(ends))
    x = PLOT_WIDTH + LEGEND_GAP
    stream.log(rerun_path(f"{root}/legend"),
               rr.Points2D([(x + width * (len(s.legend) + 2) / 2, h) for s, h in zip(series, heights)],
                           labels=[s.legend for s in series], colors=[s.color for s in series],
                           radii=[rr.components.Radius.ui_points(0.5)], show_labels=True), static=True)
    return plot
