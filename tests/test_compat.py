"""The compatibility path of the old top-level names (radarbench/_compat.py): an outside
plugin importing ``bench.core`` or ``models.kalman`` gets the very module of the new name,
and a deprecation warning naming the new import."""

import importlib
import json
import pkgutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import radarbench
import radarbench.methods.cfar.detectors  # noqa: F401 - compared with what an old name lends
from radarbench import _compat
from radarbench._compat import OldImportName, new_name
from conftest import scaled

ROOT = Path(__file__).resolve().parents[1]


def _python(*args, cwd: Path) -> list[str]:
    """The lines a fresh interpreter prints, with only this checkout on its path (exit 0)."""
    out = subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=cwd, timeout=scaled(),
                         env={"PYTHONPATH": str(ROOT), "PATH": ""})
    assert out.returncode == 0, out.stderr
    return out.stdout.splitlines()


def test_an_old_name_is_the_module_of_its_new_name_with_a_warning():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        import models.kalman as old            # noqa: PLC0415 - the import is what is tested
        from bench.core import Method as OldMethod
    from radarbench.bench.core import Method
    from radarbench.models import kalman

    assert old is kalman and OldMethod is Method
    assert sys.modules["bench.core"] is sys.modules["radarbench.bench.core"]
    messages = [str(w.message) for w in caught if issubclass(w.category, OldImportName)]
    assert any("'models.kalman' is deprecated: import 'radarbench.models.kalman'" in m for m in messages), messages
    assert issubclass(OldImportName, DeprecationWarning)


def test_only_the_old_names_are_redirected():
    assert new_name("models.kalman") == "radarbench.models.kalman"
    assert new_name("bench") == "radarbench.bench"
    assert new_name("modelsx") is None and new_name("numpy") is None
    assert new_name("methods.imm") == "radarbench.methods.kinematic.imm"                # moved into a folder
    assert new_name("radarbench.models.cfar_halves") == "radarbench.models.cfar.halves"  # moved under the package
    assert new_name("radarbench.models.kalman") is None                                 # a current name


def test_a_fresh_process_importing_an_old_name_first_gets_one_registry():
    """From a checkout on sys.path, ``import bench`` before ``radarbench`` finds bench/
    by its old name: it hands over to the new package instead of running twice (one
    warning: the module's, not its package's)."""
    code = ("import warnings\n"
            "with warnings.catch_warnings(record=True) as caught:\n"
            "    warnings.simplefilter('always')\n"
            "    import bench.registry\n"
            "print(len(caught), caught[0].category.__name__, caught[0].message)\n"
            "import sys, bench.registry as r, radarbench.bench.registry as n\n"
            "print(r is n, sys.modules['bench'] is sys.modules['radarbench.bench'])")
    lines = _python("-c", code, cwd=ROOT)
    assert lines[0].startswith("1 OldImportName 'bench.registry' is deprecated: import 'radarbench.bench.registry'"), \
        lines
    assert lines[-1] == "True True", lines


@pytest.mark.parametrize("name", ["bench", "methods", "models", "scenarios"])
def test_each_folder_is_a_subpackage_of_radarbench(name):
    module = __import__(f"radarbench.{name}", fromlist=["_"])
    assert Path(module.__file__).resolve() == ROOT / name / "__init__.py"
    assert name in radarbench.SUBPACKAGES


# ------------------------------------------------------------------ the modules that moved

PACKAGE_FOLDERS = ("bench", "methods", "models", "scenarios")
#: modules deleted without a new home in the package: their content went elsewhere
REMOVED = {
    "models._fields": "its field checks became bench.core's require, has_shape, require_arrays",
    "methods._tbd_oracle": "a test oracle now (tests/tbd_kernels_oracle.py), not installed",
}


def _module(path: str) -> str:
    parts = path[:-len(".py")].split("/")
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _in_package(path: str) -> bool:
    return path.endswith(".py") and path.split("/")[0] in PACKAGE_FOLDERS


def _exists_now(name: str) -> bool:
    path = ROOT / name.replace(".", "/")
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def _history() -> tuple[dict[str, str], set[str], set[str]]:
    """From ``git log -M``, oldest first: each module moved (old name -> its last home; a
    home outside the package is None), the modules deleted, and the old names the package
    itself had (the moves after radarbench/__init__.py was added)."""
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: the history of the moves is not here")
    log = subprocess.run(["git", "log", "--reverse", "-M", "--name-status", "--format="], cwd=ROOT,
                         capture_output=True, text=True, timeout=scaled(), check=True).stdout
    home, deleted, since_package, package_exists = {}, set(), set(), False
    for fields in (line.split("\t") for line in log.splitlines() if line):
        if fields[0] == "A" and fields[1] == "radarbench/__init__.py":
            package_exists = True
        elif fields[0].startswith("R") and _in_package(fields[1]):
            old, new = _module(fields[1]), _module(fields[2]) if _in_package(fields[2]) else None
            home.update({k: new for k, v in home.items() if v == old})      # moved again
            home[old] = new
            if package_exists and old != new:
                since_package.add(old)
        elif fields[0] == "D" and _in_package(fields[1]):
            deleted.add(_module(fields[1]))
    return home, deleted, since_package


def test_the_table_is_every_module_the_history_moved():
    home, deleted, since_package = _history()
    moved = {old: new for old, new in home.items() if new is not None and new != old}
    assert _compat.MOVED == moved
    assert set(_compat.MOVED_SINCE_PACKAGE) == since_package
    gone = {name for name in deleted | {old for old, new in home.items() if new is None}
            if not _exists_now(name) and name not in moved}
    assert gone == set(REMOVED)                 # nothing deleted that is neither mapped nor known removed
    assert all(_exists_now(new) for new in moved.values())


def _old_names() -> list[str]:
    return [*_compat.MOVED, *(f"radarbench.{name}" for name in _compat.MOVED_SINCE_PACKAGE)]


def _own_public_name(module) -> str:
    """A public name ``module`` defines itself (not one it imports)."""
    return next(name for name, obj in sorted(vars(module).items())
                if not name.startswith("_") and getattr(obj, "__module__", None) == module.__name__)


def _home(old: str) -> str:
    """The new import of ``old``, read from the table."""
    return "radarbench." + _compat.MOVED[old.removeprefix("radarbench.")]


def _import_new(new: str):
    """The new module, or the exception its import raises (an optional dependency missing,
    never the module itself)."""
    try:
        return importlib.import_module(new)
    except Exception as exc:  # noqa: BLE001 - compared with what the old name raises
        assert not (isinstance(exc, ModuleNotFoundError) and exc.name == new), exc
        return exc


@pytest.mark.parametrize("old", _old_names())
def test_each_moved_module_answers_its_old_name_in_the_harness(old, monkeypatch):
    """After ``import radarbench`` (what the ``bench`` command and its workers do first):
    the old name is the new module object, with one warning naming the new import."""
    new = _home(old)
    expected = _import_new(new)
    monkeypatch.delitem(sys.modules, old, raising=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if isinstance(expected, Exception):
            with pytest.raises(type(expected)) as raised:
                importlib.import_module(old)
            assert str(raised.value) == str(expected)
            return
        module = importlib.import_module(old)
    messages = [str(w.message) for w in caught if issubclass(w.category, OldImportName)]
    assert len(messages) == 1 and messages[0].startswith(f"'{old}' is deprecated: import '{new}'"), messages
    if old in _compat.FOLDERS_NOW:              # the folder of the same name, lending the moved module's names
        assert module is sys.modules[f"radarbench.{old}"]
        name = _own_public_name(expected)
        assert getattr(module, name) is getattr(expected, name)
    else:
        assert module is expected and sys.modules[old] is expected


_PLUGIN_SCRIPT = """
import importlib, json, sys, warnings
import radarbench                              # what a plugin's own script must do first
report = {}
for old in sys.argv[1:]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            module = importlib.import_module(old)
        except Exception as exc:
            report[old] = {"error": f"{type(exc).__name__}: {exc}"}
            continue
    report[old] = {"module": module.__name__, "same": module is sys.modules[module.__name__],
                   "warnings": [str(w.message) for w in caught if w.category.__name__ == "OldImportName"]}
print(json.dumps(report))
"""


@pytest.fixture(scope="module")
def plugin_script_imports(tmp_path_factory):
    """A plugin's own script, run by itself (not by ``bench``), importing every old name."""
    folder = tmp_path_factory.mktemp("plugin")
    (folder / "plugin_script.py").write_text(_PLUGIN_SCRIPT)
    return json.loads(_python("plugin_script.py", *_old_names(), cwd=folder)[-1])


@pytest.mark.parametrize("old", _old_names())
def test_each_moved_module_answers_its_old_name_in_a_plugins_own_script(old, plugin_script_imports):
    new = _home(old)
    got, expected = plugin_script_imports[old], _import_new(new)
    if isinstance(expected, Exception):
        assert got == {"error": f"{type(expected).__name__}: {expected}"}
        return
    module = f"radarbench.{old}" if old in _compat.FOLDERS_NOW else new
    assert got["module"] == module and got["same"], got
    assert len(got["warnings"]) == 1 and got["warnings"][0].startswith(f"'{old}' is deprecated: import '{new}'")


def test_an_old_import_through_old_packages_warns_once_in_a_fresh_process(tmp_path):
    """``from bench.tasks.tbd_report import ...`` as a script's first old import: the old
    packages it passes through (``bench``, ``bench.tasks``) add no warning of their own; the
    folder named like a moved module, reached as an attribute, still lends its names."""
    code = ("import warnings, radarbench\n"
            "with warnings.catch_warnings(record=True) as caught:\n"
            "    warnings.simplefilter('always')\n"
            "    from bench.tasks.tbd_report import __name__ as name\n"
            "    from methods import cfar\n"
            "print(name)\n"
            "for w in caught: print(w.message)\n"
            "print(cfar.DETECTORS)\n")
    lines = _python("-c", code, cwd=tmp_path)
    assert lines[0] == "radarbench.bench.tasks.tbd.report"
    assert [line.split(":")[0] for line in lines[1:-1]] == ["'bench.tasks.tbd_report' is deprecated",
                                                            "'methods' is deprecated"]
    assert lines[-1] == str(radarbench.methods.cfar.detectors.DETECTORS)


@pytest.mark.parametrize("old, package", [("methods.no_such_module", "radarbench.methods"),
                                          ("models._fields", "radarbench.models"),
                                          ("bench.tasks.no_such_task", "radarbench.bench.tasks")])
def test_an_old_name_of_no_module_is_one_line_naming_what_exists(old, package):
    with pytest.raises(ImportError) as raised:
        importlib.import_module(old)
    message = str(raised.value)
    held = sorted(m.name for m in pkgutil.iter_modules(importlib.import_module(package).__path__))
    assert "\n" not in message and raised.value.name == old
    assert message.startswith(f"No module named '{old}': its new name 'radarbench.{old}' does not exist either; "
                              f"{package} holds: {', '.join(held)}"), message


def test_a_name_the_package_never_had_is_not_answered():
    """``radarbench.methods.imm`` never existed (the methods moved into folders before the
    package came): Python's own error, no alias."""
    assert _compat.new_name("radarbench.methods.imm") is None
    with pytest.raises(ModuleNotFoundError, match="No module named 'radarbench.methods.imm'"):
        importlib.import_module("radarbench.methods.imm")
