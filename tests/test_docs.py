"""The documentation site (bench/cli/docs.py, mkdocs.yml): a page for every registered task,
method and scenario with every parameter, for every committed report with the figures it
shows, and the command line; every link of a generated page reaches a page or a file; the
strict mkdocs build where the ``[docs]`` extra is installed."""

import dataclasses
import html
import importlib.util
import inspect
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from radarbench.bench import registry
from radarbench.bench.cli import build_parser
from radarbench.bench.cli.docs import (MATHJAX, MATHS, base_docstrings, docstring_markdown, main, mathjax_script,
                                       model_docstrings, pages, published, presets, subcommands, summary_markdown)
from radarbench.bench.markdown import code, text
from radarbench.bench.results.provenance import WALL_TIME_ROW
from conftest import scaled

REPO = Path(__file__).resolve().parents[1]
#: a relative link target of a Markdown page (external URLs and bare anchors left out)
LINK = re.compile(r"!?\[(?:\\.|[^\]\\])*\]\((?![a-z][a-z0-9+.-]*:|#)([^)\s#]+)")


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("docs")
    assert main([str(out), "--root", str(REPO)]) == 0
    return out


@pytest.mark.parametrize("kind", ["methods", "scenarios"])
def test_every_plugin_has_a_page_with_every_parameter(site, kind):
    for name, cls in getattr(registry, kind)().items():
        page = (site / kind / f"{name}.md").read_text(encoding="utf-8")
        assert page.startswith(f"# {text(name)}\n") and summary_markdown(cls) in page
        for field in dataclasses.fields(cls.Params):
            row = next((line for line in page.splitlines() if line.startswith(f"| {code(field.name)} ")), None)
            assert row is not None, f"{kind}/{name}: parameter {field.name} has no row"
            plain = html.unescape(row).replace("\\", "")       # the Markdown escapes undone
            assert repr(field.default) in plain and field.metadata["doc"] in plain
            for key, sign in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")):
                assert field.metadata.get(key) is None or f"{sign} {field.metadata[key]}" in plain
            assert (field.metadata.get("why") or "") in plain
        index = (site / kind / "index.md").read_text(encoding="utf-8")
        assert f"[{code(name)}]({name}.md)" in index


def test_every_model_module_has_a_page_with_its_docstring(site):
    """The maths methods and scenarios share (``models/``) is on the site, a page per module."""
    index = (site / "models" / "index.md").read_text(encoding="utf-8")
    docs = model_docstrings(REPO)
    assert docstring_markdown(docs.pop("")) in index
    for name, doc in docs.items():
        page = (site / "models" / f"{name}.md").read_text(encoding="utf-8")
        assert page.startswith(f"# {text('models.' + name)}\n") and docstring_markdown(doc) in page
        assert f"({name}.md)" in index
    assert {"kalman", "pcrb", "cfar", "cfar.halves"} <= set(model_docstrings(REPO))


def test_a_plugin_registered_later_has_its_page(monkeypatch):
    """Pages come from the registry when the site is built: a method registered now (as an
    entry point's would be) has its page and its place in the navigation, no edit elsewhere."""
    monkeypatch.setattr(registry, "_METHODS", dict(registry.methods()))
    base = registry.get_method("cv-kf")
    registry.register_method(type("Probe", (base,), {"name": "docs-probe", "__doc__": "A probe.\n\n    x_k = F x_(k-1)"}))
    generated, nav = pages(REPO)
    assert "x_k = F x_(k-1)" in generated["methods/docs-probe.md"]
    assert {"docs-probe": "methods/docs-probe.md"} in next(s["Methods"] for s in nav if "Methods" in s)
    assert "[`docs-probe`](../methods/docs-probe.md)" in generated[f"tasks/{base.task}.md"]


def test_no_generated_page_shows_a_raw_cross_reference_role(site):
    """Docstrings are rendered (docs/architecture.md): a role such as :func:`x` becomes
    inline code, so the site shows none of them as typed."""
    role = re.compile(r":(?:func|class|meth|mod|data|attr|obj|exc|const):`")
    pages_with_roles = [str(p.relative_to(site)) for p in site.rglob("*.md")
                        if p.parts[len(site.parts)] in ("methods", "scenarios", "tasks") and role.search(p.read_text("utf-8"))]
    assert not pages_with_roles
    assert docstring_markdown("a :func:`~m.f`, :class:`m.C` and :meth:`run <m.C.run>`") == "a `f`, `m.C` and `run`"
    assert docstring_markdown("Notes\n-----\nx") == "#### Notes\n\nx"


def test_every_task_page_lists_its_methods(site):
    for name in registry.tasks():
        page = (site / "tasks" / f"{name}.md").read_text(encoding="utf-8")
        for method, cls in registry.methods().items():
            assert (f"[{code(method)}](../methods/{method}.md)" in page) == (cls.task == name)


def test_a_measured_method_shows_its_perf_row(site):
    """Every method of the committed perf.csv shows its measured sizes; one it lacks says so."""
    import pandas as pd

    perf = pd.read_csv(REPO / "reports" / "perf" / "perf.csv")
    for name in registry.methods():
        page = (site / "methods" / f"{name}.md").read_text(encoding="utf-8").split("## Performance", 1)[1]
        sizes = perf[perf.method == name]["size"]
        assert all(f"| {size} " in page for size in sizes)
        assert ("No row in" in page) == sizes.empty


def test_every_committed_report_is_a_page_with_its_figures(site):
    reports = sorted(p.parent.name for p in (REPO / "reports").glob("*/report.md"))
    assert reports
    for name in reports:
        page = site / "reports" / name / "index.md"
        figures = [t for t in LINK.findall(page.read_text(encoding="utf-8")) if t.startswith("figures/")]
        assert all((page.parent / t).is_file() for t in figures), name
        assert f"[{code(name)}]({name}/index.md)" in (site / "reports" / "index.md").read_text(encoding="utf-8")


def test_every_link_of_a_generated_page_resolves(site):
    """A relative link reaches a generated page or file, or a hand-written one in docs/."""
    for page in site.rglob("*.md"):
        for target in LINK.findall(page.read_text(encoding="utf-8")):
            resolved = os.path.normpath(page.parent.relative_to(site) / target)
            assert (site / resolved).is_file() or (REPO / "docs" / resolved).is_file(), f"{page}: {target}"


def test_a_method_page_shows_the_docstrings_of_its_family_base_classes(site):
    """A family's shared model (a base class in methods/) is on each member's page, the
    harness's own bases (bench.core) are not."""
    shown = 0
    for name, cls in registry.methods().items():
        page = (site / "methods" / f"{name}.md").read_text(encoding="utf-8")
        for base in cls.__mro__[1:]:
            doc = base.__dict__.get("__doc__")
            if doc and base.__module__.startswith("radarbench.methods") and inspect.cleandoc(doc) != inspect.getdoc(cls):
                assert docstring_markdown(inspect.cleandoc(doc)).splitlines()[0] in page, f"{name}: {base.__qualname__}"
                shown += 1
        assert "bench.core" not in "".join(base_docstrings(cls))
    assert shown


def test_the_presets_page_has_every_preset_and_the_wall_time_its_report_states(site):
    page = (site / "presets.md").read_text(encoding="utf-8")
    for preset in presets():
        report = REPO / "reports" / preset.name / "report.md"
        name = f"[{code(preset.name)}](reports/{preset.name}/index.md)" if report.is_file() else code(preset.name)
        row = next(line for line in page.splitlines() if line.startswith(f"| {name} "))
        stated = [line for line in report.read_text(encoding="utf-8").splitlines() if WALL_TIME_ROW in line] \
            if report.is_file() else []
        if stated:
            wall = re.search(r"\| ([0-9.]+ s) +\|\s*$", stated[0]).group(1)
            assert f"| {wall} " in row
        else:
            assert row.rstrip(" |").endswith("–")
        regenerated = page.split("for p in ", 1)[1].split(";")[0].split()
        assert (preset.name in regenerated) == report.is_file()


def test_the_readme_shows_the_test_command_ci_runs():
    """.ci/run runs the README's test command: the command it ends with is in the README's
    shell block as written."""
    command = (REPO / ".ci" / "run").read_text(encoding="utf-8").strip().splitlines()[-1]
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```sh\n(.*?)```", readme, re.S)
    assert command.startswith("python -m pytest") and any(line.startswith(command + " ") or line == command
                                                          for block in blocks for line in block.splitlines())


def test_the_command_line_page_has_every_subcommand(site):
    page = (site / "cli.md").read_text(encoding="utf-8")
    for name, sub in subcommands(build_parser()).items():
        assert f"## bench {name}\n" in page and f"usage: bench {name}" in page
        assert all(option in page for action in sub._actions for option in action.option_strings)


def test_links_are_rewritten_to_where_their_files_are_published(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "guide.md").write_text("# guide\n")
    (tmp_path / "reports" / "x" / "figures").mkdir(parents=True)
    (tmp_path / "reports" / "x" / "figures" / "f.png").write_bytes(b"png")
    (tmp_path / "LICENSE").write_text("MIT\n")
    (tmp_path / "README.md").write_text(
        "[g](docs/guide.md#part) [l](LICENSE) [gone](missing.md) [web](https://example.org/a.md) [here](#top)\n"
        "![a \\[b\\]](reports/x/figures/f.png \"title\")\n")
    pages = {}
    published(tmp_path, "README.md", pages)
    assert pages["index.md"] == ("[g](guide.md#part) [l](LICENSE) [gone](missing.md) [web](https://example.org/a.md) "
                                 "[here](#top)\n![a \\[b\\]](reports/x/figures/f.png \"title\")\n")
    assert pages["LICENSE"] == tmp_path / "LICENSE" and pages["reports/x/figures/f.png"].is_file()
    assert "guide.md" not in pages and "docs/guide.md" not in pages      # docs/ is the site's own folder


def test_an_output_that_is_a_file_is_refused_in_one_line(tmp_path, capsys):
    target = tmp_path / "out"
    target.write_text("keep")
    assert main([str(target), "--root", str(REPO)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "OUT_DIR" in err and target.read_text() == "keep"


DOCS_EXTRA = ("mkdocs", "material", "mathjax")
#: a page's code, maths and scripts: the rest is what the reader sees as typed
VERBATIM_OR_MATHS = re.compile(r'<(pre|code|script)\b.*?</\1>|<(span|div) class="arithmatex">.*?</\2>', re.S)
#: an equation as pymdownx.arithmatex leaves it for MathJax (generic mode): \( \) inline, \[ \] display
ARITHMATEX = re.compile(r'<(span|div) class="arithmatex">(.*?)</\1>', re.S)
#: MathJax's checker of TeX (node): the site's equations that MathJax cannot typeset
MATHJAX_CHECK = Path(__file__).with_name("mathjax_check.js")


@pytest.fixture(scope="module")
def built_site(tmp_path_factory) -> Path:
    """``mkdocs build --strict`` of the repository: a broken link or anchor, a missing image
    or a page left out of the navigation fails it."""
    missing = [m for m in DOCS_EXTRA if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"the [docs] extra is not installed ({', '.join(missing)} absent): pip install -e '.[docs]'")
    out = tmp_path_factory.mktemp("built") / "site"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
               NO_MKDOCS_2_WARNING="1")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=scaled())
    assert done.returncode == 0, done.stderr[-3000:]
    return out


def test_the_site_builds_strictly(built_site):
    for kind in ("methods", "scenarios"):
        assert all((built_site / kind / name / "index.html").is_file() for name in getattr(registry, kind)())


def _html_pages(site: Path) -> dict[str, str]:
    return {str(p.relative_to(site)): p.read_text(encoding="utf-8") for p in site.rglob("*.html")}


def test_the_built_site_shows_no_cross_reference_role_and_no_unrendered_maths(built_site):
    """Outside code and maths, no page shows a Sphinx role or a dollar sign: a ``$`` left
    there is an equation arithmatex did not take (``$x $``, ``$ x$``, an unclosed one); a
    price in prose would be written ``&#36;``."""
    role = re.compile(r":(?:func|class|meth|mod|data|attr|obj|exc|const):`")
    shown = {page: VERBATIM_OR_MATHS.sub("", body) for page, body in _html_pages(built_site).items()}
    assert not [page for page, body in shown.items() if role.search(body)]
    assert not {page: re.findall(r".{0,30}\$.{0,30}", body)[:3] for page, body in shown.items() if "$" in body}


def test_every_docstring_equation_is_maths_on_its_page_with_the_renderer(built_site):
    """Each ``$...$``/``$$...$$`` of a plugin's docstrings (its own and its family's bases')
    and of a ``models`` module's is an arithmatex element of its page, and every page with
    one loads the MathJax configuration, then MathJax, copied into the site."""
    classes = {f"{kind}/{name}": cls for kind in ("methods", "scenarios") for name, cls in getattr(registry, kind)().items()}
    classes.update({f"tasks/{name}": type(task) for name, task in registry.tasks().items()})
    docs = {page: "\n\n".join([inspect.getdoc(cls) or "", *base_docstrings(cls)]) for page, cls in classes.items()}
    docs.update({f"models/{name}" if name else "models": doc for name, doc in model_docstrings(REPO).items()})
    with_maths = 0
    for page, doc in docs.items():
        body = (built_site / page / "index.html").read_text(encoding="utf-8")
        written = len(MATHS.findall(doc))
        assert len(ARITHMATEX.findall(body)) >= written, page
        with_maths += written > 0
    assert with_maths >= 40
    for page, body in _html_pages(built_site).items():
        if ARITHMATEX.search(body):
            scripts = re.findall(r'<script src="([^"]+)"', body)
            config = next(i for i, s in enumerate(scripts) if s.endswith("javascripts/mathjax-config.js"))
            renderer = next(s for s in scripts[config:] if s.endswith(MATHJAX))
            assert (built_site / Path(page).parent / renderer).resolve().is_file(), page


@pytest.mark.skipif(shutil.which("node") is None, reason="node is absent: MathJax's TeX parser cannot be run")
def test_every_equation_of_the_site_typesets_in_mathjax(built_site):
    """MathJax (the site's own copy, run by node) parses every equation of the site: no
    unbalanced brace, no undefined macro (shown in red in a browser, an error here)."""
    equations = {(html.unescape(tex)[2:-2].strip(), tag == "div")
                 for body in _html_pages(built_site).values() for tag, tex in ARITHMATEX.findall(body)}
    assert equations
    es5 = mathjax_script().parent
    done = subprocess.run(["node", str(MATHJAX_CHECK), str(es5)], input=json.dumps(sorted(equations)),
                          capture_output=True, text=True, timeout=scaled())
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout) == []


def test_docstring_maths_passes_through_as_written():
    """The docstring step leaves LaTeX as written (no escape, no role or section rule inside it)."""
    doc = "A $\\hat{x}_{k|k}$ and $a^*_i$::\n\n$$\nJ_k = \\max_{d'} \\left[ J_{k-1} \\right]::\n$$\n\nSee :func:`~m.f`."
    assert docstring_markdown(doc) == doc.replace("$::", "$:").replace(":func:`~m.f`", "`f`")
