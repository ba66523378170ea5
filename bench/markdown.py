"""Small Markdown helpers shared by the report sections.

Text that is not ours (a sweep's description, file name or ``--out`` path, a plugin's
error text or reason, parameter values) reaches Markdown only through :func:`code`
(a code span no backtick can break) or :func:`text` (escaped to render as written);
:func:`table` escapes the cell separator in every cell. Nothing in them is live
markup: no HTML tag, no link, no emphasis (docs/architecture.md, 'Report').
"""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd

from radarbench.bench.escapes import escape_controls
from radarbench.bench.metrics import Crossing, fit_crossing, snr_at_pd


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


#: Markdown syntax in text: backslash-escaped (characters both CommonMark and the
#: ``markdown`` package unescape) or, for HTML's own, written as entities.
_MARKDOWN_SYNTAX = {**{ord(c): "\\" + c for c in "\\`*[]"}, ord("<"): "&lt;", ord(">"): "&gt;", ord("&"): "&amp;"}
#: An underscore that can open or close emphasis: one not between two letters or digits
#: (``snake_case`` stays as written; CommonMark and the ``markdown`` package agree).
_UNDERSCORE = re.compile(r"(?<![^\W_])_|_(?![^\W_])")
#: What a line may start with that makes it a block (an indented code block, a heading,
#: a list item, a rule): its indentation dropped, the marker escaped.
_INDENT = re.compile(r"^[ \t]+", re.MULTILINE)
_MARKER = re.compile(r"^(\d*)([#+-]|(?<=\d)[.)](?=[ \t]|$))", re.MULTILINE)


def text(value, inline: bool = True) -> str:
    """``value`` (text that is not ours) as Markdown that renders as written: control
    characters as escapes, Markdown and HTML syntax escaped (no tag, link, emphasis or
    code span can start), on one line unless ``inline`` is false (then line breaks are
    kept). No line starts a block: indentation is dropped, a heading or list marker escaped."""
    raw = _UNDERSCORE.sub(r"\\_", escape_controls(str(value), inline).translate(_MARKDOWN_SYNTAX))
    return _MARKER.sub(r"\1\\\2", _INDENT.sub("", raw))


def code(value) -> str:
    """``value`` as a Markdown code span that no backtick in it can end: fenced by one
    backtick more than its longest run of backticks, padded by a space where it starts
    or ends with one (CommonMark, 'Code spans'); control characters as escapes, on one
    line. "" for an empty value."""
    raw = escape_controls(str(value), inline=True)
    if not raw:
        return ""
    fence = "`" * (max((len(run) for run in re.findall("`+", raw)), default=0) + 1)
    pad = " " if raw[0] in "` " or raw[-1] in "` " else ""
    return f"{fence}{pad}{raw}{pad}{fence}"


def table(header: list[str], rows: list[list]) -> str:
    """A GitHub-flavoured Markdown table (``tabulate``), cells as given (Markdown: text
    not ours through :func:`text` or :func:`code`) with every ``|`` escaped, code spans'
    too (GFM splits the row before it reads a span); no number parsing, so "1e-05" or
    "0.010" stay as the caller formatted them."""
    from tabulate import tabulate
    esc = (lambda c: str(c).replace("|", "\\|"))
    return tabulate([[esc(c) for c in r] for r in rows], headers=[esc(h) for h in header], tablefmt="github",
                    disable_numparse=True)


def cell(value) -> str:
    """Any value as a table cell: numbers by :func:`fmt`, text by :func:`text`."""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (float, np.floating)):
        return fmt(float(value))
    if isinstance(value, (int, np.integer)):
        return fmt(int(value))
    return "–" if value is None else text(value)


def frame_table(df: pd.DataFrame) -> str:
    """A whole DataFrame as a Markdown table (column names as the header)."""
    return table([cell(c) for c in df.columns], [[cell(v) for v in row] for row in df.itertuples(index=False)])


def crossing_floors(pd_column: str, chance: dict, equal_chance: float) -> dict | None:
    """The floor of each config's ``pd_column`` curve for :func:`snr50`: for ``pd`` its
    chance Pd (``chance``: config -> chance Pd, where calibrated), for ``pd_equal_chance``
    the chance Pd every calibrated config was set to (``equal_chance``, the sweep's
    ``[calibration] chance_pd``); no floor for other columns."""
    floors = {k: v for k, v in chance.items() if np.isfinite(v)}
    if pd_column == "pd":
        return floors
    return {c: equal_chance for c in floors} if pd_column == "pd_equal_chance" else None


def snr50(summary: pd.DataFrame, pd_column: str = "pd", floors: dict | None = None,
          level: float = 0.5) -> pd.DataFrame:
    """Per config: the SNR at which ``pd_column`` (default ``pd``; also
    ``pd_equal_chance``, binomial proportions of ``n_trials``) reaches ``level``, by
    :func:`bench.metrics.fit_crossing` with the config's floor (``floors``:
    config -> chance Pd; 0 where absent). ``crossing`` holds the result, ``mid``
    its estimate (NaN unless fitted), ``order`` a sort key. ``pd_step``, an
    average over correlated steps rather than a binomial count, is crossed by
    linear interpolation, its interval where the 95% band crosses ``level``."""
    rows = []
    for (scenario, method, config), g in summary.groupby(["scenario", "method", "config"], sort=False):
        g = g.sort_values("snr_db")
        if pd_column == "pd_step":
            mid, low, high = snr_at_pd(g.snr_db, g[pd_column], g[f"{pd_column}_low"], g[f"{pd_column}_high"], level)
            kind = "below" if np.isneginf(mid) else "above" if np.isnan(mid) else "fit"
            c = Crossing(kind, mid, low if kind == "fit" else (float(g.snr_db.iloc[-1]) if kind == "above"
                                                               else -np.inf),
                         high if kind == "fit" else (float(g.snr_db.iloc[0]) if kind == "below" else np.inf))
        else:
            n = g.n_trials.to_numpy(float)
            c = fit_crossing(g.snr_db, np.round(g[pd_column].to_numpy(float) * n), n,
                             floor=float((floors or {}).get(config, 0.0) or 0.0), level=level)
        rows.append({"scenario": scenario, "method": method, "config": config, "crossing": c, "mid": c.mid,
                     "order": c.order})
    return pd.DataFrame(rows)
