"""Stage ``cli/`` of the harness. The `bench` command and its commands that are no stage of
their own: `bench list`, `bench perf`, the documentation site's generated pages.

It may import the top modules of ``bench/``, ``tasks/`` and ``recording/``, and the stages
``sweep/``, ``results/``, ``run/``, ``report/``; no stage imports it (docs/architecture.md,
'Layout'; tests/test_layout.py holds it).

The ``bench`` command: ``list``, ``run``, ``report``, ``view``, ``compare``, ``export``, ``perf``.

Arguments are checked before anything heavy is imported: the parser, ``--version``,
the preset names and ``bench list``'s presets need no plugin, NumPy or pandas, and
``bench list`` reads its plugin listing from a cache (:mod:`bench.sweep.listing`), so they
answer in a fraction of a second. Run outputs go to ``runs/<name>/`` unless ``--out``
says otherwise (git ignores ``runs/``; committed reports are written with ``--out
reports/NAME``).

Every fault ends with one line on stderr (``error: WHERE: PROBLEM``), never a
traceback, and an exit code (:data:`EXIT_CODES`): 2 for bad input (before anything
is written), 3 when the machine refuses (file system, disk, store), 4 when another
bench holds the run folder, 6 when a run's folder holds failed units (after a summary of
them on stderr), 130 on Ctrl-C.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import shlex
import sqlite3
import sys
import threading
import time
import traceback
from pathlib import Path

from radarbench.bench import __version__
from radarbench.bench.errors import (EXIT_BAD_INPUT, EXIT_BUG, EXIT_ENVIRONMENT, EXIT_FAILED_UNITS, EXIT_IN_USE, EXIT_INTERRUPTED,
                          EXIT_REGRESSION, ConfigError, Fault, is_out_of_memory, os_fault, unknown_name)
from radarbench.bench.results import runfolder
from radarbench.bench.sweep.listing import plugin_listing, preset_descriptions, presets
from radarbench.bench.run.progress import notices_of_one_command

EXIT_CODES = f"""exit codes:
  0    done
  {EXIT_BUG}    a bug in bench or a plugin (one line; BENCH_TRACEBACK=1 shows the traceback)
  {EXIT_BAD_INPUT}    bad input: the command line, the sweep file, or the folder named (a file, a name
       too long, a non-empty folder that holds no bench run, a results.sqlite that is not
       a bench store, a symbolic link inside the run folder);
       nothing is written
  {EXIT_ENVIRONMENT}    the machine refused: permission denied, read-only file system, disk full,
       file-size limit, I/O error, out of memory; nothing is half-written, and the same command
       resumes once the cause is fixed
  {EXIT_IN_USE}    the run folder is in use by another bench run or report
  {EXIT_REGRESSION}    bench compare --fail-on-regression: a method config got significantly worse
  {EXIT_FAILED_UNITS}    bench run: the run folder holds failed (unit, method config) runs; the report
       is written, stderr ends with each failing config and its first cause
       (bench report DIR --tracebacks prints the tracebacks)
  {EXIT_INTERRUPTED}  interrupted (Ctrl-C); the same command resumes
"""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2 (argparse prints usage + message)
        raise ConfigError("", f"{self.prog}: {message}")


#: Where ``bench run`` writes unless ``--out`` is given (git-ignored).
RUNS_DIR = Path("runs")
#: Where ``bench export RUN`` writes unless ``--out`` is given: a folder of the run folder.
EXPORT_DIR = "tidy"


def _int_in(lo: int, hi: int, what: str = "", note: str = ""):
    """An argparse type: a whole number in [lo, hi]."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a {what or 'whole number'}, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"expected {lo} to {hi}{note}, got {value}")
        return value
    return parse


_positive_int = _int_in(1, 1024)
_port = _int_in(1024, 65534, "port number", " (the next port is the gRPC server's)")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="bench", description="Benchmark radar maneuver detectors, trackers and TBD methods.",
                epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--version", action="version", version=f"bench {__version__} (radar-maneuver-bench)")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    ls = sub.add_parser("list", help="presets, tasks, methods and scenarios, with their summaries")
    ls.add_argument("-v", "--verbose", action="store_true", help="show every parameter with its default")
    run = sub.add_parser("run", help="run (or resume) a sweep")
    run.add_argument("sweep", nargs="?", help="sweep file (TOML)")
    run.add_argument("--preset", help=f"a packaged sweep: {', '.join(presets())} (bench list describes them)")
    run.add_argument("--out", help=f"run folder (default: {RUNS_DIR}/<name>/): new, empty, or a run folder; "
                                   "one run at a time")
    run.add_argument("--workers", type=_positive_int,
                     help="worker processes, for the units and then the report's figures (default: CPU count)")
    run.add_argument("--executor", default="local", choices=["local", "dask"],
                     help="where units run: local processes, or a dask cluster (needs the [dask] extra)")
    run.add_argument("--scheduler", metavar="ADDRESS",
                     help="with --executor dask: an existing cluster's scheduler, tcp://HOST:8786 "
                          "(default: a local cluster of --workers processes)")
    run.add_argument("--retry-failed", action="store_true",
                     help="also re-run the (unit, method config) pairs whose run failed")
    run.add_argument("--fresh", action="store_true",
                     help="discard stored results and start over (removes only the files listed in the "
                          "folder's bench-manifest.txt)")
    run.add_argument("--quiet", action="store_true",
                     help="no progress (a bar on a terminal, else a line per phase and every 10 s)")
    run.add_argument("--no-record", action="store_true", help="do not write recording.rrd")
    run.add_argument("--no-cache", action="store_true",
                     help="neither take results from the user's results cache nor keep this run's there "
                          "(~/.cache/radar-maneuver-bench/results, or $BENCH_RESULTS_CACHE_DIR)")
    run.add_argument("--viewer", action="store_true", help="stream trials live to a spawned Rerun viewer")
    run.add_argument("--yes", action="store_true", help="run a very large sweep without asking")
    over = run.add_argument_group("changes to the sweep (checked like the sweep file; plan.toml keeps the result)")
    over.add_argument("--methods", nargs="+", metavar="NAME",
                      help="only these methods: names or config labels of the sweep's [[methods]] (all their "
                           "configs), or any registered method at its defaults")
    over.add_argument("--scenarios", nargs="+", metavar="NAME",
                      help="only these scenarios: names or labels of the sweep's, or any registered one at its defaults")
    over.add_argument("--snr", nargs="+", type=float, metavar="DB", help="these SNR levels (dB), for every scenario")
    over.add_argument("--trials", type=int, metavar="N", help="trials per SNR level, for every scenario")
    over.add_argument("--seed", type=int, metavar="N", help="the sweep's seed")
    over.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="sets",
                      help="any key of the sweep, dotted (calibration.h0_trials=500, scenario_params.steps=200, "
                           "methods.0.params.window=8); VALUE is a TOML value; repeatable")
    rep = sub.add_parser("report", help="rebuild CSV, figures, report.md and recording from results.sqlite")
    rep.add_argument("dir")
    rep.add_argument("--no-record", action="store_true", help="do not rewrite recording.rrd")
    rep.add_argument("--tracebacks", action="store_true",
                     help="print the stored traceback of every failed run instead (writes nothing)")
    cmp = sub.add_parser("compare", help="differences between two run folders, with intervals "
                                         "(paired when they share trials)")
    cmp.add_argument("run_a", metavar="RUN_A", help="run folder A (e.g. before a change)")
    cmp.add_argument("run_b", metavar="RUN_B", help="run folder B (e.g. after it)")
    cmp.add_argument("--out", help="also write compare.csv, compare_summary.csv and compare.md into this folder")
    cmp.add_argument("--fail-on-regression", action="store_true",
                     help=f"exit {EXIT_REGRESSION} when a method config got significantly worse, ran in A and "
                          "failed in B, or is not comparable (for CI)")
    exp = sub.add_parser("export", help="a run's summary (one row per metric), trials and calibration as tidy "
                                        "tables with a typed column per parameter")
    exp.add_argument("run", metavar="RUN", help="a run folder or a committed reports/NAME folder")
    exp.add_argument("--format", required=True, choices=["parquet", "csv"], help="the files' format")
    exp.add_argument("--out", help=f"folder to write summary, trials and calibration into "
                                   f"(default: RUN/{EXPORT_DIR}/)")
    view = sub.add_parser("view", help="open a run's recording in the Rerun viewer (--web: in a browser)")
    view.add_argument("dir")
    view.add_argument("--web", action="store_true",
                      help="serve the recording to a browser on 127.0.0.1 and print the URL (no display needed)")
    view.add_argument("--port", type=_port, default=9090, help="--web: the web viewer's HTTP port (default 9090; "
                                                               "the gRPC server takes the next one)")
    view.add_argument("--renderer", choices=["webgl", "webgpu"], default="webgl",
                      help="--web: the browser's graphics backend (default webgl: works without WebGPU)")
    data = sub.add_parser("data", help="public data the scenarios read by default")
    data_verbs = data.add_subparsers(dest="data_command", required=True, parser_class=_Parser)
    fetch = data_verbs.add_parser("fetch", help="download it into the user's data folder, checked by its hash "
                                                "(the real-trajectories preset's ADS-B samples)")
    fetch.add_argument("--from", dest="source", metavar="FILE",
                       help="a file already downloaded (e.g. the wheel, on a machine offline): checked, then used")
    perf = sub.add_parser("perf", help="measure every method's speed and memory against its reference, "
                                       "and scene generation")
    perf.add_argument("--out", default=str(RUNS_DIR / "perf"),
                      help=f"output folder (default: {RUNS_DIR / 'perf'}; the committed one: reports/perf)")
    perf.add_argument("--methods", nargs="+", help="only these methods")
    perf.add_argument("--sizes", nargs="+", help="only these named sizes (e.g. small paper)")
    perf.add_argument("--executors", action="store_true",
                      help="also time one compute-bound sweep per executor (local x1, local xN, dask xN)")
    perf.add_argument("--workers", type=_positive_int, help="N for --executors (default: CPU count)")
    return p


# ------------------------------------------------------------------ commands

def cmd_list(args) -> int:
    print("presets (bench run --preset NAME):")
    for name, description in preset_descriptions():
        print(f"  {name:<20} {description}")
    print(plugin_listing(args.verbose), flush=True)
    return 0


def _overrides(args):
    from radarbench.bench.sweep.config import Overrides
    return Overrides(tuple(args.methods or ()), tuple(args.scenarios or ()), tuple(args.snr or ()), args.trials,
                     args.seed, tuple(args.sets))


def _sweep_data(args) -> tuple[dict, str, Path]:
    """(the sweep as data with the command line's changes, where it came from, its folder),
    its own fields checked (:func:`bench.sweep.config.check_sweep_fields`): no plugin, no NumPy yet."""
    from radarbench.bench.sweep.config import apply_overrides, check_sweep_fields, read_sweep_file, sweep_data
    if args.preset:
        source, preset = f"preset {args.preset}", presets()[args.preset]
        folder = Path(str(preset)).parent
        with _named(source, None):
            data = sweep_data(preset.read_bytes())
    else:
        source, folder = args.sweep, Path(args.sweep).parent
        with _named(source, None):
            data = sweep_data(read_sweep_file(args.sweep))
    overrides = _overrides(args)
    with _named(source, overrides):
        data = apply_overrides(data, overrides)
        check_sweep_fields(data)
    return data, source, folder


@contextlib.contextmanager
def _named(source: str, overrides):
    """A ConfigError raised inside, prefixed with where its field came from: the option of
    the command line that wrote it, or the sweep's source."""
    try:
        yield
    except ConfigError as err:
        field = err.field
        origin = overrides.origin(field) if overrides is not None and field else None
        if field.startswith("--"):                        # the command line's own words
            where = field
        else:
            where = origin or (f"{source}: {field}" if field else source)
        raise ConfigError(where, err.problem) from None


def _check_names(args, data: dict, source: str, fingerprint: str | None) -> None:
    """The sweep's plugin names checked before the plugins are imported, against the names
    a process that imported them kept for this ``fingerprint`` of the plugins' sources
    (:func:`bench.sweep.listing.cached_names`; None: this process has them already)."""
    from radarbench.bench import registry
    from radarbench.bench.sweep.config import check_names
    from radarbench.bench.sweep.listing import cached_names
    table = registry.names() if fingerprint is None else cached_names(fingerprint)
    if table is not None:
        with _named(source, _overrides(args)):
            check_names(data, lambda kind, name: registry.absent_from(table, kind, name))


def _load_plan(args, data: dict, source: str, folder: Path, fingerprint: str | None):
    """The plan; the plugins' names kept for :func:`_check_names` (under ``fingerprint``,
    taken before they were imported) once they are."""
    from radarbench.bench import registry
    from radarbench.bench.sweep.config import parse_sweep
    from radarbench.bench.sweep.listing import keep_names
    overrides = _overrides(args)
    try:
        with _named(source, overrides):
            return parse_sweep(data, source, allow_large=args.yes, base=folder,
                               drop_idle_scenarios=bool(overrides.methods) and not overrides.scenarios)
    finally:
        if fingerprint is not None and registry.discovered():
            keep_names(fingerprint)


def _command_line(args) -> str:
    words = ["bench", "run"] + (["--preset", args.preset] if args.preset else [args.sweep])
    for option, values in (("--methods", args.methods), ("--scenarios", args.scenarios),
                           ("--snr", [f"{v:g}" for v in args.snr or ()]), ("--trials", args.trials),
                           ("--seed", args.seed)):
        if values not in (None, []):
            words += [option, *map(str, values if isinstance(values, list) else [values])]
    for assignment in args.sets:
        words += ["--set", assignment]
    if args.out:
        words += ["--out", args.out]
    return shlex.join(words)


def _check_arguments(args) -> None:
    """What the command line alone decides, before the sweep (and NumPy) is loaded."""
    if args.sweep and args.preset:
        raise ConfigError("", f"{args.sweep!r} and --preset {args.preset}: give a sweep file or --preset NAME, "
                              "not both (methods are chosen with --methods, scenarios with --scenarios)")
    if not args.sweep and not args.preset:
        eaten = [v for v in (args.methods or []) + (args.scenarios or []) if v.endswith(".toml") or os.path.isfile(v)]
        hint = f" ({eaten[0]!r} was read as a name of --methods/--scenarios: put the sweep file first)" if eaten else ""
        raise ConfigError("", f"give a sweep file or --preset NAME (one of them){hint}")
    if args.preset and args.preset not in presets():
        raise ConfigError("--preset", unknown_name("preset", args.preset, presets()))
    if args.scheduler is not None and args.executor != "dask":
        raise ConfigError("--scheduler", "only with --executor dask")
    if not args.no_cache:
        from radarbench.bench.run.results_cache import bound_bytes
        bound_bytes()          # a bad size bound in the environment: one line, before anything runs


def _workers(args) -> int:
    from radarbench.bench.run.processes import default_workers
    return args.workers or default_workers()


def _check_executor(args) -> None:
    """Executor options, checked before anything is written."""
    if args.executor == "dask":
        from radarbench.bench.run.executors import require_dask
        require_dask()


def _stored_units(plan, out_dir: Path) -> tuple[int, int]:
    """(units stored in ``out_dir``, units of the plan)."""
    from radarbench.bench.run.runner import plan_units
    from radarbench.bench.results.store import Store
    total = sum(map(len, plan_units(plan)))
    if not (out_dir / "results.sqlite").exists():
        return 0, total
    store = Store(out_dir / "results.sqlite")
    try:
        return len(store.done_units()), total
    finally:
        store.close()


def _interrupted(out_dir: Path, command: str, stored: int, total: int) -> int:
    """Ctrl-C: what is kept and how to go on, in one line (the last one on stderr)."""
    report = "; the report is not written" if stored >= total else ""
    print(f"interrupted: {stored} of {total} units stored in {out_dir}{report}; "
          f"run the same command again to resume (`{command}`)", file=sys.stderr)
    return EXIT_INTERRUPTED


@contextlib.contextmanager
def _store_errors(out_dir: Path):
    """SQLite failures as one line naming the store (bench.results.store.store_fault)."""
    try:
        yield
    except sqlite3.Error as exc:
        from radarbench.bench.results.store import store_fault
        raise store_fault(out_dir / "results.sqlite", exc) from None


def cmd_run(args) -> int:
    started_ns = time.time_ns()
    _check_arguments(args)
    data, source, folder = _sweep_data(args)
    from radarbench.bench import registry
    from radarbench.bench.sweep.listing import fingerprint
    plugins = None if registry.discovered() else fingerprint()    # of the plugins' sources, before they load
    _check_names(args, data, source, plugins)
    _check_executor(args)
    out_dir = Path(args.out) if args.out else RUNS_DIR / data["name"]
    command = _command_line(args)
    key = _unchanged_key(args, command, data, source, folder, plugins)
    if key is not None and _nothing_to_do(args, out_dir, data["name"], key):
        return 0
    if args.executor == "local":
        from radarbench.bench.run.processes import prestart_forkserver
        prestart_forkserver()
    plan = _load_plan(args, data, source, folder, plugins)
    said = _skipped_lines(plan)
    if not args.quiet:
        for line in said:
            print(line, file=sys.stderr)
    created = not os.path.lexists(out_dir)
    lock = runfolder.open_for_run(out_dir, fresh=args.fresh, what=f"bench run, {plan.name}")
    try:
        with runfolder.writing(out_dir), _store_errors(out_dir):
            code = _run_locked(args, plan, out_dir, command)
            if code == 0 and key is not None:
                _remember_unchanged(plan, out_dir, key, started_ns, said)
            return code
    except BaseException as exc:
        refused = isinstance(exc, (ConfigError, Fault, OSError, sqlite3.Error, MemoryError)) or is_out_of_memory(exc)
        if created and refused:
            runfolder.discard_new(out_dir)      # a folder this command made, if it holds no result
        raise
    finally:
        lock.release()


def _skipped_lines(plan) -> list[str]:
    """What a run says of the (scenario config, method config) pairs its plan skips."""
    if not plan.skipped:
        return []
    return [f"skipping {len(plan.skipped)} (scenario config, method config) pairs the method refuses:"] + \
        [f"  {method} on {scenario}: {reason}" for scenario, method, reason in plan.skipped]


def _unchanged_key(args, command: str, data: dict, source: str, folder: Path, plugins: str | None) -> str | None:
    """The key of this run for :mod:`bench.results.unchanged`; None where no answer from
    the folder's record may stand in for the run (``--fresh``, ``--viewer``, plugins
    registered in this process)."""
    if args.fresh or args.viewer or plugins is None:
        return None
    from radarbench.bench.results import unchanged
    return unchanged.run_key(command=command, data=data, source=source, folder=folder, plugins=plugins,
                             recording=not args.no_record, allow_large=args.yes)


def _nothing_to_do(args, out_dir: Path, name: str, key: str) -> bool:
    """A run of ``key`` into ``out_dir`` that would find every unit stored and the report
    current says so as such a run does, and ends there: no plugin, no worker, no report
    module is loaded (:mod:`bench.results.unchanged`)."""
    from radarbench.bench.results import unchanged
    if not os.path.isfile(out_dir / runfolder.STORE):
        return False
    with runfolder.open_for_run(out_dir, fresh=False, what=f"bench run, {name}"), _store_errors(out_dir):
        record = unchanged.settled(out_dir, key)
    if record is None:
        return False
    if not args.quiet:
        for line in record["said"]:
            print(line, file=sys.stderr)
        print(f"Nothing to run: all {record['units']} units stored in {out_dir}", file=sys.stderr)
    print(f"the report is up to date: {out_dir / 'report.md'}")
    return True


def _remember_unchanged(plan, out_dir: Path, key: str, started_ns: int, said: list[str]) -> None:
    """After a run that succeeded: what the next one needs to see that nothing changed
    (:func:`bench.results.unchanged.remember`)."""
    from radarbench.bench import registry
    from radarbench.bench.results import unchanged
    from radarbench.bench.run.identity import files_read
    data = [path for configs, find in ((plan.scenarios, registry.get_scenario), (plan.methods, registry.get_method))
            for config in configs for path in find(config.name)().data_files(config.params)]
    unchanged.remember(out_dir, key, started_ns, [*files_read(), *data], said)


def _import_early(module: str) -> None:
    """Import ``module`` in a background thread: the report's modules (pandas, matplotlib,
    Jinja2: seconds) load while the workers run the units. A failure here is not lost: the
    import after the units raises it again."""
    with contextlib.suppress(Exception):
        importlib.import_module(module)


def _run_locked(args, plan, out_dir: Path, command: str) -> int:
    """The run, in the locked folder."""
    from radarbench.bench import registry
    from radarbench.bench.results import unchanged
    unchanged.forget(out_dir)              # before anything in the folder changes: no stale record survives
    from radarbench.bench.run.progress import Progress
    from radarbench.bench.run.runner import Interrupted, plan_record, run_sweep, write_plan_toml
    threading.Thread(target=_import_early, args=("radarbench.bench.report",), daemon=True,
                     name="bench-import-report").start()
    viewer = None
    if args.viewer:
        from radarbench.bench.recording import LiveViewer
        tasks = {m.label: registry.get_task(task) for m, task in zip(plan.methods, plan.method_tasks)}
        try:
            viewer = LiveViewer(tasks=tasks, application_id=plan.name,
                                recording_id=f"{plan.name}-{plan.fingerprint()}",
                                recording_name=f"{plan.name} · {plan.fingerprint()[:12]} (live)")
        except RuntimeError as exc:
            raise ConfigError("--viewer", str(exc)) from None
    on_result = None
    if viewer is not None:
        from radarbench.bench.recording import TrialRecord

        def on_result(result):
            viewer.log_records([TrialRecord.from_bytes(b) for _, b in result.records])
    progress = Progress(quiet=args.quiet)
    try:
        store = run_sweep(plan, out_dir, plan_record=plan_record(plan, command), workers=_workers(args),
                          executor=args.executor, fresh=False, quiet=args.quiet, on_result=on_result,
                          scheduler=args.scheduler, retry_failed=args.retry_failed, progress=progress,
                          cache=not args.no_cache)
    except Interrupted as exc:
        return _interrupted(out_dir, command, exc.stored, exc.total)
    except KeyboardInterrupt:              # outside the units (opening the store, closing the executor)
        return _interrupted(out_dir, command, *_stored_units(plan, out_dir))
    finally:
        if viewer is not None:
            viewer.close()
    try:
        digest = runfolder.outputs_digest(store, not args.no_record, _report_code(plan))
        current = runfolder.outputs_current(out_dir, digest, store.meta(runfolder.OUTPUTS_DIGEST))
        store.close()
        if current:
            progress.close()
            print(f"the report is up to date: {out_dir / 'report.md'}")
            return _failures_exit(out_dir, command)
        write_plan_toml(out_dir / "plan.toml", plan, command, store.stamps)
        from radarbench.bench.report import build_outputs
        report = build_outputs(out_dir, recording=not args.no_record, progress=progress,
                               workers=_workers(args), digest=digest)   # --workers bounds the figures' processes too
    except KeyboardInterrupt:
        return _interrupted(out_dir, command, *_stored_units(plan, out_dir))
    finally:
        progress.close()
    print(f"wrote {report}")
    return _failures_exit(out_dir, command)


def _report_code(plan) -> list[Path]:
    """The files a run folder's outputs are built with: the harness's, and the modules of
    the plan's plugins (their documentation is shown)."""
    from radarbench.bench import registry
    classes = [registry.get_scenario(s.name) for s in plan.scenarios] + [registry.get_method(m.name) for m in plan.methods]
    modules = [sys.modules.get(cls.__module__) for cls in classes]
    return runfolder.harness_files() + [Path(m.__file__) for m in modules if getattr(m, "__file__", None)]


def _failures_exit(out_dir: Path, command: str) -> int:
    """0, or after a summary of the stored failures on stderr, :data:`EXIT_FAILED_UNITS`."""
    from radarbench.bench.results.failures import failed, summary_lines
    from radarbench.bench.results.store import Store
    store = Store(out_dir / "results.sqlite")
    try:
        runs = store.runs()
    finally:
        store.close()
    lines = summary_lines(runs)
    if not lines:
        return 0
    print(f"failed: {len(failed(runs))} (unit, method config) runs of {len(lines)} method configs "
          "(the rest of the report stands):", file=sys.stderr)
    for line in lines:
        print(one_line(line), file=sys.stderr)
    print(f"tracebacks: bench report {shlex.quote(str(out_dir))} --tracebacks; after a fix: {command} "
          "(a changed plugin re-runs by itself; --retry-failed re-runs the failures of unchanged code)",
          file=sys.stderr)
    return EXIT_FAILED_UNITS


def cmd_report(args) -> int:
    from radarbench.bench.results import runfolder
    from radarbench.bench.run.progress import Progress
    from radarbench.bench.report import build_outputs
    out_dir = Path(args.dir)
    if args.tracebacks:
        return _print_tracebacks(out_dir)
    progress = Progress(quiet=True)       # `bench report` stays one line on error (its tests, its users)
    with runfolder.open_for_report(out_dir), _store_errors(out_dir):
        try:
            report = build_outputs(out_dir, recording=not args.no_record, progress=progress)
        finally:
            progress.close()
    print(f"wrote {report}")
    return 0


def _print_tracebacks(out_dir: Path) -> int:
    """``bench report DIR --tracebacks``: the stored tracebacks, read-only."""
    from radarbench.bench.results import runfolder
    from radarbench.bench.escapes import escape_controls
    from radarbench.bench.results.failures import traceback_text
    from radarbench.bench.results.store import Store
    if not (out_dir / runfolder.STORE).is_file():
        raise ConfigError("", f"{out_dir} has no {runfolder.STORE} (not a bench run folder)")
    runfolder.check_store(out_dir / runfolder.STORE, need_plan=True)
    store = Store(out_dir / runfolder.STORE)
    try:
        print(escape_controls(traceback_text(store.runs())), end="")    # plugin text: no terminal escapes
    finally:
        store.close()
    return 0


def cmd_view(args) -> int:
    from radarbench.bench.recording.serve import view
    return view(Path(args.dir), web=args.web, port=args.port, renderer=args.renderer)


def cmd_compare(args) -> int:
    from radarbench.bench.report.compare import run_compare
    return run_compare(args.run_a, args.run_b, args.out, args.fail_on_regression)


def cmd_export(args) -> int:
    from radarbench.bench.results import runfolder
    from radarbench.bench.results.tidy import check_format, export, load_run
    check_format(args.format)
    run = load_run(args.run)                 # read whole before anything is written
    out = Path(args.out) if args.out else run.path / EXPORT_DIR
    inside = out.absolute().is_relative_to(run.path.absolute())
    # inside the run folder: under its lock (no run rewrites the CSVs meanwhile) and in its
    # manifest (what `bench run --fresh` removes)
    with runfolder.RunLock(run.path, "bench export") if inside else contextlib.nullcontext(), \
            runfolder.writing(run.path) if inside else contextlib.nullcontext():
        written = export(run, out, args.format)
    print(f"wrote {', '.join(p.name for p in written)} in {out}")
    return 0


def cmd_data(args) -> int:
    """``bench data fetch``: every scenario's public data (:meth:`bench.core.Scenario.fetch_data`)."""
    from radarbench.bench import registry
    source = Path(args.source) if args.source else None
    if source is not None and not source.is_file():
        raise ConfigError("--from", f"{source}: no such file")
    said = [line for cls in registry.scenarios().values() if (line := cls().fetch_data(source))]
    for line in said:
        print(line)
    if not said:
        print("nothing to fetch: every scenario's data is here already")
    return 0


def cmd_perf(args) -> int:
    from radarbench.bench import registry
    from radarbench.bench.cli.perf import check_sizes, prepare_out, run_perf
    listed = {cls: name for name, cls in registry.methods().items()}     # a qualified name as bench list names it
    args.methods = args.methods and [listed[registry.get_method(name, "--methods")] for name in args.methods]
    check_sizes(args.methods, args.sizes)  # every bad argument is refused before the folder is touched
    prepare_out(Path(args.out))            # a file, a read-only folder: refused before hours of measuring
    report = run_perf(Path(args.out), methods=args.methods, sizes=args.sizes, executors=args.executors,
                      workers=_workers(args), progress=lambda line: print(line, file=sys.stderr))
    print(f"wrote {report}")
    return 0


def one_line(text: str, limit: int = 400) -> str:
    """``text`` safe to print as one line: control characters (newlines, terminal escapes)
    escaped, at most ``limit`` characters (hostile input can make messages huge)."""
    safe = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text[:4 * limit])
    return safe if len(safe) <= limit else safe[:limit - 3] + "..."


COMMANDS = {"list": cmd_list, "run": cmd_run, "report": cmd_report, "view": cmd_view, "perf": cmd_perf, "data": cmd_data,
            "compare": cmd_compare, "export": cmd_export}


def _error(text: str) -> None:
    if sys.stderr.isatty():
        sys.stderr.write("\r\033[K")     # off the progress bar's line
    print(f"error: {one_line(text)}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    # rerun's file writer logs its failures from a thread; write_recording checks the file
    # itself and reports them as one line: silence the log (unless the user set RUST_LOG).
    os.environ.setdefault("RUST_LOG", "warn,re_log_encoding::rrd::file_sink=off")
    restore_sigterm = lambda: None  # noqa: E731 - until a command runs
    try:
        args = build_parser().parse_args(argv)   # before any heavy import: argument errors answer at once
        if args.command != "list":
            from radarbench.bench.run.processes import sigterm_as_interrupt
            restore_sigterm = sigterm_as_interrupt()   # SIGTERM ends a command as Ctrl-C does (exit 130)
        with notices_of_one_command():          # a notice any of its processes meets, said once
            return COMMANDS[args.command](args)
    except ConfigError as err:
        _error(str(err))
        return EXIT_BAD_INPUT
    except Fault as err:
        _error(str(err))
        return err.exit_code
    except OSError as err:                 # a file-system fault no writer named more precisely
        fault = os_fault(err)
        _error(str(fault))
        return EXIT_BAD_INPUT if isinstance(fault, ConfigError) else EXIT_ENVIRONMENT
    except sqlite3.Error as err:
        _error(f"results store: {err}")
        return EXIT_ENVIRONMENT
    except MemoryError as err:
        _error(f"out of memory{f': {err}' if str(err) else ''}")
        _quiet_exit_cleanup()
        return EXIT_ENVIRONMENT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:               # a bug: one line still, the traceback on request
        if is_out_of_memory(exc):          # e.g. an import whose library could not be mapped
            _error(f"out of memory: {type(exc).__name__}: {exc}"[:400])
            _quiet_exit_cleanup()
            return EXIT_ENVIRONMENT
        if os.environ.get("BENCH_TRACEBACK"):
            raise
        frames = traceback.extract_tb(exc.__traceback__)
        where = f" ({Path(frames[-1].filename).name}:{frames[-1].lineno})" if frames else ""
        _error(f"internal error, a bug: {type(exc).__name__}: {exc}{where}; "
               "BENCH_TRACEBACK=1 shows the traceback")
        return EXIT_BUG
    finally:
        restore_sigterm()


def _quiet_exit_cleanup() -> None:
    """Out of memory, multiprocessing's removal of its temporary folder at exit fails too and
    prints a traceback after the one line: make that exit-time step quiet. The folder stays
    until exit, because this process (a test's, or a library caller's) may run again and its
    forkserver listens inside it."""
    import multiprocessing.util as mp_util
    remove = getattr(mp_util, "_remove_temp_dir", None)
    for finalizer in list(getattr(mp_util, "_finalizer_registry", {}).values()):
        if remove is not None and getattr(finalizer, "_callback", None) is remove:
            finalizer._callback = _ignoring_failures(remove)


def _ignoring_failures(step):
    def quiet(*args, **kwargs):
        try:
            step(*args, **kwargs)
        except BaseException:        # noqa: BLE001 - at exit, out of memory: nothing to tell
            pass
    return quiet

if __name__ == "__main__":
    sys.exit(main())
