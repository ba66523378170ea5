"""The user's results cache (docs/architecture.md, 'Results cache'): a new run folder takes
every unit it holds instead of computing it, and its results equal a computed run's
outside timing columns; --no-cache computes everything; an edited method parameter
computes only that config; a damaged entry is computed again with one line; the folder
stays within its size bound, and a folder that cannot be written fails no run."""

from __future__ import annotations

import errno
import os
import re
import sqlite3
import threading
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from radarbench.bench.run import results_cache
from radarbench.bench.cli import main
from radarbench.bench.run.results_cache import ResultsCache
from conftest import small_sweep_text

def _sweep(windows: str = "[1, 5]", trials: int = 12) -> str:
    """The small sweep (tests/conftest.py) in chunks of 6 trials, its innovation windows ``windows``."""
    return small_sweep_text(trials=trials, chunk=6, h0=24).replace("window = [1, 5]", f"window = {windows}")


#: the units of the sweep: 4 calibration units (24 null trials by 6) and 2 SNR levels x 2 chunks
UNITS = 8


def _run(tmp_path: Path, out: str, capsys, *options: str, windows: str = "[1, 5]") -> str:
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(_sweep(windows))
    assert main(["run", str(sweep), "--out", str(tmp_path / out), "--workers", "1", *options]) == 0
    return capsys.readouterr().err


def _counts(said: str) -> tuple[int, int, int]:
    """(from the folder, from the cache, computed) of the run's line about its units."""
    found = re.search(r"units: (\d+) reused from \S+, (?:(\d+) from the results cache|the results cache not used "
                      r"\(--no-cache\)), (\d+) computed", said)
    assert found, said
    return int(found[1]), int(found[2] or 0), int(found[3])


def _same_outside_timing(a: Path, b: Path) -> None:
    for name in ("summary.csv", "trials.csv", "calibration.csv", "comparisons.csv"):
        x, y = pd.read_csv(a / name), pd.read_csv(b / name)
        timing = [c for c in x.columns if "second" in c or c.endswith("_s") or "time" in c]
        pd.testing.assert_frame_equal(x.drop(columns=timing), y.drop(columns=timing), obj=name)


def _entries(folder: Path) -> list[Path]:
    return sorted(folder.glob(f"*/*{results_cache.SUFFIX}"))


@pytest.mark.slow
def test_a_new_run_folder_takes_every_unit_from_the_cache(tmp_path, capsys, private_results_cache):
    assert _counts(_run(tmp_path, "first", capsys, "--no-record")) == (0, 0, UNITS)
    assert _entries(private_results_cache)
    said = _run(tmp_path, "second", capsys, "--no-record")
    assert _counts(said) == (0, UNITS, 0), said
    assert "warm-up" not in said and "calibration:" not in said, said      # no worker was needed
    _same_outside_timing(tmp_path / "first", tmp_path / "second")
    said = _run(tmp_path, "second", capsys, "--no-record")                 # its own folder first
    assert f"Nothing to run: all {UNITS} units stored" in said, said


@pytest.mark.slow
def test_no_cache_computes_everything_and_keeps_nothing(tmp_path, capsys, private_results_cache):
    _run(tmp_path, "first", capsys, "--no-record")
    before = {p: p.stat().st_mtime_ns for p in _entries(private_results_cache)}
    said = _run(tmp_path, "second", capsys, "--no-record", "--no-cache")
    assert _counts(said) == (0, 0, UNITS) and "not used (--no-cache)" in said, said
    assert {p: p.stat().st_mtime_ns for p in _entries(private_results_cache)} == before
    _same_outside_timing(tmp_path / "first", tmp_path / "second")


@pytest.mark.slow
def test_an_edited_method_parameter_computes_only_that_config(tmp_path, capsys, private_results_cache):
    _run(tmp_path, "first", capsys)
    before = set(_entries(private_results_cache))
    said = _run(tmp_path, "edited", capsys, windows="[1, 3]")
    assert _counts(said) == (0, 0, UNITS) and f"({UNITS} of them in part from the results cache)" in said, said
    # what was computed and kept: one run part per unit, the new config's; nothing else
    assert len(set(_entries(private_results_cache)) - before) == UNITS
    _run(tmp_path, "fresh", capsys, "--no-cache", windows="[1, 3]")
    _same_outside_timing(tmp_path / "edited", tmp_path / "fresh")
    records = [sorted(sqlite3.connect(tmp_path / run / "results.sqlite").execute("SELECT unit, trial, data FROM records"))
               for run in ("edited", "fresh")]
    assert records[0] == records[1]          # the recorded trials too: cached scene, cached and new traces


@pytest.mark.slow
def test_more_trials_in_a_new_folder_compute_only_the_new_trials(tmp_path, capsys):
    _run(tmp_path, "first", capsys, "--no-record")
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(_sweep(trials=18))
    assert main(["run", str(sweep), "--out", str(tmp_path / "more"), "--workers", "1", "--no-record"]) == 0
    said = capsys.readouterr().err
    assert _counts(said) == (0, UNITS, 2), said              # one new chunk of 6 trials per SNR level
    assert main(["run", str(sweep), "--out", str(tmp_path / "fresh"), "--workers", "1", "--no-record",
                 "--no-cache"]) == 0
    _same_outside_timing(tmp_path / "more", tmp_path / "fresh")


@pytest.mark.slow
def test_a_damaged_entry_is_computed_again_with_one_line(tmp_path, capsys, private_results_cache):
    _run(tmp_path, "first", capsys, "--no-record")
    entries = _entries(private_results_cache)
    garbled, truncated = entries[3], entries[-2]
    blob = bytearray(garbled.read_bytes())
    blob[len(blob) // 2] ^= 0xFF
    garbled.write_bytes(bytes(blob))
    truncated.write_bytes(truncated.read_bytes()[:-40])
    said = _run(tmp_path, "second", capsys, "--no-record")
    damaged = [line for line in said.splitlines() if "damaged entry" in line]
    assert len(damaged) == 2 and all("computed again" in line for line in damaged), said
    cached, computed = _counts(said)[1:]
    assert 1 <= computed <= 2 and cached + computed == UNITS, said
    _same_outside_timing(tmp_path / "first", tmp_path / "second")
    said = _run(tmp_path, "third", capsys, "--no-record")       # written anew: served, silently
    assert "damaged entry" not in said and _counts(said) == (0, UNITS, 0), said


@pytest.mark.slow
@pytest.mark.parametrize("error", [errno.EROFS, errno.ENOSPC])
def test_a_cache_that_cannot_be_written_fails_no_run(tmp_path, capsys, monkeypatch, error):
    def refused(path, data):
        raise OSError(error, os.strerror(error), str(path))
    monkeypatch.setattr(results_cache, "_write_whole", refused)
    said = _run(tmp_path, "first", capsys, "--no-record")
    assert _counts(said) == (0, 0, UNITS)
    notes = [line for line in said.splitlines() if "results cache not written" in line]
    assert len(notes) == 1 and ("full" if error == errno.ENOSPC else "not writable") in notes[0], said


@pytest.mark.slow
@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder")
def test_a_read_only_cache_folder_serves_and_fails_no_run(tmp_path, capsys, private_results_cache):
    _run(tmp_path, "first", capsys, "--no-record")
    private_results_cache.chmod(0o500)
    try:
        said = _run(tmp_path, "second", capsys, "--no-record")
    finally:
        private_results_cache.chmod(0o700)
    assert _counts(said) == (0, UNITS, 0), said


def test_a_bad_size_bound_is_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv(results_cache.BOUND_ENV, "lots")
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(_sweep())
    assert main(["run", str(sweep), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert f"{results_cache.BOUND_ENV}: expected a size in gigabytes >= 0, got 'lots'" in err, err
    assert not (tmp_path / "run").exists()


# ------------------------------------------------------------------ the cache itself

def _put(cache: ResultsCache, name: str, size: int, mtime: float) -> Path:
    key = results_cache.key_digest([name])
    cache.put(key, {"name": name}, {"payload": np.zeros(size, np.uint8)})
    path = cache.path(key)
    os.utime(path, (mtime, mtime))
    return path


def test_eviction_keeps_the_size_bound_and_the_recently_used(tmp_path):
    cache = ResultsCache(tmp_path / "cache", bound=10_000)
    paths = [_put(cache, f"e{i}", 3_000, 1_000_000 + i) for i in range(6)]
    assert cache.get(results_cache.key_digest(["e0"]))[0] == {"name": "e0"}      # used now: the newest
    assert cache.evict() > 0
    kept = _entries(tmp_path / "cache")
    assert sum(p.stat().st_size for p in kept) <= 10_000
    assert paths[0] in kept and paths[1] not in kept and paths[5] in kept


def test_the_default_bound_and_the_folder_follow_the_environment(tmp_path, monkeypatch):
    monkeypatch.delenv(results_cache.BOUND_ENV, raising=False)
    assert results_cache.bound_bytes() == int(results_cache.DEFAULT_BOUND_GB * 1e9)
    monkeypatch.setenv(results_cache.BOUND_ENV, "0.5")
    assert results_cache.bound_bytes() == 500_000_000
    monkeypatch.delenv(results_cache.FOLDER_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert results_cache.folder() == tmp_path / "radar-maneuver-bench" / "results"


def test_writers_of_one_entry_never_leave_it_damaged(tmp_path):
    cache = ResultsCache(tmp_path / "cache")
    key = results_cache.key_digest(["shared"])
    arrays = {"values": np.arange(200_000, dtype=np.float64)}
    seen, stop = [], threading.Event()

    def write():
        for _ in range(20):
            ResultsCache(tmp_path / "cache").put(key, {"n": 1}, arrays)

    def read():
        while not stop.is_set():
            entry = cache.get(key)
            if entry is not None:
                seen.append(np.array_equal(entry[1]["values"], arrays["values"]))

    readers = [threading.Thread(target=read) for _ in range(2)]
    writers = [threading.Thread(target=write) for _ in range(3)]
    for t in readers + writers:
        t.start()
    for t in writers:
        t.join()
    stop.set()
    for t in readers:
        t.join()
    assert all(seen) and cache.get(key) is not None
    assert [p.name for p in (tmp_path / "cache" / key[:2]).iterdir()] == [f"{key}{results_cache.SUFFIX}"]


def test_a_folder_others_may_write_is_not_used(tmp_path, capsys):
    shared = tmp_path / "shared"
    shared.mkdir(mode=0o777)
    shared.chmod(0o777)
    cache = ResultsCache(shared)
    cache.put(results_cache.key_digest(["x"]), {}, {})
    assert cache.get(results_cache.key_digest(["x"])) is None and not list(shared.iterdir())
    assert "results cache skipped" in capsys.readouterr().err
