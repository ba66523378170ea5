"""One method's failure never stops the others; a broken plugin never breaks the registry."""

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import pytest

from radarbench.bench import registry
from radarbench.bench.cli import main
from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.core import MANEUVER_DETECTION, Method
from radarbench.bench.params import param
from radarbench.bench.recording import TrialRecord
from radarbench.bench.report import build_outputs
from radarbench.bench.run.runner import plan_record, run_sweep
from radarbench.bench.results.store import Store
from radarbench.methods.maneuver.innovation import Innovation


class Fragile(Method):
    """Innovation detector that raises at high SNR (a stand-in for a buggy plugin)."""

    name = "fragile"
    task = MANEUVER_DETECTION

    @dataclass(frozen=True)
    class Params:
        fail_above_db: float = param(5.0, "raise on units above this SNR (dB)", ge=-200.0, le=200.0,
                                     why="the SNR levels a sweep accepts")

    def run(self, batch, params):
        if batch.scene.realised_snr_db.mean() > params.fail_above_db:
            raise FloatingPointError("simulated failure")
        return Innovation().run(batch, Innovation.Params(window=1))

    def nominal_threshold(self, params, pfa, batch):
        return Innovation().nominal_threshold(Innovation.Params(window=1), pfa, batch)


@pytest.fixture
def fragile():
    registry.register_method(Fragile)
    yield
    registry._METHODS.pop("fragile", None)


def test_a_failing_method_is_recorded_and_the_rest_completes(fragile, tmp_path):
    plan = parse_sweep({"name": "iso", "scenario": "cv-turn-cv", "trials": 6, "chunk": 3, "snr_db": [0, 10],
                        "methods": [{"name": "fragile"}, {"name": "innovation"}],
                        "calibration": {"h0_trials": 30}})
    # a method registered in this process only: the units run here too (the serial executor)
    store = run_sweep(plan, tmp_path, plan_record=plan_record(plan, "test"), workers=1, quiet=True,
                      executor="serial")
    runs = store.runs()
    store.close()
    failed = runs[runs.error.notna()]
    assert set(failed.method) == {"fragile"} and set(failed.snr_db) == {10.0}
    assert failed.error.str.contains("FloatingPointError: simulated failure").all()
    build_outputs(tmp_path, recording=False)
    trials = pd.read_csv(tmp_path / "trials.csv")
    assert len(trials[trials.config == "innovation"]) == 12          # untouched
    assert len(trials[trials.config == "fragile"]) == 6              # only the 0 dB units
    report = (tmp_path / "report.md").read_text()
    assert "simulated failure" in report.split("## Failures")[1]


def test_a_broken_plugin_module_is_listed_as_unavailable(tmp_path, monkeypatch):
    pkg = tmp_path / "someplugins"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "broken.py").write_text("import numpy\nraise ImportError('needs libfoo 2.0')\n")
    (pkg / "fine.py").write_text("X = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registry, "_UNAVAILABLE", [])
    registry._import_package_modules("someplugins")
    assert registry._UNAVAILABLE == [registry.Unavailable("someplugins.broken", "ImportError: needs libfoo 2.0")]
    assert "someplugins.fine" in sys.modules


class Flaky(Method):
    """Innovation detector with a transient fault: while FLAKY_FAIL is set it raises on the
    null unit holding trial 0 (``fail_in = "calibration"``) or on the units above 5 dB
    (``fail_in = "evaluation"``); once the fault is gone it gives the innovation results."""

    name = "flaky"
    task = MANEUVER_DETECTION

    @dataclass(frozen=True)
    class Params:
        fail_in: str = param("evaluation", "phase whose units fail while FLAKY_FAIL is set",
                             choices=("calibration", "evaluation"))

    def run(self, batch, params):
        if os.environ.get("FLAKY_FAIL"):
            null = batch.scene.onset_step is None
            if params.fail_in == "calibration" and null and 0 in batch.trials:
                raise ConnectionError("transient fault (calibration)")
            if params.fail_in == "evaluation" and not null and batch.scene.realised_snr_db.mean() > 5:
                raise ConnectionError("transient fault (evaluation)")
        return Innovation().run(batch, Innovation.Params(window=1))

    def nominal_threshold(self, params, pfa, batch):
        return Innovation().nominal_threshold(Innovation.Params(window=1), pfa, batch)


FLAKY_SWEEP = """
name = "flaky"
scenario = "cv-turn-cv"
trials = 6
chunk = 3
seed = 11
snr_db = [0, 10]

[[methods]]
name = "flaky"
params = { fail_in = ["calibration", "evaluation"] }

[[methods]]
name = "innovation"

[calibration]
h0_trials = 30

[record]
trials = 1
"""


@pytest.fixture
def flaky(monkeypatch):
    registry.register_method(Flaky)
    # registered in this process only: `bench run` runs its units here (no worker process knows it)
    from radarbench.bench.run import runner
    from radarbench.bench.run.executors import SerialExecutor
    monkeypatch.setattr(runner, "make_executor", lambda name, workers, scheduler=None: SerialExecutor())
    yield
    registry._METHODS.pop("flaky", None)


def _bench_run(sweep, out, *options) -> int:
    return main(["run", str(sweep), "--out", str(out), "--workers", "1", "--quiet", "--no-record", *options])


def _stored(out):
    store = Store(out / "results.sqlite")
    try:
        runs = store.runs()
        records = [TrialRecord.from_bytes(b) for b in store.records()]
    finally:
        store.close()
    return runs, records


@pytest.mark.slow
def test_retry_failed_reruns_only_the_failed_pairs(flaky, tmp_path, monkeypatch):
    sweep = tmp_path / "flaky.toml"
    sweep.write_text(FLAKY_SWEEP)
    # --no-cache: the clean results (FLAKY_FAIL unset, which no identity sees) must not serve the faulty runs
    assert _bench_run(sweep, tmp_path / "clean", "--no-cache") == 0           # no fault: the reference

    monkeypatch.setenv("FLAKY_FAIL", "1")
    run = tmp_path / "run"
    assert _bench_run(sweep, run) == 6                                        # failures never stop a run: loud
    runs, _ = _stored(run)
    failed = runs[runs.error.notna()]
    cal = failed[failed.phase == "calibration"]
    assert set(cal.method) == {"flaky[fail_in=calibration]"} and len(cal) == 1
    ev = failed[failed.phase == "evaluation"]
    assert (ev[ev.method == "flaky[fail_in=calibration]"].error.str.contains("no threshold")).all()
    assert len(ev[ev.method == "flaky[fail_in=calibration]"]) == 4            # its every evaluation unit
    assert set(ev[ev.method == "flaky[fail_in=evaluation]"].snr_db) == {10.0}
    assert "transient fault" in (run / "report.md").read_text().split("## Failures")[1]

    monkeypatch.delenv("FLAKY_FAIL")
    assert _bench_run(sweep, run) == 6                                        # a plain re-run retries nothing
    assert _stored(run)[0].error.notna().sum() == len(failed)

    assert _bench_run(sweep, run, "--retry-failed") == 0
    after, records = _stored(run)
    assert after.error.isna().all() and len(after) == len(runs)               # replaced, not added
    innovation = ["unit", "seconds"]
    pd.testing.assert_frame_equal(after[after.method == "innovation"][innovation].reset_index(drop=True),
                                  runs[runs.method == "innovation"][innovation].reset_index(drop=True))  # not re-run
    ok = runs[runs.error.isna()].set_index(["unit", "method"]).seconds
    assert (after.set_index(["unit", "method"]).seconds.loc[ok.index] == ok).all()
    assert (run / "trials.csv").read_text() == (tmp_path / "clean" / "trials.csv").read_text()
    assert "transient fault" not in (run / "report.md").read_text()
    # the recorded trials gained the retried configs' traces, in plan order
    labels = ["flaky[fail_in=calibration]", "flaky[fail_in=evaluation]", "innovation"]
    assert records and all(list(r.methods) == labels for r in records)


#: fork one child per module from a parent that has only the libraries loaded: the first
#: child discovers the plugins as ``bench`` does (what is unavailable there, an optional
#: extra not installed, is the baseline); each other imports its module first, as a user's
#: script would, then discovers, and must find the same plugins unavailable, no more
_IMPORTED_FIRST = r"""
import importlib, os, sys
import numpy, scipy.stats, numba  # noqa: E401,F401 - shared by the children, loaded once

def child(first):
    if first:
        try:
            importlib.import_module(first)
        except Exception:             # an optional extra missing here: the baseline lists it
            pass
    from radarbench.bench import registry
    registry.discover()
    return sorted(f"{u.source}: {u.error}" for u in registry.unavailable())

read, write = os.pipe()
if os.fork() == 0:
    os.write(write, "\n".join(child(None)).encode())
    os._exit(0)
os.close(write)
baseline = set(filter(None, os.fdopen(read).read().split("\n")))
failures = 0
for module in sys.argv[1:]:
    pid = os.fork()
    if pid == 0:
        lost = [line for line in child(module) if line not in baseline]
        print("\n".join(f"{module} first -> {line}" for line in lost), flush=True)
        os._exit(1 if lost else 0)
    failures += os.waitpid(pid, 0)[1] != 0
sys.exit(1 if failures else 0)
"""


def _imported_by_a_sibling() -> list[str]:
    """The built-in plugin modules another module imports names from, and that register a
    plugin themselves: imported first, each registers while half-initialised."""
    import re
    root = Path(registry.__file__).resolve().parent.parent
    sources = [p for folder in ("methods", "scenarios") for p in sorted((root / folder).rglob("*.py"))]
    named = {m for p in sources for m in re.findall(r"^from (radarbench\.(?:methods|scenarios)\.[\w.]+) import",
                                                    p.read_text(), re.M)}
    dotted = {f"radarbench.{p.relative_to(root).with_suffix('').as_posix().replace('/', '.')}": p for p in sources}
    return sorted(m for m in named if m in dotted and re.search(r"^@register_(method|scenario)",
                                                                 dotted[m].read_text(), re.M))


def test_a_plugin_module_imported_first_leaves_every_sibling_available():
    """Was: importing methods.tbd.dp_tbd on its own made pf-tbd 'unavailable' (registering
    DpTbd discovered every plugin, and pf_tbd imported names dp_tbd had not defined yet)."""
    modules = _imported_by_a_sibling()
    assert "radarbench.methods.tbd.dp_tbd" in modules, modules
    proc = subprocess.run([sys.executable, "-c", _IMPORTED_FIRST, *modules], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr[-2000:]
