"""A unit of work and how a worker runs it (docs/architecture.md, 'Runner').

A **unit** is (phase, scenario config, SNR, chunk of trials): :func:`plan_units` lists a
plan's, and :func:`execute_unit`, in a worker, generates its batch once and runs every
method config on it (common random numbers). The driver that hands units to workers and
stores their results is :mod:`bench.run.runner`; the warm-up runs units too (:mod:`bench.run.warmup`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from radarbench.bench.sweep import capabilities
from radarbench.bench.results import failures
from radarbench.bench import registry
from radarbench.bench.sweep.plan import Plan, snr_key
from radarbench.bench.run.executors import in_worker
from radarbench.bench.recording.record import TrialRecord
from radarbench.bench.sweep.rng import CALIBRATION, EVALUATION, TrialRNG
from radarbench.bench.results.store import MethodRun, UnitResult
from radarbench.bench.run.worktime import work_seconds
from radarbench.bench.tasks.base import RecordedScene


@dataclass(frozen=True)
class Unit:
    phase: str                  # "calibration" | "evaluation"
    scenario_index: int
    scenario_label: str
    snr_db: float | None
    trial_start: int
    n: int

    @property
    def key(self) -> str:
        return f"{self.phase}/{self.scenario_label}/{snr_key(self.snr_db)}/{self.trial_start:09d}+{self.n}"


@dataclass
class UnitTask:
    """What a worker needs to run one unit."""

    plan: Plan
    unit: Unit
    thresholds: dict[str, float | None] = field(default_factory=dict)   # evaluation only
    methods: tuple[str, ...] | None = None     # only these method configs (--retry-failed); None: all
    isolated: bool = False     # one method config run alone, after the whole unit failed to come back


def _chunks(total: int, chunk: int):
    for start in range(0, total, chunk):
        yield start, min(chunk, total - start)


def task_of(method_config):
    """The task (bench.tasks) of a method config."""
    return registry.get_task(registry.get_method(method_config.name).task)


def calibrated_configs(plan: Plan, sc) -> list:
    """The method configs on scenario config ``sc`` whose task thresholds a statistic."""
    return [m for m in plan.pairs(sc) if task_of(m).calibrated]


def plan_units(plan: Plan) -> tuple[list[Unit], list[Unit]]:
    """Calibration units (null trials, only where some method needs a threshold)
    and evaluation units, per scenario config at its own SNR levels and trials."""
    calibration, evaluation = [], []
    for i, sc in enumerate(plan.scenarios):
        if calibrated_configs(plan, sc):
            for start, n in _chunks(plan.calibration.h0_trials, plan.chunk):
                calibration.append(Unit("calibration", i, sc.label, None, start, n))
        for snr in sc.snr_db:
            for start, n in _chunks(sc.trials, plan.chunk):
                evaluation.append(Unit("evaluation", i, sc.label, snr, start, n))
    return calibration, evaluation


# ------------------------------------------------------------------ worker side

def unit_methods(work: UnitTask) -> list:
    """The method configs ``work`` runs: on a calibration unit those whose task is
    calibrated, on an evaluation unit all that run on its scenario config; only
    ``work.methods`` when it is set."""
    plan, unit = work.plan, work.unit
    sc = plan.scenarios[unit.scenario_index]
    methods = calibrated_configs(plan, sc) if unit.phase == "calibration" else plan.pairs(sc)
    return [mc for mc in methods if work.methods is None or mc.label in work.methods]


def failed_result(work: UnitTask, cause: str, trace: str | None = None) -> UnitResult:
    """``work``'s unit with every method config it runs failed for ``cause`` (stored like any
    result, with the traceback ``trace`` if any: a re-run skips it, ``--retry-failed`` runs it again)."""
    unit = work.unit
    return UnitResult(unit.key, unit.phase, unit.scenario_label, unit.snr_db, unit.trial_start, unit.n, 0.0,
                      runs=[MethodRun(mc.label, 0.0, error=cause, traceback=trace) for mc in unit_methods(work)])


def _let_through(exc: BaseException) -> bool:
    """A Ctrl-C in the driver (the serial executor) stops the run; anything else a plugin
    raises — SystemExit included, and KeyboardInterrupt in a worker, where no user can
    type it — is the failure of a unit."""
    return isinstance(exc, KeyboardInterrupt) and not in_worker()


def _measurements_xy(batch, i: int):
    """Trial ``i``'s measurements in the plane: the scene's ``measurements_xy``,
    else the first two components of point measurements ``z`` (n, K, m >= 2);
    None for other measurements (scalars, frames)."""
    z_xy = batch.scene.measurements_xy
    if z_xy is not None:
        return z_xy[i]
    return batch.z[i][:, :2] if batch.z.ndim == 3 and batch.z.shape[-1] >= 2 else None


def _truth_xy(batch, i: int):
    """Trial ``i``'s truth as drawn in the plane (K, 2) for a single-target truth (n, K, d)
    (:meth:`bench.core.Scene.drawn_xy`); None for a set of targets (n, K, T, d), which its
    task draws itself."""
    return batch.scene.drawn_xy(batch.truth[i], batch.t) if batch.truth.ndim == 3 else None


def _trial_record(plan: Plan, unit: Unit, batch, i: int, traces: dict, tasks) -> bytes:
    """Trial ``i`` as the record the driver draws: the harness's truth and
    measurements, what each of ``tasks`` keeps of the scene, the methods' traces."""
    sc = plan.scenarios[unit.scenario_index]
    scene = RecordedScene.union(task.recorded_scene(batch, i) for task in tasks)
    rec = TrialRecord(sc.label, unit.snr_db, int(batch.trials[i]), batch.t, truth_xy=_truth_xy(batch, i),
                      measurements_xy=_measurements_xy(batch, i), methods=traces, arrays=scene.arrays,
                      images=scene.images, info=scene.info)
    valid = batch.scene.valid_steps
    return (rec if valid is None else rec.at_steps(valid[i])).to_bytes()


#: trials of a primer unit (:func:`_prime`) and of a warm-up unit (:mod:`bench.run.warmup`): two, never
#: one, since a one-trial batch makes arrays a larger one does not (a shared prior broadcast to
#: (1, d) is already contiguous, so it stays a read-only view), and numba compiles another
#: specialisation for them inside the timed units
PRIMER_TRIALS = 2

#: (scenario config, method config, phase) this process has run: its first calls are behind it
_primed: set[tuple] = set()


def _prime(work: UnitTask) -> None:
    """Run, untimed, a :data:`PRIMER_TRIALS`-trial unit of ``work``'s scenario config for the
    method configs this process has not yet run on it in this phase; its result is dropped.

    A method's first call in a process pays once what no later call pays: numba loading and
    linking its kernels (left out of the clock already, :mod:`bench.run.worktime`), but also the
    first touch of compiled libraries' pages, lazy imports, and caches of model matrices. On a
    unit of 20 sub-millisecond trials that doubled the CPU time per trial of whichever unit
    came first in each process, so a run's runtime table depended on how units fell on
    workers. The primer takes those costs out of the timed units (as ``bench perf`` times after a
    warm-up call); a failure in it is the real unit's to report."""
    sc = work.plan.scenarios[work.unit.scenario_index]
    fresh = tuple(mc.label for mc in unit_methods(work) if (sc.label, mc.label, work.unit.phase) not in _primed)
    if not fresh:
        return
    unit = work.unit
    primer = Unit(unit.phase, unit.scenario_index, unit.scenario_label, unit.snr_db, unit.trial_start, PRIMER_TRIALS)
    try:
        execute_unit(UnitTask(work.plan, primer, work.thresholds, methods=fresh), prime=False)
    except BaseException as exc:  # noqa: BLE001 - the real unit runs and reports it
        if _let_through(exc):
            raise


def execute_unit(work: UnitTask, prime: bool = True) -> UnitResult:
    """Generate one unit's batch, run every method config on it, evaluate. With ``prime``, the
    method configs' first calls in this process come first, untimed (:func:`_prime`)."""
    registry.discover()
    if prime:
        _prime(work)
    plan, unit = work.plan, work.unit
    sc = plan.scenarios[unit.scenario_index]
    domain = CALIBRATION if unit.phase == "calibration" else EVALUATION
    rng = TrialRNG(plan.seed, domain, sc.key, range(unit.trial_start, unit.trial_start + unit.n))
    methods = unit_methods(work)
    t0 = work_seconds()
    scenario_cls = None
    try:
        scenario_cls = registry.get_scenario(sc.name)
        batch = scenario_cls().generate(sc.params, unit.snr_db, unit.n, rng)
        realised = batch.scene.realised_snr_db
        common = {"trial": np.asarray(batch.trials, np.int64), "seed": rng.seed_values(),
                  "realised_snr_db": np.asarray(np.full(unit.n, np.nan) if realised is None else realised, float)}
        recorded = [i for i, t in enumerate(batch.trials) if t < plan.record_trials] \
            if unit.phase == "evaluation" else []
    except BaseException as exc:  # noqa: BLE001 - the scenario's failure: every method config's on this unit
        if _let_through(exc):
            raise
        cause, trace = failures.describe(exc, scenario_cls)
        return failed_result(work, f"the scenario failed to generate the unit: {cause}", trace)
    result = UnitResult(unit.key, unit.phase, sc.label, unit.snr_db, unit.trial_start, unit.n,
                        work_seconds() - t0)
    result.common = common
    traces: dict[int, dict] = {i: {} for i in recorded}
    for mc in methods:
        method_cls = registry.get_method(mc.name)
        run = MethodRun(mc.label, 0.0)
        t1 = work_seconds()
        try:
            task = registry.get_task(method_cls.task)
            task.check_scene(batch)
            capabilities.check_batch(method_cls, batch)
            method = method_cls()
            if unit.phase == "evaluation" and task.calibrated and work.thresholds.get(mc.label) is None:
                raise RuntimeError("no threshold: the calibration of this method failed")
            out = task.check_output(method.run(batch, mc.params), batch)
            if unit.phase == "calibration":
                run.null_values = task.null_values(batch, out)
                run.null_peaks = task.null_peaks(batch, out)
                run.null_cells = task.null_cells(batch, out)
                run.nominal_threshold = _nominal(method.nominal_threshold(mc.params, plan.calibration.pfa, batch))
            else:
                threshold = work.thresholds.get(mc.label)
                threshold = float("nan") if threshold is None else float(threshold)
                run.metrics = task.trial_metrics(batch, out, threshold)
                run.metrics["threshold"] = np.full(unit.n, threshold)
                for i in recorded:
                    traces[i][mc.label] = task.recorded_method(batch, out, i, threshold)
        except BaseException as exc:  # noqa: BLE001 - one method's failure never stops the others
            if _let_through(exc):
                raise
            run.error, run.traceback = failures.describe(exc, method_cls)
        run.seconds = work_seconds() - t1
        result.runs.append(run)
        _primed.add((sc.label, mc.label, unit.phase))
    tasks = list(dict.fromkeys(task_of(mc) for mc in methods))
    result.records = [(int(batch.trials[i]), _trial_record(plan, unit, batch, i, traces[i], tasks))
                      for i in recorded]
    result.snr_definition = batch.scene.snr_definition
    return result


def _nominal(value) -> float:
    """A method's nominal threshold as a float: a number, or NaN for none (never None: an
    override that falls through would otherwise fail as a TypeError deep in the unit)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise TypeError(f"nominal_threshold returned {type(value).__name__}, expected a float (NaN for none)")
    return float(value)
