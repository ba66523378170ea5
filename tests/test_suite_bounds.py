"""The suite's wall-clock bounds (tests/conftest.py): one knob scales them all, and a
shared fixture whose wait runs out is reported once, naming the bound and the knob."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from conftest import PROCESS_BOUND_S, TIMEOUT_SCALE_VARIABLE, scaled


def test_scaled_multiplies_by_the_knob(monkeypatch):
    monkeypatch.delenv(TIMEOUT_SCALE_VARIABLE, raising=False)
    assert scaled(30) == 30
    monkeypatch.setenv(TIMEOUT_SCALE_VARIABLE, "2.5")
    assert scaled(30) == 75 and scaled() == 2.5 * PROCESS_BOUND_S


@pytest.mark.parametrize("value", ["fast", "0", "-1", "inf", "nan"])
def test_a_bad_scale_stops_the_session_naming_the_variable(monkeypatch, value):
    monkeypatch.setenv(TIMEOUT_SCALE_VARIABLE, value)
    with pytest.raises(pytest.UsageError, match=f"{TIMEOUT_SCALE_VARIABLE}: expected a number > 0"):
        scaled(1)


SHARED_FIXTURE_TIMES_OUT = """
import subprocess
import sys

import pytest


@pytest.fixture(scope="module")
def made_once():
    # a wait bound to run out: the child sleeps far longer than the bound
    subprocess.run([sys.executable, "-c", "import time; time.sleep(60)"], timeout=0.2)


@pytest.mark.parametrize("i", range(5))
def test_uses_it(made_once, i):
    pass
"""


def test_a_shared_fixture_that_times_out_is_one_error_not_one_per_test(tmp_path):
    (tmp_path / "test_shared.py").write_text(textwrap.dedent(SHARED_FIXTURE_TIMES_OUT))
    tests = Path(__file__).resolve().parent
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
                           "-p", "conftest", "-rs", "--rootdir", str(tmp_path), str(tmp_path / "test_shared.py")],
                          cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(tests)},
                          capture_output=True, text=True, timeout=scaled(300))
    tail = proc.stdout.splitlines()[-1]
    assert "1 error" in tail and "4 skipped" in tail and "passed" not in tail, proc.stdout
    assert "wall-clock bound" in proc.stdout and f"raise {TIMEOUT_SCALE_VARIABLE}" in proc.stdout
    assert "SKIPPED [4] test_shared.py:13: a shared fixture's wait timed out (0.2 s); reported at " \
           "test_shared.py::test_uses_it[0]" in proc.stdout
