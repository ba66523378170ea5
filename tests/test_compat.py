"""The compatibility path of the old top-level names (radarbench/_compat.py): an outside
plugin importing ``bench.core`` or ``models.kalman`` gets the very module of the new name,
and a deprecation warning naming the new import."""

import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import radarbench
from radarbench._compat import OldImportName, new_name
from conftest import scaled

ROOT = Path(__file__).resolve().parents[1]


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


def test_a_fresh_process_importing_an_old_name_first_gets_one_registry():
    """From a checkout on sys.path, ``import bench`` before ``radarbench`` finds bench/
    by its old name: it hands over to the new package instead of running twice."""
    code = ("import warnings\n"
            "with warnings.catch_warnings(record=True) as caught:\n"
            "    warnings.simplefilter('always')\n"
            "    import bench.registry\n"
            "print(caught[0].category.__name__, caught[0].message)\n"
            "import sys, bench.registry as r, radarbench.bench.registry as n\n"
            "print(r is n, sys.modules['bench'] is sys.modules['radarbench.bench'])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=scaled(),
                         env={"PYTHONPATH": str(ROOT), "PATH": ""})
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].startswith("OldImportName 'bench' is deprecated: import 'radarbench.bench'"), out.stdout
    assert lines[-1] == "True True", out.stdout


@pytest.mark.parametrize("name", ["bench", "methods", "models", "scenarios"])
def test_each_folder_is_a_subpackage_of_radarbench(name):
    module = __import__(f"radarbench.{name}", fromlist=["_"])
    assert Path(module.__file__).resolve() == ROOT / name / "__init__.py"
    assert name in radarbench.SUBPACKAGES
