"""CPU seconds of a unit's work, numba's compilation left out (docs/architecture.md, 'Warm-up').

A unit's runtime is what its generation and each method config cost in CPU time
(``time.process_time``: its process's, so the wait for a busy core does not count, and a
worker runs one unit at a time), less the CPU time spent holding numba's compiler lock or its LLVM lock:
compiling a specialisation, or loading one from the on-disk cache, on a kernel's first
call with new types (linking a loaded kernel's machine code, on its first call, holds the
LLVM lock only). The warm-up compiles the kernels before any unit, so that time is
normally nil; when it is not (a cold cache the warm-up did not see, a type it did not
pass), the unit's runtime still holds the kernels' work only.
"""

from __future__ import annotations

import sys
import threading
import time

__all__ = ["work_seconds", "compiling_seconds"]

_lock = threading.Lock()
_compiling = {"seconds": 0.0, "depth": 0, "since": 0.0}
_listening = False


def _listen() -> None:
    """Count the time numba holds its compiler lock or its LLVM lock from now on (once numba
    is imported; the locks are re-entrant and nest, so only the outermost hold is timed)."""
    global _listening
    from numba.core import event

    class CompilerLockTime(event.Listener):
        def on_start(self, event_):
            with _lock:
                if _compiling["depth"] == 0:
                    _compiling["since"] = time.process_time()
                _compiling["depth"] += 1

        def on_end(self, event_):
            with _lock:
                _compiling["depth"] -= 1
                if _compiling["depth"] == 0:
                    _compiling["seconds"] += time.process_time() - _compiling["since"]

    for kind in ("numba:compiler_lock", "numba:llvm_lock"):
        event.register(kind, CompilerLockTime())
    _listening = True


def compiling_seconds() -> float:
    """CPU seconds this process has held numba's compiler or LLVM lock since this module first
    looked (0 until numba is imported: nothing can have compiled)."""
    if not _listening:
        if "numba" not in sys.modules:
            return 0.0
        _listen()
    with _lock:
        held = _compiling["seconds"]
        if _compiling["depth"]:
            held += time.process_time() - _compiling["since"]
    return held


def work_seconds() -> float:
    """A clock of CPU seconds that stands still while numba compiles: the difference of
    two readings is the CPU time of the work between them, compilation excluded."""
    return time.process_time() - compiling_seconds()
