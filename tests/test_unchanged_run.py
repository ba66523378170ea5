"""A `bench run` with nothing to do answers from the run folder's record, before any plugin,
NumPy or worker (bench/results/unchanged.py), and any change takes the long way again."""

from __future__ import annotations

import contextlib
import os
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from radarbench.bench.results import unchanged
from tests.test_identity import loop  # noqa: F401 - the fixture: a plugin package, its sweep and data file
from conftest import scaled

#: a `bench run` in a process that then says which heavy modules it imported and whether it
#: started the workers' forkserver
PROBE = """
import sys
from multiprocessing import forkserver
from radarbench.bench.cli import main
code = main(sys.argv[1:])
heavy = sorted(m for m in ("numpy", "pandas", "scipy", "numba", "matplotlib", "jinja2") if m in sys.modules)
started = forkserver._forkserver._forkserver_pid is not None
print(f"probe: heavy={','.join(heavy) or 'none'} forkserver={started}", file=sys.stderr)
sys.exit(code)
"""


def _aged(root: Path, seconds: float) -> None:
    """Every file and folder under ``root`` dated ``seconds`` ago (a record trusts no file
    modified just before its run: unchanged.SETTLE_S)."""
    when = time.time() - seconds
    for path in [root, *root.rglob("*")]:
        os.utime(path, (when, when))


def _run(env, cwd, sweep, out, *extra, code=0):
    done = subprocess.run([sys.executable, "-c", PROBE, "run", str(sweep), "--out", str(out), "--workers", "1",
                           "--no-record", *extra], env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=scaled())
    assert done.returncode == code, done.stderr
    return done


def _light(done) -> bool:
    """Whether the run answered without NumPy and without starting a worker."""
    assert "probe: " in done.stderr, done.stderr
    return "probe: heavy=none forkserver=False" in done.stderr


@pytest.fixture
def settled_run(loop, tmp_path):  # noqa: F811
    """(env, plugin package, sweep, cwd, run folder) after a run whose record is in place."""
    env, pkg, sweep = loop
    env = {**env, "PYTHONDONTWRITEBYTECODE": "1"}      # a first __pycache__ would be a change of the package's folder
    cwd = sweep.parent.parent / "elsewhere"
    out = cwd / "run"
    out.mkdir()
    _aged(tmp_path, 600)
    first = _run(env, cwd, sweep, out)
    assert not _light(first) and "computed" in first.stderr, first.stderr
    return env, pkg, sweep, cwd, out


@pytest.mark.slow
def test_a_run_with_nothing_to_do_says_what_the_long_way_says_without_numpy_or_workers(settled_run):
    env, _, sweep, cwd, out = settled_run
    quick = _run(env, cwd, sweep, out)
    assert _light(quick), quick.stderr
    with contextlib.closing(sqlite3.connect(out / "results.sqlite")) as con:
        con.execute("DELETE FROM meta WHERE key=?", (unchanged.META,))
        con.commit()
    long_way = _run(env, cwd, sweep, out)
    assert not _light(long_way), long_way.stderr
    assert quick.stdout == long_way.stdout == f"the report is up to date: {out / 'report.md'}\n"
    said = [line for line in quick.stderr.splitlines() if not line.startswith("probe: ")]
    assert said == [line for line in long_way.stderr.splitlines() if not line.startswith("probe: ")], said
    assert said == [f"Nothing to run: all 4 units stored in {out}"], said
    assert _light(_run(env, cwd, sweep, out)), "the long way records again"


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new))
    _aged(path, 300)                # older than the run after it may trust, newer than the record's


@pytest.mark.slow
@pytest.mark.parametrize("change", ["plugin code", "data file", "sweep", "command line", "output removed",
                                    "a run that failed in between"])
def test_any_change_takes_the_long_way(settled_run, change):
    env, pkg, sweep, cwd, out = settled_run
    extra = []
    if change == "plugin code":
        _edit(pkg / "argmax.py", "axis=1), axis=1)", "axis=1), axis=1).astype(np.int64)")
    elif change == "data file":
        _edit(sweep.parent / "data" / "background.csv", "0,0", "1,0")
    elif change == "sweep":
        _edit(sweep, "trials = 20", "trials = 30")
    elif change == "command line":
        extra = ["--seed", "4"]
    elif change == "output removed":
        (out / "summary.csv").unlink()
    else:       # a run of another sweep that set results aside and did not end well leaves no record behind
        _run(env, cwd, sweep, out, "--methods", "broken", code=6)
    again = _run(env, cwd, sweep, out, *extra)
    assert not _light(again), again.stderr
    if change in ("plugin code", "data file"):
        assert "code or data changed: re-running" in again.stderr, again.stderr
    elif change == "output removed":
        assert (out / "summary.csv").is_file() and "wrote " in again.stdout, again.stdout
    else:
        assert "the sweep changed" in again.stderr, again.stderr
    assert _light(_run(env, cwd, sweep, out, *extra)), "the run after a change records again"


def test_a_file_modified_just_before_a_run_is_not_trusted(tmp_path):
    """No record when a file the run depended on is as new as the run (its change may fall
    within the file system's timestamp resolution): the next run takes the long way."""
    from radarbench.bench.results.schema import SCHEMA
    out = tmp_path / "run"
    out.mkdir()
    with contextlib.closing(sqlite3.connect(out / "results.sqlite")) as con:
        con.executescript(SCHEMA)
    data = tmp_path / "data.csv"
    data.write_text("0\n")
    assert not unchanged.remember(out, "key", time.time_ns(), [data], [])
    assert unchanged.settled(out, "key") is None


def test_a_record_the_store_refuses_fails_no_run(tmp_path, monkeypatch):
    """The record only saves the next run time: a store that refuses it (a full disk) leaves
    the run that just ended complete (was: that run ended in exit 3, "results store: ...")."""
    from radarbench.bench.results import runfolder
    from radarbench.bench.results.schema import SCHEMA
    out = tmp_path / "run"
    out.mkdir()
    with contextlib.closing(sqlite3.connect(out / "results.sqlite")) as con:
        con.executescript(SCHEMA)
        con.execute("INSERT INTO meta VALUES ('units_total', '0')")
        con.commit()
    (out / "report.md").write_text("# r\n")
    runfolder._write_manifest(out, ["report.md"])
    _aged(tmp_path, 600)
    opened = unchanged._open

    def refusing(folder):
        db = opened(folder)
        db.execute("PRAGMA query_only = ON")    # every write fails as on a full disk: OperationalError
        return db
    later = time.time_ns() + 60 * 10 ** 9         # a run started after every file it read last changed
    monkeypatch.setattr(unchanged, "_open", refusing)
    assert unchanged.remember(out, "key", later, [], []) is False
    monkeypatch.setattr(unchanged, "_open", opened)
    assert unchanged.remember(out, "key", later, [], []) is True      # the same folder, writable: recorded
