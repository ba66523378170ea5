"""The documentation site (bench/cli/docs.py, mkdocs.yml): a page for every registered task,
method and scenario with every parameter, for every committed report with the figures it
shows, and the command line; every link of a generated page reaches a page or a file; the
strict mkdocs build where the ``[docs]`` extra is installed."""

import dataclasses
import html
import importlib.util
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from radarbench.bench import registry
from radarbench.bench.cli import build_parser
from radarbench.bench.cli.docs import base_docstrings, docstring_markdown, main, pages, published, presets, subcommands
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
        assert page.startswith(f"# {text(name)}\n") and text(cls.summary()) in page
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


@pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None or importlib.util.find_spec("material") is None,
                    reason="the [docs] extra is not installed (pip install -e '.[docs]')")
def test_the_site_builds_strictly(tmp_path):
    """``mkdocs build --strict``: a broken link or anchor, a missing image or a page left out
    of the navigation fails it."""
    env = dict(os.environ, PYTHONPATH=str(REPO), NO_MKDOCS_2_WARNING="1")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=scaled())
    assert done.returncode == 0, done.stderr[-3000:]
    for kind in ("methods", "scenarios"):
        assert all((tmp_path / "site" / kind / name / "index.html").is_file() for name in getattr(registry, kind)())
