"""The run folder: one run at a time, files written whole, nothing touched that bench did not write.

* **Lock.** A run (``bench run``) and a rebuild (``bench report``) hold an exclusive
  ``flock`` on ``.bench.lock`` in the folder from start to end; a second one refuses
  at once with one line (exit 4). The lock file stays (removing it would race).
* **Manifest.** ``bench-manifest.txt`` lists every file and folder bench wrote in the
  run folder, each added *before* it is created. ``--fresh`` removes exactly what it
  lists (a folder only once empty); nothing else in the folder is ever removed.
* **Run folders only.** ``bench run`` writes into a new or empty folder or a run folder
  (one with a manifest, or with the ``results.sqlite`` of an earlier bench); any other
  non-empty folder is refused (exit 2), with or without ``--fresh``.
* **Whole files, no links followed.** Every output is written to a temporary file of
  a unique name (``.NAME.XXXXXXXX.tmp``, created with ``O_EXCL | O_NOFOLLOW``, listed in
  the manifest first) and renamed over its target once complete; on any failure the
  temporary file is removed and the target left as it was. A symbolic link planted at
  a temporary name is never used; a planted link at the target is replaced, not
  followed; a ``figures`` link (or any linked folder inside the run folder) is refused.

:func:`writing` tells the writers (:func:`atomic_output`) which run folder they write
in; outside it (``bench perf``, tests) they still write atomically, without a manifest.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import fcntl
import hashlib
import importlib.metadata
import json
import os
import re
import secrets
import sqlite3
import stat
from pathlib import Path, PurePosixPath
from typing import IO, Iterator

from radarbench.bench.errors import ConfigError, Fault, FolderInUse, os_fault

LOCK = ".bench.lock"
MANIFEST = "bench-manifest.txt"
STORE = "results.sqlite"
STORE_FILES = (STORE, f"{STORE}-wal", f"{STORE}-shm", f"{STORE}-journal")
#: What a run folder of an earlier bench (a store, no manifest) is taken to hold.
LEGACY_FILES = (*STORE_FILES, "plan.toml", "trials.csv", "summary.csv", "calibration.csv", "steps.csv",
                "report.md", "recording.rrd")
_HEADER = "# bench run manifest: the files and folders bench wrote here; `bench run --fresh` removes these only"
_TEMP = re.compile(r"^\..+\.[0-9a-f]{8}\.tmp$")
_OPEN_FLAGS = os.O_CLOEXEC | getattr(os, "O_NOFOLLOW", 0)

_active: contextvars.ContextVar[Path | None] = contextvars.ContextVar("bench_run_folder", default=None)


def _link_error(path: Path) -> ConfigError:
    return ConfigError(str(path), "is a symbolic link; bench does not follow links inside a run folder "
                                  "(remove it, or choose another --out)")


# ------------------------------------------------------------------ paths inside the folder

def _relative(root: Path, path: Path) -> PurePosixPath | None:
    try:
        return PurePosixPath(Path(os.path.abspath(path)).relative_to(os.path.abspath(root)).as_posix())
    except ValueError:
        return None


def _safe_entry(text: str) -> PurePosixPath | None:
    """A manifest line as a path inside the folder, or None if it could point outside."""
    p = PurePosixPath(text.rstrip("/"))
    if not text or p.is_absolute() or not p.parts or any(part in ("..", ".", "") for part in p.parts):
        return None
    return p


@contextlib.contextmanager
def _dir_fd(root: Path, rel: PurePosixPath, *, create: bool = False, claim=None) -> Iterator[int]:
    """An fd of folder ``root/rel`` reached without following links (``rel`` may be ``.``);
    ``create``: make missing folders (``claim`` is told each one first)."""
    fd = os.open(root, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        done = PurePosixPath()
        for part in rel.parts:
            done = done / part
            try:
                st = os.stat(part, dir_fd=fd, follow_symlinks=False)
            except FileNotFoundError:
                if not create:
                    raise
                if claim is not None:
                    claim([f"{done}/"])
                os.mkdir(part, 0o755, dir_fd=fd)
                st = os.stat(part, dir_fd=fd, follow_symlinks=False)
            if stat.S_ISLNK(st.st_mode):
                raise _link_error(root / done)
            if not stat.S_ISDIR(st.st_mode):
                raise ConfigError(str(root / done), "is not a folder")
            try:
                sub = os.open(part, os.O_RDONLY | os.O_DIRECTORY | _OPEN_FLAGS, dir_fd=fd)
            except OSError as exc:
                if exc.errno == errno.ELOOP:
                    raise _link_error(root / done) from None
                raise
            os.close(fd)
            fd = sub
        yield fd
    finally:
        os.close(fd)


# ------------------------------------------------------------------ manifest

def read_manifest(root: Path) -> list[str] | None:
    """The manifest's entries (files, and folders ending in ``/``), or None without one."""
    path = root / MANIFEST
    try:
        fd = os.open(path, os.O_RDONLY | _OPEN_FLAGS)
    except FileNotFoundError:
        return None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise _link_error(path) from None
        raise
    with os.fdopen(fd, "rb") as f:
        text = f.read(1 << 20).decode("utf-8", "replace")
    lines = text.splitlines()
    if not lines or lines[0] != _HEADER:
        return None
    return [line for line in lines[1:] if _safe_entry(line) is not None]


def _write_manifest(root: Path, entries: list[str]) -> None:
    text = "\n".join([_HEADER, *sorted(set(entries))]) + "\n"
    try:
        _atomic_bytes(root, PurePosixPath(MANIFEST), text.encode("utf-8"), claim=None)
    except OSError as exc:
        raise os_fault(exc, root / MANIFEST, "cannot write") from None


def claim(root: Path, names: list[str]) -> None:
    """Add ``names`` (relative to ``root``; folders end in ``/``) to the manifest."""
    entries = read_manifest(root) or []
    new = [n for n in names if n not in entries]
    if new:
        _write_manifest(root, entries + new)


def kept(path: str | os.PathLike) -> None:
    """An output left as it was (its bytes already right) is still one bench made: inside
    :func:`writing`, listed in the manifest like one written, so ``--fresh`` removes it."""
    root = _active.get()
    rel = _relative(root, Path(path)) if root is not None else None
    if rel is not None and rel.parts:
        claim(root, [str(rel)])


def remove_output(root: Path, name: str) -> None:
    """Remove the output ``root/name`` a build no longer makes, and its manifest entry."""
    _remove(root, PurePosixPath(name))
    entries = read_manifest(root)
    if entries is not None and name in entries:
        _write_manifest(root, [e for e in entries if e != name])


def _prune_temporaries(root: Path) -> None:
    """Drop the entries of temporary files that no longer exist (renamed into place)."""
    entries = read_manifest(root)
    if entries is None:
        return
    keep = [e for e in entries if not (_TEMP.match(PurePosixPath(e).name) and not os.path.lexists(root / e))]
    if keep != entries:
        _write_manifest(root, keep)


def recover(root: Path) -> None:
    """Under the lock: remove the temporary files an interrupted writer left (listed in the
    manifest, or the manifest's own), and forget them."""
    entries = read_manifest(root) or []
    for e in entries:
        if _TEMP.match(PurePosixPath(e).name):
            _remove(root, PurePosixPath(e))
    with contextlib.suppress(FileNotFoundError):
        for name in os.listdir(root):
            if _own_temporary(name):
                _remove(root, PurePosixPath(name))
    _prune_temporaries(root)


# ------------------------------------------------------------------ writing

def _temp_name(name: str) -> str:
    return f".{name}.{secrets.token_hex(4)}.tmp"


def _atomic_bytes(root: Path, rel: PurePosixPath, data: bytes, claim) -> None:
    with _atomic(root, rel, claim) as (f, _):
        f.write(data)


@contextlib.contextmanager
def _atomic(root: Path, rel: PurePosixPath, claim) -> Iterator[tuple[IO[bytes], Path]]:
    parent, name = rel.parent, rel.name
    with _dir_fd(root, parent, create=True, claim=claim) as dfd:
        st = None
        with contextlib.suppress(FileNotFoundError):
            st = os.stat(name, dir_fd=dfd, follow_symlinks=False)
        if st is not None and stat.S_ISDIR(st.st_mode):
            raise ConfigError(str(root / rel), "is a folder; bench writes a file there (move it away)")
        for _ in range(100):
            tmp = _temp_name(name)
            if claim is not None:
                claim([str(parent / tmp)])
            try:
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _OPEN_FLAGS, 0o644, dir_fd=dfd)
                break
            except FileExistsError:
                continue
        else:  # pragma: no cover - 100 collisions of 32 random bits
            raise Fault(str(root / rel), "cannot find a free temporary name")
        ok = False
        try:
            with os.fdopen(fd, "wb") as f:
                yield f, root / parent / tmp
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, name, src_dir_fd=dfd, dst_dir_fd=dfd)
            ok = True
        finally:
            if not ok:
                with contextlib.suppress(OSError):
                    os.unlink(tmp, dir_fd=dfd)


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[tuple[IO[bytes], Path]]:
    """Write ``path`` whole or not at all: yields (binary file, its temporary path), renames
    it over ``path`` when the block ends. Inside :func:`writing` both names go into the
    manifest first, and no folder on the way may be a link. OSErrors become one-line
    errors naming ``path`` (:func:`bench.errors.os_fault`)."""
    path = Path(path)
    root = _active.get()
    rel = _relative(root, path) if root is not None else None
    if rel is None or not rel.parts:
        root, rel, claimer = path.parent, PurePosixPath(path.name), None
    else:
        def claimer(names: list[str]) -> None:
            claim(root, names)
        claimer([str(rel)])
    try:
        with _atomic(root, rel, claimer) as out:
            yield out
    except OSError as exc:
        raise os_fault(exc, path, "cannot write") from None


def probe(folder: str | os.PathLike) -> None:
    """Refuse (one line) a folder bench cannot write in: create and remove a temporary file."""
    folder = Path(folder)
    name = folder / _temp_name("probe")
    try:
        os.close(os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _OPEN_FLAGS, 0o644))
        os.unlink(name)
    except OSError as exc:
        raise os_fault(exc, folder, "cannot write in the folder") from None


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    with atomic_output(path) as (f, _):
        f.write(data)
    return Path(path)


def write_text(path: str | os.PathLike, text: str) -> Path:
    return write_bytes(path, text.encode("utf-8"))


@contextlib.contextmanager
def writing(root: str | os.PathLike) -> Iterator[Path]:
    """Within the block, :func:`atomic_output` below ``root`` lists what it writes in
    ``root``'s manifest; temporary entries are dropped at the end."""
    root = Path(root)
    token = _active.set(root)
    try:
        yield root
    finally:
        _active.reset(token)
    with contextlib.suppress(OSError, ConfigError):
        _prune_temporaries(root)


def folder_for(path: str | os.PathLike) -> Path:
    """Make folder ``path`` (inside :func:`writing`: listed, never through a link)."""
    path = Path(path)
    root = _active.get()
    rel = _relative(root, path) if root is not None else None
    try:
        if rel is None:
            path.mkdir(parents=True, exist_ok=True)
        else:
            with _dir_fd(root, rel, create=True, claim=lambda names: claim(root, names)):
                pass
    except OSError as exc:
        raise os_fault(exc, path, "cannot create the folder") from None
    return path


# ------------------------------------------------------------------ the store, checked read-only

def store_tables() -> set[str]:
    """The tables of a bench store (:data:`bench.results.schema.SCHEMA`)."""
    from radarbench.bench.results.schema import SCHEMA
    return set(re.findall(r"CREATE TABLE IF NOT EXISTS (\w+)", SCHEMA))


def check_store(db: Path, *, need_plan: bool = False) -> None:
    """Refuse (one line, exit 2) a ``results.sqlite`` that is not a bench store (garbage,
    truncated, a folder, a link, another program's SQLite file) without modifying it: read
    its header, then open it read-only (``immutable`` when it has no WAL, so no file is
    created beside it)."""
    from radarbench.bench.results.schema import read_only_uri

    def refuse(why: str) -> ConfigError:
        return ConfigError(str(db), f"not a bench results store ({why}); move it away, or choose another folder")
    try:
        st = os.lstat(db)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise os_fault(exc, db, "cannot read") from None
    if stat.S_ISLNK(st.st_mode):
        raise _link_error(db)
    if not stat.S_ISREG(st.st_mode):
        raise refuse("it is not a file")
    for extra in STORE_FILES[1:]:
        if os.path.islink(db.with_name(extra)):
            raise _link_error(db.with_name(extra))
    if st.st_size == 0:          # created, killed before the first write: bench makes it a store
        if need_plan:
            raise refuse("it is empty")
        return
    try:
        with open(db, "rb") as f:
            header = f.read(100)
    except OSError as exc:
        raise os_fault(exc, db, "cannot read") from None
    if not header.startswith(b"SQLite format 3\x00"):
        raise refuse("not an SQLite file")
    try:
        con = sqlite3.connect(read_only_uri(db), uri=True, timeout=30)
        try:
            tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")
                      if not r[0].startswith("sqlite_")}
            if not tables <= store_tables() or not {"meta", "units"} <= tables:
                raise refuse(f"tables {', '.join(sorted(tables)) or 'none'}")
            keys = {r[0] for r in con.execute("SELECT key FROM meta")}
            plan = con.execute("SELECT value FROM meta WHERE key='plan'").fetchone()
        finally:
            con.close()
    except sqlite3.Error as exc:
        name = getattr(exc, "sqlite_errorname", "") or ""
        if name.startswith(("SQLITE_CORRUPT", "SQLITE_NOTADB")):
            raise refuse(str(exc)) from None
        raise Fault(str(db), f"cannot read the store: {exc}") from None
    if need_plan and "plan" not in keys:
        raise refuse("it holds no plan")
    if plan is not None:
        _check_plan_json(db, plan[0])


def _check_plan_json(db: Path, text) -> None:
    """A stored plan that is not a JSON object is a damaged store (exit 2, every command)."""
    from radarbench.bench.results.schema import damaged
    try:
        ok = isinstance(json.loads(text), dict)
    except (TypeError, ValueError) as exc:
        raise damaged(db, f"the stored plan is not valid JSON: {exc}"[:300]) from None
    if not ok:
        raise damaged(db, "the stored plan is not a JSON object")


# ------------------------------------------------------------------ the folder

def _own_temporary(name: str) -> bool:
    """A temporary file of the manifest (bench's by its name, whatever the manifest says)."""
    return name.startswith(f".{MANIFEST}.") and bool(_TEMP.match(name))


def _listing(root: Path) -> set[str]:
    """The folder's entries but the lock and the manifest's temporary files."""
    try:
        return {n for n in os.listdir(root) if n != LOCK and not _own_temporary(n)}
    except FileNotFoundError:
        return set()
    except OSError as exc:
        raise os_fault(exc, root, "cannot read the folder") from None


def check_folder(root: Path, *, fresh: bool = False) -> str:
    """What ``root`` is for ``bench run``: "new", "empty" or "run"; refuses (exit 2) a path
    that is not a folder and a non-empty folder that holds no bench run."""
    try:
        st = os.stat(root)
    except FileNotFoundError:
        return "new"
    except OSError as exc:
        raise os_fault(exc, root, "cannot use as the run folder") from None
    if not stat.S_ISDIR(st.st_mode):
        raise ConfigError("--out", f"{root} exists and is not a folder")
    names = _listing(root)
    if not names:
        return "empty"
    if read_manifest(root) is not None:
        return "run"
    if STORE in names:
        check_store(root / STORE)
        return "run"
    raise ConfigError("--out", f"{root} is not empty and holds no bench run (no {STORE} or {MANIFEST}); "
                               f"bench writes only into a new or empty folder or a run folder"
                               f"{' and --fresh removes only what a run wrote' if fresh else ''}: "
                               "choose another --out")


def clear(root: Path) -> None:
    """``--fresh``: remove what the manifest lists (a folder once empty), nothing else."""
    entries = read_manifest(root)
    if entries is None:         # a run folder of an earlier bench: its store and outputs by name
        entries = list(LEGACY_FILES)
    files = [PurePosixPath(e) for e in entries if not e.endswith("/")]
    folders = sorted((PurePosixPath(e.rstrip("/")) for e in entries if e.endswith("/")),
                     key=lambda p: -len(p.parts))
    for rel in files:
        _remove(root, rel)
    for rel in folders:
        _remove(root, rel, folder=True)
    _write_manifest(root, [])


def _remove(root: Path, rel: PurePosixPath, folder: bool = False) -> None:
    """Remove ``root/rel`` (a file or link; with ``folder`` an empty folder) without
    following links on the way; missing is fine."""
    try:
        with _dir_fd(root, rel.parent) as dfd:
            if folder:
                with contextlib.suppress(OSError):       # not empty (a user's file), or a link
                    os.rmdir(rel.name, dir_fd=dfd)
                return
            st = os.stat(rel.name, dir_fd=dfd, follow_symlinks=False)
            if stat.S_ISDIR(st.st_mode):
                return
            os.unlink(rel.name, dir_fd=dfd)
    except FileNotFoundError:
        return
    except ConfigError:          # a linked folder on the way: what lies beyond is not ours
        return
    except OSError as exc:
        raise os_fault(exc, root / rel, "cannot remove") from None


class RunLock:
    """The exclusive lock of a run folder (``flock`` on ``.bench.lock``), held until
    :meth:`release` or the process ends (an OS lock: a killed run frees it)."""

    def __init__(self, root: Path, what: str):
        self.root = Path(root)
        path = self.root / LOCK
        try:
            self.fd = os.open(path, os.O_RDWR | os.O_CREAT | _OPEN_FLAGS, 0o644)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise _link_error(path) from None
            raise os_fault(exc, self.root, "cannot lock the run folder") from None
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = self._holder()
            os.close(self.fd)
            raise FolderInUse(str(self.root), f"in use by another bench{holder}; wait for it to end, "
                                              "or choose another folder") from None
        except OSError as exc:
            os.close(self.fd)
            raise os_fault(exc, self.root, "cannot lock the run folder") from None
        with contextlib.suppress(OSError):
            os.ftruncate(self.fd, 0)
            os.pwrite(self.fd, f"{os.getpid()} {what}\n".encode(), 0)

    def _holder(self) -> str:
        with contextlib.suppress(OSError, ValueError):
            text = os.pread(self.fd, 200, 0).decode("utf-8", "replace").split("\n")[0]
            pid, _, what = text.partition(" ")
            return f" ({what or 'bench'}, pid {int(pid)})"
        return ""

    def release(self) -> None:
        if self.fd is not None:
            os.close(self.fd)       # closing the last fd releases the flock
            self.fd = None

    def __enter__(self) -> RunLock:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def open_for_run(root: Path, *, fresh: bool, what: str = "bench run") -> RunLock:
    """Check, create and lock ``root`` for a run; with ``fresh`` remove what earlier runs
    wrote; list the store in the manifest. Refuses before writing anything when the folder
    is not for bench (and again under the lock, where the answer is final)."""
    root = Path(root)
    if not os.path.lexists(root / LOCK):      # judged before anything is written in it
        check_folder(root, fresh=fresh)
        try:
            root.mkdir(parents=True, exist_ok=True)
        except FileExistsError:
            raise ConfigError("--out", f"{root} exists and is not a folder") from None
        except OSError as exc:
            raise os_fault(exc, root, "cannot create the run folder") from None
    # a folder bench used: locked first (another run may be half-way through writing it)
    lock = RunLock(root, what)
    try:
        kind = check_folder(root, fresh=fresh)
        for name in STORE_FILES:
            if os.path.islink(root / name):
                raise _link_error(root / name)
        for entry in {"figures/", *(e for e in read_manifest(root) or [] if e.endswith("/"))}:
            if os.path.islink(root / entry.rstrip("/")):
                raise _link_error(root / entry.rstrip("/"))
        if fresh and kind == "run":
            if os.path.lexists(root / STORE) and not os.path.isfile(root / STORE):
                check_store(root / STORE)       # a folder where the store goes: --fresh removes no folder
            clear(root)
        else:
            try:
                check_store(root / STORE)
            except ConfigError as err:
                if STORE in (read_manifest(root) or []) and os.path.isfile(root / STORE) \
                        and not os.path.islink(root / STORE):         # what --fresh removes
                    raise ConfigError(err.field, err.problem.replace(
                        "move it away, or choose another folder",
                        "--fresh discards it (with what the run wrote), or move it away")) from None
                raise
        recover(root)
        claim(root, list(STORE_FILES))
    except BaseException:
        lock.release()
        raise
    return lock


def discard_new(root: Path) -> None:
    """After a failed start in a folder this command created: if it holds no stored unit,
    remove what the command wrote (listed in the manifest), the manifest, the lock and the
    folder, so a refused run leaves nothing behind. Best effort: a result is never removed."""
    root = Path(root)
    db = root / STORE
    with contextlib.suppress(Exception):
        if os.path.lexists(db):
            check_store(db)
            uri = f"{db.absolute().as_uri()}?mode=ro"
            con = sqlite3.connect(uri, uri=True, timeout=1)
            try:
                if con.execute("SELECT count(*) FROM units").fetchone()[0]:
                    return
            finally:
                con.close()
        clear(root)
        for name in (MANIFEST, LOCK):
            _remove(root, PurePosixPath(name))
        os.rmdir(root)


def open_for_report(root: Path) -> RunLock:
    """Check ``root`` holds a bench store (read-only, before anything is written), then lock it."""
    root = Path(root)
    db = root / STORE
    if not root.is_dir():
        raise ConfigError("", f"{root} is not a folder")
    if os.path.lexists(root / LOCK):
        RunLock(root, "bench report").release()    # a folder bench used: in use? (before judging its store)
    if not os.path.lexists(db):
        raise ConfigError("", f"{root} has no {STORE} (not a bench run folder)")
    check_store(db, need_plan=True)              # read-only: a foreign file is refused untouched
    lock = RunLock(root, "bench report")
    try:
        check_store(db, need_plan=True)
        recover(root)
        claim(root, list(STORE_FILES))             # a bench store: --fresh may remove it
    except BaseException:
        lock.release()
        raise
    return lock


#: the folder of a run folder that holds the results its last run replaced (bench.run.identity.PREVIOUS)
PREVIOUS_FOLDER = "previous"
#: the libraries whose versions shape a report's pages, tables and figures
REPORT_LIBRARIES = ("numpy", "scipy", "pandas", "matplotlib", "plotly", "jinja2", "markdown", "tabulate",
                    "rerun-sdk")
#: the store's record of what the folder's outputs were last built from (:func:`outputs_digest`)
OUTPUTS_DIGEST = "outputs_digest"


def outputs_digest(store, recording: bool, code_files: list[Path]) -> str:
    """What a run folder's outputs are built from: the stored results (every unit and run
    with its identity), the stored plan and identities, the files ``code_files`` (the
    harness's code, templates and presets' notes and claims, the plan's plugins), the
    versions of :data:`REPORT_LIBRARIES` and whether a recording is written. The outputs
    are rebuilt only when it changed (docs/architecture.md, 'Run folders and faults')."""
    h = hashlib.sha256()
    for query in ("SELECT key, identity, finished FROM units ORDER BY key",
                  "SELECT unit, method, identity, error, seconds FROM runs ORDER BY unit, method"):
        for row in store.db.execute(query):
            h.update(repr(row).encode())
    for key in ("fingerprint", "plan", "identities", "replaced", "units_total", "last_wall_seconds"):
        h.update(repr(store.meta(key)).encode())
    for path in sorted(set(code_files)):
        with contextlib.suppress(OSError):
            h.update(str(path).encode() + b"\0" + path.read_bytes())
    for name in REPORT_LIBRARIES:
        with contextlib.suppress(importlib.metadata.PackageNotFoundError):
            h.update(f"{name} {importlib.metadata.version(name)}".encode())
    h.update(repr(recording).encode())
    return h.hexdigest()


def outputs_current(out_dir: Path, digest: str, stored: str | None) -> bool:
    """Whether the folder's outputs were built from ``digest`` and are all still there."""
    listed = read_manifest(out_dir) or []
    return stored == digest and "report.md" in listed and all(
        (out_dir / name).exists() for name in listed
        if name not in STORE_FILES and not name.endswith("/") and not name.startswith(f"{PREVIOUS_FOLDER}/"))


def harness_files() -> list[Path]:
    """The harness's own files: its code, the report's templates, the presets' notes and claims."""
    return [p for p in Path(__file__).resolve().parents[1].rglob("*")
            if p.suffix in (".py", ".j2", ".toml", ".md") and "__pycache__" not in p.parts]
