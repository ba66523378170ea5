"""A damaged store is exit 2 in every command, out of memory is exit 3
wherever it strikes and leaves nothing behind, and the advice in a message works.

Commands run as a user runs them (``run_bench``: a subprocess) where the exit code and
stderr are the point; in-process where a fault is simulated.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from radarbench.bench.cli import main
from conftest import scaled


def _tree(root: Path) -> dict[str, int]:
    """Every file under ``root`` with its modification time: what a refusal must not touch
    (the lock, which a command takes before it judges the folder, aside)."""
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in root.rglob("*")
            if p.is_file() and p.name != ".bench.lock"}


def one_line(proc, code: int, *says: str) -> str:
    lines = proc.stderr.splitlines()
    assert proc.returncode == code, proc.stderr
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in proc.stderr, proc.stderr
    for text in says:
        assert text in lines[0], (text, lines[0])
    return lines[0]


def _damage(run: Path, sql: str) -> None:
    with contextlib.closing(sqlite3.connect(run / "results.sqlite")) as db:
        db.execute(sql)
        db.commit()


@pytest.mark.slow          # an end-to-end CLI run (or fuzzing): CI runs it, the inner loop does not
@pytest.mark.parametrize("sql, what", [
    ("UPDATE meta SET value = '{bad' WHERE key = 'plan'", "the stored plan is not valid JSON"),
    ("UPDATE meta SET value = '[1, 2]' WHERE key = 'plan'", "the stored plan is not a JSON object"),
    ("UPDATE metrics SET data = x'00112233' WHERE rowid = 1", "the metrics of "),
], ids=["plan-json", "plan-not-object", "metrics-blob"])
def test_a_damaged_store_is_exit_2_in_report_and_compare_naming_the_file(small_run, small_run_copy, bench_cli, sql,
                                                                        what):
    """Was exit 1, "internal error, a bug: JSONDecodeError"."""
    _damage(small_run_copy, sql)
    before = _tree(small_run_copy)
    store = str(small_run_copy / "results.sqlite")
    one_line(bench_cli("report", small_run_copy), 2, store, "damaged bench results store", what)
    one_line(bench_cli("compare", small_run, small_run_copy), 2, store, "damaged bench results store", what)
    assert _tree(small_run_copy) == before


@pytest.mark.slow
def test_bench_run_on_a_damaged_store_is_exit_2_and_its_advice_works(small_run_copy, write_sweep, bench_cli):
    """The advice says --fresh discards the damaged store: it does, and the run completes."""
    _damage(small_run_copy, "UPDATE meta SET value = '{bad' WHERE key = 'plan'")
    sweep = write_sweep()
    before = _tree(small_run_copy)
    line = one_line(bench_cli("run", sweep, "--out", small_run_copy, "--workers", 1, "--quiet", "--no-record"), 2,
                    "damaged bench results store", "--fresh discards it")
    assert _tree(small_run_copy) == before, line
    proc = bench_cli("run", sweep, "--out", small_run_copy, "--workers", 1, "--quiet", "--no-record", "--fresh")
    assert proc.returncode == 0, proc.stderr
    assert (small_run_copy / "report.md").is_file()


@pytest.mark.slow
def test_a_results_sqlite_that_is_a_folder_gets_advice_that_works(small_run_copy, write_sweep, bench_cli):
    """The refusal advised --fresh, which removed the run's outputs and then failed with
    exit 3 (--fresh removes what bench wrote, never a folder); now: move it away, which works."""
    for name in ("results.sqlite", "results.sqlite-wal", "results.sqlite-shm"):
        with contextlib.suppress(FileNotFoundError):
            (small_run_copy / name).unlink()
    (small_run_copy / "results.sqlite").mkdir()
    sweep = write_sweep()
    before = _tree(small_run_copy)
    for extra in ([], ["--fresh"]):
        proc = bench_cli("run", sweep, "--out", small_run_copy, "--workers", 1, "--quiet", "--no-record", *extra)
        line = one_line(proc, 2, "results.sqlite: not a bench results store (it is not a file)", "move it away")
        assert "--fresh" not in line
        assert _tree(small_run_copy) == before and (small_run_copy / "results.sqlite").is_dir()
    (small_run_copy / "results.sqlite").rmdir()                         # the advice
    proc = bench_cli("run", sweep, "--out", small_run_copy, "--workers", 1, "--quiet", "--no-record")
    assert proc.returncode == 0, proc.stderr


# ======================================================================= out of memory

def _limited(limit_mb: int, *args, cwd: Path, env=None) -> subprocess.CompletedProcess:
    """``bench ARGS`` under ``ulimit -v limit_mb`` MiB of address space. OpenBLAS runs one
    thread: below ~400 MiB its thread start-up spins instead of failing (its own behaviour,
    not bench's).

    A process still alive after ``scaled(300)`` s gets SIGABRT, on which Python's faulthandler prints
    every thread's stack: a hang inside an import (a library spinning on a failed mapping,
    seen once on CI at 422 MiB) skips, naming the frame; a hang anywhere else is bench's
    and fails."""
    env = {**(env or os.environ), "OPENBLAS_NUM_THREADS": "1", "PYTHONFAULTHANDLER": "1"}
    command = (f"ulimit -v {limit_mb * 1024}; "
               f"exec timeout -s ABRT {scaled(300):.0f} {sys.executable} -m radarbench.bench " + " ".join(map(str, args)))
    proc = subprocess.run(["bash", "-c", command], cwd=cwd, env=env, capture_output=True, text=True, timeout=scaled(600))
    if proc.returncode in (124, 134, -6) and "Fatal Python error: Aborted" in proc.stderr:
        stack = proc.stderr.split("Current thread", 1)[-1].split("\n\n", 1)[0]
        assert "importlib._bootstrap" in stack, f"bench hung outside an import:\n{proc.stderr}"
        innermost = next((line for line in stack.splitlines() if line.strip().startswith("File")), "")
        pytest.skip(f"a library hung while importing under ulimit -v {limit_mb} MiB: {innermost.strip()}")
    return proc


@pytest.fixture(scope="module")
def plugins_mb() -> int:
    """The address space (MiB) this machine needs to import every plugin: the limits below
    are set from it, so the tests do not depend on the libraries' sizes."""
    probe = ("from radarbench.bench import registry; registry.discover(); import re; "
             "print(re.search(r'VmPeak:\\s+(\\d+)', open('/proc/self/status').read()).group(1))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                         env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    return int(out.stdout.strip()) // 1024


def test_out_of_memory_while_importing_is_exit_3_and_writes_nothing(tmp_path, write_sweep, plugins_mb):
    """Was exit 1 ("a bug": an ImportError of a library that could not be mapped) or exit 2
    ("unknown method 'jpda-ukf'": a plugin module whose import failed for lack of memory)."""
    sweep = write_sweep()
    for limit in (plugins_mb - 120, plugins_mb - 60):     # NumPy fits, the plugins do not (and far from OpenBLAS's ~400 MiB)
        proc = _limited(limit, "run", sweep, "--out", tmp_path / "out", "--workers", 1, "--quiet", cwd=tmp_path)
        one_line(proc, 3, "error: out of memory")
        assert not (tmp_path / "out").exists()


def test_out_of_memory_in_validation_is_exit_3_and_writes_nothing(tmp_path, write_sweep, plugins_mb):
    """A map whose layout needs more than the process may map (its units fit the sweep's
    max_unit_memory_gb): the up-front check runs out of memory, exit 3, nothing written."""
    sweep = write_sweep(text="""
        name = "big-map"
        scenario = "rd-map"
        trials = 1
        seed = 1
        snr_db = [10]
        chunk = 1
        max_unit_memory_gb = 100.0
        scenario_params = { range_cells = 4096, doppler_cells = 4096 }
        [[methods]]
        name = "ca-cfar"
        [record]
        trials = 0
    """)
    proc = _limited(plugins_mb + 250, "run", sweep, "--out", tmp_path / "out", "--workers", 1, "--quiet",
                    cwd=tmp_path)
    one_line(proc, 3, "error: out of memory")
    assert not (tmp_path / "out").exists()


def test_a_plugin_import_that_runs_out_of_memory_is_exit_3_not_an_unknown_method(tmp_path, write_sweep):
    from tests.test_reliability_outputs import install_plugin
    env = install_plugin(tmp_path / "site", "greedy_plugin", "raise MemoryError('a 40 GB lookup table')\n",
                         "[bench.methods]\ngreedy = greedy_plugin\n")
    sweep = write_sweep()
    proc = subprocess.run([sys.executable, "-m", "radarbench.bench", "run", sweep, "--out", tmp_path / "out", "--quiet"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=scaled())
    one_line(proc, 3, "error: out of memory: out of memory while importing plugins (MemoryError: a 40 GB")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("fault", [MemoryError(), ImportError("libfoo.so: failed to map segment from shared object")],
                         ids=["MemoryError", "ImportError"])
def test_out_of_memory_after_the_folder_is_made_removes_it(tmp_path, write_sweep, monkeypatch, fault):
    """The run folder this command created, with nothing stored in it, goes (was left)."""
    from radarbench.bench import cli as bench_cli

    def fails(*args, **kwargs):
        raise fault
    monkeypatch.setattr(bench_cli, "_run_locked", fails)
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(["run", str(write_sweep()), "--out", str(tmp_path / "out"), "--quiet", "--workers", "1"])
    assert code == 3 and re.fullmatch(r"error: out of memory[^\n]*\n", err.getvalue()), err.getvalue()
    assert not (tmp_path / "out").exists()



def test_a_run_after_an_out_of_memory_in_the_same_process_works(tmp_path, write_sweep, monkeypatch):
    """Was exit 3, "No such file or directory": the out-of-memory path removed
    multiprocessing's temporary folder at once, where this process's forkserver listens."""
    import multiprocessing.util as mp_util

    from radarbench.bench import cli as bench_cli
    mp_util.get_temp_dir()                  # the folder the exit-time finalizer removes
    real_run = bench_cli._run_locked

    def fails(*args, **kwargs):
        raise MemoryError
    monkeypatch.setattr(bench_cli, "_run_locked", fails)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["run", str(write_sweep()), "--out", str(tmp_path / "oom"), "--quiet", "--workers", "1"]) == 3
    monkeypatch.setattr(bench_cli, "_run_locked", real_run)
    assert Path(mp_util.get_temp_dir()).is_dir()
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(["run", str(write_sweep()), "--out", str(tmp_path / "out"), "--quiet", "--workers", "2",
                     "--no-record"])
    assert code == 0, err.getvalue()

def test_out_of_memory_is_recognised_through_its_causes():
    import errno

    from radarbench.bench.errors import is_out_of_memory
    assert is_out_of_memory(MemoryError())
    assert is_out_of_memory(OSError(errno.ENOMEM, "Cannot allocate memory"))
    assert is_out_of_memory(ImportError("x.so: failed to map segment from shared object"))
    assert is_out_of_memory(SystemError("<built-in function x> returned NULL without setting an exception")) is False
    assert is_out_of_memory(SystemError("error return without exception set"))     # a failed allocation in C
    try:
        try:
            raise MemoryError
        except MemoryError as inner:
            raise OSError("Could not find/load shared object file 'libllvmlite.so'") from inner
    except OSError as outer:
        assert is_out_of_memory(outer)
    assert not is_out_of_memory(ImportError("No module named 'jpda'"))
    assert not is_out_of_memory(OSError(errno.EACCES, "Permission denied"))
    assert not is_out_of_memory(ValueError("out of range"))

