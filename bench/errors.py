"""Errors the harness reports to users as one line, never as a traceback.

Each kind has its exit code (docs/running.md, 'Exit codes'; ``bench --help``):

* :class:`ConfigError`, exit 2: bad input, fixed by changing the command, the sweep
  file or the folder named (a sweep error, an ``--out`` under a regular file, a
  folder that is not a run folder, a ``results.sqlite`` that is not a bench store);
* :class:`Fault`, exit 3: the machine refused (permission denied, read-only file
  system, disk full, file-size limit, I/O error); nothing is half-written, and the
  same command resumes once the cause is fixed;
* :class:`FolderInUse`, exit 4: another ``bench`` holds the run folder's lock.

Not an error kind: ``bench run`` exits 6 (:data:`EXIT_FAILED_UNITS`) when the run
folder holds failed (unit, method config) runs, after writing the report and one line
per failing config on stderr (:mod:`bench.results.failures`).

Out of memory (:func:`is_out_of_memory`: a MemoryError, or an import that could not map
its library) is exit 3 too, wherever it strikes.
"""

from __future__ import annotations

import errno
import os
import resource
import shutil
from pathlib import Path

#: The exit codes of ``bench`` (``bench --help`` lists them: :data:`bench.cli.EXIT_CODES`),
#: here so that any module can return one without importing the command line.
EXIT_BUG = 1
EXIT_BAD_INPUT = 2
EXIT_ENVIRONMENT = 3
EXIT_IN_USE = 4
EXIT_INTERRUPTED = 130
EXIT_REGRESSION = 5     # bench compare --fail-on-regression: a metric got significantly worse
EXIT_FAILED_UNITS = 6   # bench run: some (unit, method config) runs failed (bench.results.failures)


class ConfigError(ValueError):
    """Bad user input: a sweep file, a parameter, a command-line option.

    The message names the field and the problem, e.g.
    ``methods[1].params.window: expected int >= 3, got -2``. The CLI prefixes
    it with the file name, prints it on one line and exits with code 2.
    """

    def __init__(self, field: str, problem: str):
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}" if field else problem)

    def within(self, prefix: str) -> "ConfigError":
        """The same error with its field placed under ``prefix``."""
        field = f"{prefix}.{self.field}" if self.field else prefix
        return ConfigError(field, self.problem)


def unknown_name(kind: str, name: str, known) -> str:
    """``unknown method 'cumulnt' (did you mean 'cumulant'? known: ...)``: one line, the
    closest known name first (:func:`difflib.get_close_matches`), then every known one."""
    import difflib

    known = sorted(known)
    close = difflib.get_close_matches(str(name), known, n=1, cutoff=0.6)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return f"unknown {kind} {name!r} ({hint}known: {', '.join(known) or 'none'})"


class Fault(Exception):
    """The environment refused (file system, disk, store I/O): ``PATH: CAUSE``, exit 3."""

    exit_code = EXIT_ENVIRONMENT

    def __init__(self, path: str | os.PathLike, problem: str):
        self.path, self.problem = str(path), problem
        super().__init__(f"{self.path}: {problem}" if self.path else problem)


class FolderInUse(Fault):
    """Another ``bench`` process holds the run folder's lock: exit 4."""

    exit_code = EXIT_IN_USE


#: errno values that mean "the path given cannot be used" (bad input, exit 2)
#: rather than "the machine refused" (exit 3).
_BAD_PATH_ERRNOS = {errno.ENOTDIR, errno.ENAMETOOLONG, errno.ELOOP, errno.EISDIR, errno.EEXIST}


def space_hint(path: str | os.PathLike) -> str:
    """Why a write may have failed although the error does not say (SQLite's "disk I/O
    error"): a full file system or a file-size limit; "" when neither applies."""
    limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if limit != resource.RLIM_INFINITY:
        return f" (a file-size limit of {limit} bytes is set: `ulimit -f`)"
    try:
        free = shutil.disk_usage(Path(path).parent if not Path(path).is_dir() else path).free
    except OSError:
        return ""
    return f" (only {free} bytes free on the device)" if free < 16 << 20 else ""


def _short(path: str, limit: int = 160) -> str:
    """A path short enough to leave room for the cause on the error's one line."""
    return path if len(path) <= limit else f"{path[:limit // 2]}...{path[-(limit // 2 - 3):]}"


def os_fault(exc: OSError, path: str | os.PathLike | None = None, doing: str = "") -> ConfigError | Fault:
    """The one-line error for an OSError on ``path`` (default: the one the error names):
    exit 2 when the path itself is unusable (a file where a folder should be, a name too
    long, a symbolic link bench refuses to follow), exit 3 when the machine refused."""
    where = _short(str(path if path is not None else (exc.filename or "")))
    cause = exc.strerror or str(exc) or type(exc).__name__
    if exc.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT):
        cause += space_hint(where) if exc.errno == errno.EFBIG else ""
    problem = f"{doing}: {cause}" if doing else cause
    if exc.errno in _BAD_PATH_ERRNOS:
        return ConfigError(where, problem)
    return Fault(where, problem)


#: What the dynamic loader and the C libraries say when a mapping or an allocation is
#: refused (``ulimit -v``, a full machine): an import that failed for lack of memory.
_OUT_OF_MEMORY_TEXT = ("failed to map segment from shared object", "cannot allocate memory", "out of memory")


def is_out_of_memory(exc: BaseException) -> bool:
    """Whether ``exc`` (or what caused it) is the machine refusing memory: a MemoryError,
    an ENOMEM, or an ImportError of a shared library that could not be mapped. Such a
    failure is exit 3 wherever it strikes, never a plugin's bug nor an unknown name."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, MemoryError) or (isinstance(exc, OSError) and exc.errno == errno.ENOMEM):
            return True
        if isinstance(exc, (ImportError, OSError)) and any(t in str(exc).lower() for t in _OUT_OF_MEMORY_TEXT):
            return True
        # an extension module whose allocation failed during import returned NULL without
        # setting MemoryError: CPython then raises this SystemError (seen under ulimit -v)
        if isinstance(exc, SystemError) and "error return without exception set" in str(exc):
            return True
        exc = exc.__cause__ or exc.__context__
    return False
