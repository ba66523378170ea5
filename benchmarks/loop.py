"""The edit-run-read loop in seconds: what a user waits for between an edit and its report.

Measures, on this machine, the wall time and the CPU time of the *whole process tree* of
each ``bench`` command (the driver, its forkserver and the workers the forkserver forks,
the figures' pool): this script makes itself the child subreaper of its commands
(Linux ``prctl(PR_SET_CHILD_SUBREAPER)``), so a process its parent left behind (the
forkserver outlives the driver by a moment, and its workers may outlive it) is handed to
this script and reaped here, and ``getrusage(RUSAGE_CHILDREN)`` then counts every process
of the tree. ``/usr/bin/time`` counts only the processes its child waited for, so it
misses the forkserver's workers.

The steps (docs/architecture.md, 'Performance'; the Getting-started and Presets pages of
the documentation site show the results):

1. ``first quick run``: ``bench run --preset quick`` in a fresh clone of the repository's
   HEAD (``git clone``: no ``__pycache__``), with an empty numba cache (a temporary
   ``NUMBA_CACHE_DIR``) and an empty user cache folder (a temporary ``XDG_CACHE_HOME``:
   results cache, stored unit costs, parsed identities, ``bench list``'s cache);
2. ``warm quick run``: the same into a new run folder, kernels cached; ``--no-cache`` when
   ``bench run`` has it, so every unit is computed again rather than read from the results cache;
   and whether the first run's runtime table (CPU ms per trial of each config, the report's
   runtime section) is within :data:`RUNTIME_AGREEMENT` of the warm run's for every config
   (the first run's compilation must not reach its units' times);
3. ``no-op re-run``: the same command into the warm run's folder: nothing to compute;
4. ``edit one parameter``: ``--preset maneuver-detection`` run once, then again into the same
   folder with one method parameter changed (``--set``): the units it reused and computed,
   and whether its CSVs equal a fresh run of the edited sweep (without their timing columns);
5. ``trials 100 -> 150``: a small sweep (``cv-turn-cv``, two SNR levels, three detectors) at
   100 trials, then at ``--trials 150`` into the same folder, and a fresh 150-trial run to
   compare with (the CSVs without their timing columns);
6. ``overrides``: ``bench run --preset quick --methods cv-kf imm-cv-ca --snr 0 10``, and
   whether its ``plan.toml`` holds exactly those methods and levels.

The commands run in the README's environment: a fresh virtual environment in the work
folder with the clone installed as the README says (:data:`README_INSTALL`), so optional
extras (the Stone Soup peers of ``[peers]``) are absent as on a user's first day; ``--python``
runs them with another interpreter instead (the output names which, and whether the peers were
there). Steps 2-6 share the first step's caches (the user's second command onwards). The output,
a Markdown table and the same as JSON, is written to ``reports/perf/loop.md`` (``--out``).
The test suite's duration is an input (``--suite-seconds`` or ``--suite-log``: a pytest
output whose last line reads ``... in 1234.56s``), never typed into the docs.

Run it with the Python of an environment that has the package installed (its comparisons read the
runs' CSVs with pandas); the ``bench`` commands it times run in their own fresh environment.

    python benchmarks/loop.py                        # everything (CPU heavy: an idle machine)
    python benchmarks/loop.py --steps first warm noop --suite-log pytest.log
    python benchmarks/loop.py --edit-overrides --snr 0 5 --trials 20   # step 4 reduced (said in the output)
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import dataclasses
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
#: where the results go, relative to the repository
OUT = Path("reports/perf/loop.md")
#: the opening of the JSON block in the Markdown output (read back by ``bench.cli.docs.loop_record``)
JSON_FENCE = "```json"
STEPS = ("first", "warm", "noop", "edit", "trials", "overrides")
#: the README's install line (its extras), run in a fresh virtual environment unless ``--python`` is given
README_INSTALL = ("-e", ".[test]")
#: a step that needs another before it runs it too (the warm run needs the first's caches)
NEEDS = {"noop": "warm", "warm": "first"}
#: Linux prctl option: orphaned descendants are re-parented to the caller, which reaps them
PR_SET_CHILD_SUBREAPER = 36
#: how long the tree's last processes may take to exit once the command has (a hang detector)
REAP_BOUND_S = 120.0
#: a sweep small enough to run twice and once more: the trials step
SMALL_SWEEP = """name = "loop-trials"
description = "The loop benchmark's trials step: three detectors on CV-turn-CV at two SNR levels."
scenario = "cv-turn-cv"
trials = 100
seed = 39
snr_db = [0, 6]

[scenario_params]
turn_rate_deg_s = 3.0

[[methods]]
name = "innovation"

[[methods]]
name = "cumulant"
params = { window = 32 }

[[methods]]
name = "glr"
"""
#: the maneuver-detection edit: the first method of this name gets its parameter changed to this value
EDIT = ("glr", "window", 24)
#: the overrides step's methods and SNR levels
OVERRIDE_METHODS, OVERRIDE_SNR = ("cv-kf", "imm-cv-ca"), ("0", "10")
#: what a run says about the units it computes and reuses (the runner's lines; the cache's words)
COMPUTED = re.compile(r"(?<!warm-up): done, (\d+)/\d+ units")
#: the run's own count: "units: A reused from FOLDER, B from the results cache, C computed"
REUSED = re.compile(r"units: (\d+) reused from .*?, (\d+) from the results cache")
NOTHING = re.compile(r"Nothing to run")
#: an edited sweep in the same folder: "the sweep changed: reusing N stored units, computing M (unit, method config) runs"
EDITED = re.compile(r"the sweep changed: reusing (\d+) stored units, computing (\d+) \(unit, method config\) runs")
#: the report's runtime section and a row of its table: | `config` | CPU ms per trial | ...
RUNTIME_SECTION = re.compile(r"^## Runtime$(.*?)(?=^## |\Z)", re.M | re.S)
RUNTIME_ROW = re.compile(r"^\| `(?P<config>[^`]+)`\s*\| (?P<ms>[0-9.eE+-]+)\s*\|", re.M)
#: how far apart a first run's CPU per trial and a warm run's may be, either way, for any config
RUNTIME_AGREEMENT = 2.0
#: the most of a warm quick run's CPU its report phase (tables, figures, pages, recording) may take
REPORT_SHARE = 0.15
#: the store's record of its last report build's CPU seconds (bench.report.REPORT_CPU)
REPORT_CPU = "report_cpu_seconds"


@dataclasses.dataclass
class Measured:
    """One command: its wall and whole-tree CPU seconds and what it said about its units."""

    step: str
    what: str
    command: str
    wall_s: float
    cpu_s: float
    exit_code: int
    computed: int | None = None
    reused: int | None = None
    note: str = ""
    load_before: tuple = ()
    load_after: tuple = ()


# ------------------------------------------------------------------ the process tree

def become_subreaper() -> bool:
    """Make this process the subreaper of its descendants (Linux); False where it cannot."""
    if not sys.platform.startswith("linux"):
        return False
    libc = ctypes.CDLL(None, use_errno=True)
    return libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0


def reap_orphans(bound_s: float = REAP_BOUND_S) -> int:
    """Wait for every descendant handed to this process, up to ``bound_s``; the number still
    running after it (their CPU time is then not counted)."""
    deadline = time.monotonic() + bound_s
    while time.monotonic() < deadline:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return 0
        if pid == 0:
            time.sleep(0.05)
    return len(_children())


def _children() -> list[int]:
    """The pids whose parent is this process (from /proc)."""
    me, out = os.getpid(), []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == me:
            out.append(int(stat.parent.name))
    return out


def _children_cpu_s() -> float:
    import resource

    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_timed(step: str, what: str, args: list[str], env: dict, cwd: Path, log: Path) -> Measured:
    """``args`` run to its end, every process of its tree reaped; its stderr and stdout in ``log``."""
    load_before = os.getloadavg()
    cpu0, t0 = _children_cpu_s(), time.perf_counter()
    with open(log, "w", encoding="utf-8") as out:
        code = subprocess.run(args, env=env, cwd=cwd, stdout=out, stderr=subprocess.STDOUT, check=False).returncode
    wall = time.perf_counter() - t0
    left = reap_orphans()
    text = log.read_text(encoding="utf-8", errors="replace")
    computed, reused = unit_counts(text)
    note = f"{left} processes still running {REAP_BOUND_S:.0f} s after the command (not counted)" if left else ""
    edited = EDITED.search(text)
    if edited:
        note = "; ".join(filter(None, [note, f"the sweep changed: {edited[1]} stored units reused, {edited[2]} "
                                             "(unit, method config) runs computed on them"]))
    if code != 0:
        note = "; ".join(filter(None, [note, f"exit {code}: {_last_line(text)}"]))
    return Measured(step, what, " ".join(["bench", *args[3:]]), wall, _children_cpu_s() - cpu0, code, computed,
                    reused, note, tuple(round(x, 2) for x in load_before),
                    tuple(round(x, 2) for x in os.getloadavg()))


def unit_counts(text: str) -> tuple[int | None, int | None]:
    """(units computed, units reused) as a run's output states them (None: not stated)."""
    computed = sum(int(m) for m in COMPUTED.findall(text)) if COMPUTED.search(text) else None
    if computed is None and NOTHING.search(text):
        computed = 0
    found = [int(a) + int(b) for a, b in REUSED.findall(text)]
    return computed, (sum(found) if found else None)


def _last_line(text: str) -> str:
    lines = [line for line in text.splitlines() if line.strip()]
    return lines[-1][:200] if lines else ""


# ------------------------------------------------------------------ the steps

class Loop:
    """The steps' shared state: the clone, the caches, the run folders, the results."""

    def __init__(self, work: Path, python: str | None, edit_overrides: list[str]):
        self.work, self.python, self.edit_overrides = work, python, edit_overrides
        self.clone = work / "clone"
        self.results: list[Measured] = []
        self.checks: dict[str, str] = {}
        self.env = {**os.environ, "NUMBA_CACHE_DIR": str(work / "numba-cache"),
                    "XDG_CACHE_HOME": str(work / "user-cache")}
        if python is not None:                              # another interpreter: the clone on its path
            self.env["PYTHONPATH"] = str(self.clone)
        self.env.pop("PYTHONDONTWRITEBYTECODE", None)        # a fresh clone compiles its bytecode once
        self.flags: list[str] | None = None
        self.environment = ""

    def prepare(self) -> None:
        subprocess.run(["git", "clone", "--quiet", "--no-hardlinks", str(REPO), str(self.clone)], check=True)
        if self.python is None:
            self.python = install_as_the_readme(self.work / "venv", self.clone)
            self.environment = (f"a fresh virtual environment, `pip install {' '.join(README_INSTALL)}` in the "
                                "clone (the README's)")
        else:
            self.environment = "the interpreter given (`--python`), the clone on `PYTHONPATH`"
        peers = subprocess.run([self.python, "-c", "import importlib.util as u; print(u.find_spec('stonesoup') "
                                "is not None)"], env=self.env, capture_output=True, text=True, check=True)
        self.environment += "; the Stone Soup peers (`[peers]`) " + (
            "installed: the quick sweep runs them" if peers.stdout.strip() == "True"
            else "absent: the quick sweep skips them, saying so")
        self.flags = run_flags(self.python, self.env, self.clone)

    def bench(self, step: str, what: str, *args: str) -> Measured:
        logs = self.work / "logs"
        logs.mkdir(exist_ok=True)
        measured = run_timed(step, what, [self.python, "-m", "radarbench.bench", "run", *args], self.env,
                             self.clone, logs / f"{len(self.results):02d}-{step}.log")
        measured.command = measured.command.replace(str(self.work), "$WORK")    # no local path in the output
        self.results.append(measured)
        print(f"loop: {what}: {measured.wall_s:.1f} s wall, {measured.cpu_s:.1f} s CPU"
              f"{'; ' + measured.note if measured.note else ''}", file=sys.stderr)
        return measured

    def out(self, name: str) -> str:
        return str(self.work / "runs" / name)

    def no_cache(self) -> list[str]:
        """``--no-cache`` where ``bench run`` has it (a results cache would otherwise answer)."""
        return ["--no-cache"] if "--no-cache" in (self.flags or []) else []

    def first(self) -> None:
        self.bench("first", "first quick run, fresh clone (empty numba and user caches)", "--preset", "quick",
                   "--out", self.out("quick-first"))

    def warm(self) -> None:
        warm = self.bench("warm", "warm quick run (kernels cached" + (", results cache bypassed)" if self.no_cache()
                                                                       else ")"),
                          "--preset", "quick", "--out", self.out("quick-warm"), *self.no_cache())
        self.checks[f"the warm run's report phase is at most {REPORT_SHARE:.0%} of its CPU"] = \
            report_share(Path(self.out("quick-warm")) / "results.sqlite", warm)
        self.checks[f"the first run's runtime table is within {RUNTIME_AGREEMENT:g}x of the warm run's"] = \
            runtimes_agree(Path(self.out("quick-first")) / "report.md", Path(self.out("quick-warm")) / "report.md")

    def noop(self) -> None:
        self.bench("noop", "no-op re-run (nothing to compute)", "--preset", "quick", "--out", self.out("quick-warm"))

    def edit(self) -> None:
        key = edit_key(*EDIT)
        reduced = " ".join(self.edit_overrides)
        base = ["--preset", "maneuver-detection", "--out", self.out("maneuver-detection"), *self.edit_overrides]
        suffix = f" (reduced: {reduced})" if reduced else ""
        runs = [self.bench("edit", f"maneuver-detection, first run{suffix}", *base),
                self.bench("edit", f"maneuver-detection, {key} edited{suffix}", *base, "--set", key),
                self.bench("edit", f"maneuver-detection with {key}, a fresh run (to compare){suffix}", "--preset",
                           "maneuver-detection", "--out", self.out("maneuver-detection-fresh"), *self.edit_overrides,
                           "--set", key, *self.no_cache())]
        self.checks[f"maneuver-detection with {key} edited = a fresh run of the edited sweep"] = same_runs(
            runs, Path(self.out("maneuver-detection")), Path(self.out("maneuver-detection-fresh")))

    def trials(self) -> None:
        sweep = self.work / "loop-trials.toml"
        sweep.write_text(SMALL_SWEEP, encoding="utf-8")
        runs = [self.bench("trials", "small sweep at 100 trials", str(sweep), "--out", self.out("trials")),
                self.bench("trials", "the same raised to 150 trials", str(sweep), "--out", self.out("trials"),
                           "--trials", "150"),
                self.bench("trials", "a fresh 150-trial run (to compare)", str(sweep), "--out",
                           self.out("trials-fresh"), "--trials", "150", *self.no_cache())]
        self.checks["150 trials by raising 100 = a fresh 150-trial run"] = same_runs(
            runs, Path(self.out("trials")), Path(self.out("trials-fresh")))

    def overrides(self) -> None:
        out = self.out("overrides")
        self.bench("overrides", "quick with --methods cv-kf imm-cv-ca --snr 0 10", "--preset", "quick", "--out", out,
                   "--methods", *OVERRIDE_METHODS, "--snr", *OVERRIDE_SNR)
        self.checks["the overrides run exactly those methods and SNR levels"] = plan_holds(
            Path(out) / "plan.toml", set(OVERRIDE_METHODS), {float(s) for s in OVERRIDE_SNR})


def install_as_the_readme(venv: Path, clone: Path) -> str:
    """A fresh virtual environment at ``venv`` with ``clone`` installed as the README says; its python."""
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = str(venv / "bin" / "python")
    print(f"loop: installing the clone into {venv} (pip install {' '.join(README_INSTALL)})", file=sys.stderr)
    subprocess.run([python, "-m", "pip", "install", "--quiet", *README_INSTALL], cwd=clone, check=True)
    return python


def run_flags(python: str, env: dict, cwd: Path) -> list[str]:
    """The options ``bench run --help`` lists (so the script follows the command as it changes)."""
    help_text = subprocess.run([python, "-m", "radarbench.bench", "run", "--help"], env=env, cwd=cwd,
                               capture_output=True, text=True, check=True).stdout
    return re.findall(r"(--[a-z][a-z-]*)", help_text)


def edit_key(method: str, parameter: str, value) -> str:
    """``methods.N.params.P=V`` for the first ``[[methods]]`` entry named ``method`` of the
    maneuver-detection preset (read from the packaged TOML)."""
    preset = REPO / "bench" / "presets" / "maneuver-detection.toml"
    entries = tomllib.loads(preset.read_text(encoding="utf-8"))["methods"]
    index = next(i for i, entry in enumerate(entries) if entry["name"] == method)
    return f"methods.{index}.params.{parameter}={value}"


#: a CSV column that times something (it differs between any two runs)
TIMING = re.compile(r"second|time|_ms$|wall|cpu", re.IGNORECASE)


def same_runs(runs: list[Measured], left: Path, right: Path) -> str:
    """:func:`compare_runs` once every command of the comparison ended well: a failed
    command can leave CSVs that equal the other folder's (written before the failure)."""
    failed = [f"{m.what!r} exited {m.exit_code}" for m in runs if m.exit_code != 0]
    return "no: " + "; ".join(failed) if failed else compare_runs(left, right)


def compare_runs(left: Path, right: Path) -> str:
    """Whether two run folders' CSVs are equal without their timing columns: one line."""
    import pandas as pd

    names = sorted(p.name for p in left.glob("*.csv"))
    if not names:
        return f"no CSV in {left.name}"
    differing = []
    for name in names:
        a, b = (pd.read_csv(folder / name, dtype=str, keep_default_na=False) for folder in (left, right))
        a, b = (frame.drop(columns=[c for c in frame.columns if TIMING.search(c)]) for frame in (a, b))
        if not a.equals(b):
            differing.append(name)
    return "yes (" + ", ".join(names) + ")" if not differing else "no: " + ", ".join(differing) + " differ"


def runtime_table(report: Path) -> dict[str, float]:
    """config -> CPU ms per trial, from the runtime section of a run's ``report.md`` (empty
    without one)."""
    section = RUNTIME_SECTION.search(report.read_text(encoding="utf-8")) if report.is_file() else None
    return {m["config"]: float(m["ms"]) for m in RUNTIME_ROW.finditer(section.group(1))} if section else {}


def runtimes_agree(first: Path, warm: Path) -> str:
    """Whether every config's CPU per trial in the ``first`` report is within
    :data:`RUNTIME_AGREEMENT` of the ``warm`` one's, either way: one line naming the largest ratio."""
    a, b = runtime_table(first), runtime_table(warm)
    ratios = {c: max(a[c] / b[c], b[c] / a[c]) for c in sorted(set(a) & set(b)) if a[c] > 0 and b[c] > 0}
    if not ratios:
        return f"no runtime table to compare ({first.parent.name}: {len(a)} configs, {warm.parent.name}: {len(b)})"
    worst = max(ratios, key=ratios.get)
    beyond = sum(r > RUNTIME_AGREEMENT for r in ratios.values())
    return (f"{'yes' if not beyond else 'no'} (max ratio {ratios[worst]:.2f} for {worst}: {a[worst]:.3g} ms "
            f"first, {b[worst]:.3g} ms warm; {beyond} of {len(ratios)} configs beyond)")


def report_share(store: Path, run: Measured) -> str:
    """Whether the report phase of ``run`` (its CPU seconds as the run recorded them in its store)
    took at most :data:`REPORT_SHARE` of the run's whole-tree CPU: one line."""
    import sqlite3

    if not store.is_file():
        return f"no {store.name}"
    with contextlib.closing(sqlite3.connect(f"file:{store}?mode=ro", uri=True)) as db:
        row = db.execute("SELECT value FROM meta WHERE key = ?", (REPORT_CPU,)).fetchone()
    if row is None or run.cpu_s <= 0:
        return "not recorded by this bench"
    share = float(row[0]) / run.cpu_s
    return f"{'yes' if share <= REPORT_SHARE else 'no'} ({float(row[0]):.1f} s of {run.cpu_s:.1f} s, {share:.0%})"


def plan_holds(plan: Path, methods: set[str], snr_db: set[float]) -> str:
    """Whether ``plan.toml`` runs exactly ``methods`` (by name) at exactly ``snr_db``: one line."""
    if not plan.is_file():
        return f"no {plan.name}"
    data = tomllib.loads(plan.read_text(encoding="utf-8"))
    names = {entry["name"] for entry in data.get("methods", [])}
    levels = set()
    for entry in data.get("scenarios", []) or [data]:
        levels |= {float(x) for x in entry.get("snr_db", [])}
    ok = names == methods and levels == snr_db
    return ("yes" if ok else "no") + f" (methods {sorted(names)}, SNR {sorted(levels)} dB)"


# ------------------------------------------------------------------ output

def suite_seconds(args) -> float | None:
    """The test suite's wall seconds: given, or read from a pytest log's last ``in N s`` line."""
    if args.suite_seconds is not None:
        return float(args.suite_seconds)
    if args.suite_log is None:
        return None
    found = re.findall(r" in ([0-9.]+)s\b", Path(args.suite_log).read_text(encoding="utf-8", errors="replace"))
    if not found:
        raise SystemExit(f"error: --suite-log: no 'in N s' line in {args.suite_log}")
    return float(found[-1])


def document(loop: Loop, suite_s: float | None, cpu_count: int, subreaper: bool, commit: str) -> dict:
    """The JSON record of a run of this script."""
    return {"created": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), "git_commit": commit,
            "cpu_count": cpu_count, "platform": platform.platform(), "python": platform.python_version(),
            "whole_tree_cpu": subreaper, "environment": getattr(loop, "environment", ""), "test_suite_wall_s": suite_s,
            "steps": [dataclasses.asdict(m) for m in loop.results], "checks": loop.checks}


def markdown(record: dict) -> str:
    """``reports/perf/loop.md``: the table, the checks, the machine, and the JSON record."""
    def cell(value) -> str:
        return "–" if value is None else str(value)

    rows = ["| step | command | wall (s) | CPU, whole tree (s) | units computed | units reused | "
            "load average before → after | note |", "|---|---|---|---|---|---|---|---|"]
    for m in record["steps"]:
        load = f"{', '.join(map(str, m['load_before']))} → {', '.join(map(str, m['load_after']))}"
        command = m["command"].replace("|", "\\|")
        rows.append(f"| {m['what']} | `{command}` | {m['wall_s']:.1f} | {m['cpu_s']:.1f} | {cell(m['computed'])} | "
                    f"{cell(m['reused'])} | {load} | {m['note']} |")
    checks = [f"- {name}: {result}" for name, result in record["checks"].items()]
    suite = record["test_suite_wall_s"]
    cpu = ("the CPU time of every process of the command's tree (this script is their subreaper)"
           if record["whole_tree_cpu"] else "the CPU time of the processes the command waited for only "
           "(no subreaper on this system: a lower bound)")
    return "\n\n".join([
        "# The edit-run-read loop",
        f"Written by `python benchmarks/loop.py` on {record['created']} at commit {record['git_commit']}, "
        f"{record['cpu_count']} CPUs ({record['platform']}, Python {record['python']}). Wall time as the user "
        f"waits; CPU as {cpu}. The load average (1, 5, 15 min) before and after each step says how busy the "
        "machine was: other processes lengthen the wall time, not the CPU time. "
        f"Commands run in {record.get('environment') or 'the interpreter running the script'}.",
        "\n".join(rows), *(["Checks:\n\n" + "\n".join(checks)] if checks else []),
        f"Test suite (`python -m pytest -q`, given to the script): "
        f"{'not given' if suite is None else f'{suite:.0f} s wall'}.",
        f"{JSON_FENCE}\n{json.dumps(record, indent=1)}\n```"]) + "\n"


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", nargs="+", choices=STEPS, default=list(STEPS),
                        help="the steps to run (default: all; warm and noop bring the steps before them; "
                             "without first, the first step chosen compiles the kernels it uses)")
    parser.add_argument("--out", type=Path, default=REPO / OUT, help=f"the Markdown output (default: {OUT})")
    parser.add_argument("--work", type=Path, help="keep the clone, caches, runs and logs here (default: a "
                                                   "temporary folder, removed)")
    parser.add_argument("--python", help="run bench with this interpreter (the clone on its PYTHONPATH) instead "
                                          "of a fresh virtual environment installed as the README says")
    parser.add_argument("--suite-seconds", type=float, help="the test suite's wall seconds, measured apart")
    parser.add_argument("--suite-log", type=Path, help="a pytest output; its last 'in N s' is the suite's time")
    parser.add_argument("--edit-overrides", nargs=argparse.REMAINDER, default=[],
                        help="extra `bench run` options for the maneuver-detection step (e.g. --snr 0 5 "
                             "--trials 20 on a busy machine; said in the output); must come last")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    suite_s = suite_seconds(args)
    subreaper = become_subreaper()
    work = args.work or Path(tempfile.mkdtemp(prefix="bench-loop-"))
    work.mkdir(parents=True, exist_ok=True)
    loop = Loop(work, args.python, args.edit_overrides)
    try:
        loop.prepare()
        chosen = set(args.steps)
        while any(NEEDS.get(step) not in chosen for step in chosen if step in NEEDS):
            chosen |= {NEEDS[step] for step in chosen if step in NEEDS}
        for step in STEPS:
            if step in chosen:
                getattr(loop, step)()
    finally:
        commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                                text=True, check=False).stdout.strip()
        if loop.results:
            record = document(loop, suite_s, os.cpu_count() or 0, subreaper, commit)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(markdown(record), encoding="utf-8")
            print(f"loop: written {args.out} (work folder {work})", file=sys.stderr)
        else:                                   # a failed set-up measured nothing: the last record stands
            print(f"loop: nothing measured, {args.out} left as it was (work folder {work})", file=sys.stderr)
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    return 0 if all(m.exit_code == 0 for m in loop.results) else 1


if __name__ == "__main__":
    sys.exit(main())
