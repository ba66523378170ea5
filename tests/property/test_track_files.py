"""Recorded-tracks files round-trip: a table of tracks written as CSV (or Parquet, with
pyarrow) reads back as the same tracks, exactly, whatever its ids look like (numbers with
leading zeros, ``NA``, quotes and commas, spaces) and whatever its coordinates within
their physical ranges; a file is refused exactly when the table itself is, with the same
one line (docs/recorded-tracks.md)."""

from __future__ import annotations

import importlib.util
import tempfile
from pathlib import Path

import pandas as pd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from radarbench.bench.errors import ConfigError
from radarbench.scenarios.recorded_tracks.files import MAX_METRES, checked_tracks, read_file

FORMATS = ["csv", "parquet"] if importlib.util.find_spec("pyarrow") else ["csv"]
#: ids a type inference would merge or lose: numbers with leading zeros, signs, decimal
#: points or exponents ("1", "01", "1.0", "+1" are four aircraft), missing-value spellings,
#: CSV's own delimiters and quotes, spaces
IDS = st.one_of(st.from_regex(r"[+-]?0{0,2}[0-9]{1,3}(\.0{0,2})?(e[0-9])?", fullmatch=True),
                st.sampled_from(["NA", "N/A", "nan", "NaN", "null", "None", "-nan", "#N/A", " ", "TRUE"]),
                st.text("0123456789+-.eE aN,\"'#_é", min_size=1, max_size=6))


def _numbers(low: float, high: float):
    return st.floats(low, high, allow_nan=False, allow_infinity=False)


@st.composite
def track_tables(draw) -> tuple[pd.DataFrame, bool]:
    """(a table of one to three tracks of two to six points, whether to replay
    measurements): distinct ids, rows grouped by track, times drawn increasing (a sum of
    positive steps: two may still round to one time, a table both readings refuse)."""
    geodetic = draw(st.booleans())
    recorded = draw(st.booleans())
    ids = draw(st.lists(IDS, min_size=1, max_size=3, unique=True))
    if geodetic:
        axes = {"latitude": _numbers(-90.0, 90.0), "longitude": _numbers(-180.0, 180.0)}
        axes |= {"altitude_m": _numbers(-MAX_METRES, MAX_METRES)} if draw(st.booleans()) else {}
        axes |= {"latitude_meas": axes["latitude"], "longitude_meas": axes["longitude"]} if recorded else {}
    else:
        axes = {"x_m": _numbers(-MAX_METRES, MAX_METRES), "y_m": _numbers(-MAX_METRES, MAX_METRES)}
        axes |= {"x_meas_m": axes["x_m"], "y_meas_m": axes["y_m"]} if recorded else {}
    rows = []
    for track in ids:
        n = draw(st.integers(2, 6))
        t = draw(_numbers(-1e10, 1e10))
        for _ in range(n):
            rows.append({"track": track, "time_s": t, **{c: draw(s) for c, s in axes.items()}})
            t += draw(_numbers(1e-3, 1e6))
    return pd.DataFrame(rows), recorded


def _outcome(table: pd.DataFrame, recorded: bool):
    """The checked tracks, or the problem of the ConfigError (one line)."""
    try:
        return checked_tracks(table, "tracks", recorded)
    except ConfigError as err:
        assert "\n" not in str(err)
        return err.problem


@settings(max_examples=150, suppress_health_check=[HealthCheck.too_slow])
@given(drawn=track_tables(), form=st.sampled_from(FORMATS))
def test_a_written_file_reads_back_as_its_tracks(drawn, form):
    table, recorded = drawn
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"tracks.{form}"
        table.to_csv(path, index=False) if form == "csv" else table.to_parquet(path)
        read, note = read_file(str(path))
    assert note is None                                  # the ids were written as text
    expected, got = _outcome(table, recorded), _outcome(read, recorded)
    if isinstance(expected, str) or isinstance(got, str):
        assert got == expected
    else:
        pd.testing.assert_frame_equal(got, expected, check_exact=True)
        assert list(pd.unique(got["track"])) == list(table["track"].drop_duplicates())
