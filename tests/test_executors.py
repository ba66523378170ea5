"""Executors only map units: results never depend on them."""

import os
import sys

import pytest

from radarbench.bench.cli import main
from radarbench.bench.results.store import MethodRun, Store, UnitResult
from conftest import scaled

# (run name, bench run options, chunk): every one must give the trials.csv of the first
RUNS = [
    ("local-x1-chunk5", ["--workers", "1"], 5),
    ("local-x2-chunk5", ["--workers", "2"], 5),
    ("local-x2-chunk3", ["--workers", "2"], 3),
    ("local-x1-chunk12", ["--workers", "1"], 12),
    ("dask-x2-chunk5", ["--executor", "dask", "--workers", "2"], 5),   # a LocalCluster: started once
]


@pytest.fixture
def reference(small_run):
    """The small sweep run with the first configuration of RUNS: ``small_run`` (chunk 5, one
    local worker; its recording does not change the trials)."""
    return small_run / "trials.csv"


@pytest.mark.slow
@pytest.mark.parametrize("name, options, chunk", RUNS[1:], ids=[r[0] for r in RUNS[1:]])
def test_identical_trials_whatever_the_executor_workers_and_chunks(reference, bench_cli, write_sweep, tmp_path,
                                                                   name, options, chunk):
    if "dask" in options:
        pytest.importorskip("distributed")
    out = tmp_path / name
    bench_cli("run", write_sweep(f"{name}.toml", chunk=chunk), "--out", out, *options, "--quiet", "--no-record",
              check=True)
    assert (out / "trials.csv").read_text() == reference.read_text()


def test_a_lost_worker_s_unit_is_run_again_and_yielded_once(tmp_path):
    """A worker dies while it holds a unit: dask runs the unit on another worker (the
    nanny restarts the dead one); every unit comes back exactly once."""
    pytest.importorskip("distributed")
    from radarbench.bench.run.executors import DaskExecutor
    marker = str(tmp_path / "died")

    def unit(i):                      # a closure: dask ships it by value to the workers
        import os as _os
        import time as _time
        if i == 3 and not _os.path.exists(marker):
            open(marker, "w").close()
            _os._exit(1)              # the worker process dies with the unit in hand
        _time.sleep(0.05)
        return i, _os.getpid()

    ex = DaskExecutor(2)
    try:
        results = list(ex.imap_unordered(unit, range(12)))
    finally:
        ex.shutdown()
    assert os.path.exists(marker)
    assert sorted(i for i, _ in results) == list(range(12))


@pytest.mark.slow
def test_under_dask_only_the_unit_that_kills_its_worker_fails(tmp_path):
    """Dask fails every unit of a worker that dies (``KilledWorker``): the units beside the
    culprit are run again alone and come back; the culprit alone yields a failure."""
    pytest.importorskip("distributed")
    from radarbench.bench.run.executors import DaskExecutor, UnitFailure

    def unit(i):
        import os as _os
        import time as _time
        if i == 3:
            _os._exit(1)              # always: the culprit
        _time.sleep(0.3)              # the others are in flight when it strikes
        return i

    ex = DaskExecutor(2)
    try:
        results = list(ex.imap_unordered(unit, range(8)))
    finally:
        ex.shutdown()
    failures = [r for r in results if isinstance(r, UnitFailure)]
    assert [f.task for f in failures] == [3] and "worker process died" in failures[0].cause
    assert sorted(r for r in results if not isinstance(r, UnitFailure)) == [0, 1, 2, 4, 5, 6, 7]


def test_workers_that_differ_from_the_driver_are_refused(monkeypatch):
    """Workers must run the driver's harness and plugins, or results would silently differ."""
    pytest.importorskip("distributed")
    from radarbench import bench
    from radarbench.bench.errors import ConfigError
    from radarbench.bench.run.executors import DaskExecutor
    monkeypatch.setattr(bench, "__version__", "0.0.0-driver")          # the workers keep the real one
    with pytest.raises(ConfigError, match="differs from this machine: bench '.*' \\(here '0.0.0-driver'\\)"):
        DaskExecutor(1)


def _result(key="evaluation/s/+0/000000000+2", error=None, value=1.0):
    import numpy as np
    run = MethodRun("m", 0.1, error=error, metrics=None if error else {"detected": np.array([value, value])})
    return UnitResult(key, "evaluation", "s", 0.0, 0, 2, 0.01, runs=[run],
                      common={"trial": np.array([0, 1])})


def test_the_store_ignores_a_second_result_of_a_stored_unit(tmp_path):
    store = Store(tmp_path / "results.sqlite")
    assert store.save_unit(_result(value=1.0))
    assert not store.save_unit(_result(value=2.0))                 # e.g. a unit dask ran twice
    assert len(store.units()) == 1 and len(store.runs()) == 1
    [(_, _, _, _, cols)] = list(store.iter_metrics())
    assert cols["detected"].tolist() == [1.0, 1.0]                   # the first result stays
    store.close()


def test_a_failed_run_is_replaced_by_a_later_good_one(tmp_path):
    store = Store(tmp_path / "results.sqlite")
    store.save_unit(_result(error="ValueError: boom"))
    assert store.failed_runs() == {"evaluation/s/+0/000000000+2": {"m"}}
    assert store.save_unit(_result(value=3.0))
    assert store.failed_runs() == {} and len(store.runs()) == 1
    [(_, _, _, _, cols)] = list(store.iter_metrics())
    assert cols["detected"].tolist() == [3.0, 3.0]
    store.close()


def _run_main(argv, capsys):
    code = main(argv)
    return code, capsys.readouterr().err


def test_dask_missing_is_one_line_saying_how_to_install_it(write_sweep, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)          # import distributed -> ImportError
    code, err = _run_main(["run", str(write_sweep()), "--out", str(tmp_path / "out"), "--executor", "dask",
                           "--quiet"], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert 'pip install "radar-maneuver-bench[dask]"' in err
    assert not (tmp_path / "out").exists()


def test_scheduler_needs_the_dask_executor(write_sweep, tmp_path, capsys):
    code, err = _run_main(["run", str(write_sweep()), "--out", str(tmp_path / "out"), "--scheduler",
                           "tcp://127.0.0.1:8786", "--quiet"], capsys)
    assert code == 2 and err.startswith("error: --scheduler: only with --executor dask"), err
    assert not (tmp_path / "out").exists()


def test_an_unreachable_scheduler_is_one_line(write_sweep, tmp_path, monkeypatch, capsys):
    pytest.importorskip("distributed")
    from radarbench.bench.run import executors
    monkeypatch.setattr(executors.DaskExecutor, "connect_timeout", "1s")
    code, err = _run_main(["run", str(write_sweep()), "--out", str(tmp_path / "out"), "--executor", "dask",
                           "--scheduler", "tcp://127.0.0.1:9", "--quiet", "--no-record"], capsys)
    assert code == 2 and err.count("\n") == 1 and "--scheduler: cannot connect to tcp://127.0.0.1:9" in err, err


def _still_running_after(pids: list[int], seconds: float) -> list[int]:
    """The processes of ``pids`` still running once they have all ended or ``seconds`` have
    passed (a bound on a wait for an exit, not a timing); those are then killed."""
    import time
    deadline = time.monotonic() + seconds
    while any(os.path.exists(f"/proc/{p}") for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    alive = [p for p in pids if os.path.exists(f"/proc/{p}")]
    for p in alive:
        os.kill(p, 9)
    return alive


POOL_THEN_KILL = """
import os, time
from radarbench.bench.run.processes import process_pool
if __name__ == "__main__":
    pool = process_pool(2)
    for job in [pool.submit(time.sleep, 0.05) for _ in range(4)]:
        job.result()
    with open(os.environ["PIDS_FILE"], "w") as f:
        f.write(" ".join(map(str, pool._processes)))
    os.kill(os.getpid(), 9)
"""


def test_the_report_pools_processes_end_with_a_killed_driver(tmp_path):
    """bench.run.processes.process_pool (the report's figures): a driver killed with SIGKILL
    leaves none of its processes behind (they were orphans before)."""
    import subprocess

    script, pids_file = tmp_path / "pool_then_kill.py", tmp_path / "pids"
    script.write_text(POOL_THEN_KILL)
    proc = subprocess.run([sys.executable, str(script)], env={**os.environ, "PIDS_FILE": str(pids_file)},
                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=scaled())
    assert proc.returncode == -9
    pids = [int(p) for p in pids_file.read_text().split()]
    assert len(pids) == 2
    assert _still_running_after(pids, scaled(300)) == []


FRESH_THEN_STOP = """
import os, sys, time
from radarbench.bench.run.processes import call_in_fresh_process

def sleep_forever(pids_file):
    with open(pids_file, "w") as f:
        f.write(str(os.getpid()))
    time.sleep(600)

def stop_driver_when_started(signum):
    while not os.path.exists(os.environ["PIDS_FILE"]):
        time.sleep(0.05)
    os.kill(os.getpid(), signum)

if __name__ == "__main__":
    import signal, threading
    signal.signal(signal.SIGINT, signal.default_int_handler)   # Ctrl-C as on a terminal, whatever the parent ignored
    signum = signal.SIGKILL if sys.argv[1] == "kill" else signal.SIGINT     # killed, or Ctrl-C
    threading.Thread(target=stop_driver_when_started, args=(signum,), daemon=True).start()
    call_in_fresh_process(sleep_forever, os.environ["PIDS_FILE"])
"""


@pytest.mark.parametrize("stop, returncode", [("kill", -9), ("interrupt", -2)])   # -2: an uncaught Ctrl-C
def test_a_fresh_process_call_ends_with_its_interrupted_or_killed_driver(tmp_path, stop, returncode):
    """bench.run.processes.call_in_fresh_process (bench perf's measurements): Ctrl-C ends the
    call at once and a driver killed with SIGKILL leaves no process behind (with the pool
    it replaced, the interrupt waited for the call to end and SIGKILL left it running)."""
    import subprocess

    script, pids_file = tmp_path / "fresh_then_stop.py", tmp_path / "pid"
    script.write_text(FRESH_THEN_STOP)
    proc = subprocess.run([sys.executable, str(script), stop], env={**os.environ, "PIDS_FILE": str(pids_file)},
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=scaled())
    assert proc.returncode == returncode
    if stop == "interrupt":
        assert "KeyboardInterrupt" in proc.stderr
    assert _still_running_after([int(pids_file.read_text())], scaled(300)) == []


def _exit_at_once():
    os._exit(7)


def test_a_fresh_process_call_returns_raises_or_says_it_died():
    from radarbench.bench.run.processes import call_in_fresh_process
    assert call_in_fresh_process(max, 3, 11) == 11
    with pytest.raises(ValueError, match="invalid literal"):
        call_in_fresh_process(int, "eleven")
    with pytest.raises(RuntimeError, match=r"_exit_at_once died \(exit status 7\)"):
        call_in_fresh_process(_exit_at_once)
