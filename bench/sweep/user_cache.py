"""The user's cache folder of bench (``$XDG_CACHE_HOME`` or ``~/.cache``, ``radar-maneuver-bench/``):
where it is and how its files are read and written (docs/architecture.md, 'Results cache').

The folder may sit on a shared file system, so it is used only when it is a real folder (not
a link) owned by the user and writable by no one else (created 0700, :func:`private_dir`); a
file is written to an unpredictable name created exclusively then renamed into place
(:func:`write_whole`), and read without following a link (:func:`read_own`). In the first
stage, so that every stage can use it (the plugin listing, the results cache, the report's
reused figures and tables).
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from pathlib import Path

__all__ = ["cache_dir", "private_dir", "read_own", "write_whole"]


def cache_dir() -> Path:
    """The user's cache folder of bench; use it only where :func:`private_dir` holds."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "radar-maneuver-bench"


def private_dir(path: Path) -> bool:
    """Whether ``path`` is a folder only this user can write (made 0700 if absent): a real
    folder, not a link, owned by the user, writable by no group or other."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.mkdir(path, 0o700)
        except FileExistsError:
            pass
        st = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISDIR(st.st_mode) and st.st_uid == os.getuid() and not st.st_mode & 0o022


def read_own(path: Path, limit: int = -1) -> bytes | None:
    """The bytes of ``path`` (at most ``limit``), a regular file of this user read without
    following a link; None if it is not one, or cannot be read."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return None
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(f.fileno())
        if not stat.S_ISREG(st.st_mode) or st.st_uid != os.getuid():
            return None
        try:
            return f.read(limit)
        except OSError:
            return None


def write_whole(path: Path, data: bytes) -> None:
    """``data`` as ``path``: a new file of an unpredictable name in its folder, created
    exclusively, renamed into place (a reader sees the old file or the new one, whole)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):     # the write's own error is the one to raise
            os.unlink(tmp)
        raise
