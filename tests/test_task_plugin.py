"""A task from outside bench/: registered through the entry-point group
``bench.tasks`` (with its scenario and method through ``bench.scenarios`` and
``bench.methods``), run end to end by ``bench run``, with no edit in bench/.
The task defines its scene type next to it; its scenario builds that scene.

The plugin is a package plus a ``.dist-info`` folder (its entry points) on a
temporary PYTHONPATH entry, which is what ``pip install`` leaves behind.
"""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest

from conftest import scaled

ROOT = Path(__file__).resolve().parents[1]

TASK = '''
"""Peak finding: a method names the step of a single bump; scored as right or wrong."""
from dataclasses import dataclass

import numpy as np
import pandas as pd

from radarbench.bench.core import Scene, require
from radarbench.bench.metrics import binomial_interval, by_cell, mean_realised_snr
from radarbench.bench.recording.draw import log_series
from radarbench.bench.recording.record import MethodTrace
from radarbench.bench.tasks.base import OutputError, Task


@dataclass(frozen=True, kw_only=True, eq=False)
class PeakScene(Scene):
    """What a peak-finding scenario tells the harness."""

    #: (n,) the step of each trial's bump
    peak_step: np.ndarray

    def __post_init__(self):
        super().__post_init__()
        require(self, "peak_step", isinstance(self.peak_step, np.ndarray) and self.peak_step.ndim == 1,
                "an (n,) array of steps")


class PeakFinding(Task):
    """Peak finding: the step of a bump in noise."""

    name = "peak-finding"
    scene_type = PeakScene
    noun = short_noun = "peak finders"
    recording_text = "per peak finder the step it named"
    summary_columns = ("n_trials", "accuracy", "accuracy_low", "accuracy_high", "realised_snr_db")
    headline_columns = ("accuracy",)
    method_entities = ("named",)

    def check_output(self, out, batch):
        out = np.asarray(out)
        if out.shape != (batch.n,) or out.dtype.kind not in "iu":
            raise OutputError(f"expected ({batch.n},) integer steps, got {out.shape} {out.dtype}")
        return out

    def trial_metrics(self, batch, out, threshold):
        return {"correct": out == batch.scene.peak_step}

    def recorded_method(self, batch, out, i, threshold):
        return MethodTrace(arrays={"named": (np.arange(batch.steps) == out[i]).astype(float)})

    def summarise(self, trials, series):
        rows = []
        for keys, g in by_cell(trials):
            hits = int(g["correct"].sum())
            low, high = binomial_interval(hits, len(g))
            rows.append({**keys, "n_trials": len(g), "accuracy": hits / len(g), "accuracy_low": low,
                         "accuracy_high": high, "realised_snr_db": mean_realised_snr(g)})
        return pd.DataFrame(rows)

    def log_trial(self, stream, layout, rec):
        import rerun as rr
        t = np.asarray(rec.t, float)
        for m in layout.methods_of(self):
            log_series(stream, m.path("named"), t, np.arange(len(t)), rec.methods[m.label].arrays["named"],
                       rr.SeriesLines(names=m.label, colors=[m.color], widths=[1.0]))

    def report_sections(self, ctx):
        rows = "\\n".join(f"| `{r.config}` | {r.snr_db:g} | {r.accuracy:.2f} |" for r in ctx.summary.itertuples())
        return ["## Peak finding: accuracy", "| config | SNR (dB) | accuracy |\\n|---|---|---|\\n" + rows]
'''

SCENARIO = '''
"""A bump of height 10^(SNR/20) at a random step of unit Gaussian noise."""
from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import Batch, Scenario
from radarbench.bench.params import param
from benchdemo.task import PeakScene


class Bumps(Scenario):
    """One bump in white noise."""

    name = "bumps"
    tasks = ("peak-finding",)

    @dataclass(frozen=True)
    class Params:
        steps: int = param(20, "steps per trial", ge=2, le=10_000, why="a bump needs two steps; a test stays small")

    def generate(self, params, snr_db, n, rng):
        k = params.steps
        z = rng.standard_normal((k, 1))
        peak = np.minimum((rng.uniform(()) * k).astype(int), k - 1)
        if snr_db is not None:
            z[np.arange(n), peak, 0] += 10 ** (snr_db / 20)
        scene = PeakScene(peak_step=peak, realised_snr_db=np.full(n, np.nan if snr_db is None else snr_db))
        return Batch(t=np.arange(k, dtype=float), truth=np.zeros((n, k, 2)), z=z, scene=scene,
                     trials=np.asarray(rng.trials))
'''

METHOD = '''
from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import Method


class ArgMax(Method):
    """The step of the largest sample."""

    name = "argmax"
    task = "peak-finding"

    @dataclass(frozen=True)
    class Params:
        pass

    def run(self, batch, params):
        return np.argmax(batch.z[..., 0], axis=1)
'''

ENTRY_POINTS = """
[bench.tasks]
peak-finding = benchdemo.task:PeakFinding
broken = benchdemo.missing:Nothing

[bench.scenarios]
bumps = benchdemo.scenario:Bumps

[bench.methods]
argmax = benchdemo.method:ArgMax
"""

SWEEP = """
name = "peaks"
scenario = "bumps"
trials = 40
chunk = 20
seed = 3
snr_db = [0, 12]

[[methods]]
name = "argmax"
"""


def install(site, name: str, modules: dict[str, str], entry_points: str) -> None:
    """Distribution ``name`` 0.1 in the folder ``site``: package ``name`` holding
    ``modules`` (module name -> source) and a ``.dist-info`` with ``entry_points``."""
    pkg = site / name
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    for module, text in modules.items():
        (pkg / f"{module}.py").write_text(textwrap.dedent(text))
    info = site / f"{name}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(entry_points)


def env_with(site) -> dict:
    """This process's environment with ``site`` first on PYTHONPATH."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), *filter(None, [env.get("PYTHONPATH")])])
    return env


@pytest.fixture
def plugin_env(tmp_path):
    """Environment whose PYTHONPATH holds the benchdemo distribution."""
    install(tmp_path / "site", "benchdemo", {"task": TASK, "scenario": SCENARIO, "method": METHOD}, ENTRY_POINTS)
    return env_with(tmp_path / "site")


def _bench(env, *args):
    return subprocess.run([sys.executable, "-m", "radarbench.bench", *map(str, args)], env=env, capture_output=True,
                          text=True, timeout=scaled())


@pytest.mark.slow
def test_a_task_from_an_entry_point_runs_end_to_end(plugin_env, tmp_path):
    listed = _bench(plugin_env, "list")
    assert listed.returncode == 0, listed.stderr
    assert "peak-finding" in listed.stdout and "bumps" in listed.stdout and "argmax" in listed.stdout
    assert "bench.tasks:broken" in listed.stdout.split("unavailable:")[1]       # listed, never fatal

    sweep, out = tmp_path / "peaks.toml", tmp_path / "run"
    sweep.write_text(SWEEP)
    run = _bench(plugin_env, "run", sweep, "--out", out, "--workers", 2, "--quiet")
    assert run.returncode == 0, run.stderr
    summary = pd.read_csv(out / "summary.csv")
    assert {"accuracy", "accuracy_low", "accuracy_high"} <= set(summary.columns)
    assert summary.set_index("snr_db").accuracy[12.0] > summary.set_index("snr_db").accuracy[0.0]
    report = (out / "report.md").read_text()
    assert "## Peak finding: accuracy" in report and "per peak finder the step it named" in " ".join(report.split())
    assert "## Failures\n\nNone" in report

    from rerun.chunk import RrdReader

    from radarbench.bench.recording import entity_root, rerun_path
    paths = set(RrdReader(out / "recording.rrd").store().schema().entity_paths())
    assert rerun_path(f"{entity_root('bumps', 12.0, 0)}/argmax/named") in paths


@pytest.mark.slow          # a pytest session of its own (the conformance module's imports)
def test_the_conformance_tests_pass_on_the_task_plugin(plugin_env):
    """tests/test_conformance.py, as a plugin author runs it with the plugin installed: its
    method returns a bare array, which its task takes (docs/extending.md, 'Writing a task')."""
    proc = subprocess.run([sys.executable, "-m", "pytest", "-v", "-n", "0", "-p", "no:cacheprovider",
                           "tests/test_conformance.py", "-k", "argmax"], cwd=ROOT, env=plugin_env,
                          capture_output=True, text=True, timeout=scaled())
    assert proc.returncode == 0, proc.stdout[-3000:]
    ran = [line for line in proc.stdout.splitlines() if "[bumps-argmax] PASSED" in line]
    assert len(ran) == 2, proc.stdout[-3000:]           # test_method_conforms, test_a_trials_numbers_...
