"""Rerun recordings of selected trials (docs/architecture.md, 'Recordings').

Workers build a :class:`TrialRecord` per selected trial and send its bytes;
the driver alone draws records, into a file (:func:`write_recording`) or a
spawned viewer (:class:`LiveViewer`). The modules:

* :mod:`~bench.recording.record`: the record and its byte format (no rerun: workers import it);
* :mod:`~bench.recording.paths`: entity paths;
* :mod:`~bench.recording.layout`: where one trial goes (paths, colours, title);
* :mod:`~bench.recording.draw`: logging, the harness's part and the primitives tasks draw with;
* :mod:`~bench.recording.summary`: Pd / RMSE curves against SNR and the summary table;
* :mod:`~bench.recording.blueprint`: the default tabs;
* :mod:`~bench.recording.sinks`: the file and the live viewer;
* :mod:`~bench.recording.serve`: ``bench view`` (native viewer, or ``--web`` in a browser).

What a task keeps of a trial and how it draws it live with the task
(:mod:`bench.tasks`). Nothing here imports rerun at import time.
"""

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:   # the public names as static tools read them (jedi, pyright); at run time, _EXPORTS
    from radarbench.bench.recording.paths import entity_name, entity_root, method_entity_names, rerun_path, snr_part
    from radarbench.bench.recording.record import MethodTrace, Quantised, TrialRecord
    from radarbench.bench.recording.sinks import LiveViewer, write_recording

#: Public names -> the module that defines them, imported on first use (PEP 562), so that
#: ``bench view`` (:mod:`~bench.recording.serve`) does not pay for pandas and SciPy; the
#: same names as the TYPE_CHECKING imports above (tests/test_static_imports.py compares them).
_EXPORTS = {
    "entity_name": "paths", "entity_root": "paths", "method_entity_names": "paths", "rerun_path": "paths",
    "snr_part": "paths", "MethodTrace": "record", "Quantised": "record", "TrialRecord": "record",
    "LiveViewer": "sinks", "write_recording": "sinks",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
