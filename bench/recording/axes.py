"""A reference frame for a 2-D view in metres: Rerun 0.41's 2-D views draw no axes.

The harness logs one per trial that has a track view (docs/architecture.md,
'Recordings'), static, under ``{trial}/axes``; a task may draw one over an image of
the plane (e.g. a grid of cells). It is an L of two axis lines along the bottom and
the left of the drawn extent, a tick mark at every round step (1, 2 or 5 × 10^k m,
the same on both axes: the view keeps one scale for x and y) and, under
``.../axes/labels``, the ticks' values and the axes' titles, in km or m as the step
suggests. Neutral grey: no method's colour.

rerun and matplotlib are imported inside the functions: importing this module
stays cheap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from radarbench.bench.recording.layout import NEUTRAL_COLOR
from radarbench.bench.recording.paths import rerun_path

__all__ = ["DRAWABLE_MAX", "Frame", "frame_of", "log_axes", "log_frame_lines", "xy_extent"]

#: Intervals the longer side is cut into at a round step (matplotlib's MaxNLocator: at
#: most MAX_INTERVALS, with at least MIN_TICKS ticks inside the data's range; the frame
#: adds a tick at each end where the data do not start or stop on one: mostly 4 to 6)
MAX_INTERVALS, MIN_TICKS = 5, 2
#: A step from which the ticks read in km (0.5 km, 1 km, ...) rather than m
KM_FROM_STEP_M = 500.0
#: A tick mark's length, as a share of the frame's longer side
TICK_SHARE = 0.02
#: The smallest span a frame covers: a target that never moves still gets a scale
MIN_SPAN_M = 1.0
#: Room around the frame for its labels, in tick lengths (a label is about 2 high on a
#: view a few hundred pixels tall): the view's bounds (Frame.bounds)
LABEL_ROOM = {"left": 12.0, "right": 2.0, "top": 6.0, "bottom": 9.0}
#: How far left of the y axis its values are centred, in tick lengths: clear of the axis
#: for a value about 8 tick lengths wide (a view some 200 pixels wide)
Y_VALUES_LEFT = 6.0
#: the largest coordinate drawn (Rerun draws positions in float32; bench.recording.draw.north_up)
DRAWABLE_MAX = float(np.finfo(np.float32).max)


@dataclass(frozen=True)
class Frame:
    """The ticks of both axes (metres, north y not negated) and their unit; the
    ``screen_*`` and ``tick`` values place them in the view (y negated: north up)."""

    x_ticks: np.ndarray
    y_ticks: np.ndarray
    unit: str                    # "km" or "m"

    @property
    def scale(self) -> float:
        return 1000.0 if self.unit == "km" else 1.0

    def text(self, value: float) -> str:
        """A tick's value in the frame's unit, with as many decimals as the step needs."""
        step = float(self.x_ticks[1] - self.x_ticks[0]) / self.scale
        decimals = max(0, math.ceil(-math.log10(step) - 1e-9))
        return f"{value / self.scale:.{decimals}f}"

    @property
    def screen_y(self) -> np.ndarray:
        """The y ticks on screen, the bottom (north's least, the largest screen y) first."""
        return -self.y_ticks

    @property
    def tick(self) -> float:
        """A tick mark's length: TICK_SHARE of the frame's longer side."""
        return TICK_SHARE * max(self.x_ticks[-1] - self.x_ticks[0], self.y_ticks[-1] - self.y_ticks[0])

    def bounds(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The screen x and y ranges that show the frame with its labels (LABEL_ROOM)."""
        (left, right), (top, bottom) = self.x_ticks[[0, -1]], self.screen_y[[-1, 0]]
        room = {side: share * self.tick for side, share in LABEL_ROOM.items()}
        return ((float(left - room["left"]), float(right + room["right"])),
                (float(top - room["top"]), float(bottom + room["bottom"])))


def xy_extent(*arrays) -> np.ndarray | None:
    """The (2, 2) box ``[[x_min, y_min], [x_max, y_max]]`` of the finite positions among
    ``arrays`` (each (..., 2), metres); None when there is none."""
    rows = [np.asarray(a, np.float64).reshape(-1, 2) for a in arrays if a is not None]
    xy = np.concatenate(rows) if rows else np.empty((0, 2))
    xy = xy[(np.abs(xy) <= DRAWABLE_MAX).all(axis=1)]        # what is drawn (draw.north_up); no NaN
    return np.stack([xy.min(axis=0), xy.max(axis=0)]) if xy.size else None


def frame_of(extent: np.ndarray) -> Frame:
    """The ticks covering ``extent`` (:func:`xy_extent`): the round step MaxNLocator
    picks for the longer side, then every multiple of it from just below to just above
    each side."""
    from matplotlib.ticker import MaxNLocator

    lo, hi = np.asarray(extent, np.float64)
    widen = np.maximum(MIN_SPAN_M - (hi - lo), 0.0) / 2
    lo, hi = lo - widen, hi + widen
    longer = int(np.argmax(hi - lo))
    nice = MaxNLocator(nbins=MAX_INTERVALS, steps=[1, 2, 5, 10], min_n_ticks=MIN_TICKS)
    step = float(np.diff(nice.tick_values(lo[longer], hi[longer]))[0])
    ticks = [np.arange(math.floor(a / step + 1e-9), math.ceil(b / step - 1e-9) + 1) * step for a, b in zip(lo, hi)]
    ticks = [t if t.size > 1 else np.append(t, t[-1] + step) for t in ticks]
    return Frame(ticks[0], ticks[1], "km" if step >= KM_FROM_STEP_M else "m")


def log_frame_lines(stream, path: str, xs: np.ndarray, ys: np.ndarray, tick: float) -> None:
    """An L of two axis lines (left and bottom) through the ticks at screen positions
    ``xs`` (left to right) and ``ys`` (bottom first, y down), with a tick mark of length
    ``tick`` at each, as a static entity at ``path``."""
    import rerun as rr

    left, bottom, top = xs[0], ys[0], ys[-1]
    strips = [np.array([[left, top], [left, bottom], [xs[-1], bottom]])]
    strips += [np.array([[x, bottom], [x, bottom + tick]]) for x in xs]
    strips += [np.array([[left, y], [left - tick, y]]) for y in ys]
    stream.log(rerun_path(path), rr.LineStrips2D(strips, colors=[NEUTRAL_COLOR],
                                                 radii=[rr.components.Radius.ui_points(0.75)]), static=True)


def log_axes(stream, path: str, frame: Frame, scale: float = 1.0, offset=(0.0, 0.0)) -> None:
    """``frame`` as static entities at ``path`` (the lines) and ``path/labels`` (tick
    values and titles; the viewer draws a label centred below its point). Over an image
    (e.g. a grid of cells), ``scale`` and ``offset`` give its pixels: pixel = scale ·
    (x, -y) + offset, a transform of ``path`` (which its labels inherit)."""
    import rerun as rr

    if scale != 1.0 or any(offset):
        stream.log(rerun_path(path), rr.Transform3D(translation=[*map(float, offset), 0.0], scale=float(scale)),
                   static=True)
    xs, ys, tick = frame.x_ticks, frame.screen_y, frame.tick
    left, bottom, top = xs[0], ys[0], ys[-1]
    log_frame_lines(stream, path, xs, ys, tick)
    # x values under their tick, y values left of theirs (raised by half a line), the x
    # title under the values, the y title above the y axis
    places = ([(x, bottom + tick, frame.text(x)) for x in xs]
              + [(left - Y_VALUES_LEFT * tick, y - tick, frame.text(-y)) for y in ys]
              + [((left + xs[-1]) / 2, bottom + 5 * tick, f"x east ({frame.unit})"),
                 (left, top - 3 * tick, f"y north ({frame.unit})")])
    stream.log(rerun_path(f"{path}/labels"),
               rr.Points2D([p[:2] for p in places], labels=[p[2] for p in places], colors=[NEUTRAL_COLOR],
                           radii=[rr.components.Radius.ui_points(0.5)], show_labels=True), static=True)
