"""``report.html``: the Markdown report as one self-contained HTML file.

Built from the same Markdown as report.md (``report.md.j2`` with ``html``
set, :mod:`bench.report.render`), converted by the ``markdown`` package
(tables; ``md_in_html`` so the tables inside ``<details>`` are rendered), then
made self-contained: every ``figures/*.png`` embedded as a base64 data URI,
the CSS and the table-sorting script inline (``page.html.j2``), and, where a
task declares a ``curve_column``, an interactive plotly figure of it against
SNR with hover, plotly.js embedded inline once (about 4.8 MB: the file is
that much larger than the Markdown; no network is needed to open it).
"""

from __future__ import annotations

import base64
import re
from pathlib import Path

import pandas as pd

from bench.report.render import environment, sentence_case

PLACEHOLDER = '<div id="bench-interactive"></div>'
_IMG = re.compile(r'(<img[^>]*?src=")(figures/[^"]+\.png)(")')


def _embed_images(html: str, out_dir: Path) -> str:
    def data_uri(m: re.Match) -> str:
        path = out_dir / m.group(2)
        if not path.is_file():
            return m.group(1) + "data:," + m.group(3)      # never a dangling external reference
        return m.group(1) + "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode() + m.group(3)
    return _IMG.sub(data_uri, html)


def interactive_figures(summary: pd.DataFrame, task_of: dict) -> str:
    """One plotly figure per (task with a ``curve_column``, scenario config
    with two or more SNR levels): the column against SNR per method config,
    its 95% interval as error bars, values on hover. "" when none applies."""
    import plotly.graph_objects as go

    figures = []
    for task in dict.fromkeys(task_of.values()):
        col = task.curve_column
        if not col or col not in summary:
            continue
        mine = summary[summary.config.isin([c for c, t in task_of.items() if t is task])]
        for scenario, g in mine.groupby("scenario", sort=False):
            if g.snr_db.nunique() < 2 or g[col].isna().all():
                continue
            fig = go.Figure()
            for config, c in g.groupby("config", sort=False):
                c = c.sort_values("snr_db")
                y = c[col].to_numpy(float)
                low, high = c.get(f"{col}_low"), c.get(f"{col}_high")
                error = None if low is None or high is None else dict(
                    type="data", array=high.to_numpy(float) - y, arrayminus=y - low.to_numpy(float), thickness=1)
                fig.add_trace(go.Scatter(
                    x=c.snr_db, y=y, mode="lines+markers", name=config, error_y=error,
                    hovertemplate=f"{config}<br>SNR %{{x:.1f}} dB<br>{col} %{{y:.3g}}<extra></extra>"))
            fig.update_layout(title=f"{sentence_case(task.noun)} on {scenario}: {col} (summary.csv) against SNR",
                              xaxis_title="SNR (dB)", yaxis_title=f"{col} (95% interval)", template="plotly_white", height=420,
                              yaxis_type="linear" if task.ranking_binary else "log",   # a probability; an error
                              legend=dict(orientation="h", y=-0.2))
            figures.append(fig)
    if not figures:
        return ""
    parts = [f.to_html(full_html=False, include_plotlyjs=(i == 0), config={"displaylogo": False})
             for i, f in enumerate(figures)]
    return ('<section class="interactive"><h2>Interactive figures</h2><p>Hover for values; click a legend '
            'entry to hide a config. Error bars: 95% intervals.</p>' + "\n".join(parts) + "</section>")


def markdown_to_html(text: str, title: str, out_dir: Path, interactive: str = "") -> str:
    """The whole page: ``text`` (Markdown) converted, figures embedded, ``interactive`` at the placeholder."""
    import markdown
    text = text.replace("<details>", '<details markdown="1">')
    body = markdown.markdown(text, extensions=["tables", "md_in_html", "fenced_code"], output_format="html")
    body = _embed_images(body, out_dir).replace(f"<p>{PLACEHOLDER}</p>", PLACEHOLDER)
    body = body.replace(PLACEHOLDER, interactive)
    return environment().get_template("page.html.j2").render(title=title, body=body)


__all__ = ["PLACEHOLDER", "interactive_figures", "markdown_to_html"]
