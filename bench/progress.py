"""A progress bar on stderr: units done / total, rate and ETA.

Quiet when stderr is not a terminal or when asked (``--quiet``).
"""

from __future__ import annotations

import sys
import time


def _fmt_seconds(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


class Progress:
    def __init__(self, total: int, done: int = 0, *, quiet: bool = False, label: str = "units",
                 stream=None):
        self.total, self.done, self.label = total, done, label
        self.stream = stream or sys.stderr
        self.enabled = not quiet and hasattr(self.stream, "isatty") and self.stream.isatty()
        self._start = time.monotonic()
        self._start_done = done
        self._last = 0.0
        self.draw(force=True)

    def advance(self, k: int = 1) -> None:
        self.done += k
        self.draw()

    def draw(self, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self._last < 0.1 and self.done < self.total:
            return
        self._last = now
        width = 30
        frac = self.done / self.total if self.total else 1.0
        bar = "#" * int(width * frac) + "-" * (width - int(width * frac))
        elapsed = now - self._start
        new = self.done - self._start_done
        eta = _fmt_seconds(elapsed / new * (self.total - self.done)) if new else "?"
        self.stream.write(f"\r[{bar}] {self.done}/{self.total} {self.label}  "
                          f"{_fmt_seconds(elapsed)} elapsed, ETA {eta} ")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.draw(force=True)
            self.stream.write("\n")
            self.stream.flush()
