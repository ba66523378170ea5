"""The package layering, checked on every module's imports (parsed, not run).

    bench      the harness: finds plugins through the registry, never by import
    models     shared radar and filtering maths: imports bench's public API only
    methods    import bench's public API and models, never a scenario
    scenarios  import bench's public API and models, never a method

Imports inside functions count too.
"""

from pathlib import Path

import pytest

from bench.identity import imported_names

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("bench", "methods", "models", "scenarios")
#: package -> the packages of ours it must not import
FORBIDDEN = {
    "bench": {"methods", "scenarios", "models"},   # generic statistics only; plugins come via the registry
    "models": {"methods", "scenarios"},           # bench's public API only (field checks of bench.core)
    "methods": {"scenarios"},
    "scenarios": {"methods"},
}


def imported_modules(path: Path, package: str) -> set[str]:
    """Absolute dotted names a module of ``package`` imports (``from a.b import c``:
    ``a.b`` and ``a.b.c``, since ``c`` may be a module)."""
    return imported_names(path.read_text(encoding="utf-8"), f"{package}.{path.stem}")


def modules(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


@pytest.mark.parametrize("package", PACKAGES)
def test_package_imports_follow_the_layering(package):
    assert modules(package), f"no modules found in {package}/"
    bad = {f"{path.relative_to(ROOT)} imports {name}"
           for path in modules(package) for name in imported_modules(path, package)
           if name.split(".")[0] in FORBIDDEN[package]}
    assert not bad, "\n".join(sorted(bad))


@pytest.mark.parametrize("package", ("methods", "models", "scenarios"))
def test_plugins_use_only_the_public_api_of_the_harness(package):
    bad = {f"{path.relative_to(ROOT)} imports {name}"
           for path in modules(package) for name in imported_modules(path, package)
           if name.split(".")[0] == "bench" and any(part.startswith("_") for part in name.split(".")[1:])}
    assert not bad, "\n".join(sorted(bad))


def test_the_checker_sees_imports_inside_functions_and_relative_imports(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("from . import x\n\ndef f():\n    import scenarios.glint as g\n")
    assert imported_modules(module, "methods") == {"methods", "methods.x", "scenarios.glint"}
