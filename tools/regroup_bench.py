#!/usr/bin/env python3
"""Group ``bench/``'s top-level modules into one subpackage per stage of the pipeline.

Run from the repository root, on a clean checkout:  ``python tools/regroup_bench.py``

Deterministic and re-runnable: a second run changes nothing. It

1. ``git mv``s each module of :data:`MOVES` to its stage's folder (``cli.py`` becomes the
   ``cli/`` package itself, so ``radarbench.bench.cli:main`` keeps its name);
2. rewrites every import and dotted or path mention of a moved module (``radarbench.bench.X``,
   ``from radarbench.bench import X``, ``bench.X``, ``bench/X.py``) in the folders of
   :data:`TEXT_ROOTS`, and, in the moved modules, the paths they derive from their own
   location (``Path(__file__).parent``, ``__name__.rpartition(".")``: one folder deeper now);
3. adds the moved modules' old names to ``radarbench/_compat.py``'s ``MOVED`` table;
4. writes each stage's ``__init__.py`` docstring (:data:`STAGES`), lists the new packages in
   pyproject.toml, rewrites docs/architecture.md's 'Layout' for ``bench/`` and writes the
   stage layering test into tests/test_layout.py.

A top-level module of ``bench/`` that neither :data:`MOVES` nor :data:`TOP` names stops
the script before anything changes: add it to one of them.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

# ---------------------------------------------------------------- the mapping

#: stage -> (what the stage does, the stages it may import besides the top modules and the
#: shared packages), in the order a stage may import the ones before it
STAGES = {
    "sweep": ("Sweep files and presets read into a validated plan: the sweep's fields, grids expanded to "
              "configs, the plan and its file, what can run, the per-trial random streams, the presets "
              "and plugins `bench list` shows.", ()),
    "results": ("What a run keeps: the run folder (lock, manifest, whole-file writes), its SQLite store, "
                "the CSVs, the provenance of each result, the failures located in a plugin's code, and a "
                "run's tables read back as tidy frames.", ("sweep",)),
    "run": ("The plan executed: units of work, the driver that hands them to an executor (process pool "
            "or Dask) and stores each as it finishes, the forkserver and its workers, the warm-up of "
            "the kernels and numba's cache, the identities that decide what must run again, progress "
            "on stderr.", ("sweep", "results")),
    "report": ("A run's outputs rebuilt from its store: report.md and report.html, the figures, the "
               "claims of a paper preset and their baselines, the quantities they measure, "
               "`bench compare`.", ("sweep", "results", "run")),
    "cli": ("The `bench` command and its commands that are no stage of their own: `bench list`, "
            "`bench perf`, the documentation site's generated pages.", ("sweep", "results", "run", "report")),
}

#: each stage's line in docs/architecture.md's Layout
SUMMARIES = {
    "sweep": "sweep files and presets -> a validated Plan",
    "results": "what a run keeps: run folder, SQLite store, CSVs, provenance, failures",
    "run": "the Plan executed: units, executors, workers, warm-up, identities",
    "report": "outputs rebuilt from the store: report.md/.html, CSVs, claims",
    "cli": "the `bench` command (the package itself), `bench perf`, the docs' pages",
}

#: module of bench/ -> its stage
MOVES = {
    "config": "sweep", "plan": "sweep", "grid": "sweep", "feasibility": "sweep", "rng": "sweep",
    "tomlw": "sweep", "listing": "sweep", "capabilities": "sweep",
    "store": "results", "runfolder": "results", "tables": "results", "provenance": "results",
    "failures": "results", "tidy": "results", "figure_cache": "results",
    "runner": "run", "units": "run", "executors": "run", "processes": "run", "warmup": "run",
    "numba_cache": "run", "_forkserver": "run", "limits": "run", "identity": "run", "progress": "run",
    "reuse": "run", "worktime": "run", "results_cache": "run",
    "claims": "report", "baselines": "report",
    "quantities": "report",
    "cli": "cli", "perf": "cli", "docs": "cli",
}
#: modules that leave the harness: shared maths only the methods use belongs to models/
LEAVE = {"windows": "models.windows"}

#: the modules left at bench/'s top: the plugin protocol and what every stage and plugin shares
TOP = ("__init__", "__main__", "core", "errors", "params", "registry", "metrics", "calibration", "batched",
       "escapes", "markdown", "figures")
#: the subpackages that are no stage: the tasks (plugins of the harness, used by run/ and report/)
#: and the recording format; they may import the top and results/
SHARED = ("tasks", "recording")
SHARED_MAY_IMPORT = ("results",)
#: imports of the top modules that reach into a stage: the registry's discovery installs the
#: numba cache in every process and names a plugin's distribution; the figures are written whole
#: into the run folder, skip curves the tables find identical, and say what they draw
TOP_EXCEPTIONS = (("figures", "results.runfolder"), ("figures", "results.tables"), ("figures", "run.progress"),
                  ("figures", "results.figure_cache"),
                  ("registry", "results.provenance"), ("registry", "run.numba_cache"))

#: one-line descriptions for docs/architecture.md's Layout, where it has none of its own
DESCRIPTIONS = {
    "provenance.py": "where a result came from: versions, git commit, machine, each plugin's distribution",
    "perf.py": "`bench perf`: throughput and peak memory of every registered method",
    "limits.py": "the machine's limits measured by `bench perf`, a kernel's fraction of them",
    "tomlw.py": "the TOML writer of the resolved plan (plan.toml)",
    "markdown.py": "Markdown helpers shared by the report's and the tasks' sections",
    "figures.py": "figures (matplotlib, Agg): styles, saving, the pool of processes that draws them",
    "escapes.py": "text that is not ours made harmless to show (control characters as escapes)",
    "capabilities.py": "what a scene provides and a method needs: the pairing of methods with scenarios",
    "_forkserver.py": "preloaded by the forkserver: runner, numpy, scipy and the plugins imported once",
    "presets/": "the presets: sweep files (NAME.toml), their notes (NAME.md) and claims (NAME.claims.toml)",
    "report/__init__.py": "the build: the CSVs, the tasks' sections, report.md and the figures",
    "report/compare.py": "`bench compare`: two runs' shared configs side by side",
    "report/glance.py": "results at a glance, the paired comparisons",
    "report/render.py": "the Jinja2 environment of the templates",
    "report/html.py": "report.html",
    "figure_cache.py": "what a report build reuses: figures and pages keyed by their inputs and code",
    "report/building.py": "the build's steps: figures drawn or reused, the interactive figures, progress",
}

#: where mentions of the modules are rewritten (the old-name table is edited apart)
TEXT_ROOTS = ("bench", "methods", "models", "scenarios", "tests", "radarbench", "benchmarks", "docs", ".ci",
              "tools", "README.md", "CONTRIBUTING.md", "pyproject.toml", "mkdocs.yml")
TEXT_SUFFIXES = {".py", ".md", ".toml", ".yml", ".yaml", ".j2", ".txt", ".cfg", ".sh", ".ini", ""}
SKIP = {"radarbench/_compat.py", "tools/regroup_bench.py"}

ROOT = Path.cwd()
BENCH = ROOT / "bench"


def home(module: str) -> str:
    """The new name under ``radarbench``: ``config`` -> ``bench.sweep.config``; ``cli`` ->
    ``bench.cli`` (the stage's package); ``windows`` -> ``models.windows``."""
    if module in LEAVE:
        return LEAVE[module]
    stage = MOVES[module]
    return f"bench.{stage}" if module == stage else f"bench.{stage}.{module}"


def new_path(module: str) -> str:
    """``config`` -> ``bench/sweep/config.py``; ``cli`` -> ``bench/cli/__init__.py``."""
    path = home(module).replace(".", "/")
    return f"{path}/__init__.py" if module in MOVES and module == MOVES[module] else f"{path}.py"


def moving() -> list[str]:
    """The modules this script moves, in a fixed order."""
    return sorted({*MOVES, *LEAVE})


def git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, check=True, capture_output=True, text=True).stdout


# ---------------------------------------------------------------- 0. check

def check_mapping() -> None:
    """Every top-level module is mapped or kept; stop before any change otherwise."""
    found = {p.stem for p in BENCH.glob("*.py")}
    unknown = sorted(found - set(moving()) - set(TOP))
    if unknown:
        sys.exit(f"error: tools/regroup_bench.py: bench/ has modules neither MOVES nor TOP names: "
                 f"{', '.join(unknown)} (add each to one of them)")
    if set(moving()) & set(TOP):
        sys.exit(f"error: tools/regroup_bench.py: moved and kept: {sorted(set(moving()) & set(TOP))}")


# ---------------------------------------------------------------- 1. move

def move_modules() -> list[str]:
    moved = []
    for module in moving():
        old, new = BENCH / f"{module}.py", ROOT / new_path(module)
        if not old.exists():
            if not new.exists():
                print(f"warning: bench/{module}.py is gone and {new_path(module)} does not exist", file=sys.stderr)
            continue
        new.parent.mkdir(exist_ok=True)
        git("mv", str(old.relative_to(ROOT)), str(new.relative_to(ROOT)))
        moved.append(module)
    return moved


def deepen_own_paths() -> None:
    """A moved module sits one folder deeper: the paths it derives from its own place."""
    edits = ((re.compile(r"Path\(__file__\)\.resolve\(\)\.parent\b(?!s)"), "Path(__file__).resolve().parents[1]"),
             (re.compile(r"Path\(__file__\)\.parent\b(?!s)"), "Path(__file__).parents[1]"),
             (re.compile(r'__name__\.rpartition\("\."\)\[0\]'), '__name__.rsplit(".", 2)[0]'))
    for module, stage in MOVES.items():
        path = ROOT / new_path(module)
        if not path.exists():
            continue
        text = original = path.read_text(encoding="utf-8")
        for pattern, replacement in edits:
            text = pattern.sub(replacement, text)
        if text != original:
            path.write_text(text, encoding="utf-8")


# ---------------------------------------------------------------- 2. rewrite mentions

_NAMES = "|".join(sorted((re.escape(m) for m in moving()), key=len, reverse=True))
_DOTTED = re.compile(rf"(?<![\w.])radarbench\.bench\.({_NAMES})(?!\w)")
_PROSE = re.compile(rf"(?<![\w./-])bench\.({_NAMES})(?![\w-])")
_PATH = re.compile(rf"(?<![\w./-])bench/({_NAMES})\.py(?!\w)")
_FROM_PACKAGE = re.compile(r"^(?P<indent>[ \t]*)from radarbench\.bench import (?P<body>\([^)]*\)|[^\n#]*?)"
                           r"(?P<comment>[ \t]*#[^\n]*)?$", re.M)


def _split_from_package(match: re.Match) -> str:
    """``from radarbench.bench import registry, runfolder`` -> one import per package."""
    body = match["body"].strip().strip("()")
    names = [n.strip() for n in body.replace("\n", " ").split(",") if n.strip()]
    groups: dict[str, list[str]] = {}
    for name in names:
        module = name.split()[0]
        if module in moving() and home(module) != f"bench.{module}":
            groups.setdefault("radarbench." + home(module).rpartition(".")[0], []).append(name)
        else:
            groups.setdefault("radarbench.bench", []).append(name)
    if list(groups) == ["radarbench.bench"]:
        return match[0]
    comment = match["comment"] or ""
    lines = [f"{match['indent']}from {package} import {', '.join(group)}" for package, group in groups.items()]
    lines[0] += comment
    return "\n".join(lines)


def rewrite_text(text: str) -> str:
    text = _FROM_PACKAGE.sub(_split_from_package, text)
    text = _DOTTED.sub(lambda m: f"radarbench.{home(m[1])}", text)
    text = _PROSE.sub(lambda m: home(m[1]), text)
    return _PATH.sub(lambda m: new_path(m[1]), text)


def text_files() -> list[Path]:
    tracked = git("ls-files", "-z", *[r for r in TEXT_ROOTS if (ROOT / r).exists()]).split("\0")
    return [ROOT / f for f in sorted(tracked) if f and f not in SKIP and Path(f).suffix in TEXT_SUFFIXES
            and (ROOT / f).is_file()]


def rewrite_mentions() -> int:
    changed = 0
    for path in text_files():
        try:
            original = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        text = rewrite_text(original)
        if text != original:
            path.write_text(text, encoding="utf-8")
            changed += 1
    return changed


# ---------------------------------------------------------------- 3. the old names

def update_compat(moved_now: list[str]) -> None:
    """``bench.config`` -> ``bench.sweep.config`` in MOVED (and, since the package had it,
    in MOVED_SINCE_PACKAGE); a module already moved to a name that moves again follows."""
    path = ROOT / "radarbench/_compat.py"
    text = path.read_text(encoding="utf-8")
    start = text.index("MOVED = {")
    end = text.index("\n}\n", start)
    table = text[start:end]
    renamed = [m for m in moving() if home(m) != f"bench.{m}"]
    for module in renamed:                      # entries pointing at a module that moved since
        table = re.sub(rf'": "bench\.{re.escape(module)}"', f'": "{home(module)}"', table)
    entries = [f'    "bench.{m}": "{home(m)}",' for m in renamed if f'"bench.{m}":' not in table]
    header = "    # the harness's modules, into one folder per stage of the pipeline (or out to models/)"
    if entries:
        table += ("" if header in table else "\n" + header) + "\n" + "\n".join(entries)
    text = text[:start] + table + text[end:]
    since = re.search(r"MOVED_SINCE_PACKAGE = \((.*?)\)\n", text, re.S)
    names = re.findall(r'"([^"]+)"', since[1])
    names += [f"bench.{m}" for m in renamed if f"bench.{m}" not in names
              and (m in moved_now or f'"bench.{m}":' in text)]
    lines, line = [], "MOVED_SINCE_PACKAGE = ("
    for name in names:
        item = f'"{name}", '
        if len(line) + len(item) > 110:
            lines.append(line.rstrip())
            line = "                       "
        line += item
    lines.append(line.rstrip().rstrip(",") + ")")
    text = text[:since.start()] + "\n".join(lines) + "\n" + text[since.end():]
    path.write_text(text, encoding="utf-8")


# ---------------------------------------------------------------- 4. stages, packaging, docs, test

def stage_docstring(stage: str) -> str:
    what, may = STAGES[stage]
    order = list(STAGES)
    imports = ", ".join(f"``{s}/``" for s in may)
    later = [s for s in order if s != stage and s not in may]
    rule = (f"It may import the top modules of ``bench/``, ``tasks/`` and ``recording/``"
            + (f", and the stages {imports}" if may else "") + "; "
            + (f"never {', '.join(f'``{s}/``' for s in later)}" if later else "no stage imports it")
            + " (docs/architecture.md, 'Layout'; tests/test_layout.py holds it).")
    return f"Stage ``{stage}/`` of the harness. {what}\n\n{rule}"


def _wrap(text: str, width: int = 92) -> str:
    import textwrap
    return "\n\n".join(textwrap.fill(p, width) for p in text.split("\n\n"))


def write_stage_inits() -> None:
    for stage in STAGES:
        init = BENCH / stage / "__init__.py"
        init.parent.mkdir(exist_ok=True)
        doc = _wrap(stage_docstring(stage))
        text = init.read_text(encoding="utf-8") if init.exists() else ""
        body = ast.parse(text).body
        if not body or len(body) == 1 and ast.get_docstring(ast.parse(text)) is not None:
            init.write_text(f'"""{doc}\n"""\n', encoding="utf-8")
            git("add", str(init.relative_to(ROOT)))
            continue
        text = re.sub(r'^"""Stage ``\w+/`` of the harness\..*?holds\s+it\)\.\n\n', '"""', text, flags=re.S)
        if not text.startswith('"""'):
            sys.exit(f"error: {init.relative_to(ROOT)}: expected a docstring first, to put the stage's before it")
        init.write_text(f'"""{doc}\n\n' + text[3:], encoding="utf-8")


def update_pyproject() -> None:
    path = ROOT / "pyproject.toml"
    text = path.read_text(encoding="utf-8")
    block = re.search(r"packages = \[\n(.*?)\n\]", text, re.S)
    lines = block[1].split("\n")
    listed = {re.search(r'"([^"]+)"', line)[1] for line in lines if '"' in line}
    for stage in STAGES:
        package = f"radarbench.bench.{stage}"
        if package in listed:
            continue
        at = next((i for i, line in enumerate(lines) if '"radarbench.bench.' in line
                   and re.search(r'"([^"]+)"', line)[1] > package), None)
        at = at if at is not None else max(i for i, line in enumerate(lines) if '"radarbench.bench' in line) + 1
        lines.insert(at, f'    "{package}",')
    path.write_text(text[:block.start(1)] + "\n".join(lines) + text[block.end(1):], encoding="utf-8")


def _layout_descriptions(block: list[str]) -> dict[str, list[str]]:
    """``name`` -> its description lines (the first, then continuations) in the Layout block."""
    found, current, folder = {}, None, ""
    for line in block:
        entry = re.match(r"^( {2,})(\S+?/|\S+\.py) {2,}(\S.*)$", line)
        if entry and "," not in entry[2]:
            current = entry[2].split("/")[-1] if entry[2].endswith(".py") else entry[2]
            if len(entry[1]) == 2:
                folder = entry[2] if entry[2].endswith("/") else ""
            else:                               # a stage's module: also by its folder (``cli/__init__.py``)
                current = folder + current
            found.setdefault(current, [entry[3]])
        elif current and re.match(r"^ {10,}\S", line):
            found[current].append(line.strip())
        else:
            current = None
    return found


def update_architecture() -> None:
    path = ROOT / "docs/architecture.md"
    text = path.read_text(encoding="utf-8")
    lines = text.split("\n")
    first = next(i for i, line in enumerate(lines) if line.startswith("bench/ "))
    last = next(i for i in range(first + 1, len(lines)) if re.match(r"^\S", lines[i]))
    known = _layout_descriptions(lines[first + 1:last])
    col = 21

    def entry(indent: int, name: str, desc: list[str]) -> list[str]:
        head = " " * indent + name
        pad = max(col - len(head), 2)
        out = [head + " " * pad + desc[0]]
        out += [" " * (len(head) + pad) + d for d in desc[1:]]
        return out

    def described(name: str, stage: str = "") -> list[str]:
        return known.get(name) or [DESCRIPTIONS.get(f"{stage}/{name}") or DESCRIPTIONS.get(name, "")]

    out = ["bench/             the harness, one folder per stage (sweep, results, run, report, cli: each imports",
           "                   only the ones before it): it never names a method, a scenario or a task"]
    top = sorted(p.name for p in BENCH.glob("*.py") if p.stem not in ("__init__", "__main__"))
    for name in top:
        out += entry(2, name, described(name))
    for stage in STAGES:
        out += entry(2, f"{stage}/", [SUMMARIES[stage]])
        for module in sorted(p.name for p in (BENCH / stage).glob("*.py")):
            if module == "__init__.py":
                desc = (known.get("cli.py") or known.get("cli/__init__.py")) if stage == "cli" else \
                    [DESCRIPTIONS.get(f"{stage}/{module}", "")]
                if desc and desc[0]:
                    out += entry(4, module, desc)
                continue
            out += entry(4, module, known.get(f"{stage}/{module}") or described(module, stage))
    for folder in sorted(p.name for p in BENCH.iterdir() if p.is_dir() and p.name not in STAGES
                         and p.name != "__pycache__"):
        out += entry(2, f"{folder}/", described(f"{folder}/"))
    lines[first:last] = out
    text = "\n".join(lines)
    rule = ("Stages of `bench/`, checked by `tests/test_layout.py`: a stage imports the top modules of "
            "`bench/`, `tasks/`, `recording/` and the stages before it in the order sweep, results, run, "
            "report, cli (`run/` writes `results/`, so `results/` comes first), never one after it; "
            "`tasks/` and `recording/` (used by `run/` and `report/`) import the top and `results/`; "
            "the top modules import no stage but `registry`'s discovery (the numba cache of `run/`, the "
            "provenance of `results/`) and `figures` (written whole into the run folder by `results/`, "
            "curves compared by its tables, progress on stderr). At most 10 modules at `bench/`'s top: the plugin protocol "
            "(`core`, `params`, `errors`, `registry`) and what the plugins, the tasks and every stage "
            "share (`metrics`, `calibration`, `batched`, `escapes`, and `markdown` and `figures`, which "
            "the tasks' own report sections use). A stage's package is its docstring alone (`report/` "
            "and `cli/` aside), so importing one module of a stage imports no other.")
    text = re.sub(r"\nStages of `bench/`, checked by .*?\n\n", "\n", text, flags=re.S)
    marker = "\nModules stay under about 500 lines."
    text = text.replace(marker, "\n" + _wrap(rule, 92) + "\n" + marker, 1)
    path.write_text(text, encoding="utf-8")


TEST_START = "# ------------------------------------------------------------------ the harness's stages\n"
TEST_END = "# ------------------------------------------------------------------ (end of the harness's stages)\n"


def write_layering_test() -> None:
    path = ROOT / "tests/test_layout.py"
    text = path.read_text(encoding="utf-8")
    if TEST_START in text:
        text = text[:text.index(TEST_START)] + text[text.index(TEST_END) + len(TEST_END):]
    def literal(items) -> str:                  # a set's text in a fixed order (a set's repr is not)
        return "{" + ", ".join(map(repr, sorted(items))) + "}" if items else "set()"

    stages = "".join(f"    {s!r}: {literal(may)},\n" for s, (_, may) in STAGES.items())
    exceptions = ",\n                  ".join(map(repr, sorted(TOP_EXCEPTIONS)))
    block = TEST_START + STAGE_TEST.format(stages=stages, top=literal(TOP), shared=SHARED,
                                           shared_may=literal(SHARED_MAY_IMPORT), exceptions="{" + exceptions + "}")
    path.write_text(text.rstrip("\n") + "\n\n\n" + block + TEST_END, encoding="utf-8")


STAGE_TEST = '''
#: stage of bench/ -> the stages it may import (besides the top modules, the shared packages and itself);
#: the order is the pipeline's, with results/ before run/ (the driver writes the results)
STAGES = {{
{stages}}}
#: the modules at bench/'s top: the plugin protocol and what every stage and plugin shares
TOP_MODULES = {top}
#: subpackages of no stage (the tasks and the recording format, used by run/ and report/) and what they may import
SHARED = {shared}
SHARED_MAY_IMPORT = {shared_may}
#: (top module, stage.module) imports allowed: the registry sets up the numba cache and names distributions, the
#: figures are written into the run folder
TOP_EXCEPTIONS = {exceptions}
#: the module ``python -m radarbench.bench`` runs: the command line's
ENTRY = {{"bench.__main__": "cli"}}


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
                       else {{e[1] for e in TOP_EXCEPTIONS if module == f"bench.{{e[0]}}"}} | set(SHARED))
            inner = name.removeprefix("bench.")
            if there not in allowed and not any(a == inner or a.startswith(inner + ".") for a in allowed):
                bad.append(f"{{module}} ({{here}}) imports {{name}} ({{there}})")
    return bad


def test_each_stage_imports_only_the_stages_before_it():
    graph = import_graph(modules("bench"))
    assert {{stage_of(m) for m in graph}} == {{"top", *STAGES, *SHARED}}
    bad = back_imports(graph)
    assert not bad, "imports back into an earlier stage (move what both need below them):\\n" + "\\n".join(bad)


def test_the_checker_finds_an_import_back_into_an_earlier_stage():
    graph = {{"bench.sweep.plan": {{"bench.run.units"}}, "bench.run.units": {{"bench.sweep.plan", "bench.core"}},
             "bench.core": {{"bench.report.figures"}}, "bench.tasks.tbd": {{"bench.sweep.rng"}}}}
    assert back_imports(graph) == ["bench.core (top) imports bench.report.figures (report)",
                                   "bench.sweep.plan (sweep) imports bench.run.units (run)",
                                   "bench.tasks.tbd (tasks) imports bench.sweep.rng (sweep)"]


def test_bench_shows_its_stages_with_few_modules_at_the_top():
    top = sorted(p.stem for p in (ROOT / "bench").glob("*.py"))
    assert top == sorted(TOP_MODULES) and len(set(top) - {{"__init__", "__main__"}}) <= 10, top
    for stage, may in STAGES.items():
        doc = ast.get_docstring(ast.parse((ROOT / "bench" / stage / "__init__.py").read_text(encoding="utf-8")))
        assert doc and doc.startswith(f"Stage ``{{stage}}/``"), stage
        rule = next(p for p in doc.split("\\n\\n") if p.startswith("It may import"))
        named = set(re.findall(r"``(\\w+)/``", rule.split("never")[0])) - {{stage, "bench", *SHARED}}
        assert named == set(may), (stage, named)

'''


def ensure_test_imports() -> None:
    path = ROOT / "tests/test_layout.py"
    text = path.read_text(encoding="utf-8")
    for line in ("import ast\n", "import re\n"):
        if line not in text.split("from pathlib import Path")[0]:
            text = text.replace("from pathlib import Path\n", line + "from pathlib import Path\n", 1)
    path.write_text(text, encoding="utf-8")


def main() -> None:
    if not (BENCH / "core.py").exists() or not (ROOT / "radarbench/_compat.py").exists():
        sys.exit("error: tools/regroup_bench.py: run it from the repository's root")
    check_mapping()
    moved = move_modules()
    deepen_own_paths()
    write_stage_inits()
    changed = rewrite_mentions()
    update_compat(moved)
    update_pyproject()
    update_architecture()
    write_layering_test()
    ensure_test_imports()
    print(f"moved {len(moved)} modules, rewrote mentions in {changed} files")


if __name__ == "__main__":
    main()
