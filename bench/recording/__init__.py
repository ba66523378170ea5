"""Rerun recordings of selected trials (docs/architecture.md, 'Recordings').

Workers build a :class:`TrialRecord` per selected trial and send its bytes;
the driver alone draws records, into a file (:func:`write_recording`) or a
spawned viewer (:class:`LiveViewer`). The modules:

* :mod:`~bench.recording.record`: the record and its byte format (no rerun: workers import it);
* :mod:`~bench.recording.paths`: entity paths;
* :mod:`~bench.recording.layout`: where one trial goes (paths, colours, title);
* :mod:`~bench.recording.draw`: logging, the harness's part and the primitives tasks draw with;
* :mod:`~bench.recording.summary`: Pd / RMSE bars and the summary table;
* :mod:`~bench.recording.blueprint`: the default tabs;
* :mod:`~bench.recording.sinks`: the file and the live viewer.

What a task keeps of a trial and how it draws it live with the task
(:mod:`bench.tasks`). Nothing here imports rerun at import time.
"""

from bench.recording.paths import entity_name, entity_root, method_entity_names, rerun_path, snr_part
from bench.recording.record import MethodTrace, Quantised, TrialRecord
from bench.recording.sinks import LiveViewer, write_recording

__all__ = [
    "LiveViewer",
    "MethodTrace",
    "Quantised",
    "TrialRecord",
    "entity_name",
    "entity_root",
    "method_entity_names",
    "rerun_path",
    "snr_part",
    "write_recording",
]
