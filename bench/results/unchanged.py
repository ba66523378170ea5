"""A run folder that nothing changed since its last run: ``bench run`` answers it without
importing a plugin, NumPy or the report (docs/architecture.md, 'Run folders and faults').

A run that ends with every unit stored, none failed and its outputs current records in its
store (meta :data:`META`) what it was run from:

* a **key**: the command line as the run folder keeps it, the sweep as data (after the
  command line's changes), its source and folder, the working directory, whether a
  recording is written and ``--yes``, the interpreter and its ``sys.path``, the data
  folder's variable (``XDG_DATA_HOME``) and the plugins' fingerprint (their sources,
  entry points and the installed distributions' versions: :func:`bench.sweep.listing.fingerprint`);
* the **files** it depended on, by size, modification time and inode: every module the
  driver imported (the harness, the plugins, the libraries), every module file an identity
  read (:func:`bench.run.identity.files_read`, also those no class imports), the harness's
  templates, presets and claims, the plan's data files; and the folders holding them and
  the ``sys.path`` entries by the names in them (a file added, removed or renamed);
* the commits checked out where an editable plugin lies (its provenance names them,
  :func:`bench.results.provenance.git_heads`), the outputs' digest and the units stored.

The next ``bench run`` computes the key from the command line and the sweep alone and,
under the folder's lock, compares: the same key, every file as it was, the same commits,
the outputs' digest still the store's and every output present means the run would find
nothing to compute and its report current, and it says so as that run says it. Anything
else, and every run that takes the long way, which first forgets the record
(:func:`forget`), so a run stopped half-way never leaves a record behind. A file modified
less than :data:`SETTLE_S` before the run started (or during it) is not trusted: that run
records nothing, and the next one takes the long way again.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import sqlite3
import stat
import sys
from pathlib import Path

from radarbench.bench.results import runfolder

#: the store's meta key of the record
META = "unchanged_run"
#: a file modified this recently before the run started may have changed within a
#: file-system timestamp's resolution (a coarse clock tick; 2 s on FAT): not recorded
SETTLE_S = 2.0


def run_key(*, command: str, data: dict, source: str, folder: Path, plugins: str, recording: bool,
            allow_large: bool) -> str:
    """The key of a ``bench run``: what decides its plan and outputs besides the files it
    reads (``plugins``: :func:`bench.sweep.listing.fingerprint`, the plugins' sources,
    entry points and the installed distributions' versions)."""
    whole = {"command": command, "sweep": data, "source": source, "folder": os.path.abspath(folder),
             "cwd": os.getcwd(), "recording": recording, "yes": allow_large,
             "python": [sys.executable, sys.version, sys.path], "data_home": os.environ.get("XDG_DATA_HOME"),
             "plugins": plugins}
    return hashlib.sha256(json.dumps(whole, sort_keys=True, default=repr).encode()).hexdigest()


def _state(path: str) -> list[int] | str | None:
    """A file by [modification time, size, inode]; a folder by the names in it (a file added,
    removed or renamed), its ``__pycache__`` left out (Python adds one as it imports)."""
    try:
        st = os.stat(path)
        if not stat.S_ISDIR(st.st_mode):
            return [st.st_mtime_ns, st.st_size, st.st_ino]
        names = sorted(name for name in os.listdir(path) if name != "__pycache__")
    except OSError:
        return None
    return hashlib.sha256("\0".join(names).encode()).hexdigest()[:32]


def _depended_on(read) -> set[str]:
    """The files and folders this process's run depended on: ``read`` (the module files its
    identities read, its data files), every module it imported, the harness's files, and
    the folders of all of them and of ``sys.path`` (see the module doc)."""
    files = {getattr(m, "__file__", None) for m in list(sys.modules.values())}
    files = {os.path.abspath(f) for f in files if isinstance(f, str)}
    files |= {os.path.abspath(p) for p in read} | {str(p) for p in runfolder.harness_files()}
    folders = {os.path.dirname(f) for f in files} | {os.path.abspath(p or ".") for p in sys.path}
    return files | folders


def _open(out_dir: Path) -> sqlite3.Connection:
    return sqlite3.connect(Path(out_dir) / runfolder.STORE, timeout=30, isolation_level=None)


def forget(out_dir: Path) -> None:
    """Drop the record before a run changes anything in the folder (the caller holds its lock)."""
    if not os.path.isfile(Path(out_dir) / runfolder.STORE):
        return
    with contextlib.closing(_open(out_dir)) as db:
        with contextlib.suppress(sqlite3.OperationalError):       # a store without its tables yet
            db.execute("DELETE FROM meta WHERE key=?", (META,))


def remember(out_dir: Path, key: str, started_ns: int, read, said: list[str]) -> bool:
    """Record the run that just ended in ``out_dir`` (see the module doc), when every unit is
    stored, none failed, the outputs are current and no file it depended on changed since
    :data:`SETTLE_S` before it started (``started_ns``: ``time.time_ns()`` at its start).
    ``read``: the files it read that it did not import (its identities' modules, its data
    files); ``said``: the lines it wrote on stderr before its units (the pairs it skips).
    Whether it was recorded."""
    from radarbench.bench.results.provenance import git_heads
    files = {path: st for path in sorted(_depended_on(read)) if (st := _state(path)) is not None}
    if any(isinstance(st, list) and st[0] >= started_ns - SETTLE_S * 1e9 for st in files.values()):
        return False
    with contextlib.closing(_open(out_dir)) as db:
        meta = dict(db.execute("SELECT key, value FROM meta"))
        (units,) = db.execute("SELECT count(*) FROM units").fetchone()
        (failed,) = db.execute("SELECT count(*) FROM runs WHERE error IS NOT NULL").fetchone()
        digest = meta.get(runfolder.OUTPUTS_DIGEST)
        if failed or str(units) != meta.get("units_total") or not runfolder.outputs_current(out_dir, digest, digest):
            return False
        record = {"key": key, "files": files, "git": git_heads(), "outputs": digest, "units": units, "said": said}
        try:
            db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (META, json.dumps(record)))
        except sqlite3.OperationalError:   # a full disk, a store opened by another: the run stands, the next takes the long way
            return False
    return True


def settled(out_dir: Path, key: str) -> dict | None:
    """The record of ``out_dir``'s last run when a run of ``key`` would find nothing to do
    there (see the module doc), else None. The caller holds the folder's lock."""
    if not os.path.isfile(Path(out_dir) / runfolder.STORE):
        return None
    with contextlib.closing(_open(out_dir)) as db:
        try:
            meta = dict(db.execute("SELECT key, value FROM meta WHERE key IN (?, ?, ?)",
                                   (META, runfolder.OUTPUTS_DIGEST, "units_total")))
        except sqlite3.OperationalError:
            return None
    try:
        record = json.loads(meta.get(META) or "null")
    except ValueError:
        return None
    if not isinstance(record, dict) or record.get("key") != key or record.get("outputs") != meta.get(
            runfolder.OUTPUTS_DIGEST) or str(record.get("units")) != meta.get("units_total"):
        return None
    if any(_state(path) != st for path, st in record["files"].items()):
        return None
    from radarbench.bench.results.provenance import head_of
    if any(head_of(Path(folder)) != head for folder, head in record["git"].items()):
        return None
    digest = record["outputs"]
    return record if runfolder.outputs_current(Path(out_dir), digest, digest) else None
