"""Tests of bench.recording: byte round trip, entity paths, the .rrd file."""

from __future__ import annotations

import shutil
import subprocess
import sys

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from bench.recording import (
    LiveViewer,
    MethodTrace,
    TrialRecord,
    entity_name,
    entity_root,
    method_entity_names,
    rerun_path,
    snr_part,
    write_recording,
)

K = 50
CUM = "cumulant[window=32]"
INNO = "innovation[window=5, variant=fading]"


def _record(snr_db, trial, *, seed, nan_rows=(), alarm_from=None, estimate=False) -> TrialRecord:
    """A synthetic trial: a turning track, two detectors (one may never alarm)."""
    rng = np.random.default_rng(seed)
    t = np.arange(K) * 0.5
    truth = np.column_stack([100.0 * t, 50.0 * t + 0.5 * np.maximum(t - 10, 0) ** 2])
    z = truth + rng.normal(0, 20, (K, 2))
    z[list(nan_rows)] = np.nan
    stat_c = rng.chisquare(1, K)
    if alarm_from is not None:
        stat_c[alarm_from:] += 20.0
    alarms_c = stat_c >= 6.63
    stat_i = rng.chisquare(10, K) * 0.1  # far below its threshold: no alarms
    methods = {
        CUM: MethodTrace(stat_c, 6.63, alarms_c, traces={"innovation": rng.normal(size=K)}),
        INNO: MethodTrace(stat_i, 1e3, stat_i >= 1e3,
                          estimate_xy=truth + 1.0 if estimate else None),
    }
    return TrialRecord("cv-turn-cv", snr_db, trial, t, truth, z, methods)


@pytest.fixture(scope="module")
def records() -> list[TrialRecord]:
    return [
        _record(5.0, 0, seed=1, alarm_from=30, estimate=True),
        _record(-5.0, 3, seed=2, nan_rows=range(10, 20)),
        _record(2.5, 1, seed=3, nan_rows=range(K)),  # every measurement missing
    ]


def _summary() -> pd.DataFrame:
    rows = [(m, s, p) for m in (CUM, INNO) for s, p in ((-5.0, 0.1), (2.5, 0.4), (5.0, 0.8))]
    df = pd.DataFrame(rows, columns=["method", "snr_db", "pd"])
    df["scenario"] = "cv-turn-cv"
    df["n_trials"] = 100
    return df


def _assert_records_equal(a: TrialRecord, b: TrialRecord) -> None:
    assert (a.scenario, a.snr_db, a.trial) == (b.scenario, b.snr_db, b.trial)
    for key in ("t", "truth_xy", "measurements_xy"):
        x, y = getattr(a, key), getattr(b, key)
        assert x.dtype == y.dtype
        np.testing.assert_array_equal(x, y)
    assert list(a.methods) == list(b.methods)
    for label in a.methods:
        ma, mb = a.methods[label], b.methods[label]
        assert ma.threshold == mb.threshold
        for key in ("statistic", "alarms", "estimate_xy"):
            x, y = getattr(ma, key), getattr(mb, key)
            assert (x is None) == (y is None)
            if x is not None:
                assert x.dtype == y.dtype
                np.testing.assert_array_equal(x, y)
        assert list(ma.traces) == list(mb.traces)
        for name in ma.traces:
            np.testing.assert_array_equal(ma.traces[name], mb.traces[name])


# -- data and names ---------------------------------------------------------


def test_bytes_round_trip(records):
    for rec in records:
        _assert_records_equal(rec, TrialRecord.from_bytes(rec.to_bytes()))


def test_bytes_round_trip_null_trial_and_tracker():
    t = np.linspace(0, 1, 4, dtype=np.float32)
    xy = np.zeros((4, 2), dtype=np.float32)
    tracker = MethodTrace(None, None, None, estimate_xy=xy + 1)
    rec = TrialRecord("glint", None, 7, t, xy, xy, {"ekf": tracker, "x[y=inf]": MethodTrace(
        np.ones(4), float("inf"), np.zeros(4, bool))})
    _assert_records_equal(rec, TrialRecord.from_bytes(rec.to_bytes()))


def test_bad_shape_is_named():
    with pytest.raises(ValueError, match=r"methods\['m'\]\.statistic: expected shape \(3,\)"):
        TrialRecord("s", 0, 0, np.zeros(3), np.zeros((3, 2)), np.zeros((3, 2)),
                    {"m": MethodTrace(np.zeros(4), 1.0, np.zeros(4, bool))})


@pytest.mark.parametrize("snr, part", [
    (5, "snr_+05dB"), (-5, "snr_-05dB"), (10, "snr_+10dB"), (2.5, "snr_+02p5dB"),
    (-2.5, "snr_-02p5dB"), (0.0, "snr_+00dB"), (-0.0, "snr_+00dB"), (None, "null"),
])
def test_snr_part(snr, part):
    assert snr_part(snr) == part


def test_entity_root():
    assert entity_root("cv-turn-cv", 5, 3) == "/cv-turn-cv/snr_+05dB/trial_003"
    assert entity_root("cv-turn-cv", None, 12) == "/cv-turn-cv/null/trial_012"
    assert rerun_path("/cv-turn-cv/snr_+05dB/trial_003") == "/cv-turn-cv/snr_\\+05dB/trial_003"


def test_entity_names_are_safe_and_distinct():
    assert entity_name(CUM) == "cumulant_window-32"
    assert entity_name(INNO) == "innovation_window-5_variant-fading"
    labels = ["a[b_c=1]", "a_b[c=1]", CUM, "cumulant[window=64]"]
    names = method_entity_names(labels)
    assert len(set(names.values())) == len(labels)
    assert names[CUM] == "cumulant_window-32"
    # Needs no escaping: the readable name is rerun's canonical one.
    assert all(rerun_path("/" + n) == "/" + n for n in names.values())


# -- the .rrd file -----------------------------------------------------------


@pytest.fixture(scope="module")
def rrd(records, tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "recording.rrd"
    assert write_recording(out, records, _summary(), recording_id="test-rec") == out
    return out


def _column(reader, path: str, component: str) -> tuple[np.ndarray, np.ndarray]:
    """(steps, values) of a temporal component at one entity, in step order."""
    chunks = reader.stream().filter(content=path, is_static=False, components=component).to_chunks()
    batches = [c.to_record_batch() for c in chunks]
    assert batches, f"no {component} at {path}"
    table = pa.Table.from_batches(batches)
    steps = np.asarray(table.column("step").to_pylist())
    values = table.column(component).to_pylist()
    order = np.argsort(steps, kind="stable")
    return steps[order], [values[i] for i in order]


def test_file_written_atomically(rrd):
    assert rrd.exists() and rrd.stat().st_size > 0
    assert not list(rrd.parent.glob("*.tmp"))


def test_entity_paths(rrd, records):
    from rerun.chunk import RrdReader

    reader = RrdReader(rrd)
    assert len(reader.recordings()) == 1
    paths = set(reader.store().schema().entity_paths())
    root = entity_root("cv-turn-cv", 5.0, 0)
    cum, inno = f"{root}/cumulant_window-32", f"{root}/innovation_window-5_variant-fading"
    expected = [
        f"{root}/truth", f"{root}/measurements", f"{root}/measurements/all",
        f"{cum}/statistic", f"{cum}/threshold", f"{cum}/alarms", f"{cum}/innovation",
        f"{inno}/statistic", f"{inno}/threshold", f"{inno}/estimate",
        "/summary/table",
        "/summary/pd_vs_snr/cumulant_window-32",
        "/summary/pd_vs_snr/innovation_window-5_variant-fading",
    ]
    for p in expected:
        assert rerun_path(p) in paths, p
    # Skipped, never sent empty: no alarms; no finite measurement at all.
    assert rerun_path(f"{inno}/alarms") not in paths
    all_nan = entity_root("cv-turn-cv", 2.5, 1)
    assert rerun_path(f"{all_nan}/truth") in paths
    assert rerun_path(f"{all_nan}/measurements") not in paths


def test_values_read_back(rrd, records):
    from rerun.chunk import RrdReader

    reader = RrdReader(rrd)
    rec = records[0]
    base = rerun_path(entity_root("cv-turn-cv", 5.0, 0)) + "/cumulant_window-32"
    trace = rec.methods[CUM]

    steps, values = _column(reader, f"{base}/statistic", "Scalars:scalars")
    np.testing.assert_array_equal(steps, np.arange(K))
    # Scalars are float64 in rerun: exact.
    np.testing.assert_array_equal(np.concatenate(values), trace.statistic)

    steps, values = _column(reader, f"{base}/threshold", "Scalars:scalars")
    np.testing.assert_array_equal(np.concatenate(values), np.full(K, 6.63))

    steps, values = _column(reader, f"{base}/alarms", "Scalars:scalars")
    assert trace.alarms.sum() > 0
    np.testing.assert_array_equal(steps, np.flatnonzero(trace.alarms))
    np.testing.assert_array_equal(np.concatenate(values), trace.statistic[trace.alarms])


def test_points_skip_missing_and_point_north_up(rrd, records):
    from rerun.chunk import RrdReader

    reader = RrdReader(rrd)
    rec = records[1]  # rows 10..19 missing
    path = rerun_path(entity_root("cv-turn-cv", -5.0, 3)) + "/measurements"
    steps, values = _column(reader, path, "Points2D:positions")
    keep = np.r_[0:10, 20:K]
    np.testing.assert_array_equal(steps, keep)
    xy = np.array([v[0] for v in values])
    # Positions are float32 in rerun, y negated for the 2D view.
    np.testing.assert_allclose(xy[:, 0], rec.measurements_xy[keep, 0], rtol=1e-6)
    np.testing.assert_allclose(xy[:, 1], -rec.measurements_xy[keep, 1], rtol=1e-6)


def test_time_timeline_in_seconds(rrd):
    from rerun.chunk import RrdReader

    path = rerun_path(entity_root("cv-turn-cv", 5.0, 0)) + "/truth"
    chunks = RrdReader(rrd).stream().filter(
        content=path, is_static=False, components="Points2D:positions").to_chunks()
    table = pa.Table.from_batches([c.to_record_batch() for c in chunks])
    seconds = table.column("time").cast(pa.int64()).to_numpy() / 1e9
    np.testing.assert_allclose(np.sort(seconds), np.arange(K) * 0.5)


def test_blueprint_saved(rrd):
    from rerun.chunk import RrdReader

    assert len(RrdReader(rrd).blueprints()) == 1


def _rerun_cli() -> list[str]:
    exe = shutil.which("rerun")
    return [exe] if exe else [sys.executable, "-m", "rerun"]


def test_rrd_verify(rrd):
    proc = subprocess.run([*_rerun_cli(), "rrd", "verify", str(rrd)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_failed_write_leaves_nothing(tmp_path, records, monkeypatch):
    import bench.recording as recording

    def boom(*_a, **_k):
        raise RuntimeError("boom")

    monkeypatch.setattr(recording, "_log_summary", boom)
    out = tmp_path / "recording.rrd"
    with pytest.raises(RuntimeError, match="boom"):
        write_recording(out, records, _summary(), recording_id="x")
    assert list(tmp_path.iterdir()) == []


def test_empty_recording(tmp_path):
    out = write_recording(tmp_path / "empty.rrd", [], None, recording_id="empty")
    assert out.exists()


# -- live viewer (never spawned here: headless) ------------------------------


def test_live_viewer_without_display_raises_one_line(monkeypatch):
    import bench.recording as recording

    monkeypatch.setattr(recording, "_has_display", lambda: False)
    with pytest.raises(RuntimeError) as err:
        LiveViewer(recording_id="live")
    assert "\n" not in str(err.value) and "viewer" in str(err.value)


def test_live_viewer_logs_like_the_file_writer(tmp_path, records, rrd):
    import rerun as rr
    from rerun.chunk import RrdReader

    out = tmp_path / "live.rrd"
    stream = rr.RecordingStream("radar-bench", recording_id="live")
    stream.save(out)
    viewer = LiveViewer.from_stream(stream)
    viewer.log_records(records[:2])
    viewer.log_records(records[2:])
    viewer.log_summary(_summary())
    viewer.close()
    viewer.close()  # idempotent

    def data_paths(p):
        return {x for x in RrdReader(p).store().schema().entity_paths() if not x.startswith("/__")}

    assert data_paths(out) == data_paths(rrd)
