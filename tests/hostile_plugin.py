"""A hostile plugin distribution for the reliability tests, written to a folder
that goes on ``PYTHONPATH`` (a package plus a ``.dist-info`` with its entry
points: what ``pip install`` leaves behind).

* method ``crash`` — the innovation detector, except on evaluation units above
  5 dB, where it misbehaves as its parameter ``how`` says: ``os-exit``
  (``os._exit(3)``: the worker dies), ``system-exit`` (raises SystemExit),
  ``keyboard-interrupt`` (raises KeyboardInterrupt), ``sleep`` (120 s: past any
  time limit), ``wait-file`` (writes ``$HOSTILE_RELEASE.started.TRIAL``, then waits
  until the file ``$HOSTILE_RELEASE`` exists), ``none`` (never);
* scenario ``broken-cv`` — ``cv-turn-cv`` whose ``generate`` raises above 5 dB;
* entry points that must be listed as unavailable, never break a command:
  ``exits-at-import`` (``sys.exit(0)`` at import), ``innovation`` (a built-in
  name), ``bad-task`` (an unknown task), ``wrong-group`` (a method declared as
  a task).

With ``HOSTILE_OFF`` set in the environment nothing misbehaves: the results are
then those of a clean run (``--retry-failed`` must reach them).
"""

import textwrap
from pathlib import Path

METHODS = '''
import os
import sys
import time
from dataclasses import dataclass

from radarbench.bench.core import MANEUVER_DETECTION, Method
from radarbench.bench.params import param
from radarbench.methods.maneuver.innovation import Innovation


def _misbehaves(batch):
    return (not os.environ.get("HOSTILE_OFF") and batch.scene.onset_step is not None
            and batch.scene.realised_snr_db.mean() > 5)


class Crash(Method):
    """The innovation detector, misbehaving above 5 dB."""

    name = "crash"
    task = MANEUVER_DETECTION

    @dataclass(frozen=True)
    class Params:
        how: str = param("none", "how to misbehave above 5 dB",
                         choices=("none", "os-exit", "system-exit", "keyboard-interrupt", "sleep", "wait-file"))

    def run(self, batch, params):
        if _misbehaves(batch):
            if params.how == "os-exit":
                sys.stdout.flush()
                os._exit(3)
            if params.how == "system-exit":
                raise SystemExit(4)
            if params.how == "keyboard-interrupt":
                raise KeyboardInterrupt
            if params.how == "sleep":
                time.sleep(3600)                 # for as long as a test lasts: until stopped
            if params.how == "wait-file":
                release = os.environ["HOSTILE_RELEASE"]
                open(f"{release}.started.{int(batch.trials[0])}", "w").close()
                deadline = time.monotonic() + float(os.environ.get("HOSTILE_WAIT_S", "900"))
                while not os.path.exists(os.environ["HOSTILE_RELEASE"]) and time.monotonic() < deadline:
                    time.sleep(0.02)
        return Innovation().run(batch, Innovation.Params(window=1))

    def nominal_threshold(self, params, pfa, batch):
        return Innovation().nominal_threshold(Innovation.Params(window=1), pfa, batch)
'''

SCENARIOS = '''
import os

from radarbench.scenarios.cv_turn_cv import CvTurnCv


class BrokenCv(CvTurnCv):
    """cv-turn-cv whose generate raises above 5 dB."""

    name = "broken-cv"

    def generate(self, params, snr_db, n, rng):
        if not os.environ.get("HOSTILE_OFF") and snr_db is not None and snr_db > 5:
            raise ValueError("the scene generator broke")
        return super().generate(params, snr_db, n, rng)
'''

EXITS = '''
import sys
sys.exit(0)
'''

DUPLICATE = '''
from dataclasses import dataclass

from radarbench.bench.core import MANEUVER_DETECTION, Method


class Impostor(Method):
    """Takes a built-in's name: the bare name is refused, ``radarbench:innovation`` is the built-in."""

    name = "innovation"
    task = MANEUVER_DETECTION

    @dataclass(frozen=True)
    class Params:
        pass
'''

BAD_TASK = '''
from dataclasses import dataclass

from radarbench.bench.core import Method


class BadTask(Method):
    """Declares a task nobody registered."""

    name = "bad-task"
    task = "cfar"

    @dataclass(frozen=True)
    class Params:
        pass
'''

ENTRY_POINTS = """
[bench.tasks]
wrong-group = hostile_plugin.methods:Crash

[bench.scenarios]
broken-cv = hostile_plugin.scenarios:BrokenCv

[bench.methods]
crash = hostile_plugin.methods:Crash
exits-at-import = hostile_plugin.exits
innovation = hostile_plugin.duplicate:Impostor
bad-task = hostile_plugin.bad_task:BadTask
"""

#: entry point -> the reason ``bench list`` must give
UNAVAILABLE = {
    "bench.methods:exits-at-import": "SystemExit",
    "bench.methods:bad-task": "task 'cfar' is not one of",
    "bench.tasks:wrong-group": "is a Method, not a Task",
}


def install(site: Path) -> Path:
    """Write the distribution under ``site`` (a folder for PYTHONPATH); returns ``site``."""
    pkg = site / "hostile_plugin"
    pkg.mkdir(parents=True, exist_ok=True)
    (pkg / "__init__.py").write_text("")
    for name, text in (("methods", METHODS), ("scenarios", SCENARIOS), ("exits", EXITS),
                       ("duplicate", DUPLICATE), ("bad_task", BAD_TASK)):
        (pkg / f"{name}.py").write_text(textwrap.dedent(text))
    info = site / "hostile_plugin-0.1.dist-info"
    info.mkdir(exist_ok=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: hostile-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    return site
