"""Every import of the package resolves for static tools (docs/architecture.md, 'Import names').

jedi, the engine of most editors' go-to-definition, follows each ``import radarbench...``
and ``from radarbench... import ...`` statement of the package's own files to a real file
of this checkout, as an editor opened on it would (a :class:`jedi.Project` rooted here).
The package's folders are links inside ``radarbench/`` and ``src/radarbench`` is the
editable install's way in, so both routes are checked: the checkout's root, and ``src/``
alone on the path (what the editable install's ``.pth`` adds).
"""

from __future__ import annotations

import ast
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

try:
    import jedi
except ImportError:             # the [test] extra installs it
    jedi = None
needs_jedi = pytest.mark.skipif(jedi is None, reason="jedi is not installed (pip install -e '.[test]')")

ROOT = Path(__file__).resolve().parents[1]
#: the folders whose files are the package's (``radarbench/`` itself, not through its links)
PACKAGE_FOLDERS = ("bench", "methods", "models", "scenarios", "radarbench")
PACKAGE = "radarbench"
#: the subpackages, each a link in radarbench/ to the repository folder of its name
LINKED = ("bench", "methods", "models", "scenarios")


@dataclass(frozen=True)
class ImportedName:
    """One name an import statement binds, at the position an editor's cursor would be on."""
    path: Path
    line: int          # 1-based, as jedi counts
    column: int        # 0-based
    text: str          # ``radarbench.bench.run.executors`` or ``...executors.make_executor``

    def __str__(self) -> str:
        shown = self.path.relative_to(ROOT) if self.path.is_relative_to(ROOT) else self.path
        return f"{shown}:{self.line}:{self.column} {self.text}"


def package_files() -> list[Path]:
    """The package's own files (``rglob`` follows no link: each file once)."""
    return sorted(p for folder in PACKAGE_FOLDERS for p in (ROOT / folder).rglob("*.py")
                  if "__pycache__" not in p.parts)


def _module_column(source_line: str, node: ast.ImportFrom) -> int:
    """Where the last part of ``from a.b.c import ...``'s module starts on its line."""
    start = source_line.index(node.module, node.col_offset + len("from"))
    return start + node.module.rindex(".") + 1 if "." in node.module else start


def imported_names(path: Path, source: str) -> list[ImportedName]:
    """Each module and name of ours that the import statements of ``source`` (the text of
    ``path``) bind: absolute imports of :data:`PACKAGE`, at the top, in functions or under
    TYPE_CHECKING."""
    lines = source.splitlines()
    out = []
    for node in ast.walk(ast.parse(source, str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == PACKAGE:
                    last = alias.name.rpartition(".")[2]
                    out.append(ImportedName(path, alias.lineno, alias.col_offset + len(alias.name) - len(last),
                                            alias.name))
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module.split(".")[0] == PACKAGE:
            out.append(ImportedName(path, node.lineno, _module_column(lines[node.lineno - 1], node), node.module))
            out += [ImportedName(path, alias.lineno, alias.col_offset, f"{node.module}.{alias.name}")
                    for alias in node.names if alias.name != "*"]
    return out


def unresolved(project, files: list[Path], where: Path = ROOT) -> tuple[int, list[str]]:
    """(how many imported names ``files`` have, those jedi follows to no file under ``where``)."""
    asked, bad = 0, []
    for path in files:
        names, missed = unresolved_in(project, path, path.read_text(encoding="utf-8"), where)
        asked, bad = asked + names, bad + missed
    return asked, bad


def unresolved_in(project, path: Path, source: str, where: Path = ROOT) -> tuple[int, list[str]]:
    """:func:`unresolved` of one module's text ``source`` as if it were ``path``."""
    names = imported_names(path, source)
    if not names:
        return 0, []
    script = jedi.Script(source, path=str(path), project=project)
    bad = []
    for name in names:
        found = script.goto(name.line, name.column, follow_imports=True)
        if not any(_in_a_file(d, where) for d in found):
            bad.append(f"{name}: {[d.full_name for d in found] or 'no definition'}")
    return len(names), bad


def _in_a_file(definition, where: Path) -> bool:
    """A definition in a real file; one of ours in a file under ``where`` (a library's name
    that a module of ours imports, ``plt`` of bench.figures, is defined in the library)."""
    path = definition.module_path
    if path is None or not Path(path).is_file():
        return False
    return not (definition.full_name or "").startswith(PACKAGE) or Path(path).resolve().is_relative_to(where.resolve())


def checkout_project():
    """An editor opened on the checkout: the root on the path first (jedi's smart path)."""
    return jedi.Project(ROOT, sys_path=_stdlib_path(), smart_sys_path=True)


def _stdlib_path() -> list[str]:
    """The interpreter's own folders (the standard library, the installed libraries), none of
    ours: the checkout's roots are left out, a virtual environment inside the checkout (CI's
    ``.venv``) is kept."""
    ours = {ROOT.resolve(), (ROOT / "src").resolve(), (ROOT / "tests").resolve()}
    return [p for p in sys.path if p and Path(p).resolve() not in ours]


@needs_jedi
def test_every_import_of_the_package_resolves_to_its_file():
    files = package_files()
    assert len(files) > 100 and ROOT / "bench" / "run" / "runner.py" in files
    asked, bad = unresolved(checkout_project(), files)
    assert asked > 500, asked                       # the walk found the imports (one per name)
    assert not bad, f"{len(bad)} of {asked} imported names jedi cannot follow:\n" + "\n".join(bad)


@needs_jedi
def test_the_editable_install_path_alone_resolves_the_package(tmp_path):
    """What ``pip install -e .`` puts on sys.path (a ``.pth`` of ``src/``) leads to the files:
    a project outside the checkout with only ``src/`` on its path."""
    project = jedi.Project(tmp_path, sys_path=[str(ROOT / "src"), *_stdlib_path()], smart_sys_path=False)
    script = jedi.Script("from radarbench.bench.run.executors import make_executor\nmake_executor\n",
                         path=str(tmp_path / "plugin.py"), project=project)
    (found,) = script.goto(2, 0, follow_imports=True)
    assert Path(found.module_path).resolve() == ROOT / "bench" / "run" / "executors.py"


@needs_jedi
def test_the_checker_finds_an_import_that_does_not_resolve():
    source = ("from radarbench.bench.run.executors import make_executor, no_such_name\n"
              "import radarbench.nowhere\nfrom radarbench.bench.figures import plt\n")
    asked, bad = unresolved_in(checkout_project(), ROOT / "bench" / "probe.py", source)   # the text, never written
    assert asked == 6
    assert [b.split(": ")[0].rpartition(" ")[2] for b in bad] == ["radarbench.bench.run.executors.no_such_name",
                                                                  "radarbench.nowhere"]


@needs_jedi
def test_without_the_links_no_import_of_a_subpackage_resolves(tmp_path):
    """The folders beside ``radarbench/`` (the layout before the links, the subpackages
    found through ``__path__`` at run time) are nothing to jedi; a link makes them a path."""
    (tmp_path / "radarbench").mkdir()
    (tmp_path / "radarbench" / "__init__.py").write_text("")
    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "__init__.py").write_text("")
    (tmp_path / "bench" / "executors.py").write_text("def make_executor():\n    pass\n")
    source = "from radarbench.bench.executors import make_executor\n"
    project = jedi.Project(tmp_path, sys_path=_stdlib_path())
    before = unresolved_in(project, tmp_path / "bench" / "runner.py", source, where=tmp_path)
    (tmp_path / "radarbench" / "bench").symlink_to("../bench")
    after = unresolved_in(jedi.Project(tmp_path, sys_path=_stdlib_path()), tmp_path / "bench" / "runner.py", source,
                          where=tmp_path)
    assert (before[0], len(before[1]), after) == (2, 2, (2, []))


def test_the_import_walk_sees_every_kind_of_import(tmp_path):
    source = ("import radarbench.bench.core as core\nfrom radarbench.bench.run import units, executors\n"
              "import numpy\nfrom . import x\n\n"
              "def f():\n    from radarbench.models.kalman import (\n        KalmanFilter)\n")
    names = [(n.line, n.column, n.text) for n in imported_names(tmp_path / "m.py", source)]
    assert names == [(1, len("import radarbench.bench."), "radarbench.bench.core"),
                     (2, len("from radarbench.bench."), "radarbench.bench.run"),
                     (2, len("from radarbench.bench.run import "), "radarbench.bench.run.units"),
                     (2, len("from radarbench.bench.run import units, "), "radarbench.bench.run.executors"),
                     (7, len("    from radarbench.models."), "radarbench.models.kalman"),
                     (8, 8, "radarbench.models.kalman.KalmanFilter")]


def _static_exports(path: Path) -> dict[str, str]:
    """Name -> module of the imports under ``if TYPE_CHECKING:`` at a module's top."""
    out = {}
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            out.update({a.asname or a.name: n.module for n in node.body if isinstance(n, ast.ImportFrom)
                        for a in n.names})
    return out


def _lazy_packages() -> list[Path]:
    """The package files with a module-level ``__getattr__`` (PEP 562: names imported on first use)."""
    def lends(path: Path) -> bool:
        return any(isinstance(node, ast.FunctionDef) and node.name == "__getattr__"
                   for node in ast.parse(path.read_text(encoding="utf-8")).body)
    return [p for p in package_files() if p.name == "__init__.py" and lends(p)]


def test_names_a_package_imports_on_first_use_are_visible_to_static_tools():
    """A package that lends names through ``__getattr__`` (its ``_EXPORTS``: name -> module)
    imports the same names under ``if TYPE_CHECKING:``, which static tools follow."""
    import importlib

    lazy = _lazy_packages()
    assert {p.relative_to(ROOT).parts[0] for p in lazy} >= {"radarbench", "bench"}, lazy
    for path in lazy:
        relative = path.parent.relative_to(ROOT)
        name = ".".join((PACKAGE, *relative.parts)) if relative.parts[0] != PACKAGE else PACKAGE
        package = importlib.import_module(name)
        runtime = {n: importlib.import_module(m, name).__name__ for n, m in (
            (n, m if m.startswith(PACKAGE) else f".{m}") for n, m in package._EXPORTS.items())}
        assert _static_exports(path) == runtime, path


# ------------------------------------------------------------------ the links themselves

@pytest.mark.parametrize("name", LINKED)
def test_each_subpackage_is_a_relative_link_to_its_folder(name):
    link = ROOT / PACKAGE / name
    assert link.is_symlink() and str(link.readlink()) == f"../{name}", link
    assert link.resolve() == ROOT / name


def test_a_clone_without_its_links_says_so_in_one_line(tmp_path):
    """A clone made without symbolic links has each link as a small file naming its target."""
    import shutil
    import subprocess

    package = tmp_path / PACKAGE
    package.mkdir()
    for name in ("__init__.py", "_compat.py"):
        shutil.copy(ROOT / PACKAGE / name, package / name)
    for name in LINKED:
        (package / name).write_text(f"../{name}")
    out = subprocess.run([sys.executable, "-c", "import radarbench"], capture_output=True, text=True,
                         env={"PYTHONPATH": str(tmp_path), "PATH": ""}, cwd=tmp_path)
    last = out.stderr.strip().splitlines()[-1]
    assert out.returncode == 1 and last.startswith("ImportError: ") and "core.symlinks" in last, out.stderr


def test_the_editable_install_adds_only_the_package():
    """setuptools writes a plain ``.pth`` for package-dir ``{"" = "src"}`` (no import hook),
    and that folder holds the package alone (and the install's metadata, ``*.egg-info``):
    no ``bench``, ``models`` or ``tests`` on sys.path."""
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    assert setuptools["package-dir"] == {"": "src"}
    assert [p.name for p in (ROOT / "src").iterdir() if p.suffix != ".egg-info"] == [PACKAGE]
    assert (ROOT / "src" / PACKAGE).resolve() == ROOT / PACKAGE
