"""The warm-up (bench.run.warmup): a cold numba cache compiled once, in one worker, before any
unit is timed, and said so on stderr; a warm cache costs nothing."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from types import SimpleNamespace

import pytest

from radarbench.bench.run import warmup
from radarbench.bench.sweep.config import load_sweep
from conftest import scaled


def test_warm_up_is_one_task_per_pair_with_both_phases_and_two_trials(write_sweep):
    plan = load_sweep(write_sweep(snr="[8, 0]"))
    tasks = warmup.warm_up_tasks(plan, announce="marker")
    assert [units[0].methods for units, _ in tasks] == [(m.label,) for m in plan.methods]   # one pair each
    for units, announce in tasks:
        assert announce == "marker" and len({u.methods for u in units}) == 1
        assert [(u.unit.phase, u.unit.snr_db, u.unit.n) for u in units] == [("calibration", None, 2),
                                                                           ("evaluation", 0.0, 2)]  # lowest SNR
        assert units[1].thresholds == {m.label: warmup.WARM_UP_THRESHOLD for m in plan.methods}


def test_only_the_first_process_to_compile_says_so(tmp_path, monkeypatch, capsys):
    marker = str(tmp_path / "announced")
    monkeypatch.setattr(warmup, "_announced", False)
    warmup._announce_once(marker)
    warmup._announce_once(marker)                 # the same process again: silent
    monkeypatch.setattr(warmup, "_announced", False)
    warmup._announce_once(marker)                 # another process (its own flag): the marker exists
    assert capsys.readouterr().err == f"bench: {warmup.COMPILING}\n"


def _dispatcher(index_exists: bool, fresh: bool, path: str = __file__, stamp=(1.5, 100)):
    index = SimpleNamespace(_index_path="/nonexistent" if not index_exists else path,
                            _load_index=lambda: {"sig": 1} if fresh else {}, _source_stamp=stamp)
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


def test_a_kernel_a_plans_warm_up_left_stale_does_not_warm_it_up_again(monkeypatch, tmp_path):
    """After a module update, the stale kernels a plan's units never call (its warm-up left
    them stale) no longer make every run of that plan warm up; another plan, or the same
    kernel changed again, still does."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    (tmp_path / "k.nbi").write_bytes(b"")
    kernels = [_dispatcher(True, True), _dispatcher(True, False, path=str(tmp_path / "k.nbi"))]
    monkeypatch.setattr(warmup, "_cached_dispatchers", lambda: iter(kernels))
    assert warmup.cache_is_cold("plan-a") and warmup.cache_is_cold()
    warmup.remember_unused("plan-a")
    assert not warmup.cache_is_cold("plan-a")
    assert warmup.cache_is_cold("plan-b") and warmup.cache_is_cold()
    kernels[1] = _dispatcher(True, False, path=str(tmp_path / "k.nbi"), stamp=(2.5, 100))     # changed again
    assert warmup.cache_is_cold("plan-a")


@pytest.mark.parametrize("error, whole", [(None, True), ("the method raised ValueError", False)])
def test_a_warm_up_says_whether_its_pair_ran_whole(monkeypatch, error, whole):
    """A pair that failed may have stopped before a kernel it calls: that kernel stays stale
    without being unused, so such a warm-up must not be remembered (:func:`warmup.remember_unused`)."""
    from radarbench.bench.results.store import MethodRun, UnitResult

    def execute(work, prime=True):
        return UnitResult(work, "evaluation", "s", 0.0, 0, 1, 0.0, runs=[MethodRun("a", 0.0), MethodRun("b", 0.0, error)])
    monkeypatch.setattr(warmup, "execute_unit", execute)
    monkeypatch.setattr(warmup, "_announced", True)
    assert warmup.run_warm_up((["unit-1", "unit-2"], None)) is whole
    assert warmup.run_warm_up((["unit-1", "unit-2"], "marker")) is whole


@pytest.mark.parametrize("whole", [False, True])
def test_a_run_remembers_its_stale_kernels_only_after_a_whole_warm_up(monkeypatch, tmp_path, write_sweep, whole):
    from radarbench.bench.run import runner
    monkeypatch.setattr(warmup, "cache_is_cold", lambda key=None: True)
    monkeypatch.setattr(runner, "_warm_up", lambda *args: whole)
    remembered = []
    monkeypatch.setattr(warmup, "remember_unused", remembered.append)
    plan = load_sweep(write_sweep())
    runner.run_sweep(plan, tmp_path / "run", plan_record={}, executor="serial", quiet=True).close()
    assert remembered == ([warmup.plan_key(plan)] if whole else [])


def test_the_plan_key_follows_the_plans_configs(write_sweep):
    from conftest import small_sweep_text
    a = load_sweep(write_sweep())
    assert warmup.plan_key(a) == warmup.plan_key(load_sweep(write_sweep("again.toml")))
    other = small_sweep_text().replace("window = 16", "window = 24")
    assert warmup.plan_key(a) != warmup.plan_key(load_sweep(write_sweep("other.toml", text=other)))


class _SwigGlobals:
    """Like a SWIG module's ``cvar`` (OR-Tools' has one): every attribute raises, ``__class__`` too."""

    def __getattribute__(self, name):
        raise AttributeError(f"Unknown C global variable '{name}'")


def test_the_dispatcher_scan_passes_over_a_module_global_that_refuses_every_attribute(monkeypatch):
    """Scanning the imported modules for numba kernels must not stop at an object whose
    attribute lookup raises (``isinstance`` asks it for ``__class__``): the kernels are still found."""
    import types

    from radarbench.methods.multitarget import kernels as mtt_kernels
    swig_like = types.ModuleType("swig_like")
    swig_like.cvar = _SwigGlobals()
    monkeypatch.setitem(sys.modules, "swig_like", swig_like)
    found = list(warmup._cached_dispatchers())
    assert mtt_kernels.predict_all in found

@pytest.mark.slow
def test_a_cold_cache_is_compiled_once_and_said_so_a_warm_one_silently(tmp_path):
    """A sweep with a numba kernel, twice on an empty NUMBA_CACHE_DIR with two workers: the
    first run says it compiles (once) and stores the warm-up's seconds apart; the second
    says nothing and warms nothing up."""
    sweep = tmp_path / "imm.toml"
    sweep.write_text('name = "imm"\nscenario = "maneuvering-1d"\ntrials = 2\nseed = 1\nsnr_db = [10]\n'
                     'chunk = 1\n\n[[methods]]\nname = "imm-cv-ca"\n')
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    runs = []
    for name in ("cold", "warm"):
        proc = subprocess.run([sys.executable, "-m", "radarbench.bench", "run", sweep, "--out", tmp_path / name,
                               "--workers", "2", "--no-record"], capture_output=True, text=True, env=env,
                              timeout=scaled(1800))
        assert proc.returncode == 0, proc.stderr
        meta = dict(sqlite3.connect(tmp_path / name / "results.sqlite").execute("SELECT key, value FROM meta"))
        runs.append((proc.stderr.splitlines(), meta))
    (cold, cold_meta), (warm, warm_meta) = runs
    assert cold.count(f"bench: {warmup.COMPILING}") == 1 and float(cold_meta["warm_up_seconds"]) > 0
    assert not any(warmup.COMPILING in line or "warm-up" in line for line in warm)
    assert "warm_up_seconds" not in warm_meta
