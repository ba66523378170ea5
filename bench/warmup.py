"""The kernels a sweep uses, compiled once before any unit is timed (docs/architecture.md, "Runner").

Plugins compile their numba kernels on first call and keep them in numba's on-disk
cache. On a fresh install every worker would compile the same kernels at once, inside
the units it times. So when the cache looks cold (:func:`cache_is_cold`) the runner
first sends *one* worker a warm-up: a one-trial unit of every scenario config (the
calibration unit where a method needs a threshold, the evaluation unit at the lowest
SNR), every method config on it, results thrown away. That worker compiles each kernel
the sweep uses, with the types the sweep passes, writes it to the cache and says so on
stderr the moment it compiles one (:data:`COMPILING`, once); the other workers wait,
then load the kernels from the cache, and the runtime of every stored unit excludes
compilation (the warm-up's seconds are stored apart).
"""

from __future__ import annotations

import os
import sys

from bench import registry
from bench.config import Plan

__all__ = ["cache_is_cold", "warm_up_tasks", "run_warm_up", "COMPILING"]

#: the line on stderr when the warm-up compiles
COMPILING = "compiling kernels (first run only)…"


def _cached_dispatchers():
    """Every numba dispatcher with ``cache=True`` among the imported modules (none without numba)."""
    numba = sys.modules.get("numba")
    if numba is None:
        return
    from numba.core.caching import FunctionCache
    from numba.core.registry import CPUDispatcher

    for module in list(sys.modules.values()):
        for obj in list(getattr(module, "__dict__", {}).values()):
            if isinstance(obj, CPUDispatcher) and isinstance(getattr(obj, "_cache", None), FunctionCache):
                yield obj


def cache_is_cold() -> bool:
    """Whether numba's on-disk cache misses the imported kernels: no kernel has an entry
    yet (a fresh install), or the entry of one is stale (its source changed since).
    A kernel with no entry at all while others have one is taken as one this
    installation's sweeps do not call."""
    registry.discover()
    indexed = False
    for dispatcher in _cached_dispatchers():
        index = dispatcher._cache._cache_file
        if not os.path.exists(index._index_path):
            continue
        if not index._load_index():          # numba's own test: another version or another source
            return True
        indexed = True
    return not indexed and any(True for _ in _cached_dispatchers())


def warm_up_tasks(plan: Plan, announce: bool = True) -> list:
    """One-trial units covering every (scenario config, method config) pair of ``plan``
    in both phases, thresholds zero: what compiles the kernels with the types a sweep
    passes them; each as ``(unit task, announce)`` for :func:`run_warm_up`."""
    from bench.runner import Unit, UnitTask, _calibrated

    zero = {m.label: 0.0 for m in plan.methods}
    tasks = []
    for i, sc in enumerate(plan.scenarios):
        if _calibrated(plan, sc):
            tasks.append(UnitTask(plan, Unit("calibration", i, sc.label, None, 0, 1)))
        if sc.snr_db:
            tasks.append(UnitTask(plan, Unit("evaluation", i, sc.label, min(sc.snr_db), 0, 1), zero))
    return [(task, announce) for task in tasks]


_announced = False


def _announce_once(stream) -> None:
    global _announced
    if not _announced:
        _announced = True
        try:
            stream.write(f"bench: {COMPILING}\n")
            stream.flush()
        except (OSError, ValueError):   # a closed or full stderr never stops a run
            pass


def run_warm_up(task_announce) -> None:
    """In a worker: run one warm-up unit and drop its result (its failures are the real unit's
    to report). With ``announce``, the first kernel numba compiles (not one it loads from the
    cache: numba's ``numba:compile`` event) says so on stderr, once per process."""
    from bench.runner import execute_unit

    task, announce = task_announce
    if not announce or _announced:
        execute_unit(task)
        return
    from numba.core import event

    class Announce(event.Listener):
        def on_start(self, ev):
            _announce_once(sys.stderr)

        def on_end(self, ev):
            pass

    with event.install_listener("numba:compile", Announce()):
        execute_unit(task)
