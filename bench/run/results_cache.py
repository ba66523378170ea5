"""The user's results cache: entries by content, shared by every run folder
(docs/architecture.md, 'Results cache').

An entry is what one computation produced (:mod:`bench.run.reuse` says what is keyed and
how), kept as one file named by the SHA-256 of its key, in a folder of its own:
``BENCH_RESULTS_CACHE_DIR`` if set, else ``results/`` in the user's cache folder of
bench (``$XDG_CACHE_HOME/radar-maneuver-bench/``, :func:`bench.sweep.user_cache.cache_dir`).

- **checked**: a file is ``MAGIC``, the SHA-256 of the rest, then an ``.npz`` of the
  entry's arrays and a JSON header (never pickle); one that does not match (garbled,
  truncated, another format) is a miss, said in one line and removed, and its result is
  computed again and written anew;
- **whole**: written to a uniquely named temporary file in the same folder and renamed
  into place, so a reader sees an old entry or a new one, never part of one, and two
  runs writing the same entry (the same bytes) cannot corrupt it;
- **bounded**: at most ``BENCH_RESULTS_CACHE_GB`` gigabytes (default
  :data:`DEFAULT_BOUND_GB`); an entry read or written has its modification time set
  to now, and :meth:`ResultsCache.evict` removes the least recently used ones until the
  folder is within the bound;
- **never failing a run**: a folder that is not private (a link, another user's, one
  others may write: :func:`bench.sweep.user_cache.private_dir`) is not used; one that cannot be
  written (read-only, full) is read only, said once per run.
"""

from __future__ import annotations

import errno
import hashlib
import io
import json
import os
import stat
import time
import zipfile
from pathlib import Path

from radarbench.bench.sweep.user_cache import cache_dir, private_dir, read_own, write_whole

#: where the cache lives, when set (else the user's cache folder of bench, ``results/``)
FOLDER_ENV = "BENCH_RESULTS_CACHE_DIR"
#: its size bound in gigabytes (10^9 bytes), when set
BOUND_ENV = "BENCH_RESULTS_CACHE_GB"
DEFAULT_BOUND_GB = 2.0
#: what opens each entry, before the SHA-256 of the rest (a new format: a new first line)
MAGIC = b"radarbench results cache 1\n"
SUFFIX = ".entry"
_DIGEST = hashlib.sha256().digest_size
#: a temporary file older than this (s) is a writer's that died: removed by evict()
STALE_TEMPORARY_S = 3600.0


def folder() -> Path:
    """The cache's folder (module docstring)."""
    return Path(os.environ.get(FOLDER_ENV) or cache_dir() / "results")


def bound_bytes() -> int:
    """The size bound: ``$BENCH_RESULTS_CACHE_GB`` (a number >= 0) or the default; a bad
    value is a ConfigError naming the variable."""
    from radarbench.bench.errors import ConfigError
    raw = os.environ.get(BOUND_ENV, "").strip()
    if not raw:
        return int(DEFAULT_BOUND_GB * 1e9)
    try:
        gb = float(raw)
    except ValueError:
        gb = float("nan")
    if not 0 <= gb < float("inf"):
        raise ConfigError(BOUND_ENV, f"expected a size in gigabytes >= 0, got {raw!r}")
    return int(gb * 1e9)


def key_digest(parts) -> str:
    """The name of an entry: the SHA-256 of its key's canonical JSON."""
    return hashlib.sha256(json.dumps(parts, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def encode(header: dict, arrays: dict) -> bytes:
    """An entry's bytes: MAGIC, the SHA-256 of the payload, the payload (an ``.npz``: the
    arrays under ``a0``, ``a1``, ... and the header, with their names, as JSON)."""
    import numpy as np
    names = list(arrays)
    body = {f"a{i}": np.ascontiguousarray(arrays[name]) for i, name in enumerate(names)}
    body["header"] = np.frombuffer(json.dumps({"header": header, "names": names}).encode(), np.uint8)
    buf = io.BytesIO()
    np.savez(buf, **body)
    payload = buf.getvalue()
    return MAGIC + hashlib.sha256(payload).digest() + payload


class Damaged(Exception):
    """An entry whose bytes are not what was written."""


def decode(blob: bytes) -> tuple[dict, dict]:
    """(header, arrays) of an entry's bytes; :class:`Damaged` when they do not check."""
    import numpy as np
    start = len(MAGIC) + _DIGEST
    if not blob.startswith(MAGIC) or hashlib.sha256(blob[start:]).digest() != blob[len(MAGIC):start]:
        raise Damaged("its checksum does not match (garbled or truncated)")
    try:
        with np.load(io.BytesIO(blob[start:]), allow_pickle=False) as z:
            meta = json.loads(z["header"].tobytes().decode())
            return meta["header"], {name: z[f"a{i}"] for i, name in enumerate(meta["names"])}
    except (ValueError, KeyError, TypeError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise Damaged(f"it cannot be read ({type(exc).__name__})") from None


def _say(text: str) -> None:
    from radarbench.bench.run.progress import say
    say(text)


class ResultsCache:
    """The cache as one run uses it: reads and writes entries, counts and says what went
    wrong (never raising for it), and evicts."""

    def __init__(self, where: Path | None = None, bound: int | None = None):
        self.folder = Path(where) if where is not None else folder()
        self.bound = bound_bytes() if bound is None else bound
        self.usable = private_dir(self.folder)
        self.writable = self.usable
        self.written = 0
        if not self.usable:
            _say(f"results cache skipped: {self.folder} (not a folder of yours alone, or it cannot be made); "
                 "every result is computed")

    def path(self, key: str) -> Path:
        return self.folder / key[:2] / f"{key}{SUFFIX}"

    def get(self, key: str) -> tuple[dict, dict] | None:
        """The entry ``key`` (header, arrays), or None: absent, unreadable, or damaged
        (then said in one line and removed)."""
        if not self.usable:
            return None
        path = self.path(key)
        blob = read_own(path)
        if blob is None:
            return None
        try:
            entry = decode(blob)
        except Damaged as exc:
            _say(f"results cache: damaged entry {path} ({exc}): its result is computed again")
            _remove(path)
            return None
        _touch(path)
        return entry

    def put(self, key: str, header: dict, arrays: dict) -> None:
        """Write the entry ``key``, whole (a temporary file renamed into place); a folder
        that cannot be written is said once and not tried again by this run."""
        if not self.writable:
            return
        try:
            _write_whole(self.path(key), encode(header, arrays))
        except OSError as exc:
            self.writable = False
            full = exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
            _say(f"results cache not written: {self.folder} ({'full' if full else 'not writable'}: "
                 f"{exc.strerror or exc}); this run's results are kept in its run folder only")
            return
        self.written += 1

    def evict(self) -> int:
        """Remove the least recently used entries until the folder holds at most the bound;
        returns how many were removed. Another run's temporary file is left unless stale."""
        if not self.writable:
            return 0
        entries, total = [], 0
        now = time.time()
        for sub in _scan(self.folder):
            if not sub.is_dir(follow_symlinks=False):
                continue
            for item in _scan(Path(sub.path)):
                try:
                    st = item.stat(follow_symlinks=False)
                except OSError:
                    continue
                if item.name.endswith(SUFFIX) and stat.S_ISREG(st.st_mode):
                    entries.append((st.st_mtime_ns, st.st_size, Path(item.path)))
                    total += st.st_size
                elif item.name.endswith(".tmp") and now - st.st_mtime > STALE_TEMPORARY_S:
                    _remove(Path(item.path))
        removed = 0
        for _mtime, size, path in sorted(entries):
            if total <= self.bound:
                break
            if _remove(path):
                total -= size
                removed += 1
        return removed


def _scan(where: Path) -> list:
    try:
        with os.scandir(where) as it:
            return list(it)
    except OSError:
        return []


def _made(where: Path) -> None:
    try:
        os.mkdir(where, 0o700)
    except FileExistsError:
        pass


def _write_whole(path: Path, data: bytes) -> None:
    _made(path.parent)
    write_whole(path, data)


def _touch(path: Path) -> None:
    """Mark ``path`` used now (least recently used eviction reads modification times:
    access times are not kept on many file systems)."""
    try:
        os.utime(path)
    except OSError:
        pass


def _remove(path: Path) -> bool:
    try:
        path.unlink()
    except OSError:
        return False
    return True

