"""No text that is not ours reaches report.html, report.md or a terminal as live markup.

Hypothesis draws hostile strings — HTML tags and event handlers, ``javascript:`` and
``data:`` links (plain, entity-encoded, split by blanks), backtick runs, pipes,
backslashes, control, terminal-escape and bidi characters — and drives them

* through the Markdown helpers (:mod:`bench.markdown`) and the HTML conversion
  (:mod:`bench.report.html`): a code span, a text and a table cell render exactly
  as written (control characters as their escapes), with no element, attribute or
  link made from the input;
* through every user-controlled field of a run — the sweep's description, its file
  name, the ``--out`` path (in the command), method and scenario config labels,
  method and scenario parameter strings, a plugin's error text (the Failures table)
  and its reason for skipping a pair — into report.html, parsed with html5lib: no
  element or attribute that the input names, no URL scheme it carries, every script
  one of ours and hashed in the page's Content-Security-Policy; report.md free of
  control and bidi characters.

The plugins are registered in-process (a method and a scenario that carry a free
string parameter) and run by the serial executor, as tests/test_isolation.py does.
"""

from __future__ import annotations

import base64
import hashlib
import re
from dataclasses import dataclass

import html5lib
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from radarbench.bench import registry
from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.core import MANEUVER_DETECTION, Method
from radarbench.bench.escapes import escape_controls
from radarbench.bench.markdown import code, table, text
from radarbench.bench.params import param
from radarbench.bench.report import build_outputs
from radarbench.bench.report.html import _body, safe_url
from radarbench.bench.run.runner import plan_record, run_sweep
from radarbench.methods.maneuver.innovation import Innovation
from radarbench.scenarios.cv_turn_cv import CvTurnCv

FRAGMENTS = [
    "<script>alert(1)</script>", "<img src=x onerror=alert(1)>", "<svg onload=alert(1)>", "<iframe src=//e.x>",
    '<a href="javascript:alert(1)">a</a>', "[x](javascript:alert(1))", "[y](&#106;avascript:alert(1))",
    "[z](java\tscript:alert(1))", "![i](data:image/svg+xml;base64,PHN2Zz4=)", "<http://e.x>", "[r]: javascript:x",
    "`", "``", "```", " ` ", "|", "\\", "\\|", "*", "_", "&lt;b&gt;", "&", "\n", "\n\n", "#", "- ", "> ",
    "<details>", "</details>", "<details><summary>s</summary>", '<div id="bench-interactive"></div>',
    "\x1b[31m", "\x1b]0;t\x07", "\x9b2J", "\x00", "\r", "\u202e", "\u2066", "\u200f", "\u2028", "é",
]
hostile = st.lists(st.one_of(st.sampled_from(FRAGMENTS), st.text(max_size=3)), min_size=1, max_size=6).map("".join)

#: What the input's tags and handlers would be called (none may appear as an element or attribute).
TAGS_FROM_INPUT = {"script", "img", "svg", "iframe", "a", "details", "summary", "div"}
CONTROLS = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028\u2029\u202a-\u202e\u2066-\u2069]")


def parse(page: str):
    return html5lib.HTMLParser(namespaceHTMLElements=False).parse(page)


def only(doc, tag: str) -> str:
    """The text of the one ``tag`` element of ``doc``."""
    found = list(doc.iter(tag))
    assert len(found) == 1, [el.tag for el in doc.iter()]
    return "".join(found[0].itertext())


def assert_inert(doc) -> None:
    """No element the input could have made, no attribute at all (our conversion of
    Markdown sets none), nothing that reads as a URL scheme."""
    tags = {el.tag for el in doc.iter()}
    assert not tags & TAGS_FROM_INPUT, tags
    assert not [el.attrib for el in doc.iter() if el.attrib]


@given(s=hostile)
def test_a_code_span_a_text_and_a_cell_render_as_written(s):
    shown = escape_controls(s, inline=True)
    doc = parse(_body(f"{code(s)}"))
    assert_inert(doc)
    if shown.strip():
        assert only(doc, "code") == shown.strip()
    doc = parse(_body(text(s)))
    assert_inert(doc)
    assert not list(doc.iter("code")) and "".join(doc.find("body").itertext()).strip() == shown.strip()
    doc = parse(_body(table(["h"], [[code(s)], [text(s)]])))
    assert_inert(doc)
    cells = ["".join(td.itertext()) for td in doc.iter("td")]
    assert cells == [shown.strip() if shown.strip() else "", shown.strip()]


@given(s=hostile)
def test_a_description_keeps_its_lines_and_makes_nothing(s):
    doc = parse(_body(text(s, inline=False)))
    assert_inert(doc)
    assert not CONTROLS.search("".join(doc.getroot().itertext()) if hasattr(doc, "getroot") else
                               "".join(doc.itertext()))


@pytest.mark.parametrize("url, ok", [
    ("javascript:alert(1)", False), ("JaVaScRiPt:x", False), ("java\tscript:x", False), (" javascript:x", False),
    ("&#106;avascript:x", False), ("&#x6A;avascript:x", False), ("data:text/html,x", False), ("vbscript:x", False),
    ("file:///etc/passwd", False), ("http://example.org", True), ("HTTPS://example.org/a?b#c", True),
    ("#anchor", True), ("figures/a.png", True), ("a/b:c", True), ("", True)])
def test_only_http_relative_and_anchor_urls_are_kept(url, ok):
    assert safe_url(url) is ok
    doc = parse(_body(f"[x]({url}) ![y]({url})"))
    assert [a.get("href") is not None for a in doc.iter("a")] == [ok]
    assert all(img.get("src") in (None, "figures/a.png") for img in doc.iter("img"))


# ------------------------------------------------------------------ whole runs

class Scribe(Method):
    """The innovation detector with a free text note; raises with ``fail``, and without it
    refuses a scenario config noted ``refuse`` (both with the note as its words)."""

    name = "scribe"
    task = MANEUVER_DETECTION

    @dataclass(frozen=True)
    class Params:
        note: str = param("", "any text")
        fail: bool = param(False, "raise RuntimeError(note) on every unit")

    def check_scenario(self, params, scenario_params):
        return params.note if getattr(scenario_params, "note", "") == "refuse" and not params.fail else None

    def run(self, batch, params):
        if params.fail:
            raise RuntimeError(params.note)
        return Innovation().run(batch, Innovation.Params(window=1))

    def nominal_threshold(self, params, pfa, batch):
        return Innovation().nominal_threshold(Innovation.Params(window=1), pfa, batch)


class NotedCv(CvTurnCv):
    """cv-turn-cv with a free text note."""

    name = "noted-cv"

    @dataclass(frozen=True)
    class Params(CvTurnCv.Params):
        note: str = param("", "any text")


@pytest.fixture(scope="module")
def plugins():
    registry.register_method(Scribe)
    registry.register_scenario(NotedCv)
    yield
    registry._METHODS.pop("scribe", None)
    registry._SCENARIOS.pop("noted-cv", None)


LABEL_TEXT = st.sampled_from(["x[a](b)", "a (b) [c]", "y=1, z+2", "q[w]+1"])
SMALL = {"steps": 60, "onset_step": 30, "turn_steps": 10, "detect_window_steps": 10, "warmup_steps": 5}


def run_report(tmp_path, s: str, label: str):
    """A two-trial run with ``s`` in every field a user or a plugin controls; report.html's tree."""
    out = tmp_path / re.sub(r"[/\x00]", "_", s)[:60]
    data = {"name": "hostile", "description": s, "trials": 2, "seed": 3, "chunk": 2, "snr_db": [6],
            "scenarios": [{"name": "noted-cv", "label": f"{label} 1", "params": SMALL | {"note": s}},
                          {"name": "noted-cv", "label": f"{label} 2", "params": SMALL | {"note": "refuse"}}],
            "methods": [{"name": "scribe", "label": label, "params": {"note": s}},
                        {"name": "scribe", "label": f"{label} fails", "params": {"note": s, "fail": True}}],
            "calibration": {"pfa": 0.1, "mode": "empirical", "h0_trials": 10}, "record": {"trials": 0}}
    plan = parse_sweep(data, f"{s}.toml")
    store = run_sweep(plan, out, plan_record=plan_record(plan, f"bench run '{s}.toml' --out '{out}'"), workers=1,
                      quiet=True, executor="serial")
    store.close()
    build_outputs(out, recording=False)
    return out


def assert_report_inert(out):
    page = (out / "report.html").read_text()
    doc = parse(page)
    tags = {el.tag for el in doc.iter()}
    assert not tags & {"iframe", "svg", "object", "embed", "form", "base", "link"}, tags
    # the only links: the table of contents', each to a heading's anchor (never the input's)
    contents = {id(a) for nav in doc.iter("nav") for a in nav.iter("a")}
    for a in doc.iter("a"):
        assert id(a) in contents and set(a.attrib) == {"href"} and re.fullmatch(r"#[a-z0-9-]+", a.get("href")), \
            a.attrib
    for el in doc.iter():
        for name, value in el.attrib.items():
            assert not name.startswith("on"), (el.tag, name)
            assert "javascript" not in value.lower() and "alert" not in value, (el.tag, name, value[:80])
    assert all(img.get("src", "").startswith("data:image/png;base64,") for img in doc.iter("img"))
    scripts = ["".join(s.itertext()) for s in doc.iter("script")]
    assert len(scripts) == 1 and "alert" not in scripts[0]            # the table-sorting script, ours
    policy = next(m.get("content") for m in doc.iter("meta") if m.get("http-equiv") == "Content-Security-Policy")
    assert policy.startswith("default-src 'none'")
    assert all(f"'sha256-{base64.b64encode(hashlib.sha256(s.encode()).digest()).decode()}'" in policy
               for s in scripts)
    assert not CONTROLS.search((out / "report.md").read_text())


@pytest.mark.slow          # an end-to-end CLI run (or fuzzing): CI runs it, the inner loop does not
@settings(max_examples=3, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(s=hostile, label=LABEL_TEXT)
def test_hostile_text_in_every_field_of_a_run_is_inert_in_report_html(plugins, tmp_path_factory, s, label):
    out = run_report(tmp_path_factory.mktemp("hostile"), s, label)
    assert_report_inert(out)
    failures = (out / "report.html").read_text().split('<h2 id="failures">Failures</h2>')[1]
    assert "RuntimeError" in failures                        # the plugin's error is there, as text


def test_the_issues_cases_are_inert_in_report_html(plugins, tmp_path):
    """The reported case: a description with a script, an image with onerror, an iframe and a
    javascript: link; a plugin's error text with a script."""
    s = ('<script>alert(1)</script> <img src=x onerror=alert(2)> <iframe src="x"></iframe> '
         '[x](javascript:alert(3)) `<svg onload=alert(4)>`')
    out = run_report(tmp_path, s, "x[a](b)")
    assert_report_inert(out)
    doc = parse((out / "report.html").read_text())
    words = "".join(doc.find("body").itertext())
    assert "<script>alert(1)</script>" in words and "<img src=x onerror=alert(2)>" in words   # shown as written
    failures = (out / "report.html").read_text().split('<h2 id="failures">Failures</h2>')[1]
    assert "RuntimeError: &lt;script&gt;alert(1)&lt;/script&gt;" in failures
