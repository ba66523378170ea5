"""The warm-up (bench.warmup): a cold numba cache compiled once, in one worker, before any
unit is timed, and said so on stderr; a warm cache costs nothing."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from bench import warmup
from bench.config import load_sweep
from bench.executors import LocalExecutor


def test_warm_up_covers_every_scenario_config_in_both_phases_with_one_trial(write_sweep):
    plan = load_sweep(write_sweep(snr="[8, 0]"))
    tasks = warmup.warm_up_tasks(plan, announce=False)
    units = [(t.unit.phase, t.unit.snr_db, t.unit.n, t.unit.trial_start) for t, announce in tasks]
    assert units == [("calibration", None, 1, 0), ("evaluation", 0.0, 1, 0)]     # the lowest SNR
    assert tasks[1][0].thresholds == {m.label: 0.0 for m in plan.methods}
    assert not any(announce for _, announce in tasks)


def _dispatcher(index_exists: bool, fresh: bool):
    index = SimpleNamespace(_index_path="/nonexistent" if not index_exists else __file__,
                            _load_index=lambda: {"sig": 1} if fresh else {})
    return SimpleNamespace(_cache=SimpleNamespace(_cache_file=index))


@pytest.mark.parametrize("kernels, cold", [
    ([], False),                                            # no numba kernel imported: nothing to compile
    ([(False, False), (False, False)], True),               # a fresh install: no kernel cached yet
    ([(True, True), (False, False)], False),                # cached; the other one is not used by sweeps
    ([(True, True), (True, False)], True),                  # a kernel's source changed since it was cached
])
def test_cache_is_cold(monkeypatch, kernels, cold):
    monkeypatch.setattr(warmup, "_cached_dispatchers", lambda: iter([_dispatcher(*k) for k in kernels]))
    assert warmup.cache_is_cold() is cold


def _mark_pid(task):
    """A warm-up task: leave this worker's pid in the task's folder; ``die`` kills the worker."""
    folder, die = task
    Path(folder, str(os.getpid())).touch()
    if die:
        os._exit(3)
    return os.getpid()


def test_local_warm_up_runs_in_one_worker_survives_its_death_and_leaves_the_pool_whole(tmp_path):
    ex = LocalExecutor(2)
    try:
        ex.warm_up(_mark_pid, [(tmp_path, False), (tmp_path, True), (tmp_path, False)], timeout=60)
        pids = sorted(p.name for p in tmp_path.iterdir())
        assert len(pids) == 2                    # the first worker, then the one that replaced it
        later = list(ex.imap_unordered(_mark_pid, [(tmp_path, False)] * 8))
        assert len(ex._pool) == 2 and len(later) == 8 and all(isinstance(pid, int) for pid in later)
    finally:
        ex.shutdown()


@pytest.mark.slow
def test_a_cold_cache_is_compiled_once_and_said_so_a_warm_one_silently(tmp_path):
    """A sweep with a numba kernel, twice on an empty NUMBA_CACHE_DIR: the first run says
    it compiles (once) and stores the warm-up's seconds apart; the second says nothing."""
    sweep = tmp_path / "imm.toml"
    sweep.write_text('name = "imm"\nscenario = "maneuvering-1d"\ntrials = 2\nseed = 1\nsnr_db = [10]\n'
                     'chunk = 1\n\n[[methods]]\nname = "imm-cv-ca"\n')
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    runs = []
    for name in ("cold", "warm"):
        proc = subprocess.run([sys.executable, "-m", "bench", "run", sweep, "--out", tmp_path / name,
                               "--workers", "2", "--no-record"], capture_output=True, text=True, env=env,
                              timeout=1200)
        assert proc.returncode == 0, proc.stderr
        meta = dict(sqlite3.connect(tmp_path / name / "results.sqlite").execute("SELECT key, value FROM meta"))
        runs.append((proc.stderr.splitlines(), meta))
    (cold, cold_meta), (warm, warm_meta) = runs
    assert cold.count(f"bench: {warmup.COMPILING}") == 1 and float(cold_meta["warm_up_seconds"]) > 0
    assert not any(warmup.COMPILING in line or "warm-up" in line for line in warm)
    assert "warm_up_seconds" not in warm_meta
