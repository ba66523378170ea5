"""Small Markdown helpers shared by the report sections."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from bench.metrics import Crossing, fit_crossing, snr_at_pd


def fmt(x, digits: int = 3) -> str:
    """A number for a table: 3 significant digits, "–" for missing values."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    if isinstance(x, (int, np.integer)):
        return str(x)
    ax = abs(x)
    if ax == 0:
        return "0"                      # never "-0": a negative zero is a zero
    return f"{x:.{digits}g}" if ax >= 1e-3 else f"{x:.2e}"


def fmt_interval(mid, low, high, digits: int = 3) -> str:
    return f"{fmt(mid, digits)} [{fmt(low, digits)}, {fmt(high, digits)}]"


def fmt_db(x) -> str:
    """A level in dB, to 0.1 dB (reports never claim more); "–" when missing."""
    if x is None or not math.isfinite(float(x)):
        return "–"
    text = f"{float(x):.1f}"
    return "0.0" if text == "-0.0" else text


def fmt_crossing(x: float, snr) -> str:
    """A crossing SNR in dB; outside the swept range as ``< min`` / ``> max``."""
    if np.isneginf(x):
        return f"< {fmt_db(float(np.min(snr)))}"
    if np.isnan(x):
        return f"> {fmt_db(float(np.max(snr)))}"
    return fmt_db(x)


def crossing_text(c) -> tuple[str, str]:
    """(estimate, interval) of a :class:`bench.metrics.Crossing`, in dB to 0.1."""
    if c.kind == "between":
        return f"between {fmt_db(c.low)} and {fmt_db(c.high)}", "not resolved by the levels"
    if c.kind == "below":
        return f"< {fmt_db(c.high)}", "below the swept range"
    if c.kind == "above":
        return f"> {fmt_db(c.low)}", "above the swept range"
    low = f"< {fmt_db(c.mid)}" if np.isneginf(c.low) else fmt_db(c.low)
    high = f"> {fmt_db(c.mid)}" if np.isposinf(c.high) else fmt_db(c.high)
    return fmt_db(c.mid), f"[{low}, {high}]"


def crossing_difference(a, b) -> str:
    """b − a in dB between two :class:`bench.metrics.Crossing`: a number between two
    fits, a range where one is only known to lie between two levels, "–" where either
    lies outside the swept range."""
    def bounds(c):
        return (c.mid, c.mid) if c.kind == "fit" else (c.low, c.high) if c.kind == "between" else None
    x, y = bounds(a), bounds(b)
    if x is None or y is None:
        return "–"
    low, high = y[0] - x[1], y[1] - x[0]
    return f"{low:+.1f}" if low == high else f"between {low:+.1f} and {high:+.1f}"


def table(header: list[str], rows: list[list]) -> str:
    """A GitHub-flavoured Markdown table (``tabulate``), cells as given: no
    number parsing, so "1e-05" or "0.010" stay as the caller formatted them."""
    from tabulate import tabulate
    return tabulate([[str(c) for c in r] for r in rows], headers=[str(h) for h in header], tablefmt="github",
                    disable_numparse=True)


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


def snr50(summary: pd.DataFrame, pd_column: str = "pd", floors: dict | None = None) -> pd.DataFrame:
    """Per config: the SNR at which ``pd_column`` (default ``pd``; also
    ``pd_equal_chance``, binomial proportions of ``n_trials``) reaches 0.5, by
    :func:`bench.metrics.fit_crossing` with the config's floor (``floors``:
    config -> chance Pd; 0 where absent). ``crossing`` holds the result, ``mid``
    its estimate (NaN unless fitted), ``order`` a sort key. ``pd_step``, an
    average over correlated steps rather than a binomial count, is crossed by
    linear interpolation, its interval where the 95% band crosses 0.5."""
    rows = []
    for (scenario, method, config), g in summary.groupby(["scenario", "method", "config"], sort=False):
        g = g.sort_values("snr_db")
        if pd_column == "pd_step":
            mid, low, high = snr_at_pd(g.snr_db, g[pd_column], g[f"{pd_column}_low"], g[f"{pd_column}_high"])
            kind = "below" if np.isneginf(mid) else "above" if np.isnan(mid) else "fit"
            c = Crossing(kind, mid, low if kind == "fit" else (float(g.snr_db.iloc[-1]) if kind == "above"
                                                               else -np.inf),
                         high if kind == "fit" else (float(g.snr_db.iloc[0]) if kind == "below" else np.inf))
        else:
            n = g.n_trials.to_numpy(float)
            c = fit_crossing(g.snr_db, np.round(g[pd_column].to_numpy(float) * n), n,
                             floor=float((floors or {}).get(config, 0.0) or 0.0))
        rows.append({"scenario": scenario, "method": method, "config": config, "crossing": c, "mid": c.mid,
                     "order": c.order})
    return pd.DataFrame(rows)
