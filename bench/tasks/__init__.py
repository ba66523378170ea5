"""The tasks of the harness: what maneuver detection, tracking,
track-before-detect and multi-target tracking each mean to it (docs/architecture.md, 'Tasks').

Each task is a :class:`~bench.tasks.base.Task` in its own package's ``__init__.py``,
with its metrics (``metrics.py``) and report sections (``report.py``, imported only
when a report is written) in the package. :func:`bench.registry.tasks` lists the
built-ins below, then the tasks of the entry-point group ``bench.tasks``; a
new task touches its own module and the scenarios and methods that serve it,
nothing in the harness.
"""

from __future__ import annotations

from collections.abc import Iterable

from radarbench.bench.metrics import CELL_KEYS
from radarbench.bench.tasks.base import OutputError, RecordedScene, ReportContext, Task, Views
from radarbench.bench.tasks.cells import CellDetectionOutput, CellDetectionTask, MapScene
from radarbench.bench.tasks.detection import DetectionScene, DetectionTask
from radarbench.bench.tasks.detecttrack import DetectTrackScene, DetectTrackTask
from radarbench.bench.tasks.multitarget import MultiTargetScene, MultiTargetTask
from radarbench.bench.tasks.tbd import TBDScene, TBDTask
from radarbench.bench.tasks.tracking import TrackingScene, TrackingTask

__all__ = ["BUILTIN_TASKS", "CellDetectionOutput", "DetectionScene", "DetectTrackScene", "MapScene", "MultiTargetScene", "OutputError",
           "RecordedScene", "ReportContext", "TBDScene", "Task", "TrackingScene", "Views", "summary_columns"]

#: The built-in tasks, in registry order.
BUILTIN_TASKS = (DetectionTask, TrackingTask, TBDTask, CellDetectionTask, MultiTargetTask, DetectTrackTask)

#: summary.csv's leading columns, in the order its readers have always found
#: them: a cell's keys and the columns of the file's first version (some
#: shared by several tasks, ``seconds_per_trial`` the harness's own).
FIRST_COLUMNS = (*CELL_KEYS, "n_trials", "pd", "pd_low", "pd_high", "pfa", "pfa_low", "pfa_high",
                 "delay_mean", "delay_low", "delay_high", "delay_median", "rmse_mean", "rmse_low", "rmse_high",
                 "seconds_per_trial", "threshold", "realised_snr_db",
                 "divergence_rate", "divergence_low", "divergence_high", "nees_mean")


def summary_columns(tasks: Iterable[Task]) -> list[str]:
    """summary.csv's columns: :data:`FIRST_COLUMNS`, then every other column
    of each task (``Task.summary_columns``), task by task."""
    return list(dict.fromkeys([*FIRST_COLUMNS, *(c for task in tasks for c in task.summary_columns)]))
