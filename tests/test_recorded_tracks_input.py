"""Scenario recorded-tracks reads a user's file as written: hostile files (a column name
twice, numeric-looking ids, impossible coordinates, a file that cannot be parsed, a path
that is no regular file) end in one line naming ``scenario_params.path``, exit 2 and
nothing written; numeric-looking ids stay distinct tracks; reports and plan.toml name the
data file relative to the sweep's folder, never absolute."""

from __future__ import annotations

import contextlib
import io
import os
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from radarbench.bench.cli import main
from radarbench.bench.sweep.config import load_sweep
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import resolve_path
from radarbench.scenarios.recorded_tracks import RecordedTracks
from radarbench.scenarios.recorded_tracks.bank import build_bank
from radarbench.scenarios.recorded_tracks.files import checked_tracks, read_file
from tests.test_recorded_tracks import SWEEP, params_for, tracks_table


def _csv_text(table: pd.DataFrame) -> str:
    return table.to_csv(index=False)


def _duplicate_column(folder: Path) -> Path:
    """The hostile tester's file: ``x_m`` twice, the second holding other positions."""
    table = tracks_table()
    text = _csv_text(table.assign(x2=table["x_m"] + 5000.0)).replace("x2", "x_m", 1)
    return _write(folder / "dup.csv", text)


def _geodetic(folder: Path, name: str, **column) -> Path:
    """A track along the equator (0.001 degree a second) with one value of ``column`` replaced."""
    t = np.arange(0.0, 600.0, 1.0)
    table = pd.DataFrame({"track": "eq", "time_s": t, "latitude": 0.0, "longitude": 10.0 + 1e-3 * t})
    (key, value), = column.items()
    table.loc[2, key] = value
    return _write(folder / name, _csv_text(table))


def _planar(folder: Path, value: float) -> Path:
    table = tracks_table()
    table.loc[2, "y_m"] = value
    return _write(folder / "far.csv", _csv_text(table))


def _write(path: Path, text: str | bytes) -> Path:
    (path.write_bytes if isinstance(text, bytes) else path.write_text)(text)
    return path


def _fifo(folder: Path) -> Path:
    os.mkfifo(folder / "fifo.csv")
    return folder / "fifo.csv"


def _folder(folder: Path) -> Path:
    (folder / "tracks.csv").mkdir()
    return folder / "tracks.csv"


#: a hostile file (written by the function into a folder) -> what the one line says
HOSTILE = {
    "a column name twice": (_duplicate_column, "column name(s) 'x_m' appear more than once"),
    "latitude 95": (lambda d: _geodetic(d, "lat.csv", latitude=95.0),
                    "column latitude has 1 value(s) outside [-90, 90] degrees, the first (95) in track 'eq' at row 3"),
    "longitude 400": (lambda d: _geodetic(d, "lon.csv", longitude=400.0),
                      "column longitude has 1 value(s) outside [-180, 180] degrees, the first (400) in track 'eq'"),
    "1e300 m": (lambda d: _planar(d, 1e300), "column y_m has 1 value(s) outside [-1e+08, 1e+08] m, the first (1e+300)"),
    "an empty track id": (lambda d: _write(d / "noid.csv", _csv_text(tracks_table()).replace("\nA,", "\n,", 1)),
                          "column track has 1 empty id(s), the first at row 1"),
    "a row longer than the header": (lambda d: _write(d / "long.csv", "track,time_s,x_m,y_m\n" + "A,1,2,3,4\n" * 3),
                                     "not a readable CSV"),
    "an unclosed quote": (lambda d: _write(d / "quote.csv", 'track,time_s,x_m,y_m\n"A,1,2,3\n'), "not a readable CSV"),
    "garbage Parquet": (lambda d: _write(d / "bad.parquet", b"PAR1" + bytes(range(256)) + b"PAR1"),
                        "not a readable Parquet file"),
    "a folder": (_folder, "not a regular file: "),
    "a FIFO": (_fifo, "not a regular file: "),
}


def _run(folder: Path, path: str) -> tuple[int, str, Path]:
    """``bench run`` (in this process) of the small sweep on ``path``, in ``folder``: (exit
    code, stderr, the --out folder)."""
    sweep = folder / "sweep.toml"
    sweep.write_text(SWEEP.format(path=path))
    out, err = folder / "out", io.StringIO()
    with contextlib.chdir(folder), contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(["run", str(sweep), "--out", str(out), "--quiet", "--workers", "1", "--no-record"])
    return code, err.getvalue(), out


def _refused(folder: Path, path: str, says: str) -> None:
    code, err, out = _run(folder, path)
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1 and "scenario_params.path: " in lines[0] and says in lines[0], lines
    assert not out.exists()


@pytest.mark.parametrize("how", list(HOSTILE))
def test_a_hostile_file_is_refused_in_one_line_naming_the_field(tmp_path, how):
    make, says = HOSTILE[how]
    if how == "garbage Parquet":
        pytest.importorskip("pyarrow", reason="Parquet needs pyarrow")
    path = make(tmp_path)
    _refused(tmp_path, path.name, says)


def test_a_device_is_not_a_regular_file(tmp_path):
    _refused(tmp_path, "/dev/zero", "not a regular file: /dev/zero is a character device")


def test_every_path_parameter_refuses_what_is_not_a_regular_file(tmp_path):
    """In bench.params, where every plugin's ``kind="path"`` parameter is resolved."""
    _folder(tmp_path)
    _fifo(tmp_path)
    (tmp_path / "link.csv").symlink_to(tmp_path / "fifo.csv")
    for name, kind in (("tracks.csv", "a folder"), ("fifo.csv", "a FIFO"), ("link.csv", "a FIFO"),
                       ("/dev/null", "a character device")):
        with pytest.raises(ConfigError, match=f"not a regular file: .* is {kind}"):
            resolve_path(name, tmp_path)
    with pytest.raises(ConfigError, match="no such file"):
        resolve_path("absent.csv", tmp_path)


def _numbered(table: pd.DataFrame, names: dict) -> pd.DataFrame:
    return table.assign(track=table["track"].map(names))


def test_numeric_looking_ids_are_distinct_tracks(tmp_path):
    """"1" and "01" are two aircraft, B recorded from 2 s after A's last point: the bank is
    that of the same file with ids "A" and "B" (type inference made them one track, joined
    with a jump of kilometres between A's last position and B's first)."""
    table = tracks_table()
    b_rows = table["track"] == "B"
    table.loc[b_rows, "time_s"] += table.loc[~b_rows, "time_s"].max() + 2.0
    named, numbered = tmp_path / "named.csv", tmp_path / "numbered.csv"
    table.to_csv(named, index=False)
    _numbered(table, {"A": "1", "B": "01"}).to_csv(numbered, index=False)
    a, b = build_bank(params_for(named)), build_bank(params_for(numbered))
    assert a.spans == b.spans
    np.testing.assert_array_equal(a.pos, b.pos)
    np.testing.assert_array_equal(a.onsets, b.onsets)
    table, note = read_file(str(numbered))
    assert note is None and list(pd.unique(table["track"])) == ["1", "01"]


def test_an_id_spelled_like_a_missing_value_is_an_id(tmp_path):
    path = tmp_path / "na.csv"
    _numbered(tracks_table(), {"A": "NA", "B": "null"}).to_csv(path, index=False)
    RecordedTracks().check_config(params_for(path))     # two tracks, not one of NaN ids
    assert set(checked_tracks(read_file(str(path))[0], str(path))["track"]) == {"NA", "null"}


def test_parquet_ids_of_another_type_are_converted_and_said(tmp_path, capsys):
    pytest.importorskip("pyarrow", reason="Parquet needs pyarrow")
    csv, parquet = tmp_path / "tracks.csv", tmp_path / "tracks.parquet"
    _numbered(tracks_table(), {"A": "1", "B": "2"}).to_csv(csv, index=False)
    _numbered(tracks_table(), {"A": 1, "B": 2}).to_parquet(parquet)
    RecordedTracks().check_config(params_for(parquet))
    note = f"{parquet}: column track holds int64, not text: its ids are read as their text (e.g. '1')"
    assert capsys.readouterr().err == f"note: {note}\n"
    np.testing.assert_array_equal(build_bank(params_for(parquet)).pos, build_bank(params_for(csv)).pos)
    table, said = read_file(str(parquet))
    assert list(pd.unique(table["track"])) == ["1", "2"] and said == note


def test_a_parquet_file_with_a_column_name_twice_is_refused(tmp_path):
    pa = pytest.importorskip("pyarrow", reason="Parquet needs pyarrow")
    import pyarrow.parquet as pq
    table = tracks_table()
    path = tmp_path / "dup.parquet"
    pq.write_table(pa.table([table["track"], table["time_s"], table["x_m"], table["y_m"], table["x_m"] + 1.0],
                            names=["track", "time_s", "x_m", "y_m", "x_m"]), path)
    with pytest.raises(ConfigError, match=r"dup.parquet: column name\(s\) 'x_m' appear more than once"):
        read_file(str(path))


def test_recorded_measurements_are_checked_against_their_range(tmp_path):
    t = np.arange(0.0, 600.0, 1.0)
    table = pd.DataFrame({"track": "eq", "time_s": t, "latitude": 0.0, "longitude": 10.0 + 1e-3 * t,
                          "latitude_meas": 0.0, "longitude_meas": 10.0 + 1e-3 * t})
    table.loc[7, "longitude_meas"] = -181.0
    with pytest.raises(ConfigError, match=r"column longitude_meas has 1 value\(s\) outside \[-180, 180\] degrees, "
                                          r"the first \(-181\) in track 'eq' at row 8"):
        checked_tracks(table, "f.csv", recorded=True)


def _relative_run(tmp_path) -> tuple[Path, object]:
    """A CSV in data/, the small sweep in sweeps/ naming it ``../data/tracks.csv``: the plan."""
    (tmp_path / "data").mkdir()
    (tmp_path / "sweeps").mkdir()
    tracks_table().to_csv(tmp_path / "data" / "tracks.csv", index=False)
    sweep = tmp_path / "sweeps" / "mine.toml"
    sweep.write_text(SWEEP.format(path="../data/tracks.csv"))
    return sweep, load_sweep(sweep)


def test_the_report_and_plan_toml_name_the_data_file_relative_to_the_sweep(tmp_path):
    """What a report shows of the plan, and plan.toml (in the run folder), never hold the
    absolute path; plan.toml names the file relative to its own folder, so running it
    finds the same file under the same fingerprint."""
    from radarbench.bench.report import _resolved_scenario_params
    from radarbench.bench.run.runner import plan_record, write_plan_toml
    sweep, plan = _relative_run(tmp_path)
    assert plan.scenarios[0].params.path == str(tmp_path / "data" / "tracks.csv")   # what is read
    record = plan_record(plan, "bench run")
    shown, = _resolved_scenario_params(record).values()
    assert shown["path"] == "../data/tracks.csv"
    assert _resolved_scenario_params({**record, "sweep_folder": None})[plan.scenarios[0].label]["path"] == "tracks.csv"
    (tmp_path / "runs" / "out").mkdir(parents=True)
    write_plan_toml(tmp_path / "runs" / "out" / "plan.toml", plan, "bench run")
    text = (tmp_path / "runs" / "out" / "plan.toml").read_text()
    assert str(tmp_path) not in text
    assert tomllib.loads(text)["scenario_params"]["path"] == "../../data/tracks.csv"
    again = load_sweep(tmp_path / "runs" / "out" / "plan.toml")
    assert again.scenarios[0].params.path == plan.scenarios[0].params.path
    assert again.fingerprint() == plan.fingerprint()


@pytest.mark.slow
def test_a_run_on_a_users_file_shows_no_absolute_path(tmp_path):
    """End to end: report.md, report.html, plan.toml and the CSVs of a run hold no absolute
    path of the data file; ``bench run plan.toml`` resumes the run."""
    _relative_run(tmp_path)
    out = tmp_path / "runs" / "out"
    with contextlib.chdir(tmp_path), contextlib.redirect_stdout(io.StringIO()), \
            contextlib.redirect_stderr(io.StringIO()):
        assert main(["run", "sweeps/mine.toml", "--out", "runs/out", "--quiet", "--workers", "1", "--no-record"]) == 0
    written = [p for p in out.rglob("*") if p.suffix in (".md", ".html", ".toml", ".csv")]
    assert {"report.md", "report.html", "plan.toml", "summary.csv"} <= {p.name for p in written}
    for path in written:
        assert str(tmp_path) not in path.read_text(), path
    assert "path=../data/tracks.csv" in (out / "report.md").read_text()
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        assert main(["run", str(out / "plan.toml"), "--out", str(out), "--workers", "1", "--no-record"]) == 0
    assert "Nothing to run" in err.getvalue()

