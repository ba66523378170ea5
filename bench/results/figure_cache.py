"""What a report build reuses instead of drawing again (docs/architecture.md, 'Report').

A figure is named by a key: the SHA-256 of what it is drawn from — the arguments of its
figure function (data frames, arrays, records, numbers, labels; the path it is written
to left out) — and of the code that draws it (the files of the function's module and of
:mod:`bench.figures`, the versions of the libraries that render it). Its PNG is kept

- in the run folder: the store's meta ``report_figures`` names each figure's key and the
  SHA-256 of the file written; a figure whose key and file are unchanged is neither
  drawn nor written again (its modification time stays);
- in the user's cache folder (``figures/KEY.png``, the most recently used
  :data:`CACHE_BYTES`), so a new run folder whose results equal an earlier one's copies
  its figures (and report.html's interactive figures, ``KEY.html``).

An argument the key cannot describe (an object of another kind) makes its figure be
drawn every time, never reused wrongly. Every other output of a build is written only
when its bytes changed (:func:`write_if_changed`).

The tables and texts a build computes from the results alone (a task's summary, each pair's
comparison, the report's HTML body) are reused the same way (:func:`reused`): kept in the
user's cache folder as JSON (``KEY.json``), keyed by their inputs and the code that computes
them, so a run whose results equal an earlier one's (a warm re-run, an edit that left a
task's configs alone) does not compute them again.
"""

from __future__ import annotations

import contextlib
import contextvars
import hashlib
import importlib.metadata
import json
import os
import stat
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from radarbench.bench.sweep.user_cache import cache_dir, private_dir, write_whole

__all__ = ["FigureReuse", "key_of", "reuse_in_effect", "reused", "reusing", "write_if_changed", "CACHE_BYTES"]

#: the most bytes the user's cache folder of report outputs keeps (PNGs, pages, tables; the least recently used go first)
CACHE_BYTES = 256 * 2 ** 20
#: the store's meta entry naming each figure's key and file hash (:class:`FigureReuse`)
META = "report_figures"
#: the libraries whose versions change a figure's pixels
RENDERING_LIBRARIES = ("matplotlib", "numpy", "pandas", "pillow")

#: the reuse of the :func:`reusing` block in progress (a :class:`FigureReuse`), else None
_reuse: contextvars.ContextVar = contextvars.ContextVar("figure_reuse", default=None)


@contextlib.contextmanager
def reusing(reuse):
    """Within the block, figures (:func:`bench.figures.cached`) and the values of :func:`reused`
    calls are reused and counted by ``reuse`` (a :class:`FigureReuse`)."""
    token = _reuse.set(reuse)
    try:
        yield reuse
    finally:
        _reuse.reset(token)


def reuse_in_effect():
    """The :class:`FigureReuse` of the :func:`reusing` block in progress, else None."""
    return _reuse.get()


class Unkeyable(Exception):
    """An argument :func:`key_of` cannot describe."""


def _feed(h, value) -> None:
    """Feed ``value`` to the hash ``h``: its kind, then its content, in order."""
    import pandas as pd
    if value is None or isinstance(value, (bool, int, float, complex, str, np.generic)):
        h.update(f"{type(value).__name__}:{value!r};".encode())
    elif isinstance(value, bytes):
        h.update(b"bytes:%d;" % len(value) + value)
    elif isinstance(value, Path):
        h.update(f"path:{value}".encode())
    elif isinstance(value, np.ndarray):
        if value.dtype.hasobject:
            items = value.ravel().tolist()
            if all(type(item) is str for item in items):     # a column of labels: at once
                h.update(f"strings{value.shape};".encode() + json.dumps(items).encode())
                return
            h.update(f"objects{value.shape}".encode())
            for item in items:
                _feed(h, item)
        else:
            h.update(f"array:{value.dtype.str}{value.shape};".encode())
            h.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, pd.DataFrame):
        h.update(b"frame;")
        _feed(h, list(map(str, value.columns)))
        _feed(h, value.index.to_numpy())
        for name in value.columns:
            _feed(h, value[name].to_numpy())
    elif isinstance(value, pd.Series):
        h.update(f"series:{value.name!r};".encode())
        _feed(h, value.index.to_numpy())
        _feed(h, value.to_numpy())
    elif isinstance(value, pd.Index):
        _feed(h, value.to_numpy())
    elif isinstance(value, dict):
        h.update(b"dict:%d;" % len(value))
        for k, v in value.items():          # in order: a legend follows it
            _feed(h, k)
            _feed(h, v)
    elif isinstance(value, (list, tuple, frozenset, set)):
        items = sorted(value, key=repr) if isinstance(value, (set, frozenset)) else value
        h.update(f"{type(value).__name__}:{len(items)};".encode())
        for item in items:
            _feed(h, item)
    elif callable(getattr(value, "to_bytes", None)) and not isinstance(value, type):
        h.update(f"{type(value).__qualname__}:".encode())    # a record's own byte format
        _feed(h, value.to_bytes())
    else:
        raise Unkeyable(type(value).__qualname__)


def key_of(*values) -> str | None:
    """The SHA-256 of ``values`` (:func:`_feed`), None if one cannot be described."""
    h = hashlib.sha256()
    try:
        for value in values:
            _feed(h, value)
    except Unkeyable:
        return None
    return h.hexdigest()


_code_keys: dict[str, str] = {}


def code_key(module: str) -> str:
    """What draws a figure of ``module``: that module's file and :mod:`bench.figures`'s,
    the versions of :data:`RENDERING_LIBRARIES`."""
    if module not in _code_keys:
        h = hashlib.sha256()
        for name in dict.fromkeys((module, "radarbench.bench.figures")):
            file = getattr(sys.modules.get(name), "__file__", None)
            h.update(Path(file).read_bytes() if file else name.encode())
        for name in RENDERING_LIBRARIES:
            with contextlib.suppress(importlib.metadata.PackageNotFoundError):
                h.update(f"{name} {importlib.metadata.version(name)};".encode())
        _code_keys[module] = h.hexdigest()
    return _code_keys[module]


_harness_key: list[str] = []


def harness_key() -> str:
    """The harness's code (:func:`bench.results.runfolder.harness_files`) and the versions of the
    libraries a report is made with (:data:`bench.results.runfolder.REPORT_LIBRARIES`), for an
    output made by more of it than one module (the recording, :func:`reused` values)."""
    if not _harness_key:
        from radarbench.bench.results import runfolder
        h = hashlib.sha256()
        for path in sorted(runfolder.harness_files()):
            h.update(str(path.name).encode() + b"\0" + path.read_bytes())
        for name in runfolder.REPORT_LIBRARIES:
            with contextlib.suppress(importlib.metadata.PackageNotFoundError):
                h.update(f"{name} {importlib.metadata.version(name)};".encode())
        _harness_key.append(h.hexdigest())
    return _harness_key[0]


def reused(fn, *args, key: tuple | None = None, code: str | None = ""):
    """``fn(*args)``, a pure function of its arguments returning text, a list or dict of JSON
    values, or a data frame; inside
    :func:`reusing`, what an equal call returned before, from the user's cache. The call is
    named by ``fn``, ``key`` (what its arguments hold, described for :func:`key_of`; default
    ``args``), the harness's code (:func:`harness_key`) and ``code`` (more code it runs: a
    plugin's; None: code that cannot be identified, so never reused). A value :func:`_encoded`
    cannot keep exactly is computed every time."""
    reuse = _reuse.get()
    name = key_of(fn.__module__, fn.__qualname__, harness_key(), code, args if key is None else key) \
        if reuse is not None and reuse.folder is not None and code is not None else None
    if name is not None:
        data = reuse.fetch(name, ".json")
        value = _decoded(data) if data is not None else None
        if value is not None:
            return value
    value = fn(*args)
    if name is not None and (data := _encoded(value)) is not None:
        reuse.keep(name, ".json", data)
    return value


def _encoded(value) -> bytes | None:
    """``value`` (text; a list or dict of JSON values; a data frame of JSON values with a default
    index) as JSON, None unless :func:`_decoded` gives it back exactly (types, dtypes, column
    names and order, NaNs)."""
    import pandas as pd
    if isinstance(value, str):
        return json.dumps({"text": value}).encode()
    if isinstance(value, (list, dict)):
        try:
            data = json.dumps({"data": value}).encode()
        except (TypeError, ValueError):
            return None
        return data if _same(json.loads(data)["data"], value) else None
    if not isinstance(value, pd.DataFrame) or not value.index.equals(pd.RangeIndex(len(value))) \
            or not isinstance(value.index, pd.RangeIndex):
        return None
    try:
        data = json.dumps({"columns": list(value.columns), "dtypes": [str(t) for t in value.dtypes],
                           "values": [value.iloc[:, i].tolist() for i in range(value.shape[1])]}).encode()
    except (TypeError, ValueError):
        return None
    back = _decoded(data)
    try:
        pd.testing.assert_frame_equal(back, value, check_exact=True)
    except (AssertionError, TypeError, ValueError):
        return None
    return data


def _decoded(data: bytes):
    """What :func:`_encoded` wrote, None if ``data`` is not that."""
    import pandas as pd
    try:
        doc = json.loads(data)
        if "text" in doc:
            return doc["text"] if isinstance(doc["text"], str) else None
        if "data" in doc:
            return doc["data"] if isinstance(doc["data"], (list, dict)) else None
        columns = [pd.Series(values, dtype=dtype) for values, dtype in zip(doc["values"], doc["dtypes"], strict=True)]
        frame = pd.concat(columns, axis=1, ignore_index=True) if columns else pd.DataFrame(index=pd.RangeIndex(0))
        frame.columns = pd.Index(doc["columns"]) if doc["columns"] else frame.columns
        return frame
    except (ValueError, TypeError, KeyError, AttributeError):
        return None


def _same(read, value) -> bool:
    """Whether ``read`` (what JSON gave back) is ``value`` exactly: the same types (a tuple is not
    a list, a NumPy float not a float), equal values, NaN for NaN, keys in order."""
    if type(read) is not type(value):
        return False
    if isinstance(value, float):
        return read == value or (read != read and value != value)
    if isinstance(value, list):
        return len(read) == len(value) and all(map(_same, read, value))
    if isinstance(value, dict):
        return list(read) == list(value) and all(_same(read[k], value[k]) for k in value)
    return read == value


def _read_regular(path: Path, limit: int = 1 << 30) -> bytes | None:
    """The bytes of the regular file ``path`` (never through a link), None if there is none."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return None
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
            return None
        return f.read(limit)


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def write_if_changed(path: Path, data: bytes) -> bool:
    """Write ``data`` to ``path`` whole (:func:`bench.results.runfolder.write_bytes`) unless the file
    already holds exactly these bytes (then it is left, modification time and all);
    whether it was written."""
    from radarbench.bench.results import runfolder
    old = _read_regular(path, len(data) + 1)
    if old is not None and old == data:
        runfolder.kept(path)
        return False
    runfolder.write_bytes(path, data)
    return True


@dataclass
class FigureReuse:
    """One build's figures: ``previous`` (figure file name -> [key, SHA-256 of its file])
    from the store, ``folder`` the user's cache of PNGs (None: not used). Counts the
    figures drawn (and names their files) and reused."""

    previous: dict = field(default_factory=dict)
    folder: Path | None = None
    current: dict = field(default_factory=dict)
    drawn: int = 0
    reused: int = 0
    drawn_files: list = field(default_factory=list)
    kept: bool = False

    @classmethod
    def of_store(cls, store, use_cache: bool = True) -> "FigureReuse":
        try:
            previous = json.loads(store.meta(META) or "{}")
        except ValueError:
            previous = {}
        return cls(previous=previous if isinstance(previous, dict) else {},
                   folder=_cache_folder() if use_cache else None)

    def save(self, store) -> None:
        """Record the figures of this build in the store (for the next build); keep the
        user's cache within :data:`CACHE_BYTES`."""
        store.set_meta(META, json.dumps(self.current, sort_keys=True))
        if self.folder is not None and self.kept:
            with contextlib.suppress(OSError):
                _bound(self.folder)

    def drop_unmade(self, out_dir: Path) -> None:
        """Remove the figures the last build made and this one did not (a config or a
        scenario config left the sweep), unless their file was changed since: the folder
        then holds what a fresh build would."""
        from radarbench.bench.results import runfolder
        for name, (_, sha) in self.previous.items():
            path = out_dir / "figures" / name
            if name not in self.current and Path(name).name == name and (data := _read_regular(path)) is not None \
                    and _sha(data) == sha:
                runfolder.remove_output(out_dir, f"figures/{name}")

    def key(self, fn, arguments: dict) -> str | None:
        """The key of the figure ``fn(**arguments)`` (its path left out of ``arguments``)."""
        return key_of(fn.__module__, fn.__qualname__, code_key(fn.__module__), arguments)

    def reuse(self, path: Path, key: str, figure: bool = True) -> bool:
        """Whether the output ``key`` (a figure, or with ``figure`` False another output made
        from its key's inputs alone) is already at ``path`` (left alone) or in the user's
        cache (copied there); a figure either way counted as reused."""
        entry = self.previous.get(path.name)
        if entry and entry[0] == key:
            data = _read_regular(path)
            if data is not None and _sha(data) == entry[1]:
                from radarbench.bench.results import runfolder
                runfolder.kept(path)
                return self._reused(path, key, data, figure)
        data = self.fetch(key, path.suffix)
        if data is None:
            return False
        write_if_changed(path, data)
        return self._reused(path, key, data, figure)

    def _reused(self, path: Path, key: str, data: bytes, figure: bool) -> bool:
        self.current[path.name] = [key, _sha(data)]
        self.reused += figure
        return True

    def written(self, path: Path, key: str | None, data: bytes, figure: bool = True) -> None:
        """The output ``key`` was made as ``data``: written to ``path`` (if its bytes changed);
        a figure counted as drawn."""
        write_if_changed(path, data)
        if figure:
            self.drawn += 1
            self.drawn_files.append(path.name)
        if key is None:
            return
        self.current[path.name] = [key, _sha(data)]
        self.keep(key, path.suffix, data)

    def keep(self, key: str, suffix: str, data: bytes) -> None:
        """Keep ``data`` as ``KEY+suffix`` in the user's cache folder (if it is used)."""
        if self.folder is not None:
            self.kept = True
            with contextlib.suppress(OSError):
                write_whole(self.folder / (key + suffix), data)

    def fetch(self, key: str, suffix: str) -> bytes | None:
        """What :meth:`keep` kept as ``KEY+suffix``, None if nothing."""
        if self.folder is None:
            return None
        path = self.folder / f"{key}{suffix}"
        data = _read_regular(path)
        if data is None:
            return None
        with contextlib.suppress(OSError):
            os.utime(path)                  # recently used: kept longest
        return data

    def summary(self) -> str:
        return f"figures: {self.drawn} drawn, {self.reused} reused"


def _cache_folder() -> Path | None:
    """The user's cache of figures, if it is a private folder (:func:`bench.sweep.user_cache.private_dir`)."""
    folder = cache_dir() / "figures"
    return folder if private_dir(cache_dir()) and private_dir(folder) else None


#: seconds after which a temporary file of the cache folder is a killed writer's, not one in progress
STALE_TEMPORARY_S = 3600.0


def _bound(folder: Path) -> None:
    """Drop the least recently used files of ``folder`` beyond :data:`CACHE_BYTES`, and the
    temporary files writers killed mid-write left (:func:`bench.sweep.user_cache.write_whole`'s,
    older than :data:`STALE_TEMPORARY_S`)."""
    import time
    entries = []
    for entry in os.scandir(folder):
        with contextlib.suppress(OSError):
            if not entry.is_file(follow_symlinks=False):
                continue
            st = entry.stat(follow_symlinks=False)
            if not entry.name.startswith("."):
                entries.append((st.st_mtime, st.st_size, entry.path))
            elif entry.name.endswith(".tmp") and time.time() - st.st_mtime > STALE_TEMPORARY_S:
                os.unlink(entry.path)
    total = sum(size for _, size, _ in entries)
    for _, size, path in sorted(entries):
        if total <= CACHE_BYTES:
            break
        with contextlib.suppress(OSError):
            os.unlink(path)
        total -= size
