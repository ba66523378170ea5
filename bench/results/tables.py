"""How a run's tables are written, and read back: every CSV of a run folder, its report's
and its claims' (docs/architecture.md, 'Outputs of a run'), so that they read back bit-exact.

Apart from :mod:`bench.report` so that :mod:`bench.report.claims`, which the report imports,
writes its claims.csv the same way without importing the report.
"""

from __future__ import annotations

from pathlib import Path

from radarbench.bench.results import runfolder


def csv_text(df) -> str:
    """A table (a pandas DataFrame) as every CSV of a run is written (floats in full: they
    read back bit-exact)."""
    return df.to_csv(index=False, float_format=None, lineterminator="\n")


def write_csv(df, path: Path) -> None:
    """Write ``df`` to ``path`` inside a run folder (:func:`bench.results.runfolder.write_text`)."""
    runfolder.write_text(path, csv_text(df))


def read_csv(text_or_path):
    """A CSV as written by :func:`write_csv` (an empty file: an empty frame); pandas >= 3
    parses floats round-trip (what ``float_precision="round_trip"`` asked of earlier
    versions), so values are bit-exact."""
    import pandas as pd
    try:
        return pd.read_csv(text_or_path)
    except pd.errors.EmptyDataError:
        return pd.DataFrame()


def identical_curves(summary, column: str) -> dict[str, str]:
    """config -> the first config listed before it whose ``column`` (with ``_low`` and
    ``_high`` where the summary has them) equals its own at every SNR level: drawn
    against SNR, the later curve hides exactly under the earlier one, so the figures'
    legends say so. ``summary``: one scenario config's rows."""
    import numpy as np

    columns = [c for c in (column, f"{column}_low", f"{column}_high") if c in summary]
    seen: dict[bytes, str] = {}
    same: dict[str, str] = {}
    for config, g in summary.groupby("config", sort=False):
        g = g.sort_values("snr_db")
        key = np.ascontiguousarray(g[["snr_db", *columns]].to_numpy(float)).tobytes()
        if key in seen:
            same[config] = seen[key]
        else:
            seen[key] = config
    return same
