"""Progress of a command on stderr, phase by phase (calibration, evaluation, report, recording).

On a terminal, a `tqdm <https://tqdm.github.io>`_ bar per phase names the phase and
shows units done / total, rate and ETA. Anywhere else (CI, ``nohup``, a file) a bar
would be one endless line of carriage returns, so plain lines are printed instead: one
when a phase starts, one every :data:`PERIOD_S` seconds while it runs (from a timer
thread, so a phase whose units take minutes is never silent) and one when it ends::

    bench: evaluation: 37/100 units (37%), 1:02 elapsed, ETA 1:45

``quiet`` prints nothing. tqdm draws the bar; the plain lines are ours because tqdm
has no line mode for files (it rewrites one line with ``\\r`` whatever the stream).

A notice that any process of a command may come across (a worker, the forkserver, the
driver) is said once per command by :func:`say_once`, inside :func:`notices_of_one_command`.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import sys
import tempfile
import threading
import time

__all__ = ["PERIOD_S", "Progress", "say", "say_once", "notices_of_one_command"]

#: Seconds between two plain progress lines when stderr is not a terminal.
PERIOD_S = 10.0


def _fmt_seconds(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


def say(text: str, stream=None) -> None:
    """``bench: text`` as one line on ``stream`` (default stderr)."""
    stream = stream or sys.stderr
    try:
        stream.write(f"bench: {text}\n")
        stream.flush()
    except (OSError, ValueError):   # a closed or full stderr never stops a run
        pass


#: the folder where the processes of one command mark the notices said (:func:`say_once`)
NOTICES_ENV = "BENCH_NOTICES"
_said: set[str] = set()


@contextlib.contextmanager
def notices_of_one_command():
    """A folder for :func:`say_once`'s marks, named to the processes this command starts
    (by the environment they inherit), removed at its end."""
    folder = tempfile.mkdtemp(prefix="bench-notices-")
    previous = os.environ.get(NOTICES_ENV)
    os.environ[NOTICES_ENV] = folder
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop(NOTICES_ENV, None)
        else:
            os.environ[NOTICES_ENV] = previous
        shutil.rmtree(folder, ignore_errors=True)


def say_once(key: str, text: str) -> None:
    """:func:`say` ``text`` unless this process or another process of the command said
    ``key`` (the first to create the key's mark in :data:`NOTICES_ENV`'s folder speaks).
    Outside a command, or in a process that outlived its command's folder: once per process."""
    if key in _said:
        return
    _said.add(key)
    folder = os.environ.get(NOTICES_ENV)
    if folder:
        mark = os.path.join(folder, hashlib.sha256(key.encode()).hexdigest()[:32])
        try:
            os.close(os.open(mark, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        except FileExistsError:
            return
        except OSError:           # the folder is gone: this process speaks for itself
            pass
    say(text)


class Progress:
    """One command's phases. ``phase(name, total, done)`` starts a phase (ending the
    previous one), ``advance()`` counts a unit of it, ``close()`` ends the last one.
    A phase without ``total`` (report, recording) only says it started and how long
    it has run."""

    def __init__(self, *, quiet: bool = False, stream=None, period_s: float = PERIOD_S,
                 label: str = "units"):
        self.stream = stream or sys.stderr
        self.quiet = quiet
        self.terminal = bool(getattr(self.stream, "isatty", lambda: False)())
        self.period_s = period_s
        self.label = self._default_label = label
        self.detail_text = ""
        self.name: str | None = None
        self.total: int | None = None
        self.done = 0
        self._start_done = 0
        self._started = time.monotonic()
        self._bar = None
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._timer: threading.Thread | None = None

    # ---------------------------------------------------------------- the phases

    def phase(self, name: str, total: int | None = None, done: int = 0, label: str | None = None) -> None:
        """Start phase ``name`` (``total`` units of which ``done`` are already stored;
        ``label``: what it counts, if not the command's units)."""
        self._end_phase()
        with self._lock:
            self.name, self.total, self.done, self._start_done = name, total, done, done
            self.label, self.detail_text = label or self._default_label, ""
            self._started = time.monotonic()
        if self.quiet:
            return
        if self.terminal and total is not None:
            from tqdm import tqdm

            self._bar = tqdm(total=total, initial=done, desc=name, unit=" " + self.label.rstrip("s"),
                             file=self.stream, dynamic_ncols=True, leave=True, mininterval=0.2)
        else:
            self._line(f"{name}: started" if total is None else None)
            self._start_timer()

    def detail(self, text: str) -> None:
        """What the phase is at, shown after its count (e.g. the figures drawn so far)."""
        with self._lock:
            self.detail_text = text
        if self._bar is not None:
            self._bar.set_postfix_str(text, refresh=False)

    def advance(self, k: int = 1) -> None:
        with self._lock:
            self.done += k
        if self._bar is not None:
            self._bar.update(k)

    def close(self) -> None:
        """End the current phase (safe to call twice)."""
        self._end_phase()
        self._wake.set()

    # ---------------------------------------------------------------- internals

    def status(self) -> str:
        """The current phase as one line (without the ``bench:`` prefix)."""
        with self._lock:
            name, total, done, start_done = self.name, self.total, self.done, self._start_done
            elapsed = time.monotonic() - self._started
        detail = f" ({self.detail_text})" if self.detail_text else ""
        if total is None:
            return f"{name}: {_fmt_seconds(elapsed)} elapsed"
        pct = f" ({100 * done // total}%)" if total else ""
        new = done - start_done
        eta = f", ETA {_fmt_seconds(elapsed / new * (total - done))}" if new and done < total else ""
        return f"{name}: {done}/{total} {self.label}{pct}{detail}, {_fmt_seconds(elapsed)} elapsed{eta}"

    def _line(self, text: str | None = None) -> None:
        say(text or self.status(), self.stream)

    def _start_timer(self) -> None:
        self._wake = threading.Event()
        wake = self._wake

        def tick():
            while not wake.wait(self.period_s):
                self._line()

        self._timer = threading.Thread(target=tick, name="bench-progress", daemon=True)
        self._timer.start()

    def _end_phase(self) -> None:
        if self.name is None:
            return
        self._wake.set()
        if self._timer is not None:
            self._timer.join()
            self._timer = None
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif not self.quiet:
            with self._lock:
                total, done, detail = self.total, self.done, self.detail_text
                elapsed = _fmt_seconds(time.monotonic() - self._started)
            counted = f"{done}/{total} {self.label} " if total is not None else ""
            detail = f"({detail}) " if detail else ""
            self._line(f"{self.name}: done, {counted}{detail}in {elapsed}")
        self.name = None
