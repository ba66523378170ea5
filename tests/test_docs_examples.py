"""Every Python example in the docs runs as printed (docs/*.md and the README): each
block is extracted and run in a fresh interpreter, in a folder whose ``runs/`` holds the
runs the examples name (copies of the small run); a block that registers a method is
also installed as a plugin and run through a small sweep, which must fail on no unit."""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import scaled
from test_task_plugin import env_with, install

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)
#: the run folders the examples read, each a copy of the small run
RUNS = ("before", "after", "quick")


def _examples():
    for page in PAGES:
        for i, code in enumerate(BLOCK.findall(page.read_text(encoding="utf-8"))):
            yield pytest.param(code, id=f"{page.name}-{i}")


EXAMPLES = list(_examples())


def test_the_docs_have_examples():
    assert len(EXAMPLES) >= 4


@pytest.fixture(scope="module")
def workdir(small_run, tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("docs-examples")
    for name in RUNS:
        shutil.copytree(small_run, root / "runs" / name)
    return root


@pytest.mark.slow
@pytest.mark.parametrize("code", EXAMPLES)
def test_an_example_runs_as_printed(code, workdir):
    ran = subprocess.run([sys.executable, "-c", code], cwd=workdir, capture_output=True, text=True, timeout=scaled())
    assert ran.returncode == 0, ran.stderr[-2000:]


METHOD_SWEEP = """
name = "docs-example"
scenario = "cv-turn-cv"
trials = 12
chunk = 6
seed = 1
snr_db = [0, 8]

[calibration]
h0_trials = 60

[[methods]]
name = "{name}"
"""


@pytest.mark.slow
@pytest.mark.parametrize("code", [e for e in EXAMPLES if "@register_method" in e.values[0]])
def test_a_method_example_runs_on_every_unit(code, tmp_path):
    name = re.search(r'name = "([^"]+)"', code).group(1)
    cls = re.search(r"class (\w+)\(", code).group(1)
    install(tmp_path / "site", "docsexample", {"method": code}, f"[bench.methods]\n{name} = docsexample.method:{cls}\n")
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(METHOD_SWEEP.format(name=name))
    ran = subprocess.run([sys.executable, "-m", "radarbench.bench", "run", str(sweep), "--out", str(tmp_path / "run"),
                          "--workers", "1", "--quiet"], env=env_with(tmp_path / "site"), capture_output=True,
                         text=True, timeout=scaled())
    assert ran.returncode == 0, ran.stderr[-2000:]
    assert "None: every method config ran on every unit." in (tmp_path / "run" / "report.md").read_text()


def test_a_method_that_still_names_its_scenarios_is_refused_in_one_line():
    from radarbench.bench.core import MANEUVER_DETECTION, Method
    from radarbench.bench.registry import PluginError, register_method

    class Old(Method):
        name = "old-style"
        task = MANEUVER_DETECTION
        scenarios = ("cv-turn-cv",)

    with pytest.raises(PluginError, match="'scenarios' is no longer read; declare what it reads from a scene in 'needs'"):
        register_method(Old)
