"""Faults of the file system, of the store and of other runs, as a hostile user or a flaky
machine produces them.

Each fault ends with exit code 2 (bad input), 3 (the machine refused) or 4 (the folder is
in use), exactly one line on stderr naming the path and the cause, no traceback, nothing
written outside ``--out`` and no half-written file.
"""

from __future__ import annotations

import contextlib
import io
import os
import resource
import shutil
import signal
import sqlite3
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path

import pytest

from radarbench.bench.results import runfolder
from radarbench.bench.sweep import tomlw
from radarbench.bench.cli import main
from radarbench.bench.results.store import MethodRun, Store, UnitResult
from conftest import scaled

TINY = """
name = "tiny"
description = "{description}"
scenario = "cv-turn-cv"
trials = {trials}
seed = 7
snr_db = [0, 8]
chunk = 2

[[methods]]
name = "innovation"
params = {{ window = 5 }}

[calibration]
pfa = 0.05
mode = "empirical"
h0_trials = 12

[record]
trials = 1
"""


def tiny(path: Path, trials: int = 4, description: str = "tiny") -> Path:
    path.write_text(TINY.format(trials=trials, description=description))
    return path


def bench(*args, limit: int | None = None, wrap: list[str] | None = None, **kw):
    """``bench`` in a subprocess (the code under test: this interpreter's PYTHONPATH);
    ``limit``: a file-size limit (``ulimit -f``) with SIGXFSZ ignored, so writes fail
    with EFBIG as on a full disk; ``wrap``: a command put in front (unshare)."""
    def pre():
        if limit is not None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    cmd = [*(wrap or []), sys.executable, "-m", "radarbench.bench", *map(str, args)]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=scaled(), preexec_fn=pre, **kw)


def in_process(*args) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def one_line_error(code: int, err: str, expected: int, *words: str) -> str:
    """Assert the fault's form: the exit code, one line on stderr, no traceback, ``words`` in it."""
    lines = err.splitlines()
    assert code == expected, (code, err[-3000:])
    assert len(lines) == 1 and lines[0].startswith("error: "), err[-3000:]
    assert "Traceback" not in err
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def snapshot(root: Path) -> dict[str, bytes | str]:
    """Every entry under ``root``: file contents, ``->target`` for links, ``/`` for folders."""
    out = {}
    for p in sorted(root.rglob("*")):
        rel = str(p.relative_to(root))
        if p.is_symlink():
            out[rel] = "->" + os.readlink(p)
        elif p.is_dir():
            out[rel] = "/"
        else:
            out[rel] = p.read_bytes()
    return out


def temporaries(root: Path) -> list[str]:
    return [str(p.relative_to(root)) for p in root.rglob("*") if p.name.endswith(".tmp")]


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> tuple[Path, Path]:
    """A tiny sweep and its complete run folder (recording included), made once."""
    root = tmp_path_factory.mktemp("clean")
    sweep = tiny(root / "tiny.toml")
    proc = bench("run", sweep, "--out", root / "run", "--workers", 1, "--quiet")
    assert proc.returncode == 0, proc.stderr
    return sweep, root / "run"


@pytest.fixture
def run_copy(clean, tmp_path) -> Path:
    """A copy of the clean run folder, to damage."""
    out = tmp_path / "run"
    shutil.copytree(clean[1], out, symlinks=True)
    return out


# ================================================================== cause 1: one line, a documented exit code

def test_out_under_a_regular_file_or_with_a_too_long_name_is_one_line(clean, tmp_path):
    sweep, _ = clean
    (tmp_path / "afile").write_text("mine")
    code, out, err = in_process("run", sweep, "--out", tmp_path / "afile" / "run", "--quiet", "--workers", 1)
    one_line_error(code, err, 2, str(tmp_path / "afile" / "run"), "Not a directory")
    code, out, err = in_process("run", sweep, "--out", tmp_path / "afile", "--quiet", "--workers", 1)
    one_line_error(code, err, 2, str(tmp_path / "afile"), "not a folder")
    long = tmp_path / ("x" * 300)
    code, out, err = in_process("run", sweep, "--out", long / "run", "--quiet", "--workers", 1)
    one_line_error(code, err, 2, "File name too long", str(tmp_path)[:40])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]
    assert (tmp_path / "afile").read_text() == "mine"


def test_perf_out_on_a_file_is_refused_before_measuring(tmp_path, monkeypatch):
    from radarbench.bench.cli import perf

    def measured(*_, **__):
        raise AssertionError("bench perf measured before it checked --out")
    for name in ("_in_fresh_process", "measure", "measure_scene", "measure_scenes", "executor_scaling"):
        monkeypatch.setattr(perf, name, measured)
    (tmp_path / "afile").write_text("mine")
    code, out, err = in_process("perf", "--out", tmp_path / "afile", "--methods", "innovation")
    one_line_error(code, err, 2, str(tmp_path / "afile"), "not a folder")
    code, out, err = in_process("perf", "--out", tmp_path / "afile" / "perf", "--methods", "innovation")
    one_line_error(code, err, 2, str(tmp_path / "afile" / "perf"), "Not a directory")
    assert (tmp_path / "afile").read_text() == "mine"


def _garbage(db: Path) -> None:
    db.write_bytes(os.urandom(5000))


def _truncated(db: Path) -> None:
    data = db.read_bytes()
    db.write_bytes(data[:len(data) // 2])


def _directory(db: Path) -> None:
    db.unlink()
    db.mkdir()
    (db / "inside").write_text("x")


@pytest.mark.parametrize("command", ["run", "report"])
@pytest.mark.parametrize("damage", [_garbage, _truncated, _directory], ids=["garbage", "truncated", "directory"])
def test_a_damaged_store_is_one_line_and_left_as_it_is(clean, run_copy, damage, command):
    sweep, _ = clean
    db = run_copy / "results.sqlite"
    for extra in ("results.sqlite-wal", "results.sqlite-shm"):
        (run_copy / extra).unlink(missing_ok=True)
    damage(db)
    before = snapshot(run_copy)
    args = ("run", sweep, "--out", run_copy, "--quiet", "--workers", 1) if command == "run" else ("report", run_copy)
    code, out, err = in_process(*args)
    line = one_line_error(code, err, 2, str(db), "not a bench results store")
    if command == "run":
        assert "--fresh" in line or "move it away" in line
    after = snapshot(run_copy)
    after.pop(".bench.lock", None)
    before.pop(".bench.lock", None)
    assert after == before               # the store is not touched, nothing is written


def _mount_namespace() -> list[str] | None:
    """``unshare -m`` (a private mount namespace: a mount made there vanishes with the
    command), if this machine lets us mount; None otherwise."""
    if shutil.which("unshare") is None or shutil.which("mount") is None:
        return None
    probe = subprocess.run(["unshare", "-m", "--", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"],
                           capture_output=True)
    return ["unshare", "-m", "--"] if probe.returncode == 0 else None


def _read_only(folder: Path) -> list[str]:
    """A prefix running a command with ``folder`` bind-mounted read-only (in its own namespace)."""
    ns = _mount_namespace()
    if ns is None:
        pytest.skip("cannot mount here (needs root and unshare): no read-only folder to test with")
    script = 'mount --bind "$0" "$0" && mount -o remount,bind,ro "$0" && exec "$@"'
    return [*ns, "sh", "-c", script, str(folder)]


@pytest.mark.parametrize("command", ["run", "report", "fresh", "new"])
def test_a_read_only_run_folder_is_one_line(clean, run_copy, command):
    """A run folder on a read-only mount (resumed, rebuilt, started afresh), and a new run
    folder asked for on one: exit 3, one line, nothing changed."""
    sweep, _ = clean
    wrap = _read_only(run_copy)
    before = snapshot(run_copy)
    args = {"run": ("run", sweep, "--out", run_copy, "--quiet", "--workers", 1),
            "fresh": ("run", sweep, "--out", run_copy, "--quiet", "--workers", 1, "--fresh"),
            "new": ("run", sweep, "--out", run_copy / "new", "--quiet", "--workers", 1),
            "report": ("report", run_copy)}[command]
    proc = bench(*args, wrap=wrap)
    one_line_error(proc.returncode, proc.stderr, 3, str(run_copy), "Read-only file system")
    assert snapshot(run_copy) == before


@pytest.mark.slow
def test_a_file_size_limit_during_the_run_is_one_line_and_the_run_resumes(clean, tmp_path):
    """``ulimit -f`` (a full disk as the run sees it) while units are stored: exit 3, one line
    naming the store and the limit; the units stored are whole, and the same command without
    the limit ends with the results of a clean run."""
    sweep, whole = clean
    out = tmp_path / "run"
    proc = bench("run", sweep, "--out", out, "--workers", 1, "--quiet", limit=300_000)
    one_line_error(proc.returncode, proc.stderr, 3, str(out / "results.sqlite"), "ulimit -f")
    assert not (out / "report.md").exists() and not temporaries(out)
    with sqlite3.connect(out / "results.sqlite") as con:       # whole units only (transactions)
        assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        stored = con.execute("SELECT count(*) FROM units").fetchone()[0]
    assert 0 < stored < 10                                     # 6 calibration + 4 evaluation units in all
    code, _, err = in_process("run", sweep, "--out", out, "--workers", 1, "--quiet")
    assert code == 0, err
    for name in ("trials.csv", "calibration.csv"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name


@pytest.mark.slow          # an end-to-end CLI run (or fuzzing): CI runs it, the inner loop does not
@pytest.mark.parametrize("limit, culprit", [(35_000, "figures/"), (150_000, "recording.rrd")])
def test_a_file_size_limit_during_the_report_leaves_every_output_whole(run_copy, limit, culprit):
    """At 35 kB a figure cannot be written, at 150 kB the recording (whose writer,
    rerun's thread, would only log the failure): one line, exit 3, and every file is as it
    was, none truncated, no temporary file left. The figures and the recording are removed
    first, with what the report would reuse of them (docs/architecture.md, 'Report')."""
    shutil.rmtree(run_copy / "figures")
    (run_copy / "recording.rrd").unlink()
    with sqlite3.connect(run_copy / "results.sqlite") as con:
        con.execute("DELETE FROM meta WHERE key = 'report_figures'")
    con.close()
    shutil.rmtree(Path(os.environ["XDG_CACHE_HOME"]) / "radar-maneuver-bench" / "figures", ignore_errors=True)
    before = snapshot(run_copy)
    proc = bench("report", run_copy, limit=limit)
    line = one_line_error(proc.returncode, proc.stderr, 3, str(run_copy / culprit), "ulimit -f")
    assert "File too large" in line or "could not be written whole" in line
    after = snapshot(run_copy)
    assert not temporaries(run_copy)
    for name in before:
        if name not in ("bench-manifest.txt", ".bench.lock"):
            assert after[name] == before[name], name      # rebuilt identically, or left as it was


def test_a_full_disk_during_the_run_is_one_line(clean, tmp_path):
    """A real ENOSPC: the run folder on a 256 kB tmpfs (in a mount namespace of its own,
    the folder's content copied out before it vanishes)."""
    sweep, _ = clean
    ns = _mount_namespace()
    if ns is None:
        pytest.skip("cannot mount a tmpfs here (needs root and unshare)")
    out, kept = tmp_path / "run", tmp_path / "kept"
    out.mkdir()
    kept.mkdir()
    script = ('mount -t tmpfs -o size=256k tmpfs "$0" && "$@"; rc=$?; cp -a "$0"/. "$1"/ ; exit $rc')
    proc = bench("run", sweep, "--out", out, "--workers", 1, "--quiet",
                 wrap=[*ns, "sh", "-c", script.replace('"$1"', f'"{kept}"'), str(out)])
    line = one_line_error(proc.returncode, proc.stderr, 3, str(out))
    assert "full" in line or "No space left" in line, line
    assert not temporaries(kept)
    if (kept / "results.sqlite").exists():
        with sqlite3.connect(kept / "results.sqlite") as con:
            assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"


# ================================================================== cause 2: one run per folder

def _lock_holder(out: Path) -> int | None:
    try:
        text = (out / runfolder.LOCK).read_text()
    except OSError:
        return None
    head = text.split(" ", 1)[0]
    return int(head) if head.isdigit() else None


@pytest.mark.slow
def test_a_second_run_on_a_live_run_folder_says_it_is_in_use(clean, tmp_path):
    """Run A takes the folder's lock and is stopped (SIGSTOP) while it holds it: a second
    run of the same sweep, a --fresh run of another sweep and a report are each refused with
    one line (exit 4), touching nothing; A, continued, ends with the clean results."""
    sweep, whole = clean
    other = tiny(tmp_path / "other.toml", trials=6)
    out = tmp_path / "run"
    a = subprocess.Popen([sys.executable, "-m", "radarbench.bench", "run", str(sweep), "--out", str(out), "--workers", "1",
                          "--quiet", "--no-record"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + scaled(600)
        while _lock_holder(out) != a.pid and a.poll() is None and time.monotonic() < deadline:
            time.sleep(0.005)
        assert _lock_holder(out) == a.pid, "run A never took the lock"
        a.send_signal(signal.SIGSTOP)
        before = snapshot(out)
        for args in (("run", sweep, "--out", out, "--quiet", "--workers", 1),
                     ("run", other, "--out", out, "--quiet", "--workers", 1, "--fresh"),
                     ("report", out)):
            code, _, err = in_process(*args)
            line = one_line_error(code, err, 4, str(out), "in use")
            assert f"pid {a.pid}" in line, line
        assert snapshot(out) == before
    finally:
        a.send_signal(signal.SIGCONT)
    _, err = a.communicate(timeout=scaled())
    assert a.returncode == 0, err
    assert (out / "trials.csv").read_bytes() == (whole / "trials.csv").read_bytes()
    code, _, err = in_process("run", sweep, "--out", out, "--quiet", "--workers", 1, "--no-record")  # free again
    assert code == 0, err


def _unit(key="evaluation/s/+0/000000000+2") -> UnitResult:
    import numpy as np
    r = UnitResult(key, "evaluation", "s", 0.0, 0, 2, 0.1)
    r.runs = [MethodRun("m", 0.1, metrics={"detected": np.ones(2)})]
    return r


def test_the_unit_check_and_its_insert_are_one_transaction(tmp_path):
    """Two writers of one unit (a second run, a unit dask ran twice): B checks while A's
    insert is not committed; B must wait for A and then find the unit stored (never
    check, then insert, then crash on the UNIQUE constraint)."""
    db = tmp_path / "results.sqlite"
    a = Store(db)
    opened, go, started = threading.Event(), threading.Event(), threading.Event()
    result: list = []

    def writer_b():                          # sqlite3 connections belong to their thread
        b = Store(db)
        b.db.set_trace_callback(lambda sql: started.set()
                                if sql.lstrip().upper().startswith(("BEGIN", "INSERT")) else None)
        opened.set()
        go.wait(scaled(120))
        result.append(_try(b.save_unit, _unit()))
        result.append(len(b.runs()))
        b.close()

    thread = threading.Thread(target=writer_b)
    thread.start()
    assert opened.wait(scaled(120))
    a.db.execute("BEGIN IMMEDIATE")          # A is inside its transaction: the unit is not there yet
    go.set()
    assert started.wait(scaled(120))
    time.sleep(0.2)                          # B now waits for A's lock (before the fix: had already checked)
    a.db.execute("INSERT INTO units (key, phase, scenario, snr_db, trial_start, n, generate_seconds, finished) "
                 "VALUES (?,?,?,?,?,?,?,?)", ("evaluation/s/+0/000000000+2", "evaluation", "s", 0.0, 0, 2, 0.1, 0.0))
    a.db.execute("INSERT INTO runs (unit, method, seconds, error) VALUES (?,?,?,?)",
                 ("evaluation/s/+0/000000000+2", "m", 0.1, None))
    a.db.commit()
    thread.join(scaled(300))
    assert result == [False, 1], result      # B saw A's unit and stored nothing twice
    a.close()


def _try(fn, *args):
    try:
        return fn(*args)
    except Exception as exc:  # noqa: BLE001 - the failure is the result
        return exc


def test_a_run_plan_and_report_write_under_unique_temporary_names(run_copy, tmp_path):
    """Old fixed temporary names planted as regular files are left alone (another writer's
    files would be), and nothing of bench's temporaries is left."""
    planted = {name: f"someone else's {name}".encode() for name in
               ("report.md.tmp", "trials.csv.tmp", "plan.toml.tmp", "recording.rrd.tmp", "figures/runtime.tmp.png")}
    for name, data in planted.items():
        (run_copy / name).write_bytes(data)
    code, out, err = in_process("report", run_copy)
    assert code == 0, err
    for name, data in planted.items():
        assert (run_copy / name).read_bytes() == data
    assert sorted(temporaries(run_copy)) == sorted(n for n in planted if n.endswith(".tmp"))


# ================================================================== cause 5: never destroy or write what bench did not create

def test_fresh_refuses_a_folder_that_never_held_a_run(clean, tmp_path):
    sweep, _ = clean
    out = tmp_path / "thesis"
    (out / "figures").mkdir(parents=True)
    (out / "figures" / "thesis.png").write_bytes(b"my figure")
    (out / "report.md").write_text("my report")
    before = snapshot(out)
    for fresh in (["--fresh"], []):
        code, _, err = in_process("run", sweep, "--out", out, "--quiet", "--workers", 1, *fresh)
        one_line_error(code, err, 2, str(out), "holds no bench run")
        assert snapshot(out) == before


def test_fresh_removes_only_what_the_manifest_lists(clean, run_copy):
    sweep, _ = clean
    (run_copy / "notes.md").write_text("mine")
    (run_copy / "figures" / "thesis.png").write_bytes(b"my figure")
    (run_copy / "mine").mkdir()
    (run_copy / "mine" / "data.csv").write_text("1,2")
    listed = set(runfolder.read_manifest(run_copy))
    assert {"results.sqlite", "report.md", "figures/", "figures/runtime.png", "recording.rrd"} <= listed
    code, _, err = in_process("run", sweep, "--out", run_copy, "--quiet", "--workers", 1, "--fresh", "--no-record")
    assert code == 0, err
    assert (run_copy / "notes.md").read_text() == "mine"
    assert (run_copy / "figures" / "thesis.png").read_bytes() == b"my figure"
    assert (run_copy / "mine" / "data.csv").read_text() == "1,2"
    assert not (run_copy / "recording.rrd").exists()          # listed, removed, not rewritten (--no-record)


def test_a_manifest_never_points_outside_the_folder(clean, run_copy, tmp_path):
    """A hostile manifest (absolute paths, .., a path through a linked folder) removes nothing outside."""
    sweep, _ = clean
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "keep.txt").write_text("keep")
    (run_copy / "linked").symlink_to(victim, target_is_directory=True)
    manifest = (run_copy / runfolder.MANIFEST).read_text()
    (run_copy / runfolder.MANIFEST).write_text(manifest + "linked/\n")
    code, _, err = in_process("run", sweep, "--out", run_copy, "--quiet", "--workers", 1, "--fresh", "--no-record")
    one_line_error(code, err, 2, str(run_copy / "linked"), "symbolic link")     # a listed folder is now a link
    (run_copy / runfolder.MANIFEST).write_text(
        manifest + f"{victim / 'keep.txt'}\n../victim/keep.txt\nlinked/keep.txt\nlinked/../../victim/keep.txt\n")
    code, _, err = in_process("run", sweep, "--out", run_copy, "--quiet", "--workers", 1, "--fresh", "--no-record")
    assert code == 0, err
    assert (victim / "keep.txt").read_text() == "keep"
    assert (run_copy / "linked").is_symlink()


def test_planted_links_never_make_bench_write_outside(clean, run_copy, tmp_path):
    """Links planted at the old temporary names and at the outputs themselves: bench writes
    its files in the folder (replacing a link, never following it)."""
    sweep, _ = clean
    outside = tmp_path / "outside"
    outside.mkdir()
    names = ["report.md.tmp", "recording.rrd.tmp", "plan.toml.tmp", "trials.csv.tmp", "figures/runtime.tmp.png",
             "report.md", "summary.csv", "figures/roc.png", "recording.rrd"]
    for i, name in enumerate(names):
        target = outside / f"victim{i}"
        target.write_text("precious")
        (run_copy / name).unlink(missing_ok=True)
        (run_copy / name).symlink_to(target)
    code, _, err = in_process("run", sweep, "--out", run_copy, "--quiet", "--workers", 1)   # plan, outputs
    assert code == 0, err
    assert all(p.read_text() == "precious" for p in outside.iterdir())
    for name in ("report.md", "summary.csv", "figures/roc.png", "recording.rrd"):
        assert not (run_copy / name).is_symlink() and (run_copy / name).stat().st_size > 0, name


@pytest.mark.parametrize("link", ["figures", "results.sqlite", ".bench.lock", "results.sqlite-wal"])
def test_a_linked_folder_or_store_is_refused(clean, run_copy, tmp_path, link):
    sweep, _ = clean
    outside = tmp_path / "outside"
    if link == "figures":
        shutil.copytree(run_copy / "figures", outside)
        shutil.rmtree(run_copy / "figures")
    else:
        outside.mkdir()
        src = run_copy / link
        if src.exists():
            shutil.move(src, outside / link)
        else:
            (outside / link).write_bytes(b"")
        outside = outside / link
    (run_copy / link).symlink_to(outside)
    before = snapshot(tmp_path / "outside")
    for args in (("report", run_copy), ("run", sweep, "--out", run_copy, "--quiet", "--workers", 1)):
        code, _, err = in_process(*args)
        one_line_error(code, err, 2, str(run_copy / link), "symbolic link")
        assert snapshot(tmp_path / "outside") == before


@pytest.mark.parametrize("journal", ["delete", "wal"])
def test_report_on_a_foreign_sqlite_file_refuses_before_modifying_it(tmp_path, journal):
    folder = tmp_path / "theirs"
    folder.mkdir()
    db = folder / "results.sqlite"
    con = sqlite3.connect(db)
    con.execute(f"PRAGMA journal_mode={journal}")
    con.execute("CREATE TABLE patients (name TEXT)")
    con.execute("INSERT INTO patients VALUES ('x')")
    con.commit()
    con.close()
    before = snapshot(folder)
    code, _, err = in_process("report", folder)
    one_line_error(code, err, 2, str(db), "not a bench results store")
    assert snapshot(folder) == before                 # no tables added, no WAL switch, no lock file
    code, _, err = in_process("run", tiny(tmp_path / "t.toml"), "--out", folder, "--quiet", "--workers", 1)
    one_line_error(code, err, 2, str(db), "not a bench results store")
    assert snapshot(folder) == before


def test_a_refused_run_leaves_no_folder_behind(tmp_path, monkeypatch):
    """A run that fails before storing anything in a folder it created removes that folder."""
    from radarbench.bench.run import runner
    monkeypatch.setattr(runner, "make_executor", lambda *a, **k: (_ for _ in ()).throw(
        OSError(28, "No space left on device", str(tmp_path / "x"))))
    out = tmp_path / "new"
    code, _, err = in_process("run", tiny(tmp_path / "t.toml"), "--out", out, "--quiet", "--workers", 1)
    one_line_error(code, err, 3, "No space left on device")
    assert not out.exists()


# ================================================================== cause 9: control characters from a description

HOSTILE = "a\x1b[31mred\x1b[0m\x00nul\x07bell\x7fdel\x9bcsi\rcr\x08bs"


def _controls(text: str) -> list[str]:
    return [c for c in text if (ord(c) < 0x20 and c not in "\n\t") or 0x7f <= ord(c) < 0xa0]


def test_the_writers_escape_control_characters():
    from radarbench.bench.report import escape_controls
    text = tomlw.dumps({"description": HOSTILE, "nested": {"k": HOSTILE}})
    assert not _controls(text)
    assert tomllib.loads(text) == {"description": HOSTILE, "nested": {"k": HOSTILE}}
    md = escape_controls(f"# t\n\n{HOSTILE}\n\tkept")
    assert not _controls(md) and "\\x1b[31mred" in md and md.endswith("\n\tkept")


def test_control_characters_of_a_description_never_reach_report_or_plan(tmp_path):
    """From a sweep file (TOML escapes): refused with one line, or run with report.md and
    plan.toml free of control characters, and plan.toml re-runnable."""
    escaped = HOSTILE.translate({i: f"\\u{i:04x}" for i in [*range(0x20), *range(0x7f, 0xa0)]})
    sweep = tiny(tmp_path / "t.toml", description=escaped)
    out = tmp_path / "run"
    code, _, err = in_process("run", sweep, "--out", out, "--quiet", "--workers", 1, "--no-record")
    if code == 2:                                        # validation may refuse such a description
        one_line_error(code, err, 2, "description")
        return
    assert code == 0, err
    for name in ("report.md", "plan.toml"):
        assert not _controls((out / name).read_text(encoding="utf-8")), name
    assert tomllib.loads((out / "plan.toml").read_text())["description"] == HOSTILE
    again = tmp_path / "again"
    code, _, err = in_process("run", out / "plan.toml", "--out", again, "--quiet", "--workers", 1, "--no-record")
    assert code == 0, err                                # plan.toml is valid TOML and re-runs the sweep
    assert (again / "trials.csv").read_bytes() == (out / "trials.csv").read_bytes()


# ================================================================== the documented surface

def test_help_lists_the_exit_codes(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    assert "exit codes:" in text
    for code in ("2    bad input", "3    the machine refused", "4    the run folder is in use", "130"):
        assert code in text, code


def test_committed_report_folders_are_run_folders():
    """A fresh clone has no results.sqlite in reports/NAME/: its manifest makes the folder a
    run folder, so `bench run --preset NAME` (which writes there) is not refused."""
    root = Path(__file__).resolve().parent.parent / "reports"
    folders = [p.parent for p in root.glob("*/plan.toml")]
    assert folders
    for folder in folders:
        assert runfolder.read_manifest(folder) is not None, folder
        assert runfolder.check_folder(folder) == "run"


def test_a_run_folder_of_an_earlier_bench_is_adopted(clean, run_copy):
    """No manifest, a bench store: a run folder; a report lists the store it found, so a
    later --fresh removes it with the outputs."""
    sweep, _ = clean
    (run_copy / runfolder.MANIFEST).unlink()
    code, _, err = in_process("report", run_copy, "--no-record")
    assert code == 0, err
    assert {"results.sqlite", "report.md", "trials.csv"} <= set(runfolder.read_manifest(run_copy))
    other = tiny(run_copy.parent / "other.toml", trials=6)
    code, _, err = in_process("run", other, "--out", run_copy, "--quiet", "--workers", 1, "--no-record", "--fresh")
    assert code == 0, err
