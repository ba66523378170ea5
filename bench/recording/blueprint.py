"""The default blueprint of a recording: one tab per trial, then the summary.

The first :data:`MAX_TABS` trials (by scenario, SNR, trial) get a tab each.
A trial's tab stacks a row of large views over a row of smaller ones: each
task present gives its own (``Task.views``, e.g. a detector's statistics on
top, a TBD method's frames and value maps); the harness adds the 2-D track
(north up) unless a task draws the scene itself, and one time-series view per
trace name (docs/architecture.md, 'Recordings'). With nothing on top, the
first small view moves up (a tracker's track gets the large row).

rerun is imported inside the functions: importing this module stays cheap.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from bench.recording.layout import TrialLayout
from bench.recording.paths import rerun_path
from bench.recording.record import TrialRecord

__all__ = ["MAX_TABS", "TrialTab", "Views", "blueprint", "relative", "trial_tab"]

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


@dataclass(frozen=True)
class TrialTab:
    """A trial's layout and its tasks' views: all the blueprint needs of it,
    without keeping the record (frames are megabytes)."""

    layout: TrialLayout
    views: tuple[Views, ...]


def trial_tab(layout: TrialLayout, rec: TrialRecord) -> TrialTab:
    return TrialTab(layout, tuple(task.views(layout, rec) for task in layout.tasks))


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
        return [rrb.TimeSeriesView(origin=origin, name="traces", contents=[p for v in by_key.values() for p in v])]
    return [rrb.TimeSeriesView(origin=origin, name=key, contents=paths) for key, paths in by_key.items()]


def _trial_container(tab: TrialTab, title: str):
    import rerun.blueprint as rrb

    layout = tab.layout
    origin = rerun_path(layout.root)
    top = [v for views in tab.views for v in views.top]
    bottom = []
    if not any(v.draws_scene for v in tab.views) and (layout.has_xy or any(v.has_xy for v in tab.views)):
        bottom.append(rrb.Spatial2DView(origin=origin, name="track (north up)"))
    bottom += [v for views in tab.views for v in views.bottom]
    bottom += _trace_views(layout)
    if not top and bottom:
        top.append(bottom.pop(0))
    if not top:
        return rrb.Spatial2DView(origin=origin, name=title)
    if not bottom:
        return rrb.Vertical(*top, name=title)
    # More than three views side by side are too narrow: a grid instead.
    row = bottom[0] if len(bottom) == 1 else rrb.Horizontal(*bottom) if len(bottom) <= 3 else rrb.Grid(*bottom)
    return rrb.Vertical(*top, row, name=title, row_shares=[3] * len(top) + [2])


def _summary_tab(charts: tuple[tuple[str, str], ...]):
    import rerun.blueprint as rrb

    views = [rrb.BarChartView(origin=root, name=title) for root, title in charts]
    views.append(rrb.TextDocumentView(origin="/summary/table", name="summary"))
    return rrb.Horizontal(*views, column_shares=[3] * len(charts) + [2], name="summary")


def chosen(tabs: list[TrialTab]) -> list[TrialTab]:
    """The trials that get a tab: the first MAX_TABS by scenario, SNR and trial."""
    return sorted(tabs, key=lambda tab: tab.layout.sort_key)[:MAX_TABS]


def blueprint(tabs: list[TrialTab], charts: tuple | None):
    """Tabs: the chosen trials, then the summary (``charts`` from
    :func:`bench.recording.summary.summary_charts`; None: no summary tab)."""
    import rerun.blueprint as rrb

    several = len({tab.layout.scenario for tab in tabs}) > 1
    containers = [_trial_container(tab, f"{tab.layout.scenario} {tab.layout.title}" if several
                                   else tab.layout.title) for tab in chosen(tabs)]
    if charts is not None:
        containers.append(_summary_tab(charts))
    parts = [rrb.TimePanel(timeline="step")]
    if containers:
        parts.insert(0, rrb.Tabs(*containers, active_tab=0))
    return rrb.Blueprint(*parts)
