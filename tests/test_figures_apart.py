"""Report figures drawn by other processes (bench.figures.drawn_apart): the same PNG bytes as
drawn here, and no drawing process outlives the process that started it."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from bench import figures


def _figure():
    fig, ax = figures.plt.subplots(figsize=(4, 3))
    ax.plot([0, 1, 2], [1, 0, 2], "o-", label="a config")
    ax.set_xlabel("SNR (dB)")
    figures._legend_outside(ax)
    return fig


def test_a_figure_drawn_apart_is_the_figure_drawn_here(tmp_path):
    here = figures._save(_figure(), tmp_path / "here.png").read_bytes()
    with figures.drawn_apart(workers=1):
        path = figures._save(_figure(), tmp_path / "apart.png")
        assert not path.exists()                  # drawn by another process, written when waited for
        figures.wait_drawn()
        assert path.read_bytes() == here
    assert figures._drawing is None


DRIVER = """
import os, sys
from pathlib import Path
from bench import figures
import test_figures_apart as t
with figures.drawn_apart(workers=2):
    figures._save(t._figure(), Path(sys.argv[1]) / "a.png")
    figures._save(t._figure(), Path(sys.argv[1]) / "b.png")
    pool = figures._drawing[0]
    while len(pool._processes) < 1:
        pass
    print(" ".join(map(str, pool._processes)), flush=True)
    os._exit(0)                                   # the driver dies without shutting its pool down
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"     # a zombie has exited
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="finds processes through /proc")
def test_drawing_processes_exit_when_their_driver_dies(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([os.path.dirname(__file__), *sys.path])}
    proc = subprocess.run([sys.executable, "-c", DRIVER, str(tmp_path)], capture_output=True, text=True, env=env,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    pids = [int(p) for p in proc.stdout.split()]
    assert pids
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and any(map(_alive, pids)):
        time.sleep(0.1)
    assert not [p for p in pids if _alive(p)]
