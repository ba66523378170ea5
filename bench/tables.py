"""How a run's tables are written, and read back: every CSV of a run folder, its report's
and its claims' (docs/architecture.md, 'Outputs of a run'), so that they read back bit-exact.

Apart from :mod:`bench.report` so that :mod:`bench.claims`, which the report imports,
writes its claims.csv the same way without importing the report.
"""

from __future__ import annotations

from pathlib import Path

from radarbench.bench import runfolder


def csv_text(df) -> str:
    """A table (a pandas DataFrame) as every CSV of a run is written (floats in full: they
    read back bit-exact)."""
    return df.to_csv(index=False, float_format=None, lineterminator="\n")


def write_csv(df, path: Path) -> None:
    """Write ``df`` to ``path`` inside a run folder (:func:`bench.runfolder.write_text`)."""
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
