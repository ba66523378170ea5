"""Where a recording goes: an ``.rrd`` file, or a spawned Rerun viewer.

Both sinks log through the same code (:mod:`bench.recording.draw`,
:mod:`bench.recording.summary`) and send the same default blueprint
(:mod:`bench.recording.blueprint`), so a live run looks like its file
(docs/architecture.md, 'Recordings'). Both need the task of every method
config (``tasks``: label -> :class:`bench.tasks.base.Task`): the record does
not carry it, the plan does.
"""

from __future__ import annotations

import errno
import os
import struct
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

import radarbench.bench.recording.blueprint as bp
from radarbench.bench.errors import space_hint
from radarbench.bench.recording.draw import log_records
from radarbench.bench.recording.layout import trial_layout
from radarbench.bench.recording.record import TrialRecord
from radarbench.bench.recording.serve import has_display, listening, rerun_executable
from radarbench.bench.recording.summary import informative_snr, log_summary, summary_charts

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pandas as pd

__all__ = ["LiveViewer", "write_recording"]



def write_recording(
    path: str | os.PathLike,
    records: list[TrialRecord],
    summary: pd.DataFrame | None = None,
    *,
    tasks: Mapping[str, Any],
    recording_id: str,
    application_id: str = "radar-bench",
    recording_name: str | None = None,
) -> Path:
    """Write ``records`` (and the ``summary`` curves) to an ``.rrd`` file.

    Atomic: rerun encodes the recording into memory; bench writes the bytes to a
    temporary file of a unique name beside ``path`` (:func:`bench.results.runfolder.atomic_output`),
    checks the footer, and renames it. A full disk or a file-size limit is then an
    OSError of that write (one line, exit 3), never a truncated ``recording.rrd`` or a
    wait on rerun's writer thread. The whole recording is held in memory once (tens of
    MB for the largest committed preset).
    ``summary`` needs columns ``method`` and ``snr_db``; the columns each task charts
    (``Task.recording_charts``; NaN rows skipped) become curves against SNR, every row and column
    goes into the table. The viewer lists the recording under ``application_id`` by
    ``recording_name`` (default: ``recording_id``). Returns ``path``.
    """
    import rerun as rr

    from radarbench.bench.results import runfolder

    path = Path(path)
    records = list(records)  # iterated twice: blueprint, then logging
    layouts = [trial_layout(r, tasks) for r in records]  # fails on bad names before any I/O
    tabs = [bp.trial_tab(lay, rec) for lay, rec in zip(layouts, records)]
    charts = summary_charts(summary, tasks)
    runfolder.folder_for(path.parent)
    # Rerun encodes into memory and we write the bytes: a full disk or a file-size limit
    # is then an OSError of our own write (one line, exit 3), where rerun's file sink
    # only logs it in its writer thread and its flush / disconnect wait forever.
    stream = rr.RecordingStream(application_id, recording_id=recording_id)
    memory = stream.memory_recording()
    try:
        stream.send_blueprint(bp.blueprint(tabs, charts, informative_snr(summary, tasks)),
                              make_active=True, make_default=True)
        stream.send_recording_name(recording_name or recording_id)
        # The summary first: the viewer opens on it and a browser shows it while the
        # trials (megabytes of frames) still stream in.
        log_summary(stream, summary, tasks)
        log_records(records, stream, tabs)
        stream.flush()
        data = memory.drain_as_bytes()  # a whole .rrd, footer included (checked below)
    finally:
        stream.disconnect()
    with runfolder.atomic_output(path) as (handle, tmp):
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())
        if not rrd_complete(tmp):
            raise OSError(errno.EIO, "the recording could not be written whole"
                                     f"{space_hint(path) or ' (is the disk full?)'}", str(path))
    return path


#: The end of an .rrd file: footer offset and length (u64 each), a checksum (u32), this
#: magic and the format version (u32): offset + length + 32 == the file's size.
_RRD_FOOTER_MAGIC = b"RRF2FOOT"


def rrd_complete(path: str | os.PathLike) -> bool:
    """Whether the .rrd file at ``path`` ends with its footer (written whole)."""
    try:
        with open(path, "rb") as f:
            size = f.seek(0, os.SEEK_END)
            if size < 32:
                return False
            f.seek(size - 32)
            tail = f.read(32)
    except OSError:
        return False
    offset, length = struct.unpack("<QQ", tail[:16])
    return tail[20:28] == _RRD_FOOTER_MAGIC and offset + length + 32 == size


class LiveViewer:
    """Stream records to a spawned Rerun viewer (``bench run --viewer``).

    Uses the same logging code as :func:`write_recording`. The default
    blueprint is re-sent while the set of trial tabs grows (up to MAX_TABS),
    which resets a layout the user changed in the meantime.

    Raises RuntimeError (one line) when no viewer can be started: no display,
    no ``rerun`` executable, or a viewer that never listens on ``port``.
    Spawning reuses a viewer already listening on ``port``.
    """

    def __init__(self, *, tasks: Mapping[str, Any], recording_id: str, application_id: str = "radar-bench",
                 port: int = 9876, recording_name: str | None = None):
        import rerun as rr

        if not has_display():
            raise RuntimeError("cannot open the Rerun viewer: no display (DISPLAY/WAYLAND_DISPLAY unset)")
        exe = rerun_executable()
        if exe is None:
            raise RuntimeError("cannot open the Rerun viewer: `rerun` executable not found")
        stream = rr.RecordingStream(application_id, recording_id=recording_id)
        try:
            rr.spawn(port=port, connect=True, recording=stream, executable_path=exe,
                     hide_welcome_screen=True)
        except Exception as exc:  # the bindings raise various types
            stream.disconnect()
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc)
            raise RuntimeError(f"cannot open the Rerun viewer: {first}") from exc
        # rr.spawn only warns when the viewer dies at start-up: check for real.
        if not listening(port, timeout_s=1.0):
            stream.disconnect()
            raise RuntimeError(f"cannot open the Rerun viewer: nothing listens on port {port}")
        stream.send_recording_name(recording_name or recording_id)
        self._attach(stream, tasks)

    @classmethod
    def from_stream(cls, stream, *, tasks: Mapping[str, Any]) -> LiveViewer:
        """Wrap a stream whose sink is already set (an existing viewer via
        ``connect_grpc``, a file in tests) instead of spawning a viewer."""
        self = cls.__new__(cls)
        self._attach(stream, tasks)
        return self

    def _attach(self, stream, tasks: Mapping[str, Any]) -> None:
        self._stream = stream
        self._tasks = dict(tasks)
        self._tabs: list[bp.TrialTab] = []
        self._summary: tuple | None = None  # charts of the logged summary
        self._informative: dict[str, float] = {}
        self._shown: tuple | None = None

    def log_records(self, records: Iterable[TrialRecord]) -> None:
        """Log records now (the viewer shows them as they arrive)."""
        records = list(records)
        tabs = [bp.trial_tab(trial_layout(r, self._tasks), r) for r in records]
        log_records(records, self._stream, tabs)
        self._tabs += tabs
        self._send_blueprint()

    def log_summary(self, summary: pd.DataFrame | None) -> None:
        """Log the Pd / RMSE vs SNR curves and table, and add the summary tab."""
        charts = log_summary(self._stream, summary, self._tasks)
        if charts is not None:
            self._summary = tuple(charts)
            self._informative = informative_snr(summary, self._tasks)
        self._send_blueprint()

    def _send_blueprint(self) -> None:
        # Only when the tabs change: each send replaces the viewer's layout.
        chosen = tuple(tab.layout.root for tab in bp.chosen(self._tabs, self._informative))
        if (chosen, self._summary) != self._shown:
            self._stream.send_blueprint(bp.blueprint(self._tabs, self._summary, self._informative))
            self._shown = (chosen, self._summary)

    def close(self) -> None:
        """Flush and disconnect; safe to call twice."""
        if self._stream is not None:
            # Bounded: a viewer the user already closed must not hang the run.
            self._stream.flush(timeout_sec=30.0)
            self._stream.disconnect()
            self._stream = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
