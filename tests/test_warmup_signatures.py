"""The warm-up compiles every kernel with the types and layouts the units pass it
(docs/architecture.md, 'Warm-up'): after it, no dispatcher gains a specialisation while a
preset's units run, so no unit's time holds a compilation; and a unit's time leaves out
what compiling costs (:mod:`bench.run.worktime`)."""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np
import pytest

from radarbench.bench import registry
from radarbench.bench.sweep.config import load_sweep, parse_sweep
from radarbench.bench.run.numba_cache import kernels
from radarbench.bench.run.units import UnitTask, execute_unit, plan_units, Unit
from radarbench.bench.run.warmup import warm_up_tasks
from radarbench.bench.run.worktime import compiling_seconds, work_seconds


def _signatures() -> dict[str, int]:
    return {f"{k.py_func.__module__}.{k.py_func.__qualname__}": len(k.signatures) for k in kernels()}


def _warm_up(plan) -> dict[str, int]:
    for units, _ in warm_up_tasks(plan):
        for task in units:
            execute_unit(task)
    return _signatures()


def _grown(warm: dict[str, int]) -> dict[str, tuple[int, int]]:
    return {name: (warm.get(name, 0), count) for name, count in _signatures().items() if count != warm.get(name, 0)}


def _ours(plan) -> tuple[str, ...]:
    """The plan's method configs whose kernels are ours (an installed peer has none)."""
    return tuple(m.label for m in plan.methods if registry.get_method(m.name).__module__.startswith("radarbench."))


def _grown_by_the_quick_units() -> tuple[dict, dict]:
    """In this process: the quick preset's warm-up, then every one of its units; (the kernels'
    signatures after the warm-up, those that grew after the units)."""
    registry.discover()
    plan = load_sweep(Path(registry.__file__).parent / "presets" / "quick.toml")
    warm = _warm_up(plan)
    thresholds = {m.label: 1.0 for m in plan.methods}
    calibration, evaluation = plan_units(plan)
    for unit in calibration + evaluation:
        execute_unit(UnitTask(plan, unit, thresholds, methods=_ours(plan)))
    return warm, _grown(warm)


@pytest.mark.slow
def test_no_kernel_compiles_again_after_the_warm_up_of_the_quick_preset():
    """Every unit of a quick run (its calibration and evaluation units, as the runner
    plans them) after the warm-up: no dispatcher gains a signature. In a fresh process, as
    a worker's: in the suite's own, a kernel an earlier test called already holds the
    signature a warm-up may miss (the warm-up's evaluation thresholds at 0 drew no CFAR
    threshold map, so ``halves_log_survival`` compiled in a unit, found only when this test
    ran first in its worker)."""
    from radarbench.bench.run.processes import call_in_fresh_process

    warm, grown = call_in_fresh_process(_grown_by_the_quick_units)
    assert warm, "the quick preset calls no compiled kernel"
    assert not grown, f"compiled inside timed units (kernel: (after the warm-up, after the units)): {grown}"



def _per_constant(kernel) -> list:
    """A kernel's specialisations that differ from another of its own only in the literal
    value of an argument: numba types a Python int constant one kernel passes another as
    that value, and compiles the callee once per value."""
    unliteral = [tuple(numba.core.types.unliteral(t) for t in sig) for sig in kernel.signatures]
    return [sig for sig, plain in zip(kernel.signatures, unliteral) if unliteral.count(plain) > 1]


@pytest.mark.slow
def test_the_quick_preset_compiles_no_kernel_once_per_constant():
    """After the quick preset's warm-up, no kernel holds two specialisations for two values
    of one constant argument (each costs a whole compilation: the JPDA stage twice, once per
    track status)."""
    plan = load_sweep(Path(registry.__file__).parent / "presets" / "quick.toml")
    _warm_up(plan)
    repeated = {f"{k.py_func.__module__}.{k.py_func.__qualname__}": [str(sig) for sig in _per_constant(k)]
                for k in kernels() if _per_constant(k)}
    assert not repeated, f"compiled once per constant value: {repeated}"

def test_a_one_trial_unit_compiles_nothing_after_a_two_trial_warm_up():
    """A batch of one trial types its arrays as a larger one does: a prior shared by the
    trials and broadcast to (1, d) is contiguous but read-only, which numba would type as
    another array (models.kalman.kernel_array copies it)."""
    plan = parse_sweep({"name": "one-trial", "scenario": "maneuvering-1d", "trials": 3, "chunk": 2, "seed": 5,
                        "scenario_params": {"steps": 60, "maneuver_start_s": 20.0, "maneuver_duration_s": 15.0}, "snr_db": [10],
                        "methods": [{"name": n} for n in ("cv-kf", "imm-cv-ca", "current-statistical")]})
    warm = _warm_up(plan)
    calibration, evaluation = plan_units(plan)
    assert [u.n for u in evaluation] == [2, 1]
    for unit in evaluation:
        result = execute_unit(UnitTask(plan, unit))
        assert all(run.error is None for run in result.runs), [run.error for run in result.runs]
    grown = _grown(warm)
    assert not grown, f"a one-trial unit compiled (kernel: (after the warm-up, after the unit)): {grown}"


def test_a_units_seconds_leave_out_compilation():
    """A kernel compiled inside the measured work: its compilation is not in the work's seconds."""
    @numba.njit
    def fresh(a):                       # a new function: compiled on its first call
        s = 0.0
        for x in a:
            s += np.sin(x) * np.cos(x)
        return s

    before_compiling, start = compiling_seconds(), work_seconds()
    fresh(np.arange(10.0))
    work, compiling = work_seconds() - start, compiling_seconds() - before_compiling
    assert compiling > 0.01, compiling
    assert work < compiling / 2, (work, compiling)


def test_a_methods_seconds_in_a_unit_are_its_cpu_time(monkeypatch):
    """A unit's stored seconds are CPU seconds of its work: a unit whose method sleeps stores almost none."""
    plan = parse_sweep({"name": "sleepy", "scenario": "maneuvering-1d", "trials": 2, "seed": 1, "snr_db": [10],
                        "scenario_params": {"steps": 60, "maneuver_start_s": 20.0, "maneuver_duration_s": 15.0}, "methods": [{"name": "cv-kf"}]})
    method = registry.get_method("cv-kf")
    original = method.run

    def sleepy(self, batch, params):
        import time
        time.sleep(0.3)
        return original(self, batch, params)

    monkeypatch.setattr(method, "run", sleepy)
    result = execute_unit(UnitTask(plan, Unit("evaluation", 0, plan.scenarios[0].label, 10.0, 0, 2)))
    assert result.runs[0].error is None
    assert result.runs[0].seconds < 0.15, result.runs[0].seconds


def test_a_method_configs_first_call_in_a_process_comes_before_its_timed_unit(monkeypatch):
    """A unit whose (scenario config, method config, phase) this process has not run yet is
    preceded by an untimed two-trial primer of it (its first-call costs out of the clock:
    :func:`bench.run.units._prime`); the next unit of the pair is not; the primer's batch is the
    unit's first trials, so the unit's results are those of a run without it."""
    from radarbench.bench.run import units as units_module

    plan = parse_sweep({"name": "primer", "scenario": "maneuvering-1d", "trials": 12, "chunk": 6, "seed": 5,
                        "snr_db": [10.0], "scenario_params": {"steps": 30, "maneuver_start_s": 10.0,
                                                               "maneuver_duration_s": 10.0},
                        "methods": [{"name": "cv-kf"}, {"name": "singer"}]})
    calls: list[tuple[str, int]] = []
    for name in ("cv-kf", "singer"):
        cls = registry.get_method(name)
        monkeypatch.setattr(cls, "run", _counting(cls.run, name, calls))
    monkeypatch.setattr(units_module, "_primed", set())
    _, evaluation = plan_units(plan)
    first, second = (UnitTask(plan, unit, {}) for unit in evaluation)
    without = execute_unit(first, prime=False)
    monkeypatch.setattr(units_module, "_primed", set())
    calls.clear()
    primed = execute_unit(first)
    assert calls == [("cv-kf", 2), ("singer", 2), ("cv-kf", 6), ("singer", 6)]
    calls.clear()
    execute_unit(second)
    assert calls == [("cv-kf", 6), ("singer", 6)]
    for a, b in zip(without.runs, primed.runs):
        assert a.label == b.label and a.metrics.keys() == b.metrics.keys()
        for key in a.metrics:
            np.testing.assert_array_equal(a.metrics[key], b.metrics[key])


def _counting(run, name: str, calls: list):
    def counted(self, batch, params):
        calls.append((name, batch.n))
        return run(self, batch, params)
    return counted
