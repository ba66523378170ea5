import subprocess
import sys
import textwrap

import pytest


def run_bench(*args, cwd=None, timeout=300, check=False):
    """Drive the CLI as a user would: a subprocess, text output."""
    proc = subprocess.run([sys.executable, "-m", "bench", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout)
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


@pytest.fixture
def write_sweep(tmp_path):
    def write(name="sweep.toml", trials=12, snr="[0, 8]", chunk=5, h0=60, text=None):
        path = tmp_path / name
        path.write_text(textwrap.dedent(text) if text is not None else
                        SMALL_SWEEP.format(trials=trials, snr=snr, chunk=chunk, h0=h0))
        return path
    return write


@pytest.fixture
def bench_cli():
    return run_bench
