"""The documentation site's pages generated from the code (docs/architecture.md, 'Documentation').

From the registry: one page per task, method and scenario — its docstring rendered
(:func:`docstring_markdown`; its LaTeX typeset by MathJax, :data:`MATHJAX`), its
parameters as ``bench list -v`` describes them (type, default, meaning, bounds and their
reason: :func:`bench.params.describe_params`), its task, the presets that run it and the
papers they reproduce, its row of the committed ``bench perf`` tables; and a page per
module of ``models`` (its docstring: the maths they share). From the repository: every
committed report (``reports/NAME/report.md`` and the files it links), README.md as the home page and CONTRIBUTING.md, their links rewritten to
the site's; a page of the presets with the wall time each committed report records. From
:func:`bench.cli.build_parser`: the command-line reference. Everything is
discovered when the site is built, so a new plugin or report has its page without an edit
here.

``mkdocs build`` adds the pages to the site through ``docs/hooks.py`` (named by mkdocs.yml),
writing nothing into the clone; ``python -m radarbench.bench.cli.docs OUT_DIR`` writes them into a folder.
"""

from __future__ import annotations

import argparse
import functools
import inspect
import posixpath
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from radarbench.bench.markdown import code, frame_table, table, text

#: repository files published under another site path (the rest keep theirs; docs/ is the site's root)
RENAMED = {"README.md": "index.md", "CONTRIBUTING.md": "contributing.md"}
#: the committed ``bench perf`` tables (:mod:`bench.cli.perf`)
PERF_DIR = "reports/perf"
#: what ``benchmarks/loop.py`` writes: the edit-run-read loop's durations, a JSON record in a fenced block
LOOP_REPORT = f"{PERF_DIR}/loop.md"
#: where a hand-written page takes the measured durations (:func:`fill_measured`; an HTML comment,
#: so the page reads the same without them on GitHub)
MEASURED_MARKER = "<!-- bench: measured durations -->"
#: the steps of the loop benchmark the durations table shows, and how it names them
LOOP_STEPS = {"first": "first `bench run --preset quick` on a fresh clone (compiles the kernels)",
              "warm": "the same again (kernels cached)", "noop": "a re-run with nothing to compute"}
#: the width the command-line reference is wrapped to, whatever the terminal
HELP_WIDTH = 100
#: where the site serves its maths renderer: MathJax's one-file TeX-to-SVG build (every TeX
#: package and the fonts inside, so nothing more is fetched), copied from the ``[docs]``
#: extra's ``mathjax`` package (django-static-mathjax) when the site is built: no network
MATHJAX = "assets/mathjax/tex-svg-full.js"
#: an inline link or image: (its text and the opening parenthesis, the target, an optional title and ")")
_LINK = re.compile(r"(!?\[(?:\\.|[^\]\\])*\]\()([^)\s]+)((?:\s+\"[^\"]*\")?\))")


@dataclass(frozen=True)
class Preset:
    """What a packaged sweep runs, and the paper its claims file names ("" for none)."""

    name: str
    description: str
    methods: frozenset[str]
    scenarios: frozenset[str]
    paper: str


def site_path(repo_path: str) -> str:
    """Where the repository file ``repo_path`` (POSIX, relative) is published on the site."""
    if repo_path in RENAMED:
        return RENAMED[repo_path]
    if repo_path.startswith("docs/"):
        return repo_path.removeprefix("docs/")
    if repo_path.startswith("reports/") and repo_path.endswith("/report.md"):
        return repo_path.removesuffix("report.md") + "index.md"     # its figures/ stay beside it
    return repo_path


def relative(target: str, page: str) -> str:
    """The link from site page ``page`` to site path ``target``."""
    return posixpath.relpath(target, posixpath.dirname(page) or ".")


def published(root: Path, repo_path: str, pages: dict[str, str | Path]) -> None:
    """Add the repository Markdown file ``repo_path`` to ``pages``, each relative link to
    another repository file rewritten to where that file is published, and the file
    published too unless docs/ (the site's own folder) holds it; a link to nothing is left
    as written, so the strict build names it."""
    page = site_path(repo_path)

    def relink(match: re.Match) -> str:
        target, _, anchor = match.group(2).partition("#")
        if not target or re.match(r"^[a-z][a-z0-9+.-]*:|^/", target):      # an anchor, a URL, absolute
            return match.group(0)
        linked = posixpath.normpath(posixpath.join(posixpath.dirname(repo_path), target))
        if not (root / linked).is_file():
            return match.group(0)
        if not linked.startswith("docs/") and site_path(linked) not in pages:
            pages[site_path(linked)] = root / linked
        return match.group(1) + relative(site_path(linked), page) + (f"#{anchor}" if anchor else "") + match.group(3)

    pages[page] = _LINK.sub(relink, (root / repo_path).read_text(encoding="utf-8"))


def presets() -> list[Preset]:
    """Every packaged preset's description, method and scenario names, read from its TOML
    as written (not resolved into a plan: resolving reads a preset's data files, e.g.
    real-trajectories' samples of an optional extra, which building the docs must not need)."""
    import tomllib

    from radarbench.bench.report.claims import preset_claims
    from radarbench.bench.sweep.listing import presets as preset_files

    out = []
    for name, path in preset_files().items():
        sweep = tomllib.loads(path.read_text(encoding="utf-8"))
        scenarios = [sweep["scenario"]] if "scenario" in sweep else [s["name"] for s in sweep.get("scenarios", [])]
        claims = preset_claims(name)
        out.append(Preset(name, " ".join(str(sweep.get("description", "")).split()),
                          frozenset(str(m["name"]) for m in sweep.get("methods", [])),
                          frozenset(map(str, scenarios)), claims.paper if claims else ""))
    return out


def fenced(body: str, info: str = "text") -> str:
    """``body`` verbatim in a fenced block no backtick run inside it can close."""
    fence = "`" * max(3, max((len(run) for run in re.findall("`+", body)), default=0) + 1)
    return f"{fence}{info}\n{body}\n{fence}"


#: a Sphinx cross-reference role (``:func:`~a.b` ``): the docstrings' way of naming code
_ROLE = re.compile(r":(?:func|class|meth|mod|data|attr|obj|exc|const):`(~?)([^`<>]+?)(?:\s*<([^`>]+)>)?`")
#: a NumPy-style section: its title, then a line of dashes as long
_SECTION = re.compile(r"^(\S[^\n]*)\n-{3,}[ \t]*$", re.M)
#: LaTeX as the docstrings write it (CONTRIBUTING.md, 'Documentation'): a ``$$ ... $$`` display
#: block, or ``$...$`` inline with no space inside either dollar (pymdownx.arithmatex's rule)
MATHS = re.compile(r"\$\$.+?\$\$|(?<![\\$])\$(?=\S)(?:\\.|[^\\$])+?(?<=\S)\$", re.S)


def role_name(role: re.Match) -> str:
    """What a :data:`_ROLE` shows, as Sphinx does: its title, else its target (``~``: the last name)."""
    target = role.group(3) or role.group(2)
    return (target.rpartition(".")[2] if role.group(1) else role.group(2) if role.group(3) else target).strip()


def summary_markdown(component) -> str:
    """A plugin's one-line summary (its docstring's first line) as Markdown on one line."""
    return line_markdown(component.summary())


def line_markdown(line: str) -> str:
    """Plain text (a summary) as Markdown on one line: its roles as code, the rest as
    written (:func:`bench.markdown.text`)."""
    parts, last = [], 0
    for m in _ROLE.finditer(line):
        parts += [text(line[last:m.start()]), code(role_name(m))]
        last = m.end()
    return "".join(parts + [text(line[last:])])


def docstring_markdown(doc: str) -> str:
    """A docstring as Markdown for the docs site: cross-reference roles become inline code
    (``~`` keeps the last name, as Sphinx shows it), NumPy-style section titles headings,
    and a paragraph ending in ``::`` introduces the indented block after it, which Markdown
    then shows as code (a layout kept as written). The maths (:data:`MATHS`) is left as
    written for the site's renderer; the rest (``code``, ``*`` lists, emphasis) is Markdown
    already."""
    maths: list[str] = []

    def hold(m: re.Match) -> str:                    # a placeholder no rule below can match
        maths.append(m.group(0))
        return f"\x00{len(maths) - 1}\x00"

    doc = _ROLE.sub(lambda m: f"`{role_name(m)}`", MATHS.sub(hold, doc))
    doc = _SECTION.sub(lambda m: f"#### {m.group(1).strip()}\n", doc)
    doc = re.sub(r"(\S)::[ \t]*$", r"\1:", doc, flags=re.M)
    return re.sub("\x00([0-9]+)\x00", lambda m: maths[int(m.group(1))], doc)


def links(names, folder: str, page: str) -> str:
    return ", ".join(f"[{code(n)}]({relative(f'{folder}/{n}.md', page)})" for n in sorted(names)) or "–"


def report_link(name: str, page: str) -> str:
    """A link from ``page`` to the committed report of preset ``name``."""
    return f"[{code(name)}]({relative(f'reports/{name}/index.md', page)})"


def preset_links(runs: list[Preset], reports: set[str], page: str) -> str:
    """The presets of ``runs``, linked to their committed report when there is one, with the paper."""
    items = []
    for p in runs:
        name = report_link(p.name, page) if p.name in reports else code(p.name)
        items.append(name + (f" (reproduces {text(p.paper)})" if p.paper else ""))
    return "; ".join(items) or "–"


def facts_list(facts: list[tuple[str, str]]) -> str:
    """(label, Markdown) pairs as a list, the label in bold."""
    return "\n".join(f"- **{label}**: {value}" for label, value in facts)


def params_table(params_cls: type) -> str:
    from radarbench.bench.params import describe_params

    rows = [[code(name), text(ptype), code(repr(default)), text(doc)]
            for name, ptype, default, doc in describe_params(params_cls)]
    return table(["parameter", "type", "default", "meaning [bounds: why]"], rows) if rows else "None."


def perf_rows(root: Path, csv_name: str, column: str, name: str, page: str) -> str:
    """The rows of the committed ``bench perf`` table ``csv_name`` whose ``column`` is ``name``."""
    import pandas as pd

    path = root / PERF_DIR / csv_name
    source = f"[{PERF_DIR}/{csv_name}]({relative('reports/perf/index.md', page)})"
    if not path.is_file():
        return f"No committed `bench perf` table ({PERF_DIR}/{csv_name} is absent)."
    rows = pd.read_csv(path)
    rows = rows[rows[column] == name].drop(columns=column).dropna(axis=1, how="all").copy()
    if rows.empty:
        return f"No row in {source}: `bench perf` has not measured it yet."
    seconds = [c for c in rows.columns if c.endswith("seconds_per_trial")]
    rows[seconds] = rows[seconds] * 1e3
    rows = rows.rename(columns={c: c.replace("seconds_", "ms_") for c in seconds})
    rows = rows.rename(columns=lambda c: c.replace("_", " "))      # a header wraps at its spaces: no sideways scroll
    return f"From {source} (one core; how it is measured: that page).\n\n{frame_table(rows)}"


def _harness_or_builtin(module: str) -> bool:
    harness = __name__.rsplit(".", 2)[0]            # this package, whatever name it is imported by
    return module == "builtins" or module == harness or module.startswith(harness + ".")


def base_docstrings(cls: type) -> list[str]:
    """The docstrings ``cls`` inherits from its plugin's own base classes (a family's shared
    model and formulas, e.g. the GO/SO-CFAR's closed-form Pfa), each under its class's name;
    the harness's bases (``bench.core``) are left out, they state the protocol, not the plugin."""
    parts, own = [], inspect.getdoc(cls)             # getdoc falls back to the nearest base's docstring
    for base in cls.__mro__[1:]:
        doc = base.__dict__.get("__doc__")
        if doc and inspect.cleandoc(doc) != own and not _harness_or_builtin(base.__module__):
            parts += [f"### From {code(f'{base.__module__}.{base.__qualname__}')}", docstring_markdown(inspect.cleandoc(doc))]
    return parts


def component_page(kind: str, cls: type, page: str, facts: list[tuple[str, str]], perf: str) -> str:
    """A method's or a scenario's page: its summary, ``facts`` (label, Markdown), docstring
    (and its base classes'), parameters, speed."""
    return "\n\n".join([
        f"# {text(cls.name)}", summary_markdown(cls),
        facts_list(facts + [("class", code(f"{cls.__module__}.{cls.__qualname__}"))]),
        "## Description", f"The {kind}'s docstring.", docstring_markdown(inspect.getdoc(cls) or ""),
        *base_docstrings(cls),
        "## Parameters", "Set in a sweep's `params` table; `bench list -v` prints the same.", params_table(cls.Params),
        "## Performance", perf]) + "\n"


def plugin_pages(root: Path, pages: dict[str, str | Path], all_presets: list[Preset], reports: set[str]) -> None:
    """The task, method and scenario pages, and an index of each kind."""
    from radarbench.bench import registry
    from radarbench.bench.sweep.capabilities import fits

    methods, scenarios, tasks = registry.methods(), registry.scenarios(), registry.tasks()
    for name, cls in methods.items():
        page = f"methods/{name}.md"
        facts = [("task", links([cls.task], "tasks", page) + f": {summary_markdown(tasks[cls.task])}"),
                 ("runs on", links([s for s, c in scenarios.items() if fits(cls, c)], "scenarios", page)),
                 ("presets", preset_links([p for p in all_presets if name in p.methods], reports, page))]
        pages[page] = component_page("method", cls, page, facts, perf_rows(root, "perf.csv", "method", name, page))
    for name, cls in scenarios.items():
        page = f"scenarios/{name}.md"
        runners = [m for m, c in methods.items() if fits(c, cls)]
        facts = [("tasks", links(cls.tasks, "tasks", page)), ("methods", links(runners, "methods", page)),
                 ("small instance", code(cls.small_params) if cls.small_params else "the defaults"),
                 ("presets", preset_links([p for p in all_presets if name in p.scenarios], reports, page))]
        pages[page] = component_page("scenario", cls, page, facts, perf_rows(root, "scene.csv", "scenario", name, page))
    for name, task in tasks.items():
        page = f"tasks/{name}.md"
        pages[page] = "\n\n".join([
            f"# {text(name)}", summary_markdown(task), docstring_markdown(inspect.getdoc(type(task)) or ""),
            facts_list([("scenarios", links([s for s, c in scenarios.items() if name in c.tasks], "scenarios", page)),
                        ("methods", links([m for m, c in methods.items() if c.task == name], "methods", page)),
                        ("class", code(f"{type(task).__module__}.{type(task).__qualname__}"))])]) + "\n"
    for folder, title, table_of in (("tasks", "Tasks", tasks), ("methods", "Methods", methods),
                                    ("scenarios", "Scenarios", scenarios)):
        rows = [[f"[{code(n)}]({n}.md)", summary_markdown(c)] for n, c in table_of.items()]
        index = [f"# {title}", f"Every {folder[:-1]} registered when this site was built.", table([folder[:-1], "what"], rows)]
        missing = [u for u in registry.unavailable()             # "radarbench.methods.x", "bench.methods:x" -> "methods"
                   if re.split(r"[.:]", u.source.removeprefix("radarbench.").removeprefix("bench."))[0] == folder]
        if missing:
            index += ["Plugins that could not be registered in the environment that built this site:",
                      table(["plugin", "why"], [[code(u.name or u.source), text(u.error)] for u in missing])]
        pages[f"{folder}/index.md"] = "\n\n".join(index) + "\n"


def model_docstrings(root: Path) -> dict[str, str]:
    """The docstring of every module of the repository's ``models/`` (the maths methods and
    scenarios share, docs/architecture.md, 'Models'), by its dotted name under ``models``
    (``cfar`` for ``models/cfar/__init__.py``, "" for the package), read from its source:
    nothing imported (the harness never imports ``models``)."""
    import ast

    docs = {}
    for path in sorted((root / "models").rglob("*.py")):
        parts = path.relative_to(root / "models").with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)     # "" for models/__init__.py
        docs[name] = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    return dict(sorted(docs.items()))


def model_pages(root: Path, pages: dict[str, str | Path]) -> list[str]:
    """A page per module of ``models`` (its docstring, rendered as a plugin's is) and an
    index of them. Returns the modules' names."""
    docs = model_docstrings(root)
    about = docs.pop("", "")                      # the package's own docstring opens the index
    for name, doc in docs.items():
        pages[f"models/{name}.md"] = f"# {text('models.' + name)}\n\n{docstring_markdown(doc)}\n"
    rows = [[f"[{code('models.' + n)}]({n}.md)", line_markdown(" ".join(d.split("\n\n")[0].split()))]
            for n, d in docs.items()]
    pages["models/index.md"] = "\n\n".join(["# Models", docstring_markdown(about), table(["module", "what"], rows)]) + "\n"
    return list(docs)


def report_pages(root: Path, pages: dict[str, str | Path], all_presets: list[Preset]) -> list[str]:
    """Every committed report (``reports/NAME/report.md``) and the files it links; an index
    of them, the paper reproductions first. Returns the reports' names."""
    names = sorted(p.parent.name for p in (root / "reports").glob("*/report.md"))
    for name in names:
        published(root, f"reports/{name}/report.md", pages)
    by_name = {p.name: p for p in all_presets}
    rows = [[f"[{code(n)}]({n}/index.md)", text(by_name[n].paper) if n in by_name and by_name[n].paper else "–",
             text(by_name[n].description) if n in by_name else "–"]
            for n in sorted(names, key=lambda n: (not (n in by_name and by_name[n].paper), n))]
    pages["reports/index.md"] = "\n\n".join([
        "# Reports", "The committed report of each preset: a paper preset's report opens with its "
        "claims against the paper (*Paper vs ours*); every report has its figures and the command that "
        "reproduces it.", table(["report", "paper", "preset"], rows)]) + "\n"
    return names


def wall_time(report: Path) -> str:
    """The wall time of the units of the run that made the committed ``report`` (report.md),
    as its Provenance table states it; "–" when it states none."""
    from radarbench.bench.results.provenance import WALL_TIME_ROW

    for line in report.read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 2 and cells[0] == WALL_TIME_ROW:
            return cells[1]
    return "–"


def loop_record(root: Path) -> dict | None:
    """The JSON record of the committed :data:`LOOP_REPORT` (``benchmarks/loop.py``), or None."""
    import json

    path = root / LOOP_REPORT
    if not path.is_file():
        return None
    text = path.read_text(encoding="utf-8")
    start = text.find("```json")
    if start < 0:
        return None
    body = text[start + len("```json"):]
    return json.loads(body[:body.index("```")])


def durations(root: Path, page: str) -> str:
    """The measured durations of a first run, a warm run, a no-op re-run and the test suite
    (from :data:`LOOP_REPORT`, never typed), with the machine and its load, for ``page``."""
    source = f"[{LOOP_REPORT}]({relative(LOOP_REPORT, page)})"
    record = loop_record(root)
    if record is None:
        return f"Not measured yet: `python benchmarks/loop.py` writes {code(LOOP_REPORT)}."
    rows = []
    for step, what in LOOP_STEPS.items():
        done = [m for m in record["steps"] if m["step"] == step and m["exit_code"] == 0]
        if done:
            m = done[0]
            load = ", ".join(f"{x:g}" for x in m["load_before"])
            rows.append([what, f"{m['wall_s']:.0f} s", f"{m['cpu_s']:.0f} s", load])
    suite = record.get("test_suite_wall_s")
    if suite is not None:
        rows.append(["the test suite, `python -m pytest -q` (two xdist workers)", f"{suite:.0f} s", "–", "–"])
    if not rows:
        return f"{source} holds no first, warm or no-op run: `python benchmarks/loop.py` measures them."
    return "\n\n".join([
        f"Measured by `python benchmarks/loop.py` on {record['created']} ({record['cpu_count']} CPUs, "
        f"{text(record['platform'])}; {source}): wall time as you wait, CPU time of every process of the "
        "command (its workers included); a busy machine (the load average) lengthens the wall time."
        + (f" Commands ran in {record['environment']}." if record.get("environment") else ""),
        table(["what", "wall time", "CPU time", "load average before (1, 5, 15 min)"], rows)])


def fill_measured(markdown: str, root: Path, page: str) -> str:
    """A hand-written page with :data:`MEASURED_MARKER` gets the measured durations there
    (``docs/hooks.py``, when the site is built)."""
    return markdown.replace(MEASURED_MARKER, durations(root, page)) if MEASURED_MARKER in markdown else markdown


def presets_page(root: Path, all_presets: list[Preset], reports: list[str]) -> str:
    """Every packaged preset: what it runs, the paper of its claims, its committed report and
    that run's wall time (read from the report, never typed), and the commands that
    regenerate the committed reports."""
    page = "presets.md"
    rows = [[report_link(p.name, page) if p.name in reports else code(p.name), text(p.description),
             text(p.paper) if p.paper else "–",
             wall_time(root / "reports" / p.name / "report.md") if p.name in reports else "–"]
            for p in sorted(all_presets, key=lambda p: (not p.paper, p.name))]
    regenerate = [f"for p in {' '.join(n for n in reports if n in {p.name for p in all_presets})}; do",
                  "    bench run --preset $p --out reports/$p --fresh", "done"]
    if (root / PERF_DIR / "report.md").is_file():
        regenerate.append(f"bench perf --out {PERF_DIR}")
    return "\n\n".join([
        "# Presets",
        "Packaged sweep files (`bench/presets/NAME.toml`): `bench run --preset NAME` runs one into "
        "`runs/NAME/`. A paper preset's claims and notes sit beside it ([Sweep files, 'Presets and "
        "their claims'](sweep-files.md#presets-and-their-claims)); its committed report opens with them. "
        "The wall time is that of the units of the last `bench run` that wrote the committed report "
        "(before its report and recording; a run that resumed, or re-ran only what an edit changed, "
        "counts the units it ran), as the report's *Provenance* states it, on the machine it names.",
        table(["preset (its committed report)", "what", "paper", "wall time of the units"], rows),
        "## A first run, a warm run, the tests", durations(root, page),
        "## Regenerating the committed reports",
        "One command per preset with a committed report (they are regenerated after a change that "
        "alters results), then the speed tables:",
        fenced("\n".join(regenerate), "sh")]) + "\n"


def mathjax_script() -> Path | None:
    """The file :data:`MATHJAX` is a copy of, or None where the ``[docs]`` extra is not installed."""
    import importlib.util

    spec = importlib.util.find_spec("mathjax")
    if spec is None or not spec.submodule_search_locations:
        return None
    script = Path(next(iter(spec.submodule_search_locations))) / "static" / "mathjax" / "es5" / "tex-svg-full.js"
    return script if script.is_file() else None


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]   # noqa: SLF001 - argparse has no public accessor
    return dict(actions[0].choices) if actions else {}


def help_text(parser: argparse.ArgumentParser) -> str:
    """``parser``'s ``--help``, wrapped to :data:`HELP_WIDTH` columns on any terminal."""
    parser.formatter_class = functools.partial(parser.formatter_class, width=HELP_WIDTH)
    return parser.format_help().rstrip()


def cli_page() -> str:
    from radarbench.bench.cli import build_parser

    parser = build_parser()
    parts = ["# Command line", "The `bench` command's `--help` and each subcommand's, generated from its parser.",
             "## bench", fenced(help_text(parser))]
    for name, sub in subcommands(parser).items():
        parts += [f"## bench {name}", fenced(help_text(sub))]
    return "\n\n".join(parts) + "\n"


def pages(root: str | Path) -> tuple[dict[str, str | Path], list]:
    """(site path -> Markdown text or a file to copy, the generated part of the navigation)
    for the repository at ``root``."""
    root = Path(root)
    out: dict[str, str | Path] = {}
    all_presets = presets()
    for repo_path in RENAMED:
        if (root / repo_path).is_file():
            published(root, repo_path, out)
    reports = report_pages(root, out, all_presets)
    if (root / LOOP_REPORT).is_file():
        published(root, LOOP_REPORT, out)
    plugin_pages(root, out, all_presets, set(reports))
    models = model_pages(root, out)
    out["presets.md"] = presets_page(root, all_presets, reports)
    out["cli.md"] = cli_page()

    def section(folder: str, names) -> list:
        return [f"{folder}/index.md"] + [{n: f"{folder}/{n}.md"} for n in names]

    from radarbench.bench import registry
    nav = [{"Tasks": section("tasks", registry.tasks())}, {"Methods": section("methods", registry.methods())},
           {"Scenarios": section("scenarios", registry.scenarios())}, {"Models": section("models", models)},
           {"Presets": "presets.md"}, {"Reports": ["reports/index.md"] + [{n: f"reports/{n}/index.md"} for n in reports]},
           {"Command line": "cli.md"}]
    return out, nav


def write(out_dir: Path, generated: dict[str, str | Path]) -> None:
    """The pages into ``out_dir`` (the files they link copied)."""
    for path, content in generated.items():
        target = out_dir / path
        target.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, Path):
            target.write_bytes(content.read_bytes())
        else:
            target.write_text(content, encoding="utf-8")


def folder_problem(out_dir: Path, root: Path) -> str | None:
    """Why the pages cannot be written to ``out_dir`` from the repository at ``root``, in one line."""
    if out_dir.exists() and not out_dir.is_dir():
        return f"OUT_DIR: {out_dir} exists and is not a folder"
    if not (root / "README.md").is_file():
        return f"--root: {root} is not the repository's root (no README.md)"
    return None


def main(argv: list[str] | None = None) -> int:
    """``python -m radarbench.bench.cli.docs OUT_DIR [--root REPO]``: the generated pages into OUT_DIR."""
    parser = argparse.ArgumentParser(prog="python -m radarbench.bench.cli.docs", description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", help="folder to write the pages into (created if absent)")
    parser.add_argument("--root", default=".", help="the repository's root (default: the current folder)")
    args = parser.parse_args(argv)
    out_dir, root = Path(args.out_dir), Path(args.root)
    problem = folder_problem(out_dir, root)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return 2                                   # bad input (bench.errors.ConfigError's exit code)
    write(out_dir, pages(root)[0])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
