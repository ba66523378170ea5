"""Processes and plugins on a flaky machine, driven as a hostile user would: a plugin on PYTHONPATH
whose method calls ``os._exit``,
raises SystemExit or KeyboardInterrupt, sleeps past the time limit or holds its
unit; a scenario whose ``generate`` raises; plugins that exit at import, reuse a
built-in name, declare an unknown task; the driver killed with -9 or stopped with
SIGTERM or SIGINT in the middle of a run; a scheduler nobody listens on.

Every run is a ``bench`` subprocess with a marker in its environment; the
processes a run leaves behind are found by that marker in ``/proc/*/environ``.
"""

import os
import signal
import socket
import sqlite3
import subprocess
import sys
import time
import uuid

import pandas as pd
import pytest

from hostile_plugin import UNAVAILABLE, install
from conftest import scaled

pytestmark = pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="finds processes through /proc")

MARKER = "BENCH_TEST_RUN"


def _processes(marker: str) -> list[tuple[int, str]]:
    """(pid, command line) of the live processes whose environment holds ``marker``."""
    found = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/environ", "rb") as f:
                env = f.read()
            with open(f"/proc/{name}/stat") as f:
                state = f.read().rsplit(")", 1)[1].split()[0]
            with open(f"/proc/{name}/cmdline", "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode(errors="replace")[:160]
        except OSError:
            continue
        if f"{MARKER}={marker}".encode() in env.split(b"\0") and state not in ("Z", "X"):
            found.append((int(name), cmd))
    return found


def _wait_for(condition, seconds: float, what: str, proc=None) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"the run ended (exit {proc.returncode}) before {what}")
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {seconds:g} s (a bound of tests/conftest.py scaled()): {what}")
        time.sleep(0.02)


def _no_process_left(marker: str) -> None:
    deadline = time.monotonic() + scaled(300)
    while (left := _processes(marker)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not left, f"processes of the run left behind: {left}"


def _stored(db) -> list[str]:
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=scaled(60)) as con:
            return sorted(r[0] for r in con.execute("SELECT key FROM units"))
    except sqlite3.Error:
        return []


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    """An environment whose PYTHONPATH holds the hostile plugin distribution."""
    site = install(tmp_path_factory.mktemp("hostile") / "site")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), *filter(None, [env.get("PYTHONPATH")])])
    env.pop("HOSTILE_OFF", None)
    env["HOSTILE_WAIT_S"] = str(scaled(900))        # how long a held unit waits for its release
    return env


def _own_cache(env: dict) -> dict:
    """``env`` (set up once for the module) with this test's own results cache (conftest's
    ``private_results_cache``): a hostile run never takes results an earlier test's run kept."""
    return {**env, "BENCH_RESULTS_CACHE_DIR": os.environ["BENCH_RESULTS_CACHE_DIR"]}


def _bench(env, *args, **extra):
    return subprocess.run([sys.executable, "-m", "radarbench.bench", *map(str, args)],
                          env={**_own_cache(env), **extra}, capture_output=True, text=True, timeout=scaled())


def _start(env, *args, stderr, **extra):
    """A run in a session of its own (its signals reach the driver alone), Ctrl-C as at a terminal."""
    return subprocess.Popen([sys.executable, "-m", "radarbench.bench", *map(str, args)],
                            env={**_own_cache(env), **extra},
                            stdout=subprocess.DEVNULL, stderr=stderr, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _failures(report) -> str:
    return report.read_text().split("## Failures")[1].split("\n## ")[0]


# ------------------------------------------------------------------ cause 8: bad plugins

@pytest.mark.slow
def test_bad_plugins_are_listed_as_unavailable_and_every_command_still_works(hostile, tmp_path):
    listed = _bench(hostile, "list")
    assert listed.returncode == 0 and "Traceback" not in listed.stderr, listed.stderr
    head, unavailable = listed.stdout.split("\nunavailable:\n")
    for source, reason in UNAVAILABLE.items():
        line = next((x for x in unavailable.splitlines() if x.split()[0] == source), None)
        assert line is not None and reason in line, (source, unavailable)
    assert "crash " in head and "broken-cv " in head                   # the good ones of the same plugin
    innovation = next(x for x in head.splitlines() if x.split()[0] == "radarbench:innovation")
    assert "NIS" in innovation                                        # the built-in, by its qualified name
    assert "method 'innovation' is registered twice (radarbench.methods.maneuver.innovation" in head

    for name, says in (("exits-at-import", ("method 'exits-at-import' is unavailable: ", "SystemExit")),
                       ("bad-task", ("method 'bad-task' is unavailable: ", "task 'cfar' is not one of")),
                       ("innovation", ("method 'innovation' is registered twice", "hostile_plugin.duplicate",
                                       "name 'radarbench:innovation' or 'hostile-plugin:innovation'"))):
        sweep = tmp_path / f"{name}.toml"
        sweep.write_text(f'name = "x"\nscenario = "cv-turn-cv"\nsnr_db = [0]\n[[methods]]\nname = "{name}"\n')
        run = _bench(hostile, "run", sweep, "--out", tmp_path / name, "--quiet")
        lines = run.stderr.strip().splitlines()
        assert run.returncode == 2 and len(lines) == 1, run.stderr
        assert all(part in lines[0] for part in says), lines[0]
        assert not (tmp_path / name).exists()


# ------------------------------------------------------------------ cause 4: failed units, not dead runs

CRASH_SWEEP = """
name = "crash"
trials = 8
seed = 5
snr_db = [0, 10]
chunk = 4

[[scenarios]]
name = "cv-turn-cv"

[[scenarios]]
name = "broken-cv"

[[methods]]
name = "crash"
params = { how = ["os-exit", "system-exit", "keyboard-interrupt"] }

[[methods]]
name = "radarbench:innovation"

[calibration]
h0_trials = 20

[record]
trials = 1
"""


@pytest.mark.slow
def test_a_dying_or_exiting_plugin_fails_its_units_and_the_run_completes(hostile, tmp_path):
    """One worker (the driver survives a method's os._exit), then --retry-failed once the
    faults are gone: the results of a clean run."""
    sweep = tmp_path / "crash.toml"
    sweep.write_text(CRASH_SWEEP)
    clean, run = tmp_path / "clean", tmp_path / "run"
    # --no-cache: the clean results (HOSTILE_OFF, which no identity sees) must not serve the hostile run
    assert _bench(hostile, "run", sweep, "--out", clean, "--workers", 2, "--quiet", "--no-cache",
                  HOSTILE_OFF="1").returncode == 0

    first = _bench(hostile, "run", sweep, "--out", run, "--workers", 1, "--quiet")
    assert first.returncode == 6 and "Traceback" not in first.stderr, first.stderr
    _only_the_culprits_failed(run, clean, "worker process died: it exited with code 3")

    again = _bench(hostile, "run", sweep, "--out", run, "--workers", 2, "--quiet", "--retry-failed", HOSTILE_OFF="1")
    assert again.returncode == 0, again.stderr
    assert (run / "trials.csv").read_text() == (clean / "trials.csv").read_text()
    assert _failures(run / "report.md").strip() == "None: every method config ran on every unit."


@pytest.mark.slow
def test_under_dask_a_dying_plugin_fails_its_units_alone(hostile, tmp_path):
    """Dask fails every unit of a worker that dies; the units beside the culprit
    are run again alone, the culprit's unit config by config (the runner's isolation, as for
    the local pool): the failures are those of the local pool, the innocent configs' results
    those of a clean run."""
    pytest.importorskip("distributed")
    sweep = tmp_path / "crash.toml"
    sweep.write_text(CRASH_SWEEP)
    clean, run = tmp_path / "clean", tmp_path / "run"
    # --no-cache: the clean results (HOSTILE_OFF, which no identity sees) must not serve the hostile run
    assert _bench(hostile, "run", sweep, "--out", clean, "--workers", 2, "--quiet", "--no-cache",
                  HOSTILE_OFF="1").returncode == 0
    first = _bench(hostile, "run", sweep, "--out", run, "--executor", "dask", "--workers", 2, "--quiet")
    assert (run / "report.md").is_file() and "Traceback" not in first.stderr, first.stderr
    _only_the_culprits_failed(run, clean, "worker process died while running this unit (alone on the Dask")


def _only_the_culprits_failed(run, clean, death: str) -> None:
    """The failures of CRASH_SWEEP: the method's configs on its units above 5 dB (``death``: how
    its os-exit config's failure begins), every config on the broken scenario's; the rest ran."""
    with sqlite3.connect(f"file:{run / 'results.sqlite'}?mode=ro", uri=True) as con:
        runs = pd.read_sql_query("SELECT runs.*, units.scenario, units.snr_db FROM runs JOIN units "
                                 "ON runs.unit = units.key", con)
    failed = runs[runs.error.notna()]
    # the method's faults: only its own configs, only its units above 5 dB, on the working scenario
    own = failed[failed.scenario == "cv-turn-cv"]
    assert set(own.snr_db) == {10.0} and len(own) == 2 * 3
    causes = own.groupby("method").error.first()
    assert causes["crash[how=os-exit]"].startswith(death)
    assert causes["crash[how=system-exit]"].startswith("SystemExit: 4")
    assert causes["crash[how=keyboard-interrupt]"].startswith("KeyboardInterrupt")
    # the scenario's fault: every method config on its units above 5 dB, the rest of it ran
    broken = failed[failed.scenario == "broken-cv"]
    assert set(broken.snr_db) == {10.0} and len(broken) == 2 * 4
    assert broken.error.str.startswith("the scenario failed to generate the unit: ValueError").all()
    assert runs[runs.snr_db != 10.0].error.isna().all()
    failures = _failures(run / "report.md")
    assert death in failures and "SystemExit" in failures and "generate" in failures
    trials = pd.read_csv(run / "trials.csv")
    reference = pd.read_csv(clean / "trials.csv")
    ours = "radarbench:innovation"
    pd.testing.assert_frame_equal(trials[trials.config == ours].reset_index(drop=True),
                                  reference[(reference.config == ours) & ((reference.scenario == "cv-turn-cv")
                                            | (reference.snr_db == 0))].reset_index(drop=True))


# ------------------------------------------------------------------ cause 9: time limit, workers cap

SLOW_SWEEP = """
name = "slow"
scenario = "cv-turn-cv"
trials = 5
seed = 5
snr_db = [0, 10]
chunk = 5
unit_timeout_s = LIMIT

[[methods]]
name = "crash"
params = { how = "sleep" }

[[methods]]
name = "radarbench:innovation"

[calibration]
h0_trials = 10
"""


@pytest.mark.slow
def test_a_unit_past_its_time_limit_fails_and_its_worker_is_replaced(hostile, tmp_path):
    sweep = tmp_path / "slow.toml"
    limit = round(scaled(15))        # the sleeping unit's time limit; the others end long before it
    sweep.write_text(SLOW_SWEEP.replace("LIMIT", str(limit)))
    marker = uuid.uuid4().hex
    run = _bench(hostile, "run", sweep, "--out", tmp_path / "run", "--workers", 8, "--no-record",
                 **{MARKER: marker})
    assert run.returncode == 6, run.stderr                           # the method sleeps an hour: it was stopped
    # 2 calibration + 2 evaluation units: 4 workers, said in one line
    assert "4 units to run: starting 4 workers (--workers 8)" in run.stderr.splitlines(), run.stderr
    with sqlite3.connect(tmp_path / "run" / "results.sqlite") as con:
        failed = con.execute("SELECT unit, method, error FROM runs WHERE error IS NOT NULL").fetchall()
    assert [(u, m) for u, m, _ in failed] == [("evaluation/cv-turn-cv/+10/000000000+5", "crash[how=sleep]")]
    assert failed[0][2].startswith(f"timeout: the unit ran longer than unit_timeout_s = {limit} s")
    assert "timeout" in _failures(tmp_path / "run" / "report.md")
    _no_process_left(marker)                                          # the stopped worker too
    assert f"unit_timeout_s = {limit}" in (tmp_path / "run" / "plan.toml").read_text()


# ------------------------------------------------------------------ causes 3, 7, 9: signals and kill -9

HELD_SWEEP = """
name = "held"
scenario = "cv-turn-cv"
trials = 16
seed = 5
snr_db = [0, 10]
chunk = 4

[[methods]]
name = "crash"
params = { how = "wait-file" }

[calibration]
h0_trials = 16
"""
#: 4 calibration units, 4 at 0 dB, then 4 at 10 dB that hold until released: with two
#: workers, two of them are in flight and two wait
HELD_UNITS, HELD_FREE = 12, 8
HELD_IN_FLIGHT = ["evaluation/cv-turn-cv/+10/000000000+4", "evaluation/cv-turn-cv/+10/000000004+4"]


def _held_run(hostile, tmp_path, *options):
    """A held run with two workers, returned once two units are held in flight."""
    sweep = tmp_path / "held.toml"
    sweep.write_text(HELD_SWEEP)
    release = tmp_path / "release"
    marker = uuid.uuid4().hex
    err = open(tmp_path / "stderr.txt", "w")
    proc = _start(hostile, "run", sweep, "--out", tmp_path / "run", "--workers", 2, "--quiet", "--no-record",
                  *options, stderr=err, HOSTILE_RELEASE=str(release), **{MARKER: marker})
    err.close()
    started = [tmp_path / f"release.started.{t}" for t in (0, 4)]
    _wait_for(lambda: all(p.exists() for p in started), scaled(600), "two units held in flight", proc)
    assert _stored(tmp_path / "run" / "results.sqlite") == sorted(
        [f"calibration/cv-turn-cv/null/{s:09d}+4" for s in (0, 4, 8, 12)]
        + [f"evaluation/cv-turn-cv/+0/{s:09d}+4" for s in (0, 4, 8, 12)])
    return proc, marker, release, sweep


@pytest.mark.slow
def test_kill_9_of_the_driver_leaves_no_process_and_an_incomplete_report(hostile, tmp_path):
    proc, marker, release, _ = _held_run(hostile, tmp_path)
    try:
        alive = _processes(marker)
        # driver, forkserver, two workers, resource tracker: the scan sees them
        assert len(alive) >= 5 and any(p == proc.pid for p, _ in alive), alive
        os.kill(proc.pid, signal.SIGKILL)                # the driver alone
        proc.wait(timeout=scaled(300))
        _no_process_left(marker)
    finally:
        release.touch()
    report = _bench(hostile, "report", tmp_path / "run", "--no-record")
    assert report.returncode == 0, report.stderr
    text = (tmp_path / "run" / "report.md").read_text()
    assert f"**Incomplete run: {HELD_FREE} of {HELD_UNITS} units stored.**" in text


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_stopped_run_stores_its_units_in_flight_and_leaves_no_process(hostile, tmp_path, sig):
    proc, marker, release, sweep = _held_run(hostile, tmp_path)
    try:
        os.kill(proc.pid, sig)                           # the driver alone
        _wait_for(lambda: "stopping" in (tmp_path / "stderr.txt").read_text(), scaled(300), "the driver took the signal",
                  proc)
    finally:
        release.touch()                                  # the units in flight may now end
    assert proc.wait(timeout=scaled()) == 130
    err = (tmp_path / "stderr.txt").read_text()
    assert "Traceback" not in err, err
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"interrupted: {HELD_FREE + 2} of {HELD_UNITS} units stored") and \
        "run the same command again to resume" in last, err
    stored = _stored(tmp_path / "run" / "results.sqlite")
    assert set(HELD_IN_FLIGHT) <= set(stored) and len(stored) == HELD_FREE + 2      # kept; none started after
    _no_process_left(marker)

    # two units left: two workers of the eight asked for, and --quiet says nothing about it
    again = _bench(hostile, "run", sweep, "--out", tmp_path / "run", "--workers", 8, "--quiet", "--no-record",
                   HOSTILE_RELEASE=str(release))
    assert again.returncode == 0 and again.stderr == "", again.stderr
    assert len(_stored(tmp_path / "run" / "results.sqlite")) == HELD_UNITS
    assert _failures(tmp_path / "run" / "report.md").strip() == "None: every method config ran on every unit."


# ------------------------------------------------------------------ cause 7: the scheduler, before the folder

def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("address, problem", [
    ("foo://x", "is not a scheduler address"),
    ("tcp://127.0.0.1:{port}", "cannot connect to tcp://127.0.0.1:{port}"),
], ids=["bad-scheme", "nobody-listens"])
def test_a_bad_or_unreachable_scheduler_is_one_line_at_once_and_writes_nothing(write_sweep, tmp_path, capsys,
                                                                              monkeypatch, address, problem):
    """At once: refused before dask's client is made (its 15 s of retries and 30 s of clean-up
    never start), checked by making the client a failure rather than by timing the run."""
    pytest.importorskip("distributed")
    from radarbench.bench.run import executors
    from radarbench.bench.cli import main

    def no_client(*_):
        raise AssertionError("dask's client was made for an address that check_scheduler should refuse")
    monkeypatch.setattr(executors, "_client", no_client)
    port = _free_port()
    address, problem = address.format(port=port), problem.format(port=port)
    code = main(["run", str(write_sweep()), "--out", str(tmp_path / "out"), "--executor", "dask", "--scheduler",
                 address, "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith("error: --scheduler: ") and problem in err, err
    assert not (tmp_path / "out").exists()
