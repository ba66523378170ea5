"""Results bound to the code and data that made them, loud failures, bounds at
discovery, one nominal-threshold contract, data paths read from the sweep's folder.

The method author's loop is tried as a user types it, from an outside plugin package
(registered through entry points, as in tests/test_task_plugin.py): edit a method, run
the same command, compare the folder with its own previous state.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import sqlite3
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from radarbench.bench import registry
from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.core import Method
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params, declaration_problem, param
from tests.test_task_plugin import METHOD as TASK_PLUGIN_METHOD
from tests.test_task_plugin import SCENARIO as TASK_PLUGIN_SCENARIO
from tests.test_task_plugin import TASK
from conftest import scaled

def _edited(text: str, *changes: tuple[str, str]) -> str:
    for old, new in changes:
        assert old in text, old
        text = text.replace(old, new)
    return text


#: tests/test_task_plugin.py's scenario, its bumps over a background read from a data file
SCENARIO = _edited(
    TASK_PLUGIN_SCENARIO, ("benchdemo", "benchloop"), ('name = "bumps"', 'name = "csv-bumps"'),
    ('steps: int = param(20, "steps per trial", ge=2, le=10_000, why="a bump needs two steps; a test stays small")',
     'background: str = param("", "CSV of one background value per step", kind="path")'),
    ("        k = params.steps\n        z = rng.standard_normal((k, 1))\n",
     '        background = np.loadtxt(params.background, delimiter=",", ndmin=1)\n        k = background.size\n'
     "        z = rng.standard_normal((k, 1)) + background[None, :, None]\n"))

ARGMAX = '''
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

from radarbench.bench.core import Method
from radarbench.bench.params import param


class SmoothedArgMax(Method):
    """The step of the largest moving average."""

    name = "argmax"
    task = "peak-finding"

    @dataclass(frozen=True)
    class Params:
        smooth: int = param(1, "moving-average length (steps)", ge=1, le=9, why="a short window")

    def run(self, batch, params):
        return np.argmax(uniform_filter1d(batch.z[..., 0], params.smooth, axis=1), axis=1)
'''

ABSMAX = _edited(TASK_PLUGIN_METHOD, ('name = "argmax"', 'name = "absmax"'),
                 ("np.argmax(batch.z[..., 0]", "np.argmax(np.abs(batch.z[..., 0])"))

BROKEN = '''
from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import Method


class Broken(Method):
    """Inverts a singular matrix: fails on every unit, inside NumPy."""

    name = "broken"
    task = "peak-finding"

    @dataclass(frozen=True)
    class Params:
        pass

    def run(self, batch, params):
        gram = np.zeros((2, 2))
        return np.linalg.inv(gram)  # the line the failure must name
'''

UNBOUNDED = '''
from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import Method
from radarbench.bench.params import param


class Unbounded(Method):
    """Declares a window without bounds."""

    name = "unbounded"
    task = "peak-finding"

    @dataclass(frozen=True)
    class Params:
        window: int = param(3, "window length")

    def run(self, batch, params):
        return np.zeros(batch.n, int)
'''

ENTRY_POINTS = """
[bench.tasks]
peak-finding = benchloop.task:PeakFinding

[bench.scenarios]
csv-bumps = benchloop.scenario:Bumps

[bench.methods]
argmax = benchloop.argmax:SmoothedArgMax
absmax = benchloop.absmax:ArgMax
broken = benchloop.broken:Broken
unbounded = benchloop.unbounded:Unbounded
"""

SWEEP = """
name = "loop"
scenario = "csv-bumps"
trials = 20
chunk = 10
seed = 3
snr_db = [0, 12]
scenario_params = {background = "data/background.csv"}

[[methods]]
name = "argmax"
params = {smooth = [1, 3]}

[[methods]]
name = "absmax"
"""

#: the peak-finding task of tests/test_task_plugin.py, ranked by its per-trial hits (bench compare reads them)
RANKED_TASK = _edited(TASK, ('headline_columns = ("accuracy",)', 'headline_columns = ("accuracy",)\n'
                             '    ranking_metric = "correct"\n    ranking_label = "accuracy"\n    ranking_binary = True'))
MODULES = {"task": RANKED_TASK, "scenario": SCENARIO, "argmax": ARGMAX,
           "absmax": ABSMAX, "broken": BROKEN, "unbounded": UNBOUNDED}


@pytest.fixture
def loop(tmp_path):
    """(environment, the plugin package folder, the sweep file): the sweep and its data in
    their own folder, run from another one (data paths are the sweep's, not the cwd's)."""
    site = tmp_path / "site"
    pkg = site / "benchloop"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    for name, text in MODULES.items():
        (pkg / f"{name}.py").write_text(textwrap.dedent(text))
    info = site / "benchloop-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: benchloop\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    sweeps = tmp_path / "sweeps"
    (sweeps / "data").mkdir(parents=True)
    (sweeps / "data" / "background.csv").write_text(",".join(["0"] * 16) + "\n")
    (sweeps / "loop.toml").write_text(SWEEP)
    (tmp_path / "elsewhere").mkdir()
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), *filter(None, [env.get("PYTHONPATH")])])
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    return env, pkg, sweeps / "loop.toml"


def _bench(env, cwd, *args):
    return subprocess.run([sys.executable, "-m", "radarbench.bench", *map(str, args)], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=scaled())


def _runs(db: Path) -> dict[tuple[str, str], tuple]:
    """(unit, method config) -> (identity, seconds, error, traceback) of a store."""
    with contextlib.closing(sqlite3.connect(db)) as con:
        return {(u, m): rest for u, m, *rest in
                con.execute("SELECT unit, method, identity, seconds, error, traceback FROM runs")}


def _identity(runs: dict, config: str) -> set[str]:
    return {v[0] for (_, m), v in runs.items() if m == config}


@pytest.mark.slow
def test_the_method_authors_loop_reruns_exactly_what_changed(loop):
    env, pkg, sweep = loop
    cwd = sweep.parent.parent / "elsewhere"
    out = cwd / "run"
    first = _bench(env, cwd, "run", sweep, "--out", out, "--workers", 1, "--quiet", "--no-record")
    assert first.returncode == 0, first.stderr
    before = _runs(out / "results.sqlite")
    assert len(before) == 4 * 3 and all(v[0] for v in before.values())

    # edit one method's source: exactly its two configs re-run, absmax's results stay
    source = pkg / "argmax.py"
    source.write_text(source.read_text().replace("axis=1), axis=1)", "axis=1), axis=1).astype(np.int64)"))
    second = _bench(env, cwd, "run", sweep, "--out", out, "--workers", 1, "--no-record")
    assert second.returncode == 0, second.stderr
    assert "Nothing to run" not in second.stderr
    assert "code or data changed: re-running 8 (unit, method config) runs" in second.stderr, second.stderr
    after = _runs(out / "results.sqlite")
    assert after.keys() == before.keys()
    for key, value in after.items():
        same = key[1] == "absmax"
        assert (value == before[key]) == same, key
    old, new = _identity(before, "argmax[smooth=1]"), _identity(after, "argmax[smooth=1]")
    assert len(old) == len(new) == 1 and old != new
    previous = _runs(out / "previous" / "results.sqlite")
    assert {m for _, m in previous} == {"argmax[smooth=1]", "argmax[smooth=3]"} and len(previous) == 8
    assert all(previous[k] == before[k] for k in previous)
    report = (out / "report.md").read_text()
    provenance = report.split("## Provenance")[1]
    row = next(line for line in provenance.splitlines() if line.startswith("| `argmax[smooth=1]`"))
    assert f"`{new.pop()}`" in row and f"`{old.pop()}`" in row       # both identities, new and replaced
    code_cell = row.split("|")[5]                      # config, kind, module (distribution), identity, code
    assert "benchloop 0.1" not in code_cell            # a plugin on PYTHONPATH: its sources, not a version

    compare = _bench(env, cwd, "compare", out / "previous", out)
    assert compare.returncode == 0, compare.stderr
    assert "argmax[smooth=1]" in compare.stdout
    # absmax did not change: previous/ holds none of its results, so compare lists it as in one run only
    assert all("not run in A" in line for line in compare.stdout.splitlines() if "absmax" in line)

    # edit the data file the scenario reads: its units re-run, whole
    (sweep.parent / "data" / "background.csv").write_text(",".join(["0"] * 15 + ["0.5"]) + "\n")
    third = _bench(env, cwd, "run", sweep, "--out", out, "--workers", 1, "--no-record")
    assert third.returncode == 0, third.stderr
    assert "code or data changed: re-running 4 units (csv-bumps" in third.stderr, third.stderr
    assert all(v[0] == after[k][0] for k, v in _runs(out / "results.sqlite").items())   # methods unchanged
    with contextlib.closing(sqlite3.connect(out / "previous" / "results.sqlite")) as con:
        assert con.execute("SELECT count(*) FROM units").fetchone()[0] == 4


@pytest.mark.slow
def test_a_config_failing_every_unit_is_loud(loop):
    env, _pkg, sweep = loop
    sweep.write_text(SWEEP.replace('name = "absmax"', 'name = "broken"'))
    out = sweep.parent / "run"
    run = _bench(env, sweep.parent, "run", sweep, "--out", out, "--workers", 1, "--quiet", "--no-record")
    assert run.returncode == 6, run.stderr
    lines = run.stderr.splitlines()
    failing = [line for line in lines if line.startswith("  broken:")]
    assert len(failing) == 1 and "4 of 4 units failed (on csv-bumps)" in failing[0], run.stderr
    assert re.search(r"LinAlgError: Singular matrix \(broken\.py:\d+\)", failing[0]), failing[0]
    assert not any(line.startswith("  argmax") for line in lines)
    stored = [v for (_, m), v in _runs(out / "results.sqlite").items() if m == "broken"]
    assert len(stored) == 4 and all("Traceback (most recent call last)" in v[3] and "numpy" in v[3]
                                    for v in stored)
    assert "broken.py:" in (out / "report.md").read_text().split("## Failures")[1]
    printed = _bench(env, sweep.parent, "report", out, "--tracebacks")
    assert printed.returncode == 0 and printed.stdout.startswith("== broken: 4 units")
    assert "np.linalg.inv(gram)" in printed.stdout


@pytest.mark.slow          # an end-to-end CLI run (or fuzzing): CI runs it, the inner loop does not
def test_a_plugin_parameter_without_bounds_is_refused_at_discovery(loop):
    env, _pkg, sweep = loop
    listed = _bench(env, sweep.parent, "list")
    assert listed.returncode == 0, listed.stderr
    unavailable = listed.stdout.split("unavailable:")[1]
    assert "method 'unbounded': parameter 'window' is not bounded on both sides" in unavailable
    sweep.write_text(SWEEP.replace('name = "absmax"', 'name = "unbounded"\nparams = {window = -5}'))
    run = _bench(env, sweep.parent, "run", sweep, "--out", sweep.parent / "run", "--quiet")
    assert run.returncode == 2 and "'unbounded' is unavailable: method 'unbounded': parameter 'window'" \
        in run.stderr, run.stderr
    assert not (sweep.parent / "run").exists()


# ------------------------------------------------------------------ in process

@pytest.mark.parametrize("declare, says", [
    (lambda: param(3, "w"), "parameter 'x' is not bounded on both sides"),
    (lambda: param(3, "w", ge=1), "parameter 'x' is not bounded on both sides"),
    (lambda: param(3, "w", ge=1, le=9), "parameter 'x': its bounds give no reason"),
    (lambda: param(30, "w", ge=1, le=9, why="short"), "its default 30 breaks its own declaration"),
    (lambda: param(1.0, "w", gt=0.0, lt=2.0, why="a ratio"), None),
    (lambda: param((1.0,), "w", ge=0.0, le=2.0, why="ratios"), None),
    (lambda: param("a.csv", "w", kind="path"), None),
], ids=["none", "one-side", "no-why", "default-outside", "float", "tuple", "path"])
def test_the_parameter_convention_is_checked_on_declaration(declare, says):
    tp = {tuple: tuple[float, ...], str: str}.get(type(declare().default), type(declare().default))
    params = dataclass(frozen=True)(type("Params", (), {"__annotations__": {"x": tp}, "x": declare()}))
    problem = declaration_problem(params)
    assert (problem is None) if says is None else (says in problem), problem


def test_an_unsupported_parameter_type_is_refused():
    params = dataclass(frozen=True)(type("Params", (), {"__annotations__": {"x": dict}, "x": None}))
    assert "type dict is not supported" in declaration_problem(params)


def test_a_method_without_a_nominal_threshold_has_none_and_nominal_calibration_is_refused():
    dp = registry.get_method("dp-tbd")
    assert not dp.has_nominal_threshold() and registry.get_method("cumulant").has_nominal_threshold()
    assert np.isnan(Method.nominal_threshold(dp(), dp.Params(), 0.01, None))
    sweep = {"name": "n", "scenario": "tbd-grid", "snr_db": [6], "trials": 2,
             "scenario_params": dict(registry.get_scenario("tbd-grid").small_params),
             "methods": [{"name": "dp-tbd"}], "calibration": {"mode": "nominal", "h0_trials": 10}}
    with pytest.raises(ConfigError, match=r"calibration\.mode: 'nominal' needs an analytic threshold and "
                                          r"'dp-tbd' has none .*use 'empirical', 'gumbel'"):
        parse_sweep(sweep)
    parse_sweep(sweep | {"calibration": {"mode": "gumbel", "h0_trials": 10}})


@dataclass(frozen=True)
class _PathParams:
    data: str = param("", "a data file", kind="path")


def test_a_data_path_is_read_from_the_sweep_folder_and_labelled_by_its_name(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "x.csv").write_text("1\n")
    with contextlib.chdir(tmp_path / "d"):                # the working directory is never the base
        with pytest.raises(ConfigError, match=r"data: no such file: .*/elsewhere/x\.csv \(relative to the sweep"):
            build_params(_PathParams, {"data": "x.csv"}, tmp_path / "elsewhere")
    resolved = build_params(_PathParams, {"data": "d/x.csv"}, tmp_path)
    assert resolved.data == str(tmp_path / "d" / "x.csv")
    assert build_params(_PathParams, {"data": resolved.data}).data == resolved.data    # a resolved plan
    from radarbench.bench.sweep.plan import ComponentConfig, label_value
    assert label_value(resolved, "data") == "x.csv"
    moved = build_params(_PathParams, {"data": "/somewhere/else/x.csv"})
    assert ComponentConfig("s", resolved, "s", "").key == ComponentConfig("s", moved, "s", "").key


SMALL = {"name": "id", "scenario": "cv-turn-cv", "trials": 4, "seed": 1, "snr_db": [6], "chunk": 4,
         "scenario_params": {"steps": 120, "onset_step": 60}, "methods": [{"name": "innovation"}],
         "calibration": {"pfa": 0.05, "h0_trials": 10}, "record": {"trials": 0}}


def test_a_store_without_identities_is_rerun_and_its_results_kept_aside(tmp_path):
    """An earlier bench's store (no identity columns): every unit is unknown, re-run once,
    with one line saying so; the old results go to previous/ and equal the new ones."""
    from radarbench.bench.run.runner import plan_record, run_sweep
    from radarbench.bench.results.store import SCHEMA, Store
    plan = parse_sweep(SMALL)
    out = tmp_path / "run"
    run_sweep(plan, out, plan_record=plan_record(plan, "t"), executor="serial", quiet=True).close()
    with contextlib.closing(sqlite3.connect(out / "results.sqlite")) as con:
        con.execute("UPDATE units SET identity = NULL")
        con.commit()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        store = run_sweep(plan, out, plan_record=plan_record(plan, "t"), executor="serial")
    assert "stored without a recorded identity (by an earlier bench): re-running 4 units" in err.getvalue()
    assert "Nothing to run" not in err.getvalue()
    assert all(known for (known,) in store.db.execute("SELECT identity IS NOT NULL FROM units"))
    new = dict(store.db.execute("SELECT unit, data FROM metrics"))
    store.close()
    old = Store(out / "previous" / "results.sqlite")
    assert dict(old.db.execute("SELECT unit, data FROM metrics")) == new
    old.close()
    again = io.StringIO()
    with contextlib.redirect_stderr(again):
        run_sweep(plan, out, plan_record=plan_record(plan, "t"), executor="serial").close()
    assert again.getvalue().startswith("Nothing to run: all 4 units stored")
    # the columns an earlier store lacks are added when it is opened
    legacy = tmp_path / "legacy.sqlite"
    with contextlib.closing(sqlite3.connect(legacy)) as con:
        con.executescript(SCHEMA.replace(", identity TEXT);", ");").replace(
            "identity TEXT, traceback TEXT, PRIMARY KEY", "PRIMARY KEY"))
    Store(legacy).close()
    with contextlib.closing(sqlite3.connect(legacy)) as con:
        assert {r[1] for r in con.execute("PRAGMA table_info(runs)")} >= {"identity", "traceback"}
        assert "identity" in {r[1] for r in con.execute("PRAGMA table_info(units)")}


def test_identities_follow_the_plugins_own_modules_only():
    from radarbench.bench.run.identity import code_identity, identity_roots
    cumulant = dict(code_identity(*identity_roots(registry.get_method("cumulant"))).modules)
    assert {"radarbench.methods.maneuver.cumulant", "radarbench.methods.maneuver.base", "radarbench.models.kalman"} <= set(cumulant)
    assert not any(m.split(".")[0] in ("numpy", "scipy") for m in cumulant)
    assert "radarbench.methods.maneuver.innovation" not in cumulant
    assert code_identity("radarbench.methods.maneuver.cumulant").hash != code_identity("radarbench.methods.maneuver.innovation").hash


def test_plan_toml_lists_the_identities(tmp_path):
    import tomllib
    from radarbench.bench.run.runner import plan_record, run_sweep, write_plan_toml
    plan = parse_sweep(SMALL)
    store = run_sweep(plan, tmp_path, plan_record=plan_record(plan, "t"), executor="serial", quiet=True)
    write_plan_toml(tmp_path / "plan.toml", plan, "t", store.stamps)
    stamps = json.loads(store.meta("identities"))
    store.close()
    written = tomllib.loads((tmp_path / "plan.toml").read_text())["provenance"]["identities"]
    assert written == stamps and set(written["methods"]) == {"innovation"}


def test_a_code_identity_follows_edits_of_the_plugin_and_of_what_it_imports_only(tmp_path, monkeypatch):
    """In one process too: an edit of the module or of a module it imports changes the
    identity; an edit of a module that another registered class of its package imports
    does not (a module no class imports may be loaded by a computed name: it counts)."""
    import importlib

    from radarbench.bench.run.identity import code_identity
    pkg = tmp_path / "idpkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "_helpers.py").write_text("SCALE = 1\n")
    (pkg / "other.py").write_text("X = 1\n")
    (pkg / "mine.py").write_text("import numpy as np\n\n\ndef f():\n    from ._helpers import SCALE\n"
                                 "    return np.ones(2) * SCALE\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.import_module("idpkg.mine")

    class Other:                              # a registered class of the package that imports other.py
        __module__ = "idpkg.other"
    monkeypatch.setattr(registry, "_METHODS", {**registry._METHODS, "other": Other})
    first = code_identity("idpkg.mine")
    assert [m for m, _ in first.modules] == ["idpkg", "idpkg._helpers", "idpkg.mine"] and not first.distribution
    (pkg / "other.py").write_text("X = 22\n")
    assert code_identity("idpkg.mine") == first
    (pkg / "_helpers.py").write_text("SCALE = 22\n")
    assert code_identity("idpkg.mine").hash != first.hash


def test_a_name_in_a_module_that_fails_to_import_is_not_a_module(tmp_path, monkeypatch):
    """``from methods.multitarget.stonesoup_peer import X`` scanned in a module whose peer lacks its extra:
    locating ``methods.multitarget.stonesoup_peer.X`` imports the peer, which raises; the scan must go on."""
    from radarbench.bench.run import identity
    (tmp_path / "brokenpkg").mkdir()
    (tmp_path / "brokenpkg" / "__init__.py").write_text("")
    (tmp_path / "brokenpkg" / "peer.py").write_text("raise RuntimeError('needs an extra')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert identity.module_file("brokenpkg.peer.Name") is None
    assert identity.module_file("brokenpkg.peer") == (tmp_path / "brokenpkg" / "peer.py").resolve()
