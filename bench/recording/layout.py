"""Where one recorded trial goes: its entity paths, colours and tab title.

A :class:`TrialLayout` is computed once per record and is the one source of
paths for the logging code and for the blueprint, so the two cannot disagree
(docs/architecture.md, 'Recordings'). It knows only what the harness logs
(truth, measurements, each method's traces); the paths a task logs under the
trial root or a method entity are named by that task, which reserves them here
(``Task.scene_entities``, ``Task.method_entities``) so that no method or trace
name can shadow them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from radarbench.bench.recording.paths import entity_root, method_entity_names
from radarbench.bench.recording.record import TrialRecord

__all__ = ["AXES", "MEASUREMENT_COLOR", "NEUTRAL_COLOR", "PALETTE", "TRUTH_COLOR", "MethodLayout", "TrialLayout",
           "method_colors", "trial_layout"]

# tab10 with its grey replaced by teal (grey is the truth's): distinct on the viewer's dark
# (native) and light (web, by default) themes alike.
PALETTE = [
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (0, 128, 128), (188, 189, 34), (23, 190, 207),
]
#: the truth's and the colour scales' labels: a mid grey, readable on both themes (a light
#: grey vanishes on the web viewer's light theme)
NEUTRAL_COLOR = (140, 140, 140)
TRUTH_COLOR = NEUTRAL_COLOR
MEASUREMENT_COLOR = (255, 200, 60)


def method_colors(tasks: Mapping[str, Any]) -> dict[str, tuple[int, int, int]]:
    """The colour of each method config of a run (``tasks``: config label -> its task, or
    None): by its rank among the run's configs of the same task (sorted labels), so a
    config has one colour in every chart and every trial of a recording, whichever configs
    share the chart or the scenario, and the configs of a task (which share its charts)
    have distinct colours up to the PALETTE's ten. Configs of different tasks, which share
    no chart, may share a colour."""
    by_task: dict[str, list[str]] = {}
    for label in sorted(tasks):
        by_task.setdefault(str(getattr(tasks[label], "name", "")), []).append(label)
    return {label: PALETTE[i % len(PALETTE)] for labels in by_task.values() for i, label in enumerate(labels)}


#: The child of a trial root that holds its track view's axes (bench.recording.axes).
AXES = "axes"
#: Children of a trial root the harness logs itself.
ROOT_CHILDREN = ("truth", "measurements", AXES)


@dataclass(frozen=True)
class MethodLayout:
    """One method config under one trial: its entity, colour, task and traces."""

    label: str
    task: Any                        # the method's Task (bench.tasks.base.Task)
    color: tuple[int, int, int]
    base: str
    traces: dict[str, str]           # trace key -> entity path

    def path(self, child: str) -> str:
        return f"{self.base}/{child}"


@dataclass(frozen=True)
class TrialLayout:
    """Entity paths and a tab title for one record."""

    root: str
    scenario: str
    title: str                       # without the scenario, which is the same in most recordings
    sort_key: tuple
    methods: tuple[MethodLayout, ...]
    tasks: tuple[Any, ...]           # the tasks of the methods, each once, in the order given
    has_xy: bool                     # truth or measurements in metres
    steps: int = 0                   # the trial's steps (its time axis runs 0 .. steps - 1); 0: unknown

    def path(self, child: str) -> str:
        return f"{self.root}/{child}"

    def methods_of(self, task) -> list[MethodLayout]:
        return [m for m in self.methods if m.task is task]

    def label_at(self, m: MethodLayout | None = None) -> float:
        """Where along its track a series is named on a 2-D plot, as a share of its drawn
        points: the truth (``m`` None) at its first point (the viewer opens on the last
        step, where the current measurement is named), the i-th of n methods at
        (i + 1) / (n + 1), so that the names of tracks that overlap (an estimate on the truth)
        do not."""
        return 0.0 if m is None else (self.methods.index(m) + 1) / (len(self.methods) + 1)


def trial_layout(rec: TrialRecord, tasks: Mapping[str, Any]) -> TrialLayout:
    """The layout of ``rec``; ``tasks`` maps each method config label of the run to its
    task (all of them: a config's colour is its rank among its task's, :func:`method_colors`)."""
    missing = [label for label in rec.methods if label not in tasks]
    if missing:
        raise ValueError(f"no task given for method config(s) {', '.join(map(repr, missing))}")
    present = tuple(dict.fromkeys(tasks[label] for label in tasks if label in rec.methods))
    root = entity_root(rec.scenario, rec.snr_db, rec.trial)
    reserved = set(ROOT_CHILDREN).union(*(t.scene_entities for t in present))
    names = method_entity_names(rec.methods, reserved=reserved)
    methods, colors = [], method_colors(tasks)
    for label in sorted(rec.methods):
        task, base = tasks[label], f"{root}/{names[label]}"
        trace_names = method_entity_names(rec.methods[label].traces, reserved=task.method_entities)
        traces = {key: f"{base}/{trace_names[key]}" for key in rec.methods[label].traces}
        methods.append(MethodLayout(label, task, colors[label], base, traces))
    snr = "null" if rec.snr_db is None else f"{rec.snr_db:+g} dB"
    return TrialLayout(root=root, scenario=rec.scenario, title=f"{snr} · trial {rec.trial}",
                       sort_key=(rec.scenario, rec.snr_db is None, rec.snr_db or 0.0, rec.trial),
                       methods=tuple(methods), tasks=present,
                       has_xy=rec.truth_xy is not None or rec.measurements_xy is not None, steps=len(rec.t))
