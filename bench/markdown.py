"""Small Markdown helpers shared by the report sections."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from bench.metrics import snr_at_pd


def fmt(x, digits: int = 3) -> str:
    """A number for a table: 3 significant digits, "–" for missing values."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    if isinstance(x, (int, np.integer)):
        return str(x)
    ax = abs(x)
    return f"{x:.{digits}g}" if (ax >= 1e-3 or ax == 0) else f"{x:.2e}"


def fmt_interval(mid, low, high, digits: int = 3) -> str:
    return f"{fmt(mid, digits)} [{fmt(low, digits)}, {fmt(high, digits)}]"


def fmt_crossing(x: float, snr) -> str:
    """A crossing SNR; outside the swept range as ``< min`` / ``> max``."""
    if np.isneginf(x):
        return f"< {fmt(float(np.min(snr)))}"
    if np.isnan(x):
        return f"> {fmt(float(np.max(snr)))}"
    return fmt(x)


def table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def cell(value) -> str:
    """Any value as a table cell: numbers by :func:`fmt`, text with its pipes escaped."""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (float, np.floating)):
        return fmt(float(value))
    if isinstance(value, (int, np.integer)):
        return fmt(int(value))
    return "–" if value is None else str(value).replace("|", "\\|")


def frame_table(df: pd.DataFrame) -> str:
    """A whole DataFrame as a Markdown table (column names as the header)."""
    return table([cell(c) for c in df.columns], [[cell(v) for v in row] for row in df.itertuples(index=False)])


def snr50(summary: pd.DataFrame, pd_column: str = "pd") -> pd.DataFrame:
    """Per config: the SNR at which ``pd_column`` (default ``pd``; also
    ``pd_step``, ``pd_equal_chance``) reaches 0.5 (``mid``) and its interval
    (``low``, ``high``), see :func:`bench.metrics.snr_at_pd`; ``order`` sorts
    them, a crossing above the swept range (NaN) last."""
    rows = []
    for (scenario, method, config), g in summary.groupby(["scenario", "method", "config"], sort=False):
        g = g.sort_values("snr_db")
        mid, low, high = snr_at_pd(g.snr_db, g[pd_column], g[f"{pd_column}_low"], g[f"{pd_column}_high"])
        rows.append({"scenario": scenario, "method": method, "config": config, "mid": mid, "low": low,
                     "high": high, "order": np.inf if np.isnan(mid) else mid})
    return pd.DataFrame(rows)
