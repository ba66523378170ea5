"""The runner: plans units of work, executes them, stores results as they finish.

A **unit** is (scenario config, SNR, chunk of trials). Its batch is generated
once and every method config runs on it (common random numbers: differences
between methods are not noise differences). Each trial's random stream is
derived from the sweep seed and the trial's identity only (:mod:`bench.sweep.rng`),
so results do not depend on chunk size, workers or executor.

A run has two phases:

1. **calibration** units: ``h0_trials`` null-hypothesis trials per scenario
   config; each method's null statistic values and nominal threshold are stored;
2. **evaluation** units: ``trials`` per SNR level, evaluated at the threshold
   the calibration chose (:mod:`bench.calibration`).

The driver alone writes the store, one transaction per unit. Units already in
the store are skipped, which is what makes an interrupted run resumable.
"""

from __future__ import annotations

import shutil
import signal
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from radarbench.bench import registry
from radarbench.bench.sweep import tomlw
from radarbench.bench.run import warmup
from radarbench.bench.calibration import EQUAL_CHANCE_PD, CalibrationResult, calibrate
from radarbench.bench.sweep.plan import Plan
from radarbench.bench.run.executors import SerialExecutor, UnitFailure, make_executor
from radarbench.bench.run.processes import STOP_SIGNALS, restore_handler
from radarbench.bench.run.identity import PREVIOUS, content_keys, set_aside_changed
from radarbench.bench.run.progress import Progress
from radarbench.bench.results.provenance import origin_text, provenance
from radarbench.bench.run.results_cache import ResultsCache
from radarbench.bench.run.reuse import Reuse, merge_records
from radarbench.bench.results.store import Store, UnitResult
from radarbench.bench.run.units import Unit, UnitTask, execute_unit, failed_result, plan_units, unit_methods

RUN_FILES = ("results.sqlite", "results.sqlite-wal", "results.sqlite-shm", "plan.toml", "trials.csv",
             "summary.csv", "calibration.csv", "steps.csv", "report.md", "recording.rrd")


class Interrupted(Exception):
    def __init__(self, stored: int, total: int):
        super().__init__(f"interrupted: {stored} of {total} units are stored")
        self.stored, self.total = stored, total


# ------------------------------------------------------------------ driver side

def calibrations(store: Store, scenarios: list[str], methods: list[str], pfa: float,
                 mode: str, chance_pd: float = EQUAL_CHANCE_PD,
                 per_cell: frozenset[str] = frozenset()) -> list[CalibrationResult]:
    """Calibrate every (scenario config, method config) from the stored null values.

    A method config whose calibration failed on any unit gets no threshold.
    ``per_cell``: the method configs whose task counts the Pfa per cell of a map
    (``Task.pfa_per_cell``; :func:`bench.calibration.calibrate`).
    """
    runs = store.runs()
    failed = runs[(runs.phase == "calibration") & runs.error.notna()]
    failed_pairs = set(zip(failed.scenario, failed.method))
    out = []
    for sc in scenarios:
        for m in methods:
            values, peaks, nominal = store.null_values(sc, m)
            if (sc, m) in failed_pairs or values.size == 0:
                continue
            out.append(calibrate(sc, m, values, np.nan if nominal is None else nominal, pfa, mode, peaks,
                                 store.null_trial_lengths(sc, m), chance_pd, store.null_cells(sc, m),
                                 per_cell=m in per_cell))
    return out


def retry_tasks(plan: Plan, units: list[Unit], failed: dict[str, set[str]],
                thresholds: dict[str, dict[str, float | None]] | None = None) -> list[UnitTask]:
    """``--retry-failed``: for each stored unit on which method configs failed, a task that
    runs only those configs again (:meth:`Store.save_unit` then replaces their failed runs
    and leaves the other configs' results untouched)."""
    labels = [m.label for m in plan.methods]
    return [UnitTask(plan, u, thresholds[u.scenario_label] if thresholds else {},
                     tuple(label for label in labels if label in failed[u.key]))
            for u in units if u.key in failed]


class _TaskQueue:
    """The tasks of a phase, handed to the executor one at a time; the runner adds
    tasks while it consumes results (a unit's method configs run one by one)."""

    def __init__(self, tasks):
        self._items = deque(tasks)

    def __iter__(self):
        return self

    def __next__(self):
        if not self._items:
            raise StopIteration
        return self._items.popleft()

    def extend(self, tasks) -> None:
        self._items.extend(tasks)


@dataclass
class _Split:
    """A unit whose whole run failed to come back (its worker died, it timed out), run
    again one method config at a time: the configs that fail alone are its failures."""

    work: UnitTask
    labels: list[str]
    parts: list[UnitResult] = field(default_factory=list)

    def done(self) -> bool:
        return {run.label for part in self.parts for run in part.runs} >= set(self.labels)

    def merged(self) -> UnitResult:
        ok = [p for p in self.parts if p.common]
        base = ok[0] if ok else self.parts[0]
        runs = {run.label: run for part in self.parts for run in part.runs}
        return UnitResult(base.key, base.phase, base.scenario, base.snr_db, base.trial_start, base.n,
                          base.generate_seconds, runs=[runs[label] for label in self.labels if label in runs],
                          common=base.common, records=merge_records(ok, self.labels) if ok else [],
                          snr_definition=next((p.snr_definition for p in ok if p.snr_definition), ""))


#: the user's record of seconds per trial, by what computes them (content keys, not labels)
UNIT_SECONDS_FILE = "unit-seconds.json"


#: seconds per trial remembered at most (the oldest forgotten first)
KNOWN_SECONDS = 10_000


def _known_seconds() -> dict[str, float]:
    """Seconds per trial kept from earlier runs: ``SCENARIO_KEY`` (generating the scenes)
    and ``SCENARIO_KEY/METHOD_KEY`` (a method config on them)."""
    from radarbench.bench.sweep.listing import read_table
    return {k: v for k, v in read_table(UNIT_SECONDS_FILE).items() if isinstance(v, float)}


def longest_first(plan: Plan, tasks: list[UnitTask]) -> list[UnitTask]:
    """``tasks`` by expected seconds, longest first (from earlier runs' seconds per trial,
    :func:`remember_seconds`), so a phase ends near its critical path rather than waiting
    on a long unit handed out last; tasks of unknown cost keep their order, after the known."""
    known = _known_seconds()
    if not known:
        return tasks
    keys = content_keys(plan)

    def expected(task: UnitTask) -> float:
        scenario = keys["scenarios"][task.unit.scenario_label]
        parts = [known.get(scenario)] + [known.get(f"{scenario}/{keys['methods'][m.label]}")
                                         for m in unit_methods(task)]
        return -sum(p for p in parts if p is not None) * task.unit.n
    return sorted(tasks, key=expected)


def remember_seconds(plan: Plan, store: Store) -> None:
    """Keep the seconds per trial of this run's units and runs in the user's cache folder
    (for :func:`longest_first`); a cache that cannot be written costs only the ordering."""
    from radarbench.bench.sweep.listing import write_table
    keys, known = content_keys(plan), _known_seconds()
    for _key, scenario, n, seconds in store.db.execute("SELECT key, scenario, n, generate_seconds FROM units"):
        if scenario in keys["scenarios"] and n:
            known[keys["scenarios"][scenario]] = float(seconds) / n
    for scenario, method, n, seconds in store.db.execute(
            "SELECT units.scenario, runs.method, units.n, runs.seconds FROM runs JOIN units ON runs.unit = units.key "
            "WHERE runs.error IS NULL"):
        if scenario in keys["scenarios"] and method in keys["methods"] and n:
            known[f"{keys['scenarios'][scenario]}/{keys['methods'][method]}"] = float(seconds) / n
    write_table(UNIT_SECONDS_FILE, known, KNOWN_SECONDS)


def _save(store: Store, result: UnitResult) -> None:
    store.save_unit(result)
    if result.snr_definition and store.meta("snr_definition") is None:
        store.set_meta("snr_definition", result.snr_definition)


def _run_phase(executor, tasks, store: Store, progress: Progress, stop=None, timeout: float | None = None,
               on_result=None, reuse: Reuse | None = None) -> None:
    queue = _TaskQueue(tasks)
    splits: dict[str, _Split] = {}
    for item in executor.imap_unordered(execute_unit, queue, stop=stop, timeout=timeout):
        if isinstance(item, UnitFailure):
            work = item.task
            if not work.isolated:
                labels = [mc.label for mc in unit_methods(work)]
                splits[work.unit.key] = _Split(work, labels)
                queue.extend(replace(work, methods=(label,), isolated=True) for label in labels)
                if labels:
                    continue
            result = failed_result(work, item.cause)
        else:
            result = item
        split = splits.get(result.key)
        if split is not None:
            split.parts.append(result)
            if not split.done():
                continue
            result = splits.pop(result.key).merged()
        if reuse is not None:     # a split's parts record only their own tasks' scenes: not a whole unit
            result = reuse.completed(result, whole=split is None)
        _save(store, result)
        progress.advance()
        if on_result is not None:
            on_result(result)


def _served(reuse: Reuse | None, store: Store, tasks: list[UnitTask], on_result=None) -> list[UnitTask]:
    """The tasks left to compute once the results cache served what it holds: a unit it
    holds whole is stored now; one it holds in part runs only its other method configs
    (:class:`bench.run.reuse.Reuse`)."""
    if reuse is None:
        return tasks
    left = []
    for task in tasks:
        result, missing = reuse.serve(task)
        if result is None:
            left.append(task)
        elif missing:
            reuse.pending[task.unit.key] = result
            reuse.partly += 1
            left.append(replace(task, methods=missing))
        else:
            _save(store, result)
            reuse.whole += 1
            if on_result is not None:
                on_result(result)
    return left


class _StopOnSignal:
    """While a run computes: the first SIGINT or SIGTERM starts no new unit, lets the
    units in flight end and stores them (the run then raises :class:`Interrupted`); a
    second one raises KeyboardInterrupt at once (the units in flight are killed).
    A signal that was ignored when the run started (``nohup``) stays ignored."""

    def __init__(self):
        self.signum: int | None = None
        self._previous: dict = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in STOP_SIGNALS:
                if signal.getsignal(sig) is not signal.SIG_IGN:
                    self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self._previous.items():
            restore_handler(sig, handler)
        self._previous.clear()

    def _handle(self, signum, frame) -> None:
        if self.signum is not None:
            raise KeyboardInterrupt
        self.signum = signum
        name = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
        lead = "\n" if getattr(sys.stderr, "isatty", lambda: False)() else ""
        print(f"{lead}stopping ({name}): no new unit starts; the units in flight end and are stored "
              "(Ctrl-C or SIGTERM again kills them)", file=sys.stderr, flush=True)

    def __call__(self) -> bool:
        return self.signum is not None


def clear_run_folder(out_dir: Path) -> None:
    """Remove what a previous run wrote (and only that) for ``--fresh``."""
    for name in RUN_FILES:
        (out_dir / name).unlink(missing_ok=True)
    shutil.rmtree(out_dir / "figures", ignore_errors=True)
    shutil.rmtree(out_dir / PREVIOUS, ignore_errors=True)


def _capped_workers(workers: int, to_run: int, quiet: bool) -> int:
    """No more workers than units to run (each would cost a process and its memory)."""
    if workers <= to_run:
        return workers
    n = max(1, to_run)
    if not quiet:
        print(f"{to_run} unit{'s' if to_run != 1 else ''} to run: starting {n} worker{'s' if n != 1 else ''} "
              f"(--workers {workers})", file=sys.stderr)
    return n


def _warm_up(executor, plan: Plan, store: Store, progress: Progress, timeout: float | None) -> bool:
    """Compile the sweep's kernels in one worker before any unit is timed (:mod:`bench.run.warmup`);
    its seconds are stored apart (meta ``warm_up_seconds``), never in a unit's runtime.
    Returns whether every pair's warm-up ran whole (:func:`bench.run.warmup.run_warm_up`)."""
    import tempfile

    tasks = warmup.warm_up_tasks(plan)
    progress.phase("warm-up", len(tasks))
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="bench-warm-up-") as folder:
        announce = None if progress.quiet else str(Path(folder) / "announced")
        whole = True
        for ran_whole in executor.imap_unordered(warmup.run_warm_up, [(units, announce) for units, _ in tasks],
                                                 timeout=timeout):
            whole &= ran_whole is True
            progress.advance()
    store.set_meta("warm_up_seconds", repr(time.monotonic() - t0))
    progress.close()
    return whole


def _thresholds(plan: Plan, store: Store) -> dict[str, dict[str, float | None]]:
    """Scenario config label -> method config label -> the threshold its evaluation runs at
    (None: an uncalibrated task, or a calibration that failed), from the stored null values."""
    thresholds: dict[str, dict[str, float | None]] = {
        sc.label: {m.label: None for m in plan.methods} for sc in plan.scenarios}
    per_cell = frozenset(m.label for m in plan.methods
                         if registry.get_task(registry.get_method(m.name).task).pfa_per_cell)
    for c in calibrations(store, [s.label for s in plan.scenarios], [m.label for m in plan.methods],
                          plan.calibration.pfa, plan.calibration.mode, plan.calibration.chance_pd, per_cell):
        thresholds[c.scenario][c.method] = c.used if np.isfinite(c.used) else None
    return thresholds


def _evaluation_tasks(plan: Plan, store: Store, units: list[Unit], done: set[str], failed: dict[str, set[str]],
                      reuse: Reuse | None, on_result) -> list[UnitTask]:
    """The evaluation units to compute, at the thresholds the calibration chose, less what
    the results cache serves."""
    thresholds = _thresholds(plan, store)
    if reuse is not None:
        reuse.thresholds = thresholds
    tasks = [UnitTask(plan, u, thresholds[u.scenario_label]) for u in units if u.key not in done] \
        + retry_tasks(plan, units, failed, thresholds)
    return longest_first(plan, _served(reuse, store, tasks, on_result))


def _phase(progress: Progress, name: str, units: list[Unit], tasks: list[UnitTask], store: Store) -> None:
    """Start showing phase ``name`` when it has ``tasks`` to compute (the units stored count as done)."""
    if tasks:
        done = store.done_units()
        stored = sum(u.key in done for u in units)
        progress.phase(name, stored + len(tasks), stored)


def _reused_line(total: int, computed: int, reuse: Reuse | None, out_dir: Path) -> str:
    """One line: how many units the run took from its folder, from the results cache, and computed."""
    cached = reuse.whole if reuse is not None else 0
    line = (f"units: {total - computed - cached} reused from {out_dir}, "
            + (f"{cached} from the results cache" if reuse is not None else "the results cache not used (--no-cache)")
            + f", {computed} computed")
    return line + (f" ({reuse.partly} of them in part from the results cache)" if reuse and reuse.partly else "")


def run_sweep(plan: Plan, out_dir: Path, *, plan_record: dict, workers: int = 1,
              executor: str = "local", fresh: bool = False, quiet: bool = False,
              on_result=None, scheduler: str | None = None, retry_failed: bool = False,
              progress: Progress | None = None, cache: bool = True) -> Store:
    """Run (or resume) a sweep into ``out_dir``; returns the open store.

    ``retry_failed``: also re-run the (unit, method config) pairs whose run failed,
    the calibration ones before the thresholds are computed. ``progress`` (default: a
    new :class:`~bench.run.progress.Progress`, silent when ``quiet``) shows the phases
    ``calibration`` and ``evaluation``; the caller closes it. A run with nothing left
    to compute says so in one line (unless ``quiet``); otherwise one line says how many
    units it reused from the folder, took from the results cache and computed.
    ``cache``: take results from the user's results cache and keep the computed ones
    there (:mod:`bench.run.reuse`; ``bench run --no-cache``: neither).

    A unit whose worker dies or overruns the plan's ``unit_timeout_s`` is run again one
    method config at a time; the configs that fail alone are stored as failed with the
    cause, the others with their results. The first SIGINT or SIGTERM lets the units in
    flight end, stores them and raises :class:`Interrupted`; a second one kills them.
    """
    out_dir = Path(out_dir)
    cal_units, eval_units = plan_units(plan)
    total = len(cal_units) + len(eval_units)
    timeout = getattr(plan, "unit_timeout_s", None)
    ex = store = reuse = None
    progress = progress or Progress(quiet=quiet)
    with _StopOnSignal() as stop:
        try:
            if scheduler is not None:          # an existing cluster: connect before the folder is touched
                ex = make_executor(executor, workers, scheduler)
            if fresh and out_dir.exists():
                clear_run_folder(out_dir)
            out_dir.mkdir(parents=True, exist_ok=True)
            store = Store(out_dir / "results.sqlite")
            # code, data or the sweep changed: set aside what no longer matches, re-run it
            changed = set_aside_changed(store, plan, out_dir, quiet)
            store.bind_plan(plan.fingerprint(), plan_record)
            # before the first unit: a report of a run stopped short says it is incomplete
            store.set_meta("units_total", str(total))
            reuse = Reuse(plan, store.stamps, ResultsCache()) if cache else None
            done = store.done_units()
            failed = store.failed_runs() if retry_failed else {}
            failed = {u: failed.get(u, set()) | changed.get(u, set()) for u in {*failed, *changed}}
            cal_tasks = longest_first(plan, _served(reuse, store, [UnitTask(plan, u) for u in cal_units
                                                                   if u.key not in done]
                                                    + retry_tasks(plan, cal_units, failed)))
            # calibrated from what is stored already: the evaluation's cached units are known before any worker
            tasks = None if cal_tasks else _evaluation_tasks(plan, store, eval_units, done, failed, reuse, on_result)
            to_run = len(cal_tasks) + (len(tasks) if tasks is not None else
                                       sum(u.key not in done or u.key in failed for u in eval_units))
            computed = {t.unit.key for t in cal_tasks + (tasks or [])}
            if to_run == 0 and not quiet and not (reuse and reuse.whole):
                print(f"Nothing to run: all {total} units stored in {out_dir}", file=sys.stderr)
            if ex is None:
                ex = SerialExecutor() if to_run == 0 else \
                    make_executor(executor, _capped_workers(workers, to_run, quiet), scheduler)
            started = time.monotonic()
            if to_run and ex.local:                                 # a cluster's workers have their own caches
                key = warmup.plan_key(plan)
                if warmup.cache_is_cold(key) and _warm_up(ex, plan, store, progress, timeout):
                    warmup.remember_unused(key)       # not after a failed pair: it may not have reached a kernel
            _phase(progress, "calibration", cal_units, cal_tasks, store)
            _run_phase(ex, cal_tasks, store, progress, stop, timeout, reuse=reuse)
            if not stop():
                if tasks is None:
                    tasks = _evaluation_tasks(plan, store, eval_units, done, failed, reuse, on_result)
                    computed |= {t.unit.key for t in tasks}
                _phase(progress, "evaluation", eval_units, tasks, store)
                _run_phase(ex, tasks, store, progress, stop, timeout, on_result, reuse)
        except KeyboardInterrupt:              # a second signal: the units in flight are lost
            progress.close()
            if ex is not None:
                ex.kill()
            if store is None:
                raise
            raise Interrupted(len(store.done_units()), total) from None
        except BaseException:
            progress.close()
            if ex is not None:
                ex.kill()
            raise
        ex.shutdown()
        progress.close()
    if stop():
        raise Interrupted(len(store.done_units()), total)
    if computed or (reuse and reuse.whole):
        if not quiet:
            print(_reused_line(total, len(computed), reuse, out_dir), file=sys.stderr)
        if reuse is not None:
            reuse.cache.evict()
    if to_run:                             # the units' wall time of the last run that computed any
        store.set_meta("last_wall_seconds", repr(time.monotonic() - started))
        remember_seconds(plan, store)
    return store


def plan_record(plan: Plan, command: str) -> dict:
    """What the store keeps of the plan: the sweep, the configs (with the module and
    distribution of each one's plugin), the command."""
    return {
        "sweep": plan.to_dict(),
        "source": plan.source,
        "sweep_folder": plan.sweep_folder,
        "contents": content_keys(plan),
        "command": command,
        "methods": [{"label": m.label, "name": m.name, "params": m.params_text,
                     "task": registry.get_method(m.name).task, **registry.origin(registry.get_method(m.name))}
                    for m in plan.methods],
        "scenarios": [{"label": s.label, "name": s.name, "params": s.params_text, "tasks": list(s.tasks),
                       "snr_db": list(s.snr_db), "trials": s.trials, **registry.origin(registry.get_scenario(s.name))}
                      for s in plan.scenarios],
        "unavailable": [{"label": entry.get("label", entry["name"]), "name": entry["name"], "reason": reason}
                    for entry, reason in plan.skipped_methods],
        "skipped_pairs": [{"scenario": sc, "method": m, "reason": why} for sc, m, why in plan.skipped],
    }


def write_plan_toml(path: Path, plan: Plan, command: str, identities: dict | None = None) -> None:
    """The resolved sweep, re-runnable as a sweep file (its data files named relative to
    its folder, from which a sweep's relative paths are read), with provenance: the
    identities (config label -> short hash, ``Store.stamps``) the results were computed
    with, and the plugins (config label -> "module (distribution)") that computed them."""
    plugins = {"scenarios": {s.label: origin_text(registry.origin(registry.get_scenario(s.name)))
                             for s in plan.scenarios},
               "methods": {m.label: origin_text(registry.origin(registry.get_method(m.name))) for m in plan.methods}}
    body = {**plan.to_dict(paths_from=path.parent),
            "provenance": {"command": command, "fingerprint": plan.fingerprint(), **provenance(),
                           "identities": identities, "plugins": plugins}}
    text = "# Resolved plan written by bench; `bench run plan.toml` reproduces the results.\n" + tomlw.dumps(body)
    from radarbench.bench.results.runfolder import write_text      # whole, a unique temporary name, listed in the manifest
    write_text(path, text)
