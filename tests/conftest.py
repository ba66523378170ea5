"""Shared fixtures and the suite's settings.

The suite runs in parallel (pytest-xdist, ``addopts`` in pyproject.toml): a fixture that
writes must write under ``tmp_path``/``tmp_path_factory``, which are per worker. A
session-scoped fixture runs once per worker process.
"""

import os

#: numba's kernel cache, one folder for the whole suite: its xdist workers and every ``bench``
#: process a test starts (they inherit the variable). Without it the cache followed
#: ``$XDG_CACHE_HOME``, which ``private_cache_home`` makes private to each worker, so each
#: worker compiled every kernel again (minutes of the suite). The folder is numba's
#: user-wide one, where a user's own runs keep their kernels; sharing it changes no result
#: (an entry is keyed by its source, checked by its checksum, and one process compiles a
#: kernel while the others wait: bench/run/numba_cache.py). Set before numba is imported,
#: since numba reads it once. A test of the cache itself sets its own folder.
os.environ.setdefault("NUMBA_CACHE_DIR", os.path.join(os.environ.get("XDG_CACHE_HOME")
                                                      or os.path.expanduser("~/.cache"), "numba"))

from radarbench import bench  # noqa: E402,F401 - first: the portable target (bench/__init__.py) precedes numpy's import
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from hypothesis import settings

#: Hypothesis for every run of the suite (CI included): the same examples every time
#: (``derandomize``), no per-example deadline (a loaded CI machine is no bug), no example
#: database in the working tree. ``max_examples`` is the default for a test that does not
#: ask for a count; the statistical tests set theirs with ``@settings`` and keep them.
#: ``dev``, the inner loop's (``-m "not slow"``, see ``hypothesis_profile``), is ``ci`` with
#: fewer examples for those tests. ``HYPOTHESIS_PROFILE=default`` gives Hypothesis's own
#: randomised search instead.
settings.register_profile("ci", derandomize=True, deadline=None, database=None, max_examples=25,
                          print_blob=True)
settings.register_profile("dev", parent=settings.get_profile("ci"), max_examples=10)


def hypothesis_profile(config) -> str:
    """``$HYPOTHESIS_PROFILE`` if set; else ``dev`` when the ``-m`` expression leaves out a
    test marked ``slow`` (only) and keeps an unmarked one (the inner loop); else ``ci``, the
    profile of the README's command."""
    if "HYPOTHESIS_PROFILE" in os.environ:
        return os.environ["HYPOTHESIS_PROFILE"]
    markexpr = config.getoption("markexpr")
    if not markexpr:
        return "ci"
    try:                                  # pytest's own evaluation of ``-m`` (a private module)
        from _pytest.mark.expression import Expression
        expression = Expression.compile(markexpr)

        def keeps(*marks):                # is a test carrying exactly these marks selected?
            return expression.evaluate(lambda name, **_: name in marks)
        return "dev" if keeps() and not keeps("slow") else "ci"
    except (ImportError, AttributeError, TypeError):    # another pytest: the full profile, never fewer examples
        return "ci"


def pytest_configure(config):
    """Load the Hypothesis profile before the test modules (and their ``@settings``) are
    imported; check the timeout scale once, before any test waits on it."""
    settings.load_profile(hypothesis_profile(config))
    timeout_scale()


#: Test modules each run by one xdist worker as a whole: each has a module-scoped fixture
#: that costs a bench run (or several tests that share one), made once that way. The other
#: tests go one by one to whichever worker is free.
ONE_WORKER_MODULES = ("tests/test_cells_task.py", "tests/test_cli.py", "tests/test_compare.py",
                      "tests/test_recording.py", "tests/test_reliability_io.py", "tests/test_reliability_outputs.py",
                      "tests/test_report_ux.py")


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadgroup`` with ONE_WORKER_MODULES as groups. xdist's own grouping, by the
    ``xdist_group`` mark, never reaches its scheduler under pytest 9 (the worker appends the
    group to ``item._nodeid``, which pytest 9 no longer reads), so the groups are named here,
    by module, for the scheduler on the controller."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadGroupScheduling

    missing = [m for m in ONE_WORKER_MODULES if not (config.rootpath / m).is_file()]
    assert not missing, f"ONE_WORKER_MODULES names no module: {missing}"

    class ModuleGroups(LoadGroupScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return module if module in ONE_WORKER_MODULES else super()._split_scope(nodeid)

    return ModuleGroups(config, log)


def parse_sweep_or_skip(sweep: dict, source: str):
    """``bench.sweep.config.parse_sweep``, or skip the test when the sweep reads data of an optional
    extra not installed here (its one line says what to install, e.g. the [data] extra's
    traffic samples for the real-trajectories preset)."""
    from radarbench.bench.sweep.config import parse_sweep
    from radarbench.bench.errors import ConfigError
    try:
        return parse_sweep(sweep, source)
    except ConfigError as err:
        if "the optional extra: pip install" in err.problem or "run `bench data fetch`" in err.problem:
            pytest.skip(f"{source} needs an optional extra: {err.problem}")
        raise


#: The suite's one knob for its wall-clock bounds: every wait on a process, a lock or a
#: socket is ``scaled(seconds)``, the bound times this variable (default 1). The bounds
#: detect hangs, never slowness: each is several times what the wait takes on a loaded
#: machine; raise the scale on a slower one (CONTRIBUTING.md, 'Tests').
TIMEOUT_SCALE_VARIABLE = "BENCH_TEST_TIMEOUT_SCALE"
#: the bound of a wait for a ``bench`` command or another fresh Python process (s)
PROCESS_BOUND_S = 900


def timeout_scale() -> float:
    """``$BENCH_TEST_TIMEOUT_SCALE`` as a number > 0 (1 when unset); a UsageError naming the
    variable otherwise, so a typo stops the session instead of disabling every bound."""
    raw = os.environ.get(TIMEOUT_SCALE_VARIABLE, "").strip() or "1"
    try:
        scale = float(raw)
    except ValueError:
        scale = float("nan")
    if not (scale > 0 and scale != float("inf")):
        raise pytest.UsageError(f"{TIMEOUT_SCALE_VARIABLE}: expected a number > 0, got {raw!r}")
    return scale


def scaled(seconds: float = PROCESS_BOUND_S) -> float:
    """A wall-clock bound of ``seconds`` times ``$BENCH_TEST_TIMEOUT_SCALE``."""
    return seconds * timeout_scale()


#: id of a TimeoutExpired already reported -> (the exception, kept alive so its id stays
#: unique; the test it was reported at)
_REPORTED_TIMEOUTS: dict[int, tuple] = {}


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """A bound that ran out (``subprocess.TimeoutExpired``) says which knob raises it; in a
    fixture shared by several tests (module or session scope, whose error pytest re-raises
    for each), it is reported once, as the error of the first test, and the others are
    skipped naming it, instead of one error per test."""
    outcome = yield
    report = outcome.get_result()
    if call.excinfo is None or not isinstance(call.excinfo.value, subprocess.TimeoutExpired):
        return
    expired = call.excinfo.value
    first = _REPORTED_TIMEOUTS.setdefault(id(expired), (expired, item.nodeid))[1]
    if report.when == "setup" and first != item.nodeid:
        report.outcome = "skipped"
        report.longrepr = (str(item.path), item.location[1] or 0,
                           f"Skipped: a shared fixture's wait timed out ({expired.timeout:.3g} s); reported at {first}")
        return
    report.sections.append(("wall-clock bound", f"{expired} — a bound of the suite (tests/conftest.py, scaled()); "
                                                f"on a loaded or slow machine raise {TIMEOUT_SCALE_VARIABLE} "
                                                f"(now {timeout_scale():g})"))


def run_bench(*args, cwd=None, timeout=None, check=False):
    """Drive the CLI as a user would: a subprocess, text output, waited on for at most
    ``timeout`` seconds (``scaled()`` by default)."""
    proc = subprocess.run([sys.executable, "-m", "radarbench.bench", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=scaled() if timeout is None else timeout)
    if check and proc.returncode != 0:
        raise AssertionError(f"bench {' '.join(map(str, args))} failed ({proc.returncode}):\n{proc.stderr}")
    return proc


SMALL_SWEEP = """
name = "small"
scenario = "cv-turn-cv"
trials = {trials}
seed = 7
snr_db = {snr}
chunk = {chunk}

[[methods]]
name = "innovation"
params = {{ window = [1, 5] }}

[[methods]]
name = "cumulant"
params = {{ window = 16 }}

[calibration]
pfa = 0.02
mode = "empirical"
h0_trials = {h0}

[record]
trials = 1
"""


def small_sweep_text(trials=12, snr="[0, 8]", chunk=5, h0=60) -> str:
    """SMALL_SWEEP filled in; the defaults are the small sweep of ``write_sweep`` and ``small_run``."""
    return SMALL_SWEEP.format(trials=trials, snr=snr, chunk=chunk, h0=h0)


@pytest.fixture(scope="session", autouse=True)
def private_cache_home(tmp_path_factory):
    """``$XDG_CACHE_HOME`` of this test process and the ``bench`` processes it starts: a
    folder of its own, so the suite neither reads nor writes the user's cache (the ``bench
    list`` cache, docs/running.md 'Commands') and parallel workers never share one."""
    cache = tmp_path_factory.mktemp("cache-home")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("XDG_CACHE_HOME", str(cache))
        patch.delenv("BENCH_RESULTS_CACHE_DIR", raising=False)     # the user's own setting: not in tests
        patch.delenv("BENCH_RESULTS_CACHE_GB", raising=False)
        yield cache


@pytest.fixture(autouse=True)
def private_results_cache(tmp_path_factory, monkeypatch):
    """The results cache (``$BENCH_RESULTS_CACHE_DIR``) of each test: a folder of its own, so
    no test takes results another computed (a test that counts what a run computes, or makes
    a method fail, sees its own runs only). The module and session fixtures, set up before
    it, share the session's cache folder under ``private_cache_home``."""
    folder = tmp_path_factory.mktemp("results-cache")
    monkeypatch.setenv("BENCH_RESULTS_CACHE_DIR", str(folder))
    return folder


@pytest.fixture
def write_sweep(tmp_path):
    """Write a sweep file under ``tmp_path``: ``text``, or the small sweep with ``sizes``
    (``small_sweep_text``'s keywords) changed."""
    def write(name="sweep.toml", text=None, **sizes):
        path = tmp_path / name
        path.write_text(textwrap.dedent(text) if text is not None else small_sweep_text(**sizes))
        return path
    return write


@pytest.fixture
def bench_cli():
    return run_bench


@pytest.fixture(scope="session")
def small_run(tmp_path_factory) -> Path:
    """The small sweep (``write_sweep()``'s) run once through the CLI with one worker, its
    recording included: a complete run folder (``small/sweep.toml``'s ``run/``) that the
    tests using it only read. A test that changes the folder takes ``small_run_copy``."""
    root = tmp_path_factory.mktemp("small")
    sweep = root / "sweep.toml"
    sweep.write_text(small_sweep_text())
    run_bench("run", sweep, "--out", root / "run", "--workers", 1, "--quiet", check=True)
    return root / "run"


@pytest.fixture
def small_run_copy(small_run, tmp_path) -> Path:
    """A copy of ``small_run`` (``tmp_path / "run"``) for a test to change."""
    out = tmp_path / "run"
    shutil.copytree(small_run, out, symlinks=True)
    return out
