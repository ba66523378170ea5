"""The ``bench`` command: ``list``, ``run``, ``report``, ``view``, ``perf``.

Bad input ends with one line on stderr (``error: FILE: FIELD: PROBLEM``) and
exit code 2, before anything is written.
"""

from __future__ import annotations

import argparse
import importlib.resources
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from bench import registry
from bench.errors import ConfigError

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2 (argparse prints usage + message)
        raise ConfigError("", f"{self.prog}: {message}")


def _presets() -> dict[str, object]:
    root = importlib.resources.files("bench") / "presets"
    return {p.name[:-5]: p for p in root.iterdir() if p.name.endswith(".toml")}


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if not 1 <= value <= 1024:
        raise argparse.ArgumentTypeError(f"expected 1 to 1024, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    from bench.executors import default_workers
    p = _Parser(prog="bench", description="Benchmark radar maneuver detectors, trackers and TBD methods.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    ls = sub.add_parser("list", help="tasks, methods and scenarios, with task and summary")
    ls.add_argument("-v", "--verbose", action="store_true", help="show every parameter with its default")
    run = sub.add_parser("run", help="run (or resume) a sweep")
    run.add_argument("sweep", nargs="?", help="sweep file (TOML)")
    run.add_argument("--preset", help=f"a packaged sweep: {', '.join(sorted(_presets()))}")
    run.add_argument("--out", help="run folder (default: reports/<name>/)")
    run.add_argument("--workers", type=_positive_int, default=default_workers(),
                     help="worker processes (default: CPU count)")
    run.add_argument("--executor", default="local", choices=["local", "dask"],
                     help="where units run: local processes, or a dask cluster (needs the [dask] extra)")
    run.add_argument("--scheduler", metavar="ADDRESS",
                     help="with --executor dask: an existing cluster's scheduler, tcp://HOST:8786 "
                          "(default: a local cluster of --workers processes)")
    run.add_argument("--retry-failed", action="store_true",
                     help="also re-run the (unit, method config) pairs whose run failed")
    run.add_argument("--fresh", action="store_true", help="discard stored results and start over")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--no-record", action="store_true", help="do not write recording.rrd")
    run.add_argument("--viewer", action="store_true", help="stream trials live to a spawned Rerun viewer")
    run.add_argument("--yes", action="store_true", help="run a very large sweep without asking")
    rep = sub.add_parser("report", help="rebuild CSV, figures, report.md and recording from results.sqlite")
    rep.add_argument("dir")
    rep.add_argument("--no-record", action="store_true", help="do not rewrite recording.rrd")
    view = sub.add_parser("view", help="open a run's recording in the Rerun viewer")
    view.add_argument("dir")
    perf = sub.add_parser("perf", help="measure every method's speed and memory against its reference, "
                                       "and scene generation")
    perf.add_argument("--out", default="reports/perf", help="output folder (default: reports/perf)")
    perf.add_argument("--methods", nargs="+", help="only these methods")
    perf.add_argument("--sizes", nargs="+", help="only these named sizes (e.g. small paper)")
    perf.add_argument("--executors", action="store_true",
                      help="also time one compute-bound sweep per executor (local x1, local xN, dask xN)")
    perf.add_argument("--workers", type=_positive_int, default=default_workers(), help="N for --executors")
    return p


# ------------------------------------------------------------------ commands

def cmd_list(args) -> int:
    from bench.params import describe_params
    print("tasks:")
    for name, task in registry.tasks().items():
        print(f"  {name:<20} {task.summary()}")
    for title, table in (("scenarios", registry.scenarios()), ("methods", registry.methods())):
        print(f"{title}:")
        for name, cls in table.items():
            kind = ", ".join(cls.tasks) if title == "scenarios" else cls.task
            print(f"  {name:<14} {kind:<20} {cls.summary()}")
            if args.verbose:
                for pname, ptype, default, doc in describe_params(cls.Params):
                    print(f"      {pname} ({ptype}, default {default!r}): {doc}")
    missing = registry.unavailable()
    if missing:
        print("unavailable:")
        for u in missing:
            print(f"  {u.source:<14} {u.error}")
    return 0


def _load_plan(args):
    from bench.config import load_sweep, parse_sweep_text
    if bool(args.sweep) == bool(args.preset):
        raise ConfigError("", "give a sweep file or --preset NAME (one of them)")
    if args.preset:
        presets = _presets()
        if args.preset not in presets:
            raise ConfigError("--preset", f"unknown preset {args.preset!r} (known: {', '.join(sorted(presets))})")
        source = f"preset {args.preset}"
        try:
            return parse_sweep_text(presets[args.preset].read_bytes(), source, allow_large=args.yes)
        except ConfigError as err:
            raise ConfigError(f"{source}: {err.field}" if err.field else source, err.problem) from None
    try:
        return load_sweep(args.sweep, allow_large=args.yes)
    except ConfigError as err:
        raise ConfigError(f"{args.sweep}: {err.field}" if err.field else args.sweep, err.problem) from None


def _command_line(args) -> str:
    words = ["bench", "run"] + (["--preset", args.preset] if args.preset else [args.sweep])
    if args.out:
        words += ["--out", args.out]
    return shlex.join(words)


def _check_executor(args) -> None:
    """Executor options, checked before anything is written."""
    if args.scheduler is not None and args.executor != "dask":
        raise ConfigError("--scheduler", "only with --executor dask")
    if args.executor == "dask":
        from bench.executors import require_dask
        require_dask()


def _stored_units(plan, out_dir: Path) -> tuple[int, int]:
    """(units stored in ``out_dir``, units of the plan)."""
    from bench.runner import plan_units
    from bench.store import Store
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


def cmd_run(args) -> int:
    from bench.report import build_outputs
    from bench.runner import Interrupted, plan_record, run_sweep, write_plan_toml
    _check_executor(args)
    plan = _load_plan(args)
    out_dir = Path(args.out) if args.out else Path("reports") / plan.name
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError("--out", f"{out_dir} exists and is not a folder")
    command = _command_line(args)
    viewer = None
    if args.viewer:
        from bench.recording import LiveViewer
        tasks = {m.label: registry.get_task(task) for m, task in zip(plan.methods, plan.method_tasks)}
        try:
            viewer = LiveViewer(tasks=tasks, application_id="radar-bench",
                                recording_id=f"{plan.name}-{plan.fingerprint()}")
        except RuntimeError as exc:
            raise ConfigError("--viewer", str(exc)) from None
    on_result = None
    if viewer is not None:
        from bench.recording import TrialRecord

        def on_result(result):
            viewer.log_records([TrialRecord.from_bytes(b) for _, b in result.records])
    try:
        store = run_sweep(plan, out_dir, plan_record=plan_record(plan, command), workers=args.workers,
                          executor=args.executor, fresh=args.fresh, quiet=args.quiet, on_result=on_result,
                          scheduler=args.scheduler, retry_failed=args.retry_failed)
    except Interrupted as exc:
        return _interrupted(out_dir, command, exc.stored, exc.total)
    except KeyboardInterrupt:              # outside the units (opening the store, closing the executor)
        return _interrupted(out_dir, command, *_stored_units(plan, out_dir))
    finally:
        if viewer is not None:
            viewer.close()
    try:
        write_plan_toml(out_dir / "plan.toml", plan, command)
        store.close()
        report = build_outputs(out_dir, recording=not args.no_record)
    except KeyboardInterrupt:
        return _interrupted(out_dir, command, *_stored_units(plan, out_dir))
    print(f"wrote {report}")
    return 0


def cmd_report(args) -> int:
    from bench.report import build_outputs
    report = build_outputs(Path(args.dir), recording=not args.no_record)
    print(f"wrote {report}")
    return 0


def cmd_view(args) -> int:
    path = Path(args.dir) / "recording.rrd"
    if not path.exists():
        raise ConfigError("", f"{path} does not exist (was the run made with --no-record?)")
    exe = shutil.which("rerun")
    cmd = [exe, str(path)] if exe else [sys.executable, "-m", "rerun", str(path)]
    return subprocess.call(cmd)


def cmd_perf(args) -> int:
    from bench.perf import run_perf
    known = set(registry.methods())
    for name in args.methods or []:
        if name not in known:
            raise ConfigError("--methods", f"unknown method {name!r} (known: {', '.join(sorted(known))})")
    report = run_perf(Path(args.out), methods=args.methods, sizes=args.sizes, executors=args.executors,
                      workers=args.workers, progress=lambda line: print(line, file=sys.stderr))
    print(f"wrote {report}")
    return 0


def one_line(text: str, limit: int = 400) -> str:
    """``text`` safe to print as one line: control characters (newlines, terminal escapes)
    escaped, at most ``limit`` characters (hostile input can make messages huge)."""
    safe = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text[:4 * limit])
    return safe if len(safe) <= limit else safe[:limit - 3] + "..."


COMMANDS = {"list": cmd_list, "run": cmd_run, "report": cmd_report, "view": cmd_view, "perf": cmd_perf}


def main(argv: list[str] | None = None) -> int:
    from bench.executors import sigterm_as_interrupt
    restore_sigterm = sigterm_as_interrupt()       # SIGTERM ends a command as Ctrl-C does (exit 130)
    try:
        args = build_parser().parse_args(argv)
        return COMMANDS[args.command](args)
    except ConfigError as err:
        print(f"error: {one_line(str(err))}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    finally:
        restore_sigterm()


if __name__ == "__main__":
    sys.exit(main())
