"""The package layering, checked on every module's imports (parsed, not run).

    bench      the harness: finds plugins through the registry, never by import
    models     shared radar and filtering maths: imports bench's public API only
    methods    import bench's public API and models, never a scenario
    scenarios  import bench's public API and models, never a method

Imports inside functions count too.
"""

import ast
import re
from pathlib import Path

import pytest

from radarbench.bench.run.identity import imported_names

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("bench", "methods", "models", "scenarios")
#: package -> the packages of ours it must not import
FORBIDDEN = {
    "bench": {"methods", "scenarios", "models"},   # generic statistics only; plugins come via the registry
    "models": {"methods", "scenarios"},           # bench's public API only (field checks of bench.core)
    "methods": {"scenarios"},
    "scenarios": {"methods"},
}


#: the import package the folders are installed under (pyproject.toml's package-dir)
NEW_PACKAGE = "radarbench."


def imported_modules(path: Path, package: str) -> set[str]:
    """Dotted names, by folder (``radarbench.models.kalman`` -> ``models.kalman``), a module
    of ``package`` imports (``from a.b import c``: ``a.b`` and ``a.b.c``, since ``c`` may be a module)."""
    names = imported_names(path.read_text(encoding="utf-8"), f"{NEW_PACKAGE}{package}.{path.stem}")
    return {name.removeprefix(NEW_PACKAGE) for name in names}


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


# ------------------------------------------------------------------ no import circles

def module_name(path: Path) -> str:
    """``bench/report/compare.py`` -> ``bench.report.compare``; a package's ``__init__.py`` is the package."""
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(paths) -> dict[str, set[str]]:
    """Module -> the modules of ours it imports (anywhere: at the top, in a function, under
    TYPE_CHECKING). ``from a.b import c`` imports ``a.b``, and ``a.b.c`` when that is a module."""
    names = {module_name(p): p for p in paths}
    return {name: {m for m in (i.removeprefix(NEW_PACKAGE) for i in imported_names(
                path.read_text(encoding="utf-8"), NEW_PACKAGE + name, path.name == "__init__.py"))
                   if m in names and m != name}
            for name, path in names.items()}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of two modules or more (Tarjan's algorithm,
    iterative): each is a set of modules that import one another in a circle."""
    index, low, on_stack, stack, found = {}, {}, set(), [], []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root), on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is None:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while not component or component[-1] != node:
                        component.append(stack.pop())
                        on_stack.discard(component[-1])
                    if len(component) > 1:
                        found.append(sorted(component))
            elif child not in index:
                index[child] = low[child] = len(index)
                stack.append(child), on_stack.add(child)
                work.append((child, iter(sorted(graph[child]))))
            elif child in on_stack:
                low[node] = min(low[node], index[child])
    return found


def test_no_import_circles_among_our_modules():
    graph = import_graph([path for package in PACKAGES for path in modules(package)])
    assert "bench.tasks.cells.metrics" in graph["bench.tasks.cells"]       # the graph sees packages' modules
    found = circles(graph)
    assert not found, "import circles (break each by moving what both sides need below them):\n" + "\n".join(
        " <-> ".join(component) for component in found)


def test_the_circle_finder_sees_long_circles_and_only_circles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e"}, "f": {"g"}, "g": {"f"}}
    assert sorted(circles(graph)) == [["a", "b", "c"], ["f", "g"]]


# ------------------------------------------------------------------ one import package

def test_the_wheel_lists_every_package_folder():
    """pyproject.toml names the packages one by one (each a folder under package-dir's
    ``src/``, through the links radarbench/bench -> ../bench, ...): a new family folder
    missing from the list would be left out of the wheel."""
    import tomllib

    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    folders = {NEW_PACKAGE + module_name(init) for package in PACKAGES
               for init in (ROOT / package).rglob("__init__.py")} | {NEW_PACKAGE.strip(".")}
    listed = set(setuptools["packages"])
    assert folders <= listed, sorted(folders - listed)
    source = ROOT / setuptools["package-dir"][""]
    for name in listed:
        assert (source / name.replace(".", "/")).is_dir(), name


def test_comments_explain_the_code_not_the_ticket():
    """No "issue N" in the code, its comments or docstrings, nor in the presets: a tracker's
    number means nothing to a reader of the code."""
    import re

    cited = re.compile(r"\b[Ii]ssues? ?#?\d+")
    roots = ("bench", "methods", "models", "scenarios", "tests", "radarbench", "benchmarks")
    found = [f"{p.relative_to(ROOT)}:{i}" for root in roots for p in (ROOT / root).rglob("*")
             if p.suffix in (".py", ".toml", ".j2") and p.is_file()
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if cited.search(line)]
    assert not found


# ------------------------------------------------------------------ the harness's stages

#: stage of bench/ -> the stages it may import (besides the top modules, the shared packages and itself);
#: the order is the pipeline's, with results/ before run/ (the driver writes the results)
STAGES = {
    'sweep': set(),
    'results': {'sweep'},
    'run': {'results', 'sweep'},
    'report': {'results', 'run', 'sweep'},
    'cli': {'report', 'results', 'run', 'sweep'},
}
#: the modules at bench/'s top: the plugin protocol and what every stage and plugin shares
TOP_MODULES = {'__init__', '__main__', 'batched', 'calibration', 'core', 'errors', 'escapes', 'figures', 'markdown', 'metrics', 'params', 'registry'}
#: subpackages of no stage (the tasks and the recording format, used by run/ and report/) and what they may import
SHARED = ('tasks', 'recording')
SHARED_MAY_IMPORT = {'results'}
#: (top module, stage.module) imports allowed: the registry sets up the numba cache and names distributions, the
#: figures are written into the run folder
TOP_EXCEPTIONS = {('figures', 'results.figure_cache'),
                  ('figures', 'results.runfolder'),
                  ('figures', 'results.tables'),
                  ('figures', 'run.progress'),
                  ('registry', 'results.provenance'),
                  ('registry', 'run.numba_cache')}
#: the module ``python -m radarbench.bench`` runs: the command line's
ENTRY = {"bench.__main__": "cli"}


def stage_of(module: str) -> str:
    """``bench.run.units`` -> ``run``; ``bench.core`` -> ``top``; ``bench.tasks.tbd`` -> ``tasks``."""
    parts = module.split(".")
    if module in ENTRY:
        return ENTRY[module]
    return parts[1] if len(parts) > 2 or parts[1:] and parts[1] in (*STAGES, *SHARED) else "top"


def back_imports(graph: dict[str, set[str]]) -> list[str]:
    """The imports of bench/'s modules that reach a stage they may not import."""
    bad = []
    for module, imported in sorted(graph.items()):
        here = stage_of(module)
        for name in sorted(m for m in imported if m.startswith("bench.") and m != "bench"):
            there = stage_of(name)
            if there in (here, "top") or there in SHARED and here != "top":
                continue
            allowed = (STAGES[here] if here in STAGES else SHARED_MAY_IMPORT if here in SHARED
                       else {e[1] for e in TOP_EXCEPTIONS if module == f"bench.{e[0]}"} | set(SHARED))
            inner = name.removeprefix("bench.")
            if there not in allowed and not any(a == inner or a.startswith(inner + ".") for a in allowed):
                bad.append(f"{module} ({here}) imports {name} ({there})")
    return bad


def test_each_stage_imports_only_the_stages_before_it():
    graph = import_graph(modules("bench"))
    assert {stage_of(m) for m in graph} == {"top", *STAGES, *SHARED}
    bad = back_imports(graph)
    assert not bad, "imports back into an earlier stage (move what both need below them):\n" + "\n".join(bad)


def test_the_checker_finds_an_import_back_into_an_earlier_stage():
    graph = {"bench.sweep.plan": {"bench.run.units"}, "bench.run.units": {"bench.sweep.plan", "bench.core"},
             "bench.core": {"bench.report.figures"}, "bench.tasks.tbd": {"bench.sweep.rng"}}
    assert back_imports(graph) == ["bench.core (top) imports bench.report.figures (report)",
                                   "bench.sweep.plan (sweep) imports bench.run.units (run)",
                                   "bench.tasks.tbd (tasks) imports bench.sweep.rng (sweep)"]


def test_bench_shows_its_stages_with_few_modules_at_the_top():
    top = sorted(p.stem for p in (ROOT / "bench").glob("*.py"))
    assert top == sorted(TOP_MODULES) and len(set(top) - {"__init__", "__main__"}) <= 10, top
    for stage, may in STAGES.items():
        doc = ast.get_docstring(ast.parse((ROOT / "bench" / stage / "__init__.py").read_text(encoding="utf-8")))
        assert doc and doc.startswith(f"Stage ``{stage}/``"), stage
        rule = next(p for p in doc.split("\n\n") if p.startswith("It may import"))
        named = set(re.findall(r"``(\w+)/``", rule.split("never")[0])) - {stage, "bench", *SHARED}
        assert named == set(may), (stage, named)

# ------------------------------------------------------------------ (end of the harness's stages)
