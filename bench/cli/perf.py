"""``bench perf``: throughput and peak memory of every registered method.

For each method and each named size of its scenario (``Scenario.perf_sizes``:
``name -> (scenario params, trials)``), one batch is generated and the method
runs on it after a warm-up on one trial (so JIT compilation is not timed). In the
same process, the method's *reference implementation* (``Method.reference_run``,
when ``Method.reference_name`` is set; e.g. the straightforward SciPy DP-TBD, or
a Kalman-innovation detector on innovations from a per-trial ``filterpy`` loop)
runs on the first ``Method.reference_trials`` trials of the same batch after its
own warm-up; the two are timed in :data:`ROUNDS` interleaved rounds (method,
then reference, so a burst of load on the machine hits both) and each keeps its
minimum. The reference is timed two ways, the whole batch in one call and one
trial per call (a vectorised peer's whole batch can outgrow the caches its
per-trial use fits in), and keeps the faster (``reference_mode``). Times are the CPU time of the measuring thread (``time.thread_time``),
not wall time, so other processes on a shared machine cost little; the load
average is recorded with the machine. A reference may time parts of itself
apart (``Method.reference_parts``, e.g. a peer tracker's initiator): each part
gets a second row, the reference less that part, against the same method time.

Each measurement runs in a fresh process, so ``peak_rss_mb`` (the process's
maximum resident set size, including the interpreter, the libraries and the
batch, read before the reference first runs) is the method's alone, and runs
single-threaded (:data:`ONE_CORE`: numba, OpenMP, MKL and OpenBLAS held to one
thread), so every rate is per core. Every method counts its work in its own unit
(``Method.work(batch, params) -> (unit, count)``: trials by default, cells of a
CFAR map, DP state transitions), reported as ``<unit>_per_second`` beside
``trials_per_second``, and methods may declare ``Method.perf_targets``
(``speedup``, ``<unit>_per_second``, ``seconds_per_trial``), which the report
shows against the measurements. Before any method, the machine's limits are
measured the same way (:mod:`bench.run.limits`: memory bandwidth of a streaming
copy, the SIMD add/max rate of a tight loop), and each row shows its fraction
of them: the least time of what its run must at least move and compute
(``Method.least_cost``) at those limits over the time measured, or why no
honest model exists. The plugin protocol (:mod:`bench.core`) gives
every one of these a default, read here as "not provided".

Scene generation is measured too, in its own table: for every (scenario,
size) of every registered scenario (with ``--methods``, of the scenarios those
methods run on, at the sizes they accept), ``Scenario.generate`` of that many
trials (after a one-trial warm-up, best of a few repetitions, fresh process),
which is what every unit of a sweep pays before any method runs. A size that
reads a data file is timed on one the scenario writes into a temporary folder
(``Scenario.perf_data``); one that cannot be generated (a ``ConfigError``, e.g.
an optional extra's data absent) is reported with its reason, not timed. A
scenario may declare ``Scenario.perf_targets`` (``size -> {"seconds_per_trial": goal}``) for it.
Nothing here is asserted by tests: speed is measured, never a pass/fail gate.

Optionally (``--executors``) a compute-bound sweep, the packaged preset
``perf-scaling`` (``bench/presets/perf-scaling.toml``), is run with one local
worker, N local workers and N Dask workers, to measure the executors' scaling.
"""

from __future__ import annotations

import contextlib
import os
import platform
import resource
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from radarbench.bench.sweep import capabilities
from radarbench.bench.run import limits
from radarbench.bench import registry
from radarbench.bench.errors import ConfigError
from radarbench.bench.markdown import code, fmt, table, text
from radarbench.bench.params import build_params
from radarbench.bench.run.processes import call_in_fresh_process
from radarbench.bench.sweep.rng import EVALUATION, TrialRNG, stable_key
from radarbench.bench.results.tables import write_csv

PERF_COLUMNS = ["method", "size", "trials", "seconds_per_trial", "trials_per_second", "chunk",
                "chunk_seconds_per_trial", "reference",
                "reference_seconds_per_trial", "reference_mode", "speedup", "limit_fraction", "limit", "limit_note", "peak_rss_mb"]
SCENE_COLUMNS = ["scenario", "size", "trials", "seconds_per_trial", "peak_rss_mb", "skipped"]
SEED = 20261121
REPEATS = 3
#: interleaved rounds of a method and its reference (each keeps its minimum)
ROUNDS = 5
#: how a reference is timed (:func:`_reference_timing`): one call on the whole batch, or one per trial
REFERENCE_MODES = ("whole batch", "per trial")
#: a row's note when its method declares no least cost (``Method.least_cost`` returned None)
NO_MODEL = "no model declared (`Method.least_cost`)"
#: the environment of a measuring process: one thread per library, so a rate is per core
ONE_CORE = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


@dataclass(frozen=True)
class Job:
    method: str
    scenario: str
    size: str
    scenario_params: dict
    trials: int
    reference_trials: int    # trials of the batch the reference runs on; 0: the method alone
    chunk: int | None = None     # also time a batch of this many trials (a preset's chunk), or not


@dataclass(frozen=True)
class SceneJob:
    scenario: str
    size: str
    scenario_params: dict
    trials: int


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0   # Linux: kB


def _scenario(job: Job | SceneJob, folder: Path):
    """The job's scenario and its params, with the data files the size reads written into
    ``folder`` (:meth:`bench.core.Scenario.perf_data`)."""
    scenario = registry.get_scenario(job.scenario)()
    return scenario, build_params(type(scenario).Params, {**job.scenario_params,
                                                          **scenario.perf_data(job.size, folder)})


def _batch(job: Job | SceneJob, n: int, scenario, params, first: int = 0):
    """Trials ``first .. first + n - 1`` of the job's scenes (a trial is the same in any batch:
    its own stream)."""
    return scenario.generate(params, float(scenario.perf_snr_db), n, _trial_rng(job, n, first))


def _trial_rng(job: Job | SceneJob, n: int, first: int = 0) -> TrialRNG:
    return TrialRNG(SEED, EVALUATION, stable_key([job.scenario, job.scenario_params]), range(first, first + n))


def reference_of(method):
    """``(name, callable(batch, params))`` of the method's reference, or None
    when it declares none (:attr:`bench.core.Method.reference_name`)."""
    if method.reference_name is None:
        return None
    return method.reference_name, method.reference_run


def _cpu_seconds(fn) -> float:
    """CPU time of the calling thread spent in ``fn()`` (one thread: :data:`ONE_CORE`)."""
    t0 = time.thread_time()
    fn()
    return time.thread_time() - t0


def measure(job: Job) -> dict:
    """Run in a fresh process: CPU seconds per trial of the method and of its
    reference (min over :data:`ROUNDS` interleaved rounds, each after a one-trial
    warm-up), of the reference less each of its parts, and the peak RSS."""
    registry.discover()
    with tempfile.TemporaryDirectory() as folder:
        return _measure(job, *_scenario(job, Path(folder)))


def _measure(job: Job, scenario, scenario_params) -> dict:
    method = registry.get_method(job.method)()
    params = method.Params()

    def batch_of(n: int, first: int = 0):
        return _batch(job, n, scenario, scenario_params, first)

    def method_round() -> None:
        best["method"] = min(best["method"], _cpu_seconds(lambda: method.run(batch, params)))

    batch = batch_of(job.trials)
    unit, count = method.work(batch, params)
    out = {"name": None, "work_unit": unit, "work_per_trial": float(count) / job.trials,
           "reference_seconds_per_trial": np.nan, "reference_mode": "", "parts": {}}
    method.run(batch_of(1), params)
    outputs = []
    best = {"method": _cpu_seconds(lambda: outputs.append(method.run(batch, params)))}
    out["least_cost"] = method.least_cost(batch, params, outputs.pop())
    out["peak_rss_mb"] = _peak_rss_mb()                  # before the reference adds its own
    ref = reference_of(method) if job.reference_trials else None
    if ref is not None:
        out["name"], reference_run = ref
        whole, per_trial = REFERENCE_MODES
        calls = {whole: [batch_of(job.reference_trials)]}
        if job.reference_trials > 1:
            calls[per_trial] = [batch_of(1, first=i) for i in range(job.reference_trials)]
        try:
            reference_run(batch_of(1), params)
        except registry.PluginError as exc:       # an optional peer not installed: the row says so
            out["name"] = f"{out['name']}: not timed, {exc}"
            for _ in range(ROUNDS - 1):
                method_round()
            return _with_chunk(job, out, best, batch_of, method, params)
        out["reference_mode"], seconds, parts = _reference_timing(method, reference_run, params, calls, method_round)
        out["reference_seconds_per_trial"] = seconds / job.reference_trials
        out["parts"] = {part: spent / job.reference_trials for part, spent in parts.items()}
    else:
        for _ in range(ROUNDS - 1):
            method_round()
    return _with_chunk(job, out, best, batch_of, method, params)


def _with_chunk(job: Job, out: dict, best: dict, batch_of, method, params) -> dict:
    """``out`` with the method's seconds per trial, and per trial at the job's chunk when it has one."""
    out["chunk_seconds_per_trial"] = np.nan
    if job.chunk:      # the same batch cut to a preset's chunk: what a sweep's unit pays per trial
        chunk = batch_of(job.chunk)
        out["chunk_seconds_per_trial"] = min(_cpu_seconds(lambda: method.run(chunk, params))
                                             for _ in range(ROUNDS)) / job.chunk
    return {**out, "seconds_per_trial": best["method"] / job.trials}


def _reference_timing(method, reference_run, params, calls: dict[str, list], method_round):
    """``(mode, seconds, parts)``: the reference's least CPU seconds over :data:`ROUNDS` rounds
    in the faster of its ways to be called (``calls``: mode -> the batches of one call each,
    :data:`REFERENCE_MODES`), and of the reference less each of its parts in that mode. Each
    round times every mode, then the method (``method_round()``): interleaved."""
    best: dict[str, float] = {}
    parts: dict[str, dict[str, float]] = {mode: {} for mode in calls}
    for _ in range(ROUNDS):
        for mode, batches in calls.items():
            seconds, spent = _calls_seconds(method, reference_run, params, batches)
            best[mode] = min(best.get(mode, np.inf), seconds)
            for part, part_seconds in spent.items():
                parts[mode][part] = min(parts[mode].get(part, np.inf), seconds - part_seconds)
        method_round()
    mode = min(best, key=best.get)
    return mode, best[mode], parts[mode]


def _calls_seconds(method, reference_run, params, batches: list) -> tuple[float, dict[str, float]]:
    """CPU seconds of one ``reference_run`` per batch, summed, and of each of its parts
    (:attr:`bench.core.Method.reference_part_seconds`), summed over the calls."""
    total, parts = 0.0, {}
    for batch in batches:
        total += _cpu_seconds(lambda: reference_run(batch, params))
        for part, spent in (method.reference_part_seconds or {}).items():
            parts[part] = parts.get(part, 0.0) + spent
    return total, parts


def measure_scene(job: SceneJob) -> dict:
    """Run in a fresh process: seconds per trial of ``generate`` (best of REPEATS; the
    per-trial streams are set up outside the timing, and the warm-up reads the data a
    scenario caches per process), peak RSS; or, when the size cannot be generated
    (a ``ConfigError``), why (``skipped``)."""
    registry.discover()
    with tempfile.TemporaryDirectory() as folder:
        try:
            scenario, params = _scenario(job, Path(folder))
            _batch(job, 1, scenario, params)               # warm-up: JIT compilation, data read
        except ConfigError as err:
            return {"seconds_per_trial": np.nan, "peak_rss_mb": np.nan, "skipped": str(err)}
        best = np.inf
        for _ in range(REPEATS):
            rng = _trial_rng(job, job.trials)
            t0 = time.perf_counter()
            scenario.generate(params, float(scenario.perf_snr_db), job.trials, rng)
            best = min(best, time.perf_counter() - t0)
    return {"seconds_per_trial": best / job.trials, "peak_rss_mb": _peak_rss_mb(), "skipped": ""}


@contextlib.contextmanager
def _environment(values: dict[str, str]):
    """``os.environ`` updated with ``values`` inside the block (processes started there inherit it)."""
    saved = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _in_fresh_process(job: Job | SceneJob) -> dict:
    """``measure`` (or ``measure_scene``) in a fresh spawned process held to one core (:data:`ONE_CORE`)."""
    return _spawned(measure_scene if isinstance(job, SceneJob) else measure, job)


def _spawned(fn, *args) -> dict:
    """``fn(*args)`` in a fresh spawned process held to one core (:data:`ONE_CORE`;
    :func:`bench.run.processes.call_in_fresh_process`)."""
    with _environment(ONE_CORE):
        return call_in_fresh_process(fn, *args)


def machine_limits() -> dict:
    """The machine's limits (:func:`bench.run.limits.measure_limits`), in a fresh process held to one core."""
    return _spawned(limits.measure_limits)


def limit_columns(cost, seconds: float, machine: dict) -> dict:
    """A row's ``limit_fraction``, ``limit`` (the binding one's name) and ``limit_note`` (why
    there is none) from a method's declared least cost of a call taking ``seconds``."""
    if not isinstance(cost, dict):
        return {"limit_fraction": np.nan, "limit": "",
                "limit_note": cost or NO_MODEL}
    fraction, binding = limits.limit_fraction(cost, seconds, machine)
    return {"limit_fraction": fraction, "limit": binding, "limit_note": ""}


def accepted_sizes(method_cls, scenario) -> dict:
    """The perf sizes of ``scenario`` a method runs on: those whose resolved params fit its
    capabilities (:func:`bench.sweep.capabilities.fits`) and its default config's
    ``check_scenario`` accepts (none for a scenario of another task)."""
    if method_cls.task not in scenario.tasks:
        return {}
    method, params = method_cls(), build_params(method_cls.Params, {})
    sized = {size: (entry, build_params(scenario.Params, entry[0])) for size, entry in scenario.perf_sizes.items()}
    return {size: entry for size, (entry, resolved) in sized.items()
            if capabilities.fits(method_cls, scenario, resolved) and method.check_scenario(params, resolved) is None}


def perf_sizes_of(method_cls) -> tuple[type | None, dict]:
    """The scenario a method is timed on and its perf sizes the method accepts
    (:func:`accepted_sizes`): the first registered scenario with one; (None, {}) if none."""
    for scenario in registry.scenarios().values():
        accepted = accepted_sizes(method_cls, scenario)
        if accepted:
            return scenario, accepted
    return None, {}


def scene_sizes(methods: list[str] | None = None) -> dict[str, dict]:
    """Scenario name -> the perf sizes whose scene generation is timed: every size of every
    registered scenario, or with ``methods`` the sizes those methods accept
    (:func:`accepted_sizes`) on any scenario."""
    out = {}
    for name, scenario in registry.scenarios().items():
        if not methods:
            sizes = dict(scenario.perf_sizes)
        else:
            sizes = {}
            for method in methods:
                sizes |= accepted_sizes(registry.get_method(method), scenario)
        if sizes:
            out[name] = {size: scenario.perf_sizes[size] for size in scenario.perf_sizes if size in sizes}
    return out


def check_sizes(methods: list[str] | None, sizes: list[str] | None) -> None:
    """Raise ConfigError('--sizes', ...) naming an unknown size and the known ones (those
    :func:`scene_sizes` times: a method's sizes are among them), before anything is
    measured or written."""
    registry.discover()
    if not sizes:
        return
    known = sorted({size for sized in scene_sizes(methods).values() for size in sized})
    for size in sizes:
        if size not in known:
            raise ConfigError("--sizes", f"unknown size {size!r} (known: {', '.join(known) or 'none'})")


def preset_chunks() -> dict[str, int]:
    """Method name -> the smallest ``chunk`` among the packaged presets that run it: the
    batch size a sweep's units hand it, where a fixed cost per call weighs most per trial.
    Read from the presets' TOML as written (resolving a plan would read their data files)."""
    import tomllib

    from radarbench.bench.sweep.config import DEFAULT_CHUNK
    from radarbench.bench.sweep.listing import presets

    out: dict[str, int] = {}
    for path in presets().values():
        sweep = tomllib.loads(path.read_text(encoding="utf-8"))
        chunk = int(sweep.get("chunk", DEFAULT_CHUNK))
        for method in sweep.get("methods", []):
            out[method["name"]] = min(out.get(method["name"], chunk), chunk)
    return out


def jobs(methods: list[str] | None = None, sizes: list[str] | None = None) -> list[Job]:
    """A job for every method x its scenario's sizes, with the trials its reference runs on
    (0 when it declares none), each also timed at its presets' smallest chunk
    (:func:`preset_chunks`) when that is fewer trials."""
    check_sizes(methods, sizes)
    chunks = preset_chunks()
    out = []
    for name, cls in registry.methods().items():
        if methods and name not in methods:
            continue
        scenario, perf_sizes = perf_sizes_of(cls)
        for size, (params, trials) in perf_sizes.items():
            if sizes and size not in sizes:
                continue
            ref_trials = trials if cls.reference_trials is None else max(1, min(trials, cls.reference_trials))
            chunk = chunks.get(name)
            out.append(Job(name, scenario.name, size, dict(params), int(trials),
                           ref_trials if cls.reference_name is not None else 0,
                           chunk if chunk is not None and chunk < trials else None))
    return out


def scene_jobs(methods: list[str] | None = None, sizes: list[str] | None = None) -> list[SceneJob]:
    """One scene-generation job per (scenario, size) of :func:`scene_sizes`, in registry
    order, only ``sizes`` if given."""
    return [SceneJob(scenario, size, dict(params), int(trials))
            for scenario, sized in scene_sizes(methods).items()
            for size, (params, trials) in sized.items() if not sizes or size in sizes]


def measure_scenes(planned: list[SceneJob], progress=print) -> pd.DataFrame:
    rows = []
    for job in planned:
        progress(f"perf: {job.scenario} scene generation at {job.size} ({job.trials} trials)")
        m = _in_fresh_process(job)
        rows.append({"scenario": job.scenario, "size": job.size, "trials": job.trials, **m})
    return pd.DataFrame(rows, columns=SCENE_COLUMNS)


def run_perf(out_dir: Path, *, methods=None, sizes=None, executors: bool = False, workers: int = 2,
             progress=print) -> Path:
    rows, extra = [], []
    planned = jobs(methods, sizes)
    progress("perf: the machine's limits (streaming copy, add/max loop)")
    machine = machine_limits()
    for job in planned:
        progress(f"perf: {job.method} at {job.size} ({job.trials} trials)")
        m = _in_fresh_process(job)
        cls = registry.get_method(job.method)
        info = {"scenario": job.scenario, "params": job.scenario_params, "reference_trials": job.reference_trials,
                "targets": cls.perf_targets}
        references = [(m["name"] or "", m["reference_seconds_per_trial"])]
        references += [(f"{m['name']}, without its {cls.reference_parts[part]} (timed apart)", seconds)
                       for part, seconds in m["parts"].items()]
        fraction = limit_columns(m["least_cost"], m["seconds_per_trial"] * job.trials, machine)
        for name, seconds in references:
            rows.append({"method": job.method, "size": job.size, "trials": job.trials,
                         "seconds_per_trial": m["seconds_per_trial"], "trials_per_second": 1.0 / m["seconds_per_trial"],
                         "chunk": job.chunk, "chunk_seconds_per_trial": m["chunk_seconds_per_trial"],
                         "reference": name, "reference_seconds_per_trial": seconds,
                         "reference_mode": m["reference_mode"],
                         "speedup": seconds / m["seconds_per_trial"] if np.isfinite(seconds) else np.nan,
                         **fraction, "peak_rss_mb": m["peak_rss_mb"],
                         f"{m['work_unit']}_per_second": m["work_per_trial"] / m["seconds_per_trial"]})
            extra.append(info)
    scenes = measure_scenes(scene_jobs(methods, sizes), progress)
    scaling, sweep = None, ""
    if executors:
        plan = scaling_plan()
        scaling, sweep = executor_scaling(workers, progress, plan), f"Preset {code(plan.name)}: {plan.description}"
    return write_report(Path(out_dir), perf_table(rows), extra, scaling, sweep, scenes, machine)


def perf_table(rows: list[dict]) -> pd.DataFrame:
    """The rows of ``perf.csv``: :data:`PERF_COLUMNS`, then one ``<unit>_per_second``
    column per other work unit the methods reported (:meth:`bench.core.Method.work`;
    empty where a method counts another unit)."""
    units = sorted({key for row in rows for key in row if key.endswith("_per_second")} - set(PERF_COLUMNS))
    return pd.DataFrame(rows, columns=PERF_COLUMNS + units)


def rate_columns(perf: pd.DataFrame) -> list[str]:
    """The ``<unit>_per_second`` columns of a perf table, trials first."""
    return [column for column in perf.columns if column.endswith("_per_second")]


# ------------------------------------------------------------------ executors

#: the packaged preset (``bench/presets/``) that ``--executors`` times
SCALING_PRESET = "perf-scaling"


def scaling_plan():
    """The executor-scaling sweep, packaged as preset :data:`SCALING_PRESET`
    (the harness names no plugin itself)."""
    import importlib.resources

    from radarbench.bench.sweep.config import parse_sweep_text
    path = importlib.resources.files("radarbench.bench") / "presets" / f"{SCALING_PRESET}.toml"
    return parse_sweep_text(path.read_bytes(), f"preset {SCALING_PRESET}")


def executor_scaling(workers: int, progress=print, plan=None) -> pd.DataFrame:
    """Wall time of one compute-bound sweep (``plan``, default
    :func:`scaling_plan`) per executor (units only, no report)."""
    import tempfile

    from radarbench.bench.run.runner import plan_record, run_sweep
    plan = scaling_plan() if plan is None else plan
    rows = []
    for executor, n in (("local", 1), ("local", workers), ("dask", workers)):
        progress(f"perf: scaling sweep with {executor} x {n}")
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            try:
                store = run_sweep(plan, Path(tmp), plan_record=plan_record(plan, "bench perf"), workers=n,
                                  executor=executor, quiet=True, cache=False)   # timed: every unit computed
                store.close()
            except Exception as exc:  # noqa: BLE001 - e.g. dask not installed: reported, not fatal
                rows.append({"executor": executor, "workers": n, "seconds": np.nan, "error": str(exc)})
                continue
            rows.append({"executor": executor, "workers": n, "seconds": time.perf_counter() - t0, "error": ""})
    df = pd.DataFrame(rows)
    base = df.seconds.iloc[0]
    df["speedup"] = base / df.seconds
    df["efficiency"] = df.speedup / df.workers
    return df


# ------------------------------------------------------------------ report

def _verdict(value: float, ok: bool) -> str:
    """✓ or ✗, or *not measured* for a value that is not there (a reference not installed)."""
    return ("✓" if ok else "✗") if np.isfinite(value) else "not measured"


def _target_text(targets: dict, row: dict) -> str:
    checks = []
    for key, goal in targets.items():
        if key == "speedup":
            value = row["speedup"]
            checks.append(f"speed-up ≥ {goal:g}: {fmt(value)} {_verdict(value, value >= goal)}")
        elif key.endswith("_per_second"):
            rate = row.get(key, np.nan)
            ok = bool(np.isfinite(rate) and rate >= goal)
            checks.append(f"≥ {goal:.0e} {key.removesuffix('_per_second')}/s: {rate:.2e} {'✓' if ok else '✗'}")
        elif key == "seconds_per_trial":
            value = row["seconds_per_trial"]
            checks.append(f"≤ {goal:g} s/trial: {fmt(value)} {'✓' if value <= goal else '✗'}")
    return "; ".join(checks) or "–"


def prepare_out(out_dir: Path) -> Path:
    """Check and create the output folder before anything is measured: one line (exit 2)
    when it is a file or lies under one, exit 3 when the machine refuses."""
    from radarbench.bench.errors import ConfigError
    from radarbench.bench.results.runfolder import folder_for, probe
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError("--out", f"{out_dir} exists and is not a folder")
    folder_for(out_dir)
    probe(out_dir)
    return out_dir


def _scene_section(scenes: pd.DataFrame) -> list[str]:
    rows = []
    for r in scenes.to_dict("records"):
        cls = registry.scenarios().get(r["scenario"])
        targets = cls.perf_targets if cls is not None else {}
        goal = targets.get(r["size"], targets.get("*", {}))
        if isinstance(r.get("skipped"), str) and r["skipped"]:
            rows.append([code(r["scenario"]), r["size"], r["trials"], "–", "–", f"not timed: {text(r['skipped'])}"])
            continue
        rows.append([code(r["scenario"]), r["size"], r["trials"], f"{r['seconds_per_trial'] * 1e3:.3g}",
                     f"{r['peak_rss_mb']:.0f}", _target_text(goal, r)])
    return ["## Scene generation", "`Scenario.generate` alone (the scene every unit of a sweep draws before "
            "its methods run), at each perf size of every scenario (of the scenarios the methods measured run "
            "on, with `--methods`): one core, fresh process, best of 3 runs after a one-trial warm-up (which "
            "reads what a scenario caches once per worker, e.g. a tracks file; a size that reads a file reads "
            "one its scenario writes, `Scenario.perf_data`); `scene.csv` holds the same numbers.",
            table(["scenario", "size", "trials", "ms per trial", "peak RSS (MB)", "targets"], rows)]


def _chunk_text(row: dict) -> str:
    """Per-trial time at the presets' smallest chunk and its ratio to the large batch's, or –."""
    at_chunk = row.get("chunk_seconds_per_trial", np.nan)
    if not (isinstance(at_chunk, float) and np.isfinite(at_chunk)):
        return "–"
    return f"{at_chunk * 1e3:.3g} ({int(row['chunk'])} trials; ×{at_chunk / row['seconds_per_trial']:.2g})"


def _reference_calls(row: dict, info: dict) -> str:
    """How the reference's time was taken: its trials and, when it had two ways, the faster one."""
    mode = row.get("reference_mode")
    return f"{info['reference_trials']} trials" + (f", {mode}" if isinstance(mode, str) and mode else "")


def _limits_text(machine: dict) -> str:
    """The header's paragraph: the limits measured at the start of the run, and the fraction column."""
    cache = machine.get("last_level_cache_bytes")
    cache_text = f"the last-level cache's {cache / 2**20:.0f} MiB" if cache else "a last-level cache it could not read"
    return (f"Machine limits, measured at the start of this run the same way (one core, fresh process, the "
            f"minimum CPU time over {limits.ROUNDS} rounds; `limits.csv` holds them): memory bandwidth "
            f"{machine['bytes_per_second'] / 1e9:.3g} GB/s (bytes read plus written by `np.copyto` of "
            f"{machine['stream_bytes'] / 2**20:.0f} MiB into another array, no less than {cache_text}); add/max "
            f"rate {machine['float32_operations_per_second'] / 1e9:.3g} G float32 and "
            f"{machine['float64_operations_per_second'] / 1e9:.3g} G float64 operations/s (a compiled loop "
            f"`acc[i] = max(acc[i], x[i] + c)` over {limits.IN_CACHE_BYTES >> 10} KiB arrays in the "
            "first-level cache). The column \"of the machine's limit\" is the least time of what the method's "
            "run must at least move and compute on the batch (`Method.least_cost`: bytes read and written "
            "once, the adds and maxima its algorithm cannot avoid; each method's model is a comment at its "
            "declaration) at these limits, the larger of the two (a roofline), over the time measured, with "
            "the limit that binds; a batch whose data stay in a cache can pass 1 against memory bandwidth. "
            "A row without an honest model says why in the notes below the table.")


def _fraction_cell(row: dict, notes: list[str]) -> str:
    """``0.12 (memory bandwidth)``, or a dash pointing at the note (added to ``notes``) saying why none."""
    fraction = row.get("limit_fraction", np.nan)
    if isinstance(fraction, float) and np.isfinite(fraction):
        return f"{fraction:.2g} ({limits.LIMIT_NAMES[row['limit']]})"
    note = row.get("limit_note")
    note = note if isinstance(note, str) and note else NO_MODEL
    if note not in notes:
        notes.append(note)
    return f"— (note {notes.index(note) + 1})"


def write_report(out_dir: Path, perf: pd.DataFrame, extra: list[dict], scaling: pd.DataFrame | None,
                 scaling_sweep: str = "", scenes: pd.DataFrame | None = None, machine: dict | None = None) -> Path:
    """``perf.csv``, ``scene.csv``, ``limits.csv`` and ``report.md``; ``scaling_sweep`` describes the
    sweep ``scaling`` timed, ``machine`` holds the limits measured (:func:`machine_limits`)."""
    from radarbench.bench.results.provenance import provenance
    prepare_out(out_dir)
    write_csv(perf, out_dir / "perf.csv")
    if scenes is not None:
        write_csv(scenes, out_dir / "scene.csv")
    if machine is not None:
        write_csv(pd.DataFrame([machine]), out_dir / "limits.csv")
    rows, rates, notes = [], rate_columns(perf), []
    for row, info in zip(perf.to_dict("records"), extra):
        targets = info["targets"].get(row["size"], info["targets"].get("*", {}))
        rows.append([code(row["method"]), row["size"], row["trials"], f"{row['seconds_per_trial'] * 1e3:.3g}",
                     _chunk_text(row),
                     *("–" if not np.isfinite(row[rate]) else f"{row[rate]:.3g}" for rate in rates),
                     text(row["reference"]) if row["reference"] else "–",      # a plugin's words
                     "–" if not np.isfinite(row["reference_seconds_per_trial"])
                     else f"{row['reference_seconds_per_trial'] * 1e3:.3g} ({_reference_calls(row, info)})",
                     fmt(row["speedup"]), _fraction_cell(row, notes), f"{row['peak_rss_mb']:.0f}",
                     _target_text(targets, row)])
    parts = ["# Performance", "Written by `bench perf`; `perf.csv` holds the same numbers. One core per "
             "measurement (a fresh process, numba, OpenMP, MKL and OpenBLAS held to one thread); times are "
             f"the CPU time of that thread, the minimum over {ROUNDS} rounds in which the method and its "
             "reference (on the reference's trials, same process) run in turn, each after a one-trial "
             "warm-up (JIT compilation is not timed); the reference both on its whole batch in one call and "
             "one trial per call, the faster kept (named in its column: a vectorised peer's whole batch can "
             "outgrow the caches one trial fits in); the method also at the smallest chunk of the presets "
             "that run it (the batch a sweep's unit hands it; × its per-trial time over the large batch's: "
             "the fixed cost per call). A reference timed with a part apart (a peer tracker's "
             "initiator) has a second row: the reference less that part. Rates are per core: trials per "
             "second, and each method's own work unit per second (`Method.work`: cells of a CFAR map, DP "
             "state transitions). Peak RSS is the whole measuring process's (interpreter and libraries "
             "included) before the reference runs.",
             _limits_text(machine) if machine is not None else "",
             table(["method", "size", "trials", "ms per trial", "ms per trial at a preset's chunk",
                    *(f"{rate.removesuffix('_per_second')}/s per core" for rate in rates), "reference",
                    "reference ms per trial", "speed-up", "of the machine's limit", "peak RSS (MB)", "targets"],
                   rows),
             "Notes: " + "; ".join(f"({i}) {note}" for i, note in enumerate(notes, 1)) if notes else "",
             "Sizes: " + "; ".join(sorted({f"{code(i['scenario'])} {r['size']} = {i['params'] or 'defaults'}"
                                          for r, i in zip(perf.to_dict("records"), extra)}))]
    if scenes is not None and len(scenes):
        parts += _scene_section(scenes)
    if scaling is not None:
        srows = [[r.executor, r.workers, fmt(r.seconds), fmt(r.speedup), fmt(r.efficiency), r.error or ""]
                 for r in scaling.itertuples()]
        parts += ["## Executor scaling", f"{scaling_sweep} Wall time of the units including the executor's "
                  "start-up (a Dask `LocalCluster` takes a few seconds); speed-up against one local worker. "
                  "Target for Dask: ≥ 0.8·N on N local workers.",
                  table(["executor", "workers", "seconds", "speed-up", "speed-up / workers", "error"], srows)]
    prov = provenance()
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    parts.append("## Machine\n\n" + table(["", ""], [["CPU count", os.cpu_count()], ["platform", platform.platform()],
                                                    ["python", platform.python_version()],
                                                    ["load average (1, 5, 15 min) at the end", load]] +
                                          [[k, v] for k, v in prov.items()]))
    from radarbench.bench.results.runfolder import write_text
    return write_text(out_dir / "report.md", "\n\n".join(part for part in parts if part) + "\n")
