"""The summary of a run in a recording: Pd and RMSE against SNR, and a table.

Static entities (they show on any timeline)::

    /summary/pd_vs_snr/{method}     BarChart of Pd (abscissa = SNR, dB)
    /summary/rmse_vs_snr/{method}   BarChart of rmse_mean (m), when the summary has it
    /summary/table                  TextDocument (Markdown, :mod:`bench.markdown`)

``pd`` and ``rmse_mean`` are the columns summary.csv shares across tasks
(docs/architecture.md, 'Outputs of a run'). When the summary mixes scenarios,
the bar charts gain a level: ``/summary/pd_vs_snr/{scenario}/{method}``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from bench.markdown import frame_table
from bench.recording.layout import PALETTE
from bench.recording.paths import entity_name, method_entity_names, rerun_path

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pandas as pd

__all__ = ["CHARTS", "log_summary", "summary_charts", "summary_markdown"]

#: Summary bar charts: (summary column, entity root, view title).
CHARTS = (
    ("pd", "/summary/pd_vs_snr", "Pd vs SNR (dB)"),
    ("rmse_mean", "/summary/rmse_vs_snr", "RMSE (m) vs SNR (dB)"),
)


def curves(summary: pd.DataFrame, column: str, root: str) -> list[tuple[str, tuple, pd.DataFrame]]:
    """(entity path, colour, rows sorted by SNR) per curve with data in ``column``.

    One curve per method, or per (scenario, method) when the summary mixes
    scenarios. Colours follow the sorted labels, as in the trial plots.
    """
    if column not in summary.columns:
        return []
    df = summary.dropna(subset=["snr_db", column])
    multi = "scenario" in df.columns and df["scenario"].nunique() > 1
    groups = list(df.groupby(["scenario", "method"] if multi else ["method"], sort=False))
    labels = sorted({str(key[-1]) for key, _ in groups})  # keys are tuples (list `by`)
    names = method_entity_names(labels)
    out = []
    for key, rows in groups:
        label = str(key[-1])
        scope = f"{entity_name(str(key[0]))}/" if multi else ""
        color = PALETTE[labels.index(label) % len(PALETTE)]
        out.append((f"{root}/{scope}{names[label]}", color, rows.sort_values("snr_db")))
    return out


def log_bars(stream, bars: list, column: str) -> None:
    """Grouped bars: one BarChart per curve of :func:`curves`, shifted so bars sit side by side.

    A BarChart is static and needs no timeline; its legend entry is the entity
    name (BarChart has no series name).
    """
    import rerun as rr

    if not bars:
        return
    snrs = np.unique(np.concatenate([rows["snr_db"].to_numpy(float) for _, _, rows in bars]))
    step = float(np.min(np.diff(snrs))) if snrs.size > 1 else 1.0
    width = 0.8 * step / len(bars)
    for i, (path, color, rows) in enumerate(bars):
        x = rows["snr_db"].to_numpy(float) + (i - (len(bars) - 1) / 2) * width
        stream.log(
            rerun_path(path),
            rr.BarChart(rows[column].to_numpy(float), abscissa=x,
                        widths=np.full(x.size, width, np.float32), color=color),
            static=True,
        )


def summary_markdown(summary: pd.DataFrame) -> str:
    """A compact pivot (SNR x method) of Pd and of RMSE, then every row."""
    parts = ["# Summary"]
    for column, title in (("pd", "Pd"), ("rmse_mean", "RMSE (m)")):
        if column not in summary.columns:
            continue
        df = summary.dropna(subset=["snr_db", column])
        if not df.empty and ("scenario" not in df.columns or df["scenario"].nunique() <= 1):
            pivot = df.pivot_table(index="snr_db", columns="method", values=column, sort=False)
            parts += [f"## {title} by SNR (dB)", frame_table(pivot.sort_index().reset_index())]
    parts += ["## All rows", frame_table(summary)]
    return "\n\n".join(parts) + "\n"


def summary_charts(summary: pd.DataFrame | None) -> tuple[tuple[str, str], ...] | None:
    """None for no/empty summary, else the (entity root, title) of each bar
    chart with data (possibly none: the table alone). ValueError when
    ``method`` or ``snr_db`` is missing."""
    if summary is None or summary.empty:
        return None
    missing = {"method", "snr_db"} - set(summary.columns)
    if missing:
        raise ValueError(f"summary: missing column(s) {', '.join(sorted(missing))}")
    return tuple((root, title) for column, root, title in CHARTS if curves(summary, column, root))


def log_summary(stream, summary: pd.DataFrame | None) -> tuple[tuple[str, str], ...] | None:
    """Pd / RMSE vs SNR bars and a Markdown table; returns the charts logged
    (see :func:`summary_charts`), None when there is no summary."""
    import rerun as rr

    charts = summary_charts(summary)
    if charts is None:
        return None
    for column, root, _ in CHARTS:
        log_bars(stream, curves(summary, column, root), column)
    stream.log("/summary/table", rr.TextDocument(summary_markdown(summary),
                                                 media_type=rr.MediaType.MARKDOWN), static=True)
    return charts
