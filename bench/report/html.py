"""``report.html``: the Markdown report as one self-contained HTML file.

Built from the same Markdown as report.md (``report.md.j2`` with ``html``
set, :mod:`bench.report.render`), converted by the ``markdown`` package
(tables, fenced code), then made self-contained: every ``figures/*.png``
embedded as a base64 data URI, the CSS and the table-sorting script inline
(``page.html.j2``), and, where a task declares ``curves``, an
interactive plotly figure of it against SNR with hover, plotly.js embedded
inline once (about 4.8 MB: the file is that much larger than the Markdown; no
network is needed to open it).

A report is opened from other people's runs, so nothing in it runs but our own
scripts (docs/architecture.md, 'Report'). The Markdown holds text that is not
ours only escaped (:mod:`bench.markdown`); on top of that the conversion passes
no raw HTML at all (the ``markdown`` package's HTML block and inline HTML
parsers are removed, so every ``<`` in the source is text), our own folds
(``<details>``) and the figures' placeholder are recognised as whole lines and
written here, a link keeps its URL only for http(s), a relative path or an
anchor, an image only for ``figures/*.png``; and the page carries a
Content-Security-Policy that runs only its own inline scripts (by their sha256)
and loads nothing from anywhere.
"""

from __future__ import annotations

import base64
import hashlib
import html
import re
from pathlib import Path

import pandas as pd

from radarbench.bench.report.render import environment, sentence_case
from radarbench.bench.results.figure_cache import reused
from radarbench.bench.results.tables import identical_curves

PLACEHOLDER = '<div id="bench-interactive"></div>'
_IMG = re.compile(r'(<img[^>]*?src=")(figures/[^"]+\.png)(")')
#: Our own HTML in the Markdown, each on a line of its own: a fold's start and end, the placeholder.
_FOLD = re.compile(r"^<details><summary>([^<>]*)</summary>$")
_FOLD_END = "</details>"
#: URLs a link may keep (what a browser reads, entities decoded and blanks removed):
#: http(s), or relative (no scheme: nothing before a ":" but a path, query or fragment follows).
_SAFE_URL = re.compile(r"(?i:https?:)|[^:/?#]*(?:[/?#]|$)")
_URL_BLANKS = re.compile(r"[\x00-\x20\x7f]+")
_FIGURE = re.compile(r"figures/[^/\\?#:]+\.png")
_SCRIPT = re.compile(r"<script\b[^>]*>(.*?)</script>", re.DOTALL | re.IGNORECASE)
_POLICY = "default-src 'none'; script-src {scripts}; style-src 'unsafe-inline'; img-src data:; base-uri 'none'; " \
          "form-action 'none'"


def _embed_images(html: str, out_dir: Path) -> str:
    def data_uri(m: re.Match) -> str:
        path = out_dir / m.group(2)
        if not path.is_file():
            return m.group(1) + "data:," + m.group(3)      # never a dangling external reference
        return m.group(1) + "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode() + m.group(3)
    return _IMG.sub(data_uri, html)


def _plotly_text(label: str) -> str:
    """A label in plotly's texts, which read a few HTML tags (``<a href>`` too) and ``%{...}``
    templates: tags and template starts as entities, shown as written."""
    return html.escape(str(label)).replace("%", "&#37;")


def interactive_specs(summary: pd.DataFrame, task_of: dict) -> list[dict]:
    """What :func:`interactive_figures` draws, as plain data (a pool's process can draw it):
    one figure per (task, scenario config with two or more SNR levels, column of the
    task's ``curves``), the glance's metric first: the column against SNR per method
    config, its 95% interval as error bars. A config whose curve equals another's at every
    level says so in its legend entry (it is drawn exactly under that one)."""
    specs = []
    for task in dict.fromkeys(task_of.values()):
        mine = summary[summary.config.isin([c for c, t in task_of.items() if t is task])]
        for col, label in task.curves:
            if col not in summary:
                continue
            for scenario, g in mine.groupby("scenario", sort=False):
                if g.snr_db.nunique() < 2 or g[col].isna().all():
                    continue
                same = identical_curves(g, col)
                traces = []
                for config, c in g.groupby("config", sort=False):
                    c = c.sort_values("snr_db")
                    y = c[col].to_numpy(float)
                    low, high = c.get(f"{col}_low"), c.get(f"{col}_high")
                    error = None if low is None or high is None else dict(
                        type="data", array=high.to_numpy(float) - y, arrayminus=y - low.to_numpy(float), thickness=1)
                    name = config if config not in same else f"{config} (identical to {same[config]})"
                    traces.append({"label": _plotly_text(name), "x": c.snr_db, "y": y, "error": error})
                specs.append({"title": f"{sentence_case(task.noun)} on {_plotly_text(scenario)}: "
                                       f"{_plotly_text(label)} against SNR", "column": col, "axis": _plotly_text(label),
                              "traces": traces, "log": not task.ranking_binary})   # a probability; an error
    return specs


def interactive_figures(specs: list[dict]) -> str:
    """The figures of :func:`interactive_specs` (plotly), hover for values; "" when none."""
    import plotly.graph_objects as go

    figures = []
    for spec in specs:
        fig = go.Figure()
        for trace in spec["traces"]:
            label = trace["label"]
            fig.add_trace(go.Scatter(
                x=trace["x"], y=trace["y"], mode="lines+markers", name=label, error_y=trace["error"],
                hovertemplate=f"{label}<br>SNR %{{x:.1f}} dB<br>{spec['axis']} %{{y:.3g}}<extra></extra>"))
        fig.update_layout(title=spec["title"], xaxis_title="SNR (dB)", yaxis_title=f"{spec['axis']} (95% interval)",
                          template="plotly_white", height=420, yaxis_type="log" if spec["log"] else "linear",
                          legend=dict(orientation="h", y=-0.2))
        figures.append(fig)
    if not figures:
        return ""
    # named by their place (plotly's default is a random name): the same figures, the same page
    parts = [f.to_html(full_html=False, include_plotlyjs=(i == 0), config={"displaylogo": False},
                       div_id=f"interactive-{i}") for i, f in enumerate(figures)]
    return ('<section class="interactive"><h2>Interactive figures</h2><p>Hover for values; click a legend '
            'entry to hide a config. Error bars: 95% intervals.</p>' + "\n".join(parts) + "</section>")


def safe_url(url: str) -> bool:
    """Whether a link may keep ``url``: http(s), a relative path or an anchor (never
    ``javascript:``, ``data:`` or another scheme, however it is spelt)."""
    return bool(_SAFE_URL.match(_URL_BLANKS.sub("", html.unescape(url))))


def _converter():
    """The ``markdown`` package without raw HTML, its links and images checked."""
    import markdown
    from markdown.treeprocessors import Treeprocessor
    from markdown.util import AtomicString

    class Checked(Treeprocessor):
        def run(self, root):
            for el in root.iter("a"):
                if not safe_url(el.get("href", "")):
                    el.attrib.pop("href")
            for el in root.iter("img"):
                if not _FIGURE.fullmatch(el.get("src", "")):
                    el.attrib.pop("src", None)
            for cell in [*root.iter("td"), *root.iter("th")]:      # "\|" in a cell's code span is "|" (GFM)
                for el in cell.iter("code"):
                    el.text = AtomicString((el.text or "").replace("\\|", "|"))

    md = markdown.Markdown(extensions=["tables", "fenced_code"], output_format="html")
    md.preprocessors.deregister("html_block")
    md.inlinePatterns.deregister("html")
    md.treeprocessors.register(Checked(md), "checked", 5)     # after "inline" made the links
    return md


def _converted(text: str) -> str:
    """Markdown ``text`` as HTML (:func:`_converter`)."""
    return _converter().convert(text)


def _body(text: str) -> str:
    """``text`` (Markdown) as HTML: our folds and placeholder, the rest converted between them,
    each part reused where an earlier report converted the same text (:func:`reused`)."""
    out, chunk = [], []

    def flush():
        out.append(reused(_converted, "\n".join(chunk)))
        chunk.clear()
    for line in text.split("\n"):
        fold = _FOLD.match(line)
        if fold or line in (_FOLD_END, PLACEHOLDER):
            flush()
            out.append(f"<details><summary>{html.escape(fold.group(1))}</summary>" if fold else line)
        else:
            chunk.append(line)
    flush()
    return "\n".join(out)


def with_policy(page: str) -> str:
    """``page`` with its Content-Security-Policy: its own inline scripts (sha256 of each)
    and inline styles only, images from data: URIs, nothing loaded from anywhere."""
    digests = sorted({"'sha256-" + base64.b64encode(hashlib.sha256(s.encode()).digest()).decode() + "'"
                      for s in _SCRIPT.findall(page)})
    policy = _POLICY.format(scripts=" ".join(digests) or "'none'")
    charset = '<meta charset="utf-8">\n'
    return page.replace(charset, f'{charset}<meta http-equiv="Content-Security-Policy" content="{policy}">\n', 1)


_HEADING = re.compile(r"<h([23])>(.*?)</h\1>", re.S)


def with_contents(body: str) -> tuple[str, str]:
    """(``body`` with an anchor on each section heading, the page's table of contents: a
    link to each, sections and their subsections), for a long report one can navigate."""
    taken: dict[str, int] = {}
    entries: list[str] = []

    def anchor(match) -> str:
        level, inner = match.groups()
        shown = re.sub(r"<[^>]+>", "", inner)                 # escaped text: it stays escaped
        slug = re.sub(r"[^a-z0-9]+", "-", html.unescape(shown).lower()).strip("-") or "section"
        taken[slug] = taken.get(slug, 0) + 1
        slug = slug if taken[slug] == 1 else f"{slug}-{taken[slug]}"
        entries.append(f'<li class="toc-h{level}"><a href="#{slug}">{shown}</a></li>')
        return f'<h{level} id="{slug}">{inner}</h{level}>'
    body = _HEADING.sub(anchor, body)
    return body, f'<nav class="toc" aria-label="Contents"><p>Contents</p><ul>{"".join(entries)}</ul></nav>'


def markdown_to_html(text: str, title: str, out_dir: Path, interactive: str = "") -> str:
    """The whole page: ``text`` (Markdown) converted, figures embedded, ``interactive`` at
    the placeholder, a table of contents beside it, the policy added (the page is final: a
    changed script would not run)."""
    from markupsafe import Markup
    body, contents = with_contents(_embed_images(_body(text), out_dir).replace(PLACEHOLDER, interactive))
    page = environment().get_template("page.html.j2").render(title=title, body=Markup(body), contents=Markup(contents))
    return with_policy(page)


__all__ = ["PLACEHOLDER", "interactive_figures", "interactive_specs", "markdown_to_html", "safe_url", "with_contents",
           "with_policy"]
