"""The warm-up compiles every kernel with the types and layouts the units pass it
(docs/architecture.md, 'Warm-up'): after it, no dispatcher gains a specialisation while a
preset's units run, so no unit's time holds a compilation."""

from __future__ import annotations

from pathlib import Path

import pytest

from radarbench.bench import registry
from radarbench.bench.config import load_sweep
from radarbench.bench.numba_cache import kernels
from radarbench.bench.units import Unit, UnitTask, calibrated_configs, execute_unit
from radarbench.bench.warmup import warm_up_tasks


def _signatures() -> dict[str, int]:
    return {f"{k.py_func.__module__}.{k.py_func.__qualname__}": len(k.signatures) for k in kernels()}


@pytest.mark.slow
def test_no_kernel_compiles_again_after_the_warm_up_of_the_quick_preset():
    plan = load_sweep(Path(registry.__file__).parent / "presets" / "quick.toml")
    for units, _ in warm_up_tasks(plan):
        for task in units:
            execute_unit(task)
    warm = _signatures()
    assert warm, "the quick preset calls no compiled kernel"
    thresholds = {m.label: 1.0 for m in plan.methods}
    for i, sc in enumerate(plan.scenarios):
        n = min(plan.chunk, sc.trials)
        calibrated = {m.label for m in calibrated_configs(plan, sc)}
        for mc in plan.pairs(sc):
            if not registry.get_method(mc.name).__module__.startswith("radarbench."):
                continue                                   # an installed peer: none of our kernels
            units = [Unit("evaluation", i, sc.label, max(sc.snr_db), 0, n)]
            if mc.label in calibrated:
                units.append(Unit("calibration", i, sc.label, None, 0, min(plan.chunk, plan.calibration.h0_trials)))
            for unit in units:
                execute_unit(UnitTask(plan, unit, thresholds, methods=(mc.label,)))
    grown = {name: (warm.get(name, 0), count) for name, count in _signatures().items() if count != warm.get(name, 0)}
    assert not grown, f"compiled inside timed units (kernel: (after the warm-up, after the units)): {grown}"
