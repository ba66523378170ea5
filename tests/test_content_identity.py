"""A config's identity is the content of the code that computes its numbers
(docs/architecture.md, 'Identities'): an edit of executed code reaches it, wherever the code
is loaded from (a dynamic import, a module without source, the harness's numerics), and a
comment, a docstring, a move or a rename does not; and a scenario's random streams are
keyed by the parameters set away from their defaults (docs/architecture.md, 'Random streams').
"""

from __future__ import annotations

import contextlib
import importlib
import io
import py_compile
import sqlite3
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from radarbench.bench.run import identity
from radarbench.bench import registry
from radarbench.bench.params import param, params_as_dict
from radarbench.bench.sweep.plan import ComponentConfig
from radarbench.bench.sweep.rng import stable_key
from tests.test_identity import _bench, loop  # noqa: F401 - the outside plugin's fixture


def _package(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))


def _fresh(*names: str) -> None:
    """Forget modules a test rewrote (the identity reads files; the import system caches)."""
    for name in [m for m in sys.modules if m.split(".")[0] in names]:
        del sys.modules[name]
    identity.module_file.cache_clear()
    importlib.invalidate_caches()


@pytest.fixture
def idpkg(tmp_path, monkeypatch):
    """A plugin package on sys.path: ``mine`` imports a helper module and a numeric helper."""
    _package(tmp_path, {
        "idpkg/__init__.py": "",
        "idpkg/helpers/__init__.py": "",
        "idpkg/helpers/kalman.py": '''
            """A helper."""
            import numpy as np


            def gain(p, r):
                return p / (p + r)   # the scalar Kalman gain
            ''',
        "idpkg/mine.py": '''
            """The plugin."""
            from idpkg.helpers.kalman import gain


            def run(p):
                return gain(p, 1.0)
            ''',
    })
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path / "idpkg"
    _fresh("idpkg")


def _code(module: str = "idpkg.mine") -> identity.CodeIdentity:
    _fresh("idpkg")
    importlib.import_module(module)
    return identity.code_identity(module)


def test_comments_docstrings_and_formatting_are_not_code(idpkg):
    first = _code()
    helper = idpkg / "helpers" / "kalman.py"
    helper.write_text(helper.read_text().replace('"""A helper."""', '"""A helper, now documented at length."""')
                      .replace("# the scalar Kalman gain", "# K = P / (P + R)")
                      .replace("p / (p + r)", "p / ( p + r )"))
    assert _code().hash == first.hash
    helper.write_text(helper.read_text().replace("p / ( p + r )", "p / (p + 2 * r)"))
    assert _code().hash != first.hash


def test_a_module_moved_or_renamed_keeps_every_identity(idpkg):
    first = _code()
    moved = idpkg / "filters" / "scalar_gain.py"
    moved.parent.mkdir()
    (moved.parent / "__init__.py").write_text('"""Filters."""\n')
    (idpkg / "helpers" / "kalman.py").rename(moved)
    mine = idpkg / "mine.py"
    mine.write_text(mine.read_text().replace("from idpkg.helpers.kalman import gain",
                                             "from idpkg.filters.scalar_gain import gain"))
    second = _code()
    assert second.hash == first.hash
    assert "idpkg.filters.scalar_gain" in dict(second.modules)


def test_a_module_no_registered_class_imports_is_in_the_identity(idpkg):
    """A module loaded by a computed name (``importlib.import_module(f"...{name}")``) is
    seen by no import statement: every module of a plugin's package that none of its
    registered classes imports belongs to each of its identities."""
    mine = idpkg / "mine.py"
    mine.write_text("import importlib\n\n\ndef run(p, kind='scalar'):\n"
                    "    return importlib.import_module(f'idpkg.loaded.{kind}').gain(p)\n")
    _package(idpkg.parent, {"idpkg/loaded/__init__.py": "", "idpkg/loaded/scalar.py": "def gain(p):\n    return p\n"})
    first = _code()
    assert "idpkg.loaded.scalar" in dict(first.modules)
    (idpkg / "loaded" / "scalar.py").write_text("def gain(p):\n    return 2 * p\n")
    assert _code().hash != first.hash


def test_a_literal_dynamic_import_is_followed(idpkg):
    mine = idpkg / "mine.py"
    mine.write_text("import importlib\n\n\ndef run(p):\n"
                    "    return importlib.import_module('idpkg.helpers.kalman').gain(p, 1.0)\n")
    assert "idpkg.helpers.kalman" in dict(_code().modules)


def test_a_module_without_source_is_hashed_by_its_bytes(idpkg):
    """A plugin shipped as a ``.pyc`` (no ``.py``): never a constant "unknown"."""
    helper = idpkg / "helpers" / "kalman.py"

    def compile_only(text: str) -> None:
        helper.write_text(textwrap.dedent(text))
        py_compile.compile(str(helper), cfile=str(helper.with_suffix(".pyc")))
        helper.unlink()

    compile_only("def gain(p, r):\n    return p / (p + r)\n")
    first = _code()
    assert identity.module_file("idpkg.helpers.kalman").suffix == ".pyc"
    assert "idpkg.helpers.kalman" in dict(first.modules)
    compile_only("def gain(p, r):\n    return p / (p + 3 * r)\n")
    assert _code().hash != first.hash


def test_the_harness_numerics_are_in_the_identities_that_use_them():
    tracker = dict(identity.code_identity(*identity.identity_roots(registry.get_method("cv-kf"))).modules)
    assert {"radarbench.bench.batched", "radarbench.bench.tasks.tracking", "radarbench.bench.tasks.tracking.metrics",
            "radarbench.bench.metrics", "radarbench.bench.calibration", "radarbench.models.kalman"} <= set(tracker)
    assert not {"radarbench.bench.cli", "radarbench.bench.core", "radarbench.bench.report", "radarbench"} & set(tracker)
    scenario = dict(identity.code_identity(*identity.identity_roots(registry.get_scenario("cv-turn-cv"))).modules)
    assert "radarbench.bench.sweep.rng" in scenario and "radarbench.bench.calibration" not in scenario


def test_a_harness_module_counts_only_when_it_computes_results(tmp_path, monkeypatch):
    """``COMPUTES_RESULTS = True`` brings a harness module into the identities that load it."""
    _package(tmp_path, {
        "harnesspkg/__init__.py": "",
        "harnesspkg/numeric.py": "COMPUTES_RESULTS = True\n\n\ndef twice(x):\n    return 2 * x\n",
        "harnesspkg/messages.py": "def say(x):\n    return f'got {x}'\n",
        "userpkg/__init__.py": "",
        "userpkg/method.py": "from harnesspkg.numeric import twice\nfrom harnesspkg.messages import say\n",
    })
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(identity, "_HARNESS", (tmp_path / "harnesspkg").resolve())
    try:
        first = _code("userpkg.method")
        assert set(dict(first.modules)) == {"harnesspkg.numeric", "userpkg", "userpkg.method"}
        (tmp_path / "harnesspkg" / "messages.py").write_text("def say(x):\n    return f'received {x}'\n")
        assert _code("userpkg.method").hash == first.hash
        (tmp_path / "harnesspkg" / "numeric.py").write_text("COMPUTES_RESULTS = True\n\n\ndef twice(x):\n"
                                                            "    return x + x\n")
        assert _code("userpkg.method").hash != first.hash
    finally:
        _fresh("harnesspkg", "userpkg")


def test_the_libraries_it_loads_are_named_with_their_versions():
    libraries = dict(identity.code_identity(*identity.identity_roots(registry.get_method("cumulant"))).libraries)
    assert {"numpy", "scipy", "numba", "pandas"} <= set(libraries)
    assert libraries["numpy"] == np.__version__ and libraries["pandas"] == pd.__version__


def test_a_data_file_counts_by_content_not_by_where_it_lies(tmp_path):
    from radarbench.scenarios.recorded_tracks import RecordedTracks

    class Moved(RecordedTracks):
        def data_files(self, params):
            return [params]

    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    (tmp_path / "a" / "t.csv").write_text("1\n")
    (tmp_path / "b" / "u.csv").write_text("1\n")
    code = identity.code_identity(*identity.identity_roots(RecordedTracks))
    here = identity.config_identity(Moved, tmp_path / "a" / "t.csv", code)
    there = identity.config_identity(Moved, tmp_path / "b" / "u.csv", code)
    assert here["identity"] == there["identity"] and here["data"] != there["data"]


def test_identities_of_a_preset_are_computed_from_a_cold_start(tmp_path, monkeypatch):
    """The user's cache of parsed modules only saves time: the same identities without it."""
    from radarbench.bench.sweep.config import load_sweep
    plan = load_sweep(Path(registry.__file__).parent / "presets" / "quick.toml")
    warm = identity.plan_identities(plan)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "empty"))
    identity._parsed.cache_clear()
    identity._parse_module.cache_clear()
    try:
        assert identity.plan_identities(plan) == warm
    finally:
        identity._parsed.cache_clear()
        identity._parse_module.cache_clear()


# --- the random streams -------------------------------------------------------------------

@dataclass(frozen=True)
class _Before:
    steps: int = param(20, "steps", ge=1, le=100, why="small")


@dataclass(frozen=True)
class _After:
    steps: int = param(20, "steps", ge=1, le=100, why="small")
    skew: float = param(0.0, "a new option", ge=0, le=1, why="a fraction")


def test_a_parameter_added_at_its_default_keys_the_same_streams():
    before = ComponentConfig("unregistered", _Before(), "u", "").key
    assert ComponentConfig("unregistered", _After(), "u", "").key == before
    assert ComponentConfig("unregistered", _After(skew=0.5), "u", "").key != before
    assert ComponentConfig("unregistered", _Before(steps=30), "u", "").key != before


def test_a_built_in_scenario_keeps_the_streams_it_was_first_keyed_by():
    """Every parameter a built-in listed keys its streams as it always did (the committed
    reports' numbers), and one added later at its default changes nothing; a scenario
    written after the rule lists none, and its default config is keyed by its name alone."""
    for name, cls in registry.scenarios().items():
        params = cls.Params()
        config = ComponentConfig(name, params, name, "")
        values = params_as_dict(params)
        if cls.stream_params is None:
            assert config.key == stable_key([name, {}]), name
            continue
        first = {k: v for k, v in values.items() if k in cls.stream_params}
        if not any(cls.Params.__dataclass_fields__[k].metadata.get("kind") == "path" for k in values):
            assert config.key == stable_key([name, first]), name
        assert set(cls.stream_params) <= set(values), name


def test_a_scenario_given_a_new_parameter_draws_the_same_bytes(tmp_path, monkeypatch):
    """End to end: a registered scenario whose class gains a parameter at its default makes
    the same batches, bit for bit."""
    from radarbench.bench.sweep.rng import EVALUATION, TrialRNG
    from radarbench.scenarios.cv_turn_cv import CvTurnCv

    @dataclass(frozen=True)
    class Extended(CvTurnCv.Params):
        wind_m_s: float = param(0.0, "a new option, off by default", ge=0, le=50, why="a breeze")

    config = ComponentConfig(CvTurnCv.name, CvTurnCv.Params(steps=80, onset_step=40), "x", "")
    extended = ComponentConfig(CvTurnCv.name, Extended(steps=80, onset_step=40), "x", "")
    assert extended.key == config.key

    def batch(cfg):
        return CvTurnCv().generate(cfg.params, 6.0, 3, TrialRNG(7, EVALUATION, cfg.key, range(3)))

    a, b = batch(config), batch(extended)
    assert np.array_equal(a.z, b.z) and np.array_equal(a.truth, b.truth)


# --- end to end: the method author's loop ---------------------------------------------------

DYNAMIC = '''
import importlib
from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import Method
from radarbench.bench.params import param, params_as_dict


class Dynamic(Method):
    """The step of the largest value after a transform loaded by name."""

    name = "dynamic"
    task = "peak-finding"

    @dataclass(frozen=True)
    class Params:
        transform: str = param("square", "the transform's module", choices=("square",))

    def run(self, batch, params):
        transform = importlib.import_module(f"benchloop.transforms.{params.transform}")
        return np.argmax(transform.apply(batch.z[..., 0]), axis=1)
'''


def _table(out: Path, name: str) -> pd.DataFrame:
    table = pd.read_csv(out / name)
    return table.drop(columns=[c for c in table.columns if "second" in c or c.endswith("_s") or "time" in c])


@pytest.mark.slow
def test_an_edit_of_a_dynamically_loaded_helper_reruns_and_equals_a_fresh_run(loop):  # noqa: F811
    env, pkg, sweep = loop
    (pkg / "dynamic.py").write_text(textwrap.dedent(DYNAMIC))
    (pkg / "transforms").mkdir()
    (pkg / "transforms" / "__init__.py").write_text("")
    (pkg / "transforms" / "square.py").write_text("def apply(z):\n    return z * z\n")
    entry_points = pkg.parent / "benchloop-0.1.dist-info" / "entry_points.txt"
    entry_points.write_text(entry_points.read_text() + "dynamic = benchloop.dynamic:Dynamic\n")
    sweep.write_text(sweep.read_text().replace('name = "absmax"', 'name = "dynamic"'))
    cwd = sweep.parent.parent / "elsewhere"
    out = cwd / "run"
    first = _bench(env, cwd, "run", sweep, "--out", out, "--workers", 1, "--quiet", "--no-record")
    assert first.returncode == 0, first.stderr

    (pkg / "transforms" / "square.py").write_text("def apply(z):\n    return -z * z\n")
    second = _bench(env, cwd, "run", sweep, "--out", out, "--workers", 1, "--no-record")
    assert second.returncode == 0, second.stderr
    assert "Nothing to run" not in second.stderr and "code or data changed" in second.stderr, second.stderr

    fresh = cwd / "fresh"
    third = _bench(env, cwd, "run", sweep, "--out", fresh, "--workers", 1, "--quiet", "--no-record")
    assert third.returncode == 0, third.stderr
    for name in ("summary.csv", "trials.csv"):
        pd.testing.assert_frame_equal(_table(out, name), _table(fresh, name))
    with contextlib.closing(sqlite3.connect(out / "results.sqlite")) as con:
        identities = {m: i for m, i in con.execute("SELECT method, identity FROM runs")}
    with contextlib.closing(sqlite3.connect(fresh / "results.sqlite")) as con:
        assert identities == {m: i for m, i in con.execute("SELECT method, identity FROM runs")}


@pytest.mark.slow
def test_a_comment_edit_or_a_move_reruns_nothing(loop):  # noqa: F811
    env, pkg, sweep = loop
    cwd = sweep.parent.parent / "elsewhere"
    out = cwd / "run"
    first = _bench(env, cwd, "run", sweep, "--out", out, "--workers", 1, "--quiet", "--no-record")
    assert first.returncode == 0, first.stderr
    source = pkg / "argmax.py"
    source.write_text(source.read_text().replace('"""The step of the largest moving average."""',
                                                 '"""The step of the largest moving average.\n\n    Reworded."""')
                      .replace("    def run(self, batch, params):", "    # a comment\n    def run(self, batch, params):"))
    (pkg / "methods").mkdir()
    (pkg / "methods" / "__init__.py").write_text("")
    source.rename(pkg / "methods" / "smoothed.py")
    entry_points = pkg.parent / "benchloop-0.1.dist-info" / "entry_points.txt"
    entry_points.write_text(entry_points.read_text().replace("benchloop.argmax:", "benchloop.methods.smoothed:"))
    second = _bench(env, cwd, "run", sweep, "--out", out, "--workers", 1, "--no-record")
    assert second.returncode == 0, second.stderr
    assert "Nothing to run" in second.stderr, second.stderr


def test_a_store_of_the_earlier_scheme_is_rerun_once_and_said(tmp_path):
    from radarbench.bench.sweep.config import parse_sweep
    from radarbench.bench.run.runner import plan_record, run_sweep
    from tests.test_identity import SMALL
    plan = parse_sweep(SMALL)
    store = run_sweep(plan, tmp_path, plan_record=plan_record(plan, "t"), executor="serial", quiet=True)
    store.db.execute("DELETE FROM meta WHERE key='identity_scheme'")
    store.db.execute("UPDATE runs SET identity='0123456789ab'")
    store.db.commit()
    store.close()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        run_sweep(plan, tmp_path, plan_record=plan_record(plan, "t"), executor="serial", quiet=False).close()
    said = [line for line in err.getvalue().splitlines() if "earlier bench" in line]
    assert len(said) == 1 and "one-time re-run" in said[0], err.getvalue()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        run_sweep(plan, tmp_path, plan_record=plan_record(plan, "t"), executor="serial", quiet=False).close()
    assert "earlier bench" not in err.getvalue()
