"""The kernels a sweep uses, compiled once before any unit is timed (docs/architecture.md, "Runner").

Plugins compile their numba kernels on first call and keep them in numba's on-disk
cache. On a fresh install every worker would compile the same kernels, inside the
units it times. So when the cache looks cold (:func:`cache_is_cold`) the runner first
hands the workers a warm-up: per (scenario config, method config) pair, one task that
runs a :data:`WARM_UP_TRIALS`-trial calibration unit (where its task needs a threshold)
and evaluation unit (at the lowest SNR), results thrown away. Each method's kernels are compiled by the
one worker that takes its pair (the pairs spread over the workers), with the types the
sweep passes, and cached; a kernel two methods share compiles in one worker while the
other waits for it, then loads it (:class:`bench.run.numba_cache.CompileLock`). The first worker to compile says so on stderr (:data:`COMPILING`, once per run).
The sweep's units then load the kernels from the cache, so the runtime of every stored
unit excludes compilation (the warm-up's seconds are stored apart).
"""

from __future__ import annotations

import json
import os
import sys

from radarbench.bench import registry
from radarbench.bench.sweep.plan import Plan
from radarbench.bench.run.progress import say
from radarbench.bench.run.units import PRIMER_TRIALS, Unit, UnitTask, calibrated_configs, execute_unit

__all__ = ["cache_is_cold", "plan_key", "remember_unused", "warm_up_tasks", "run_warm_up", "COMPILING"]

#: trials of a warm-up unit (why two: :data:`bench.run.units.PRIMER_TRIALS`)
WARM_UP_TRIALS = PRIMER_TRIALS

#: the threshold of a warm-up evaluation unit, for every method config: one with a nominal Pfa in
#: (0, 1) (0.1 for a -log10 Pfa statistic), as a calibrated run's, so the recorded trial's trace
#: takes the path a real unit takes; at 0 a CFAR trace drew no threshold map, and the kernel
#: behind it (``models.cfar.halves.halves_log_survival`` from Python) compiled inside a timed unit
WARM_UP_THRESHOLD = 1.0

#: the line on stderr when the warm-up compiles
COMPILING = "compiling kernels (first run only)…"


def _cached_dispatchers():
    """Every numba dispatcher with ``cache=True`` among the imported modules (none without numba)."""
    if "numba" not in sys.modules:
        return iter(())
    from radarbench.bench.run.numba_cache import kernels
    return kernels()


def _stale_kernels() -> dict[str, list]:
    """index file -> numba's stamp of the kernel's source (as a JSON list) for each kernel
    whose cache entry is stale: another numba, or its source changed since it was cached."""
    stale = {}
    for dispatcher in _cached_dispatchers():
        index = dispatcher._cache._cache_file
        if os.path.exists(index._index_path) and not _entries(index):
            stale[index._index_path] = list(index._source_stamp)
    return stale


def _entries(index) -> dict:
    """The entries of a kernel's cache index; none when it is damaged (its kernel compiles,
    :mod:`bench.run.numba_cache`)."""
    try:
        return index._load_index()
    except Exception:  # noqa: BLE001 - any damage: the entry is stale
        return {}


def cache_is_cold(plan_key: str | None = None) -> bool:
    """Whether numba's on-disk cache misses the imported kernels: no kernel has an entry
    yet (a fresh install), or the entry of one is stale (its source changed since),
    unless the last warm-up of the plan (``plan_key``, :func:`plan_key`) left that same
    entry stale: the plan's units never call it (:func:`remember_unused`). A kernel with
    no entry at all while others have one is taken as one this installation's sweeps
    do not call."""
    registry.discover()
    unused = _read_unused().get(plan_key, {}) if plan_key is not None else {}
    if any(unused.get(path) != stamp for path, stamp in _stale_kernels().items()):
        return True
    indexed = any(os.path.exists(d._cache._cache_file._index_path) for d in _cached_dispatchers())
    return not indexed and any(True for _ in _cached_dispatchers())


#: the kernels each plan's last warm-up left stale (:func:`remember_unused`), in the user's cache folder
UNUSED_FILE = "warm-up-unused.json"
#: how many plans it remembers (the oldest forgotten first)
UNUSED_PLANS = 32


def plan_key(plan: Plan) -> str:
    """A plan's code and parameters (:func:`bench.run.identity.plan_identities`) as one digest:
    a changed method or scenario is a new plan to warm up."""
    from radarbench.bench.run.identity import digest, plan_identities
    return digest(json.dumps(plan_identities(plan), sort_keys=True, default=str).encode())


def _read_unused() -> dict:
    from radarbench.bench.sweep.listing import read_table
    return read_table(UNUSED_FILE)           # damaged or absent: every stale kernel counts


def remember_unused(key: str) -> None:
    """After a warm-up of the plan ``key`` whose every pair ran whole (:func:`run_warm_up`):
    the kernels still stale are ones its units do not call, so its next runs need no warm-up for them
    (:func:`cache_is_cold`). Without this, every run after an update of a kernel module
    would warm up again until some sweep called every kernel of it. Kept in the user's
    cache folder (:func:`bench.sweep.user_cache.cache_dir`); where it cannot be written, the
    warm-up simply runs again."""
    from radarbench.bench.sweep.listing import write_table
    data = {k: v for k, v in _read_unused().items() if k != key}
    data[key] = _stale_kernels()
    write_table(UNUSED_FILE, data, UNUSED_PLANS)


def warm_up_tasks(plan: Plan, announce: str | None = None) -> list:
    """One task per (scenario config, method config) pair of ``plan``: its warm-up
    calibration unit (when its task is calibrated) then its warm-up evaluation unit at
    the lowest SNR (thresholds :data:`WARM_UP_THRESHOLD`), for one worker to run both (:func:`run_warm_up`), so
    each method's kernels compile in one process, with the types a sweep passes them.
    ``announce``: the marker file whose creation elects the one process that says it
    compiles (None: silent)."""
    thresholds = {m.label: WARM_UP_THRESHOLD for m in plan.methods}
    tasks = []
    for i, sc in enumerate(plan.scenarios):
        calibrated = {m.label for m in calibrated_configs(plan, sc)}
        for mc in plan.pairs(sc):
            units = [UnitTask(plan, Unit("calibration", i, sc.label, None, 0, WARM_UP_TRIALS),
                              methods=(mc.label,))] \
                if mc.label in calibrated else []
            if sc.snr_db:
                unit = Unit("evaluation", i, sc.label, min(sc.snr_db), 0, WARM_UP_TRIALS)
                units.append(UnitTask(plan, unit, thresholds, methods=(mc.label,)))
            tasks.append((units, announce))
    return tasks


_announced = False


def _announce_once(marker: str) -> None:
    """Say on stderr that kernels compile, if no process of this run has said it (the first
    to create ``marker`` speaks)."""
    global _announced
    if _announced:
        return
    _announced = True
    try:
        os.close(os.open(marker, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except OSError:            # another worker said it (or the folder is gone: the run is over)
        return
    say(COMPILING)


def _ran_whole(results) -> bool:
    """Whether every method config of every unit ran to its end: a pair that failed may have
    stopped before a kernel it calls, which then stays stale without being unused."""
    return all(run.error is None for result in results for run in result.runs)


def run_warm_up(units_announce) -> bool:
    """In a worker: run one pair's warm-up units and drop their results (their failures are the
    real units' to report); returns whether they all ran whole (:func:`_ran_whole`). With
    ``announce`` (:func:`warm_up_tasks`), the first kernel numba compiles (not one it loads
    from the cache: numba's ``numba:compile`` event) says so."""
    units, announce = units_announce
    if announce is None or _announced:
        return _ran_whole([execute_unit(unit, prime=False) for unit in units])
    from numba.core import event

    class Announce(event.Listener):
        def on_start(self, ev):
            _announce_once(announce)

        def on_end(self, ev):
            pass

    with event.install_listener("numba:compile", Announce()):
        return _ran_whole([execute_unit(unit, prime=False) for unit in units])
