"""numba's on-disk cache in the harness's processes (docs/architecture.md, 'Pipeline', numba cache).

Kernels are compiled with ``@numba.njit(cache=True)``; numba keeps each one's object code
in an index file (``.nbi``) and one data file per signature (``.nbc``). Left to itself,
numba fails the call that compiles a kernel when a file of its cache is damaged (a
truncated index raises from :mod:`pickle`; a garbled data file raises, or loads object
code that is wrong) or when the folder is full, and when ``NUMBA_CACHE_DIR`` cannot be
written it falls back to the ``__pycache__`` folders of the installed package.

:func:`install` (called by :func:`bench.registry.discover`, so in every process of a run
before it imports a plugin) gives every kernel compiled with ``cache=True`` a
:class:`GuardedCache` instead, the ones decorated earlier included:

- its folder is ``NUMBA_CACHE_DIR`` if set, else numba's user-wide folder (``~/.cache/numba``,
  where numba itself goes when the source's folder cannot be written); never a package's folder;
- each of its files carries the SHA-256 of its content, so a garbled or truncated file is
  found before anything in it is used; its names end in ``.checked.nbi`` /
  ``.checked.N.nbc``, apart from the files of numba's own format in a shared folder;
- a failure to load or save (a damaged entry, a folder not writable or full) never fails
  the kernel: it compiles without the cache; a damaged entry is written anew; a folder that
  could not be written is not tried again by this process. stderr says, once per command
  (:func:`bench.run.progress.say_once`: the first of its processes to say it), which folder
  was skipped and why;
- a kernel is compiled by one process at a time (:class:`CompileLock`): a process that misses
  a kernel in the cache while another compiles it waits, then loads what the other saved, so
  the workers of a cold run never compile the same kernel twice.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import io
import os
import pickle
import sys
import time

from numba.core import caching, config
from numba.core.dispatcher import Dispatcher
from numba.misc.appdirs import AppDirs

from radarbench.bench.run.progress import say_once

#: what opens each file of the cache, before the SHA-256 of the rest
MAGIC = b"radarbench numba cache 1\n"
#: what the names of the cache's files carry before numba's extension
SUFFIX = ".checked"
_DIGEST = hashlib.sha256().digest_size


class DamagedEntry(Exception):
    """A file of the cache whose checksum does not match its content."""


def cache_root() -> str:
    """The folder of the kernels' cache: ``NUMBA_CACHE_DIR`` (numba's setting), else
    numba's user-wide cache folder (under ``XDG_CACHE_HOME`` on Linux)."""
    return config.CACHE_DIR or AppDirs(appname="numba", appauthor=False).user_cache_dir


def _framed(payload: bytes) -> bytes:
    return MAGIC + hashlib.sha256(payload).digest() + payload


def _unframed(blob: bytes, path: str) -> bytes:
    start = len(MAGIC) + _DIGEST
    if not blob.startswith(MAGIC) or hashlib.sha256(blob[start:]).digest() != blob[len(MAGIC):start]:
        raise DamagedEntry(f"{os.path.basename(path)}: its checksum does not match (damaged or truncated)")
    return blob[start:]


def _read(path: str) -> bytes:
    with open(path, "rb") as f:
        return f.read()


class _CheckedFile(caching.IndexDataCacheFile):
    """numba's index and data files, each framed with its checksum (:func:`_framed`)."""

    def _load_index(self) -> dict:
        try:
            blob = _read(self._index_path)
        except FileNotFoundError:
            return {}
        stream = io.BytesIO(_unframed(blob, self._index_path))
        if pickle.load(stream) != self._version:     # another numba: its pickles may not load here
            return {}
        stamp, overloads = pickle.loads(stream.read())
        return overloads if stamp == self._source_stamp else {}

    def _save_index(self, overloads: dict) -> None:
        self._write(self._index_path, pickle.dumps(self._version, protocol=-1)
                    + self._dump((self._source_stamp, overloads)))

    def _load_data(self, name: str):
        path = self._data_path(name)
        return pickle.loads(_unframed(_read(path), path))

    def _save_data(self, name: str, data) -> None:
        self._write(self._data_path(name), self._dump(data))

    def _write(self, path: str, payload: bytes) -> None:
        with self._open_for_write(path) as f:
            f.write(_framed(payload))

    def save(self, key, data) -> None:
        """numba's save, over a damaged index replaced by an empty one (its other entries
        are compiled again when next called)."""
        try:
            self._load_index()
        except DamagedEntry:
            self.flush()
        super().save(key, data)


class _Locator(caching._SourceFileBackedLocatorMixin, caching._CacheLocator):
    """A kernel's folder in :func:`cache_root` (numba's own sub-path of the source's
    folder), checked when written, not when the kernel is decorated."""

    def __init__(self, py_func, py_file: str):
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        self.root = cache_root()
        self._cache_path = os.path.join(self.root, self.get_suitable_cache_subpath(py_file))

    def get_cache_path(self) -> str:
        return self._cache_path

    @classmethod
    def from_function(cls, py_func, py_file: str):
        return cls(py_func, py_file) if os.path.exists(py_file) else None


def _numba_locator(*names: str) -> tuple:
    return tuple(getattr(caching, name) for name in names if hasattr(caching, name))


#: numba's locators that write into NUMBA_CACHE_DIR or beside the source (the package's
#: __pycache__): :class:`_Locator` takes their place (numba 0.60 names them with a leading _)
_REPLACED = _numba_locator("UserProvidedCacheLocator", "_UserProvidedCacheLocator",
                           "InTreeCacheLocator", "_InTreeCacheLocator")


class _Impl(caching.FunctionCache._impl_class):
    _locator_classes = [_Locator, *(cls for cls in caching.FunctionCache._impl_class._locator_classes
                                    if not issubclass(cls, _REPLACED))]

    def get_filename_base(self, fullname, abiflags):
        return super().get_filename_base(fullname, abiflags) + SUFFIX


class GuardedCache(caching.FunctionCache):
    """numba's cache of one kernel whose failures never fail the kernel (module docstring)."""

    _impl_class = _Impl

    def __init__(self, py_func):
        super().__init__(py_func)
        self._cache_file = _CheckedFile(self._cache_path, self._impl.filename_base, self._cache_file._source_stamp)
        self._root = getattr(self._impl.locator, "root", self._cache_path)

    def load_overload(self, sig, target_context):
        """The kernel's object code for ``sig`` from the cache; on a miss, once no other process
        compiles this kernel (:class:`CompileLock`, held by this one until :meth:`save_overload`
        or a failed compilation), what that process may have saved meanwhile."""
        loaded = self._load(sig, target_context)
        if loaded is None and self._root not in _UNWRITABLE and COMPILE_LOCK.take(self._lock_path()):
            loaded = self._load(sig, target_context)
            if loaded is not None:
                COMPILE_LOCK.give_back(self._lock_path())
        return loaded

    def _load(self, sig, target_context):
        try:
            return super().load_overload(sig, target_context)
        except Exception as exc:  # noqa: BLE001 - whatever the cache holds, the kernel compiles
            _skipped(self._root, exc, saving=False)
            return None

    def _lock_path(self) -> str:
        return self._cache_file._index_path + LOCK_SUFFIX

    def save_overload(self, sig, data) -> None:
        try:
            self._save(sig, data)
        finally:
            COMPILE_LOCK.give_back(self._lock_path())

    def _save(self, sig, data) -> None:
        if self._root in _UNWRITABLE:
            return
        try:
            super().save_overload(sig, data)
        except Exception as exc:  # noqa: BLE001 - the kernel is compiled: only the cache lacks it
            if _skipped(self._root, exc, saving=True) in (NOT_WRITABLE, FULL):
                _UNWRITABLE.add(self._root)


#: what the lock file of a kernel's index file adds to its name
LOCK_SUFFIX = ".lock"
#: how long a process waits for another to compile a kernel before it compiles the kernel itself
#: (a bound, never reached by a compilation: the other process may be stopped)
COMPILE_WAIT_S = 300.0
#: how often a waiting process looks whether the other one is done
_POLL_S = 0.02


class CompileLock:
    """One process compiles a kernel at a time: an exclusive ``flock`` on a file beside the
    kernel's index, taken on a miss in the cache, given back once the kernel is saved (or its
    compilation failed). The operating system gives it back when a process ends, so a killed
    compiler blocks no one. Taken again by the process that holds it (a kernel compiled for a
    second signature while its first compiles), it counts. A kernel's callees are compiled
    inside it and take their own locks: numba's calls between kernels never loop, so neither
    do the waits. Where the lock cannot be had (a folder not writable, a file system without
    ``flock``, the wait's bound) the kernel simply compiles."""

    def __init__(self):
        self._held: dict[str, list] = {}         # lock path -> [file descriptor, depth]

    def take(self, path: str) -> bool:
        """Hold ``path``'s lock, waiting while another process holds it; False if it cannot be had."""
        if path in self._held:
            self._held[path][1] += 1
            return True
        try:
            os.makedirs(os.path.dirname(path), exist_ok=True)
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:
            return False
        if not _flock(fd, time.monotonic() + COMPILE_WAIT_S):
            os.close(fd)
            return False
        self._held[path] = [fd, 1]
        return True

    def give_back(self, path: str) -> None:
        """Release one hold of ``path``'s lock (the lock itself with the last)."""
        held = self._held.get(path)
        if held is None:
            return
        held[1] -= 1
        if held[1] == 0:
            del self._held[path]
            os.close(held[0])                    # closing the file releases its flock

    def held(self) -> list[str]:
        return list(self._held)


def _flock(fd: int, deadline: float) -> bool:
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if time.monotonic() > deadline:
                return False
            time.sleep(_POLL_S)
        except OSError:
            return False


#: this process's compile locks
COMPILE_LOCK = CompileLock()


def _release_after_failed_compilations() -> None:
    """A kernel whose compilation raises is never saved: its lock is given back when numba's
    ``numba:compile`` event ends with the exception."""
    from numba.core import event

    class FailedCompilation(event.Listener):
        def on_start(self, ev):
            pass

        def on_end(self, ev):
            cache = getattr(ev.data["dispatcher"], "_cache", None)
            if getattr(ev, "_exc_details", None) is not None and isinstance(cache, GuardedCache):
                COMPILE_LOCK.give_back(cache._lock_path())

    event.register("numba:compile", FailedCompilation())


#: the folders this process does not write again (not writable, or full)
_UNWRITABLE: set[str] = set()

NOT_WRITABLE, FULL, DAMAGED, UNREADABLE = "not writable", "full", "a damaged entry", "not readable"
_CONSEQUENCE = {
    NOT_WRITABLE: "the kernels it lacks are compiled in every run",
    FULL: "the kernels it lacks are compiled in every run until there is room",
    DAMAGED: "its kernel is compiled and the entry written anew",
    UNREADABLE: "its kernels are compiled",
}


def why(exc: BaseException, saving: bool) -> str:
    """The reason a folder of the cache was skipped, one of :data:`NOT_WRITABLE`,
    :data:`FULL`, :data:`DAMAGED` and :data:`UNREADABLE`."""
    if isinstance(exc, OSError):
        if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
            return FULL
        return NOT_WRITABLE if saving else UNREADABLE
    return DAMAGED


def _skipped(root: str, exc: BaseException, saving: bool) -> str:
    """Say (once per command) that ``root`` was skipped and why; returns the reason."""
    reason = why(exc, saving)
    detail = exc.strerror if isinstance(exc, OSError) and exc.strerror else \
        str(exc) if isinstance(exc, DamagedEntry) else f"{type(exc).__name__}: {exc}"
    say_once(f"numba cache {root} {reason}",
             f"numba cache skipped: {root} ({reason}: {' '.join(detail.split())}); {_CONSEQUENCE[reason]}")
    return reason


def kernels():
    """Every numba dispatcher with ``cache=True`` among the imported modules."""
    from numba.core.registry import CPUDispatcher

    for module in list(sys.modules.values()):
        for obj in list(getattr(module, "__dict__", {}).values()):
            # type(obj), not isinstance: a SWIG module's ``cvar`` (OR-Tools') raises on any attribute, __class__ too
            if issubclass(type(obj), CPUDispatcher) and isinstance(getattr(obj, "_cache", None), caching.FunctionCache):
                yield obj


_installed = False


def _enable_guarded_caching(self) -> None:
    self._cache = GuardedCache(self.py_func)


def install() -> None:
    """Every kernel decorated with ``cache=True`` from now on keeps a :class:`GuardedCache`,
    and so does every one decorated before (numba chose its folder then, but wrote nothing
    yet unless it compiled)."""
    global _installed
    if not _installed:
        _release_after_failed_compilations()
        _installed = True
    Dispatcher.enable_caching = _enable_guarded_caching
    for kernel in kernels():
        if not isinstance(kernel._cache, GuardedCache):
            kernel.enable_caching()
