"""The default blueprint of a recording: the summary, then one tab per chosen trial.

The viewer opens on the summary (each task's charts against SNR, split by scenario
config, and the table). Up to :data:`MAX_TABS` trials get a tab each, every scenario
config in turn, from its most informative SNR level (where Pd is nearest 0.5, for the
tasks that say so: ``Task.informative_column``) outwards.
A trial's tab stacks a row of large views over a row of smaller ones: each
task present gives its own (``Task.views``, e.g. a detector's statistics on
top, a TBD method's frames and value maps); the harness adds the 2-D track
(north up) unless a task draws the scene itself, and one time-series view per
trace name (docs/architecture.md, 'Recordings'). With nothing on top, the
first small view moves up (a tracker's track gets the large row).

rerun is imported inside the functions: importing this module stays cheap.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from radarbench.bench.recording.axes import Frame, frame_of, xy_extent
from radarbench.bench.recording.layout import TrialLayout
from radarbench.bench.recording.paths import rerun_path
from radarbench.bench.recording.record import TrialRecord

__all__ = ["MAX_TABS", "TrialTab", "Views", "blueprint", "legend_headroom", "relative", "trial_tab", "trial_time_axis"]

#: Trials that get their own tab in the default blueprint; more tabs are unusable.
MAX_TABS = 12
#: Trace views per tab: up to this many distinct trace names get one view each
#: (a tracker's error_x ... error_vz), more share one view.
MAX_TRACE_VIEWS = 8


@dataclass
class Views:
    """What one task adds to a trial's tab (rerun blueprint views)."""

    top: list = field(default_factory=list)
    bottom: list = field(default_factory=list)
    #: the task shows the scene itself (e.g. TBD frames): no 2-D track view
    draws_scene: bool = False
    #: the task logs positions in the plane (e.g. a tracker's estimate): a 2-D track view
    has_xy: bool = False
    #: those positions, in metres (arrays (..., 2), north y not negated): the track view's
    #: axes cover them besides the truth and the measurements
    xy: tuple = ()


@dataclass(frozen=True)
class TrialTab:
    """A trial's layout and its tasks' views: all the blueprint needs of it,
    without keeping the record (frames are megabytes)."""

    layout: TrialLayout
    views: tuple[Views, ...]
    #: the track view's axes (bench.recording.axes); None: no track view, or nothing drawn in it
    frame: Frame | None = None

    @property
    def has_track_view(self) -> bool:
        """Whether the harness adds the 2-D track (north up): positions in the plane and no
        task drawing the scene itself."""
        return (not any(v.draws_scene for v in self.views)
                and (self.layout.has_xy or any(v.has_xy for v in self.views)))


def trial_tab(layout: TrialLayout, rec: TrialRecord) -> TrialTab:
    tab = TrialTab(layout, tuple(task.views(layout, rec) for task in layout.tasks))
    if not tab.has_track_view:
        return tab
    # the tab keeps the frame, not the positions (a multi-target trial's every plot)
    extent = xy_extent(rec.truth_xy, rec.measurements_xy, *(xy for v in tab.views for xy in v.xy))
    return TrialTab(layout, tuple(replace(v, xy=()) for v in tab.views), None if extent is None else frame_of(extent))


#: Share of a plot's data range kept free above the data for the legend (top right).
LEGEND_HEADROOM = 1.0


def legend_headroom(lo: float, hi: float) -> float:
    """A value above ``hi`` by LEGEND_HEADROOM of the range ``lo``..``hi``: a series drawn
    there (e.g. the onset marker) makes the plot's automatic y range leave room for the
    legend above the data. (A blueprint ``ScalarAxis`` range is not applied by the 0.41
    viewer, measured: its plots fit the data.)"""
    span = (hi - lo) or max(abs(hi), 1.0)
    return hi + LEGEND_HEADROOM * span


def trial_time_axis(layout: TrialLayout):
    """A trial's time-series views show its own steps: a recording whose trials differ in
    length (25 scans beside 160 steps) would otherwise stretch every plot, and put the
    time cursor, to the longest; None when the length is unknown."""
    import rerun.blueprint as rrb

    if layout.steps < 2:
        return None
    return rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.absolute(seq=0),
                                                 end=rrb.TimeRangeBoundary.absolute(seq=layout.steps - 1)))


def relative(layout: TrialLayout, path: str) -> str:
    """A view's content entry for ``path``, relative to the trial root.

    Explicit paths: entity filters only support a trailing ``/**``, and
    ``$origin`` spares re-escaping the root."""
    return "+ $origin" + rerun_path(path)[len(rerun_path(layout.root)):]


def _trace_views(layout: TrialLayout) -> list:
    """One time-series view per trace name (``error_x`` of every method
    together), or a single one when there are many names."""
    import rerun.blueprint as rrb

    by_key: dict[str, list[str]] = {}
    for m in layout.methods:
        for key, path in m.traces.items():
            by_key.setdefault(key, []).append(relative(layout, path))
    if not by_key:
        return []
    origin = rerun_path(layout.root)
    if len(by_key) > MAX_TRACE_VIEWS:
        return [rrb.TimeSeriesView(origin=origin, name="traces", contents=[p for v in by_key.values() for p in v],
                                   axis_x=trial_time_axis(layout))]
    # The legend only where several methods share the view (else the view's name says it).
    return [rrb.TimeSeriesView(origin=origin, name=_with_unit(layout, key), contents=paths, axis_x=trial_time_axis(layout),
                               plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop, visible=len(paths) > 1))
            for key, paths in by_key.items()]


def _with_unit(layout: TrialLayout, trace: str) -> str:
    """A trace's view name with its unit, as the first of the trial's tasks that knows it
    says (:meth:`bench.tasks.base.Task.trace_unit`)."""
    unit = next((u for u in (task.trace_unit(trace) for task in layout.tasks if hasattr(task, "trace_unit")) if u), "")
    return f"{trace} ({unit})" if unit else trace


def _track_view(tab: TrialTab):
    """The 2-D track (north up), framed on its axes and their labels (the viewer's own fit
    leaves labels out)."""
    import rerun.blueprint as rrb

    bounds = None
    if tab.frame is not None:
        x_range, y_range = tab.frame.bounds()
        bounds = rrb.VisualBounds2D(x_range=x_range, y_range=y_range)
    return rrb.Spatial2DView(origin=rerun_path(tab.layout.root), name="track (north up)", visual_bounds=bounds)


def _trial_container(tab: TrialTab, title: str):
    import rerun.blueprint as rrb

    layout = tab.layout
    origin = rerun_path(layout.root)
    top = [v for views in tab.views for v in views.top]
    track = _track_view(tab) if tab.has_track_view else None
    bottom = [track] if track is not None else []
    bottom += [v for views in tab.views for v in views.bottom]
    bottom += _trace_views(layout)
    if not top and bottom:
        top.append(bottom.pop(0))
    track_below = bool(bottom) and bottom[0] is track
    if not top:
        return rrb.Spatial2DView(origin=origin, name=title)
    if not bottom:
        return rrb.Vertical(*top, name=title)
    # More than three views side by side are too narrow: a grid instead, beside the track
    # (a third of the width: its axes and names need room).
    row = bottom[0] if len(bottom) == 1 else rrb.Horizontal(*bottom) if len(bottom) <= 3 else (
        rrb.Horizontal(bottom[0], rrb.Grid(*bottom[1:]), column_shares=[1, 2]) if track_below else rrb.Grid(*bottom))
    return rrb.Vertical(*top, row, name=title, row_shares=[3] * len(top) + [2])


def _chart_view(chart):
    """A chart's 2-D view (:mod:`bench.recording.plot`), framed on its plot, axis titles
    and legend."""
    import rerun.blueprint as rrb

    x_range, y_range = chart.bounds()
    return rrb.Spatial2DView(origin=rerun_path(chart.root), name=chart.title,
                             visual_bounds=rrb.VisualBounds2D(x_range=x_range, y_range=y_range))


def _summary_tab(charts):
    """The charts of :func:`bench.recording.summary.summary_charts`, a sub-tab per task
    (its charts side by side; a row per scenario config when it ran on several), then
    the table in a sub-tab of its own."""
    import rerun.blueprint as rrb

    by_task: dict[str, list] = {}
    for chart in charts:
        by_task.setdefault(chart.task, []).append(chart)
    tabs = []
    for task, mine in by_task.items():
        views = [_chart_view(chart) for chart in mine]
        per_scenario = len({chart.column for chart in mine})
        tabs.append(views[0] if len(views) == 1 else rrb.Horizontal(*views, name=task)
                    if len(views) == per_scenario else rrb.Grid(*views, grid_columns=per_scenario, name=task))
    table = rrb.TextDocumentView(origin="/summary/table", name="summary table")
    return rrb.Tabs(*tabs, table, name="summary", active_tab=0)


def _informativeness(tab: TrialTab, informative: dict[str, float], middle: dict[str, float]):
    """Sort key within a scenario config: the informative SNR level first (else the
    middle one), then the levels nearest it; null trials last."""
    layout = tab.layout
    snr = layout.sort_key[2] if not layout.sort_key[1] else None
    if snr is None:
        return (1, 0.0, 0.0, layout.sort_key[3])
    best = informative.get(layout.scenario, middle.get(layout.scenario, snr))
    return (0, abs(snr - best), snr, layout.sort_key[3])


def chosen(tabs: list[TrialTab], informative: dict[str, float] | None = None) -> list[TrialTab]:
    """The trials that get a tab, at most MAX_TABS: every scenario config gets its turn
    (round robin, so every family is reachable), each starting from its most
    informative SNR level (``informative``: scenario config -> SNR, from
    :func:`bench.recording.summary.informative_snr`; else the middle recorded level)."""
    informative = informative or {}
    by_scenario: dict[str, list[TrialTab]] = {}
    for tab in sorted(tabs, key=lambda tab: tab.layout.sort_key):
        by_scenario.setdefault(tab.layout.scenario, []).append(tab)
    queues = []
    for scenario, group in by_scenario.items():
        levels = sorted({t.layout.sort_key[2] for t in group if not t.layout.sort_key[1]})
        middle = {scenario: levels[(len(levels) - 1) // 2]} if levels else {}
        queues.append(sorted(group, key=lambda tab: _informativeness(tab, informative, middle)))
    picked: list[TrialTab] = []
    while len(picked) < MAX_TABS and any(queues):
        for queue in queues:
            if queue and len(picked) < MAX_TABS:
                picked.append(queue.pop(0))
    order = {scenario: i for i, scenario in enumerate(by_scenario)}
    return sorted(picked, key=lambda tab: (order[tab.layout.scenario], picked.index(tab)))


def blueprint(tabs: list[TrialTab], charts, informative: dict[str, float] | None = None):
    """Tabs: the summary first, where the viewer opens (``charts`` from
    :func:`bench.recording.summary.summary_charts`; None: no summary tab), then the
    chosen trials, the most informative of each scenario config first."""
    import rerun.blueprint as rrb

    several = len({tab.layout.scenario for tab in tabs}) > 1
    containers = [_trial_container(tab, f"{tab.layout.scenario} {tab.layout.title}" if several
                                   else tab.layout.title) for tab in chosen(tabs, informative)]
    if charts is not None:
        containers.insert(0, _summary_tab(charts))
    # The side panels collapsed: the views get the whole width of a laptop's window
    # (legends name the methods); the time panel keeps its play bar.
    parts = [rrb.TimePanel(timeline="step", state="collapsed"), rrb.BlueprintPanel(state="collapsed"),
             rrb.SelectionPanel(state="collapsed")]
    if containers:
        parts.insert(0, rrb.Tabs(*containers, active_tab=0))
    return rrb.Blueprint(*parts)
