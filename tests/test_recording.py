"""Tests of bench.recording and of the tasks' recording hooks: byte round trip, entity paths, the .rrd file."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from radarbench.bench.recording import (
    LiveViewer,
    Quantised,
    TrialRecord,
    entity_name,
    entity_root,
    method_entity_names,
    rerun_path,
    snr_part,
    write_recording,
)
from radarbench.bench.tasks import RecordedScene, detection, tbd, tracking
from radarbench.bench.tasks.detection import DetectionTask
from radarbench.bench.tasks.tbd import TBDTask
from radarbench.bench.tasks.tracking import TrackingTask

K = 50
CUM = "cumulant[window=32]"
INNO = "innovation[window=5, variant=fading]"
TRACKER = "ekf"
DET, TRK, TBD = DetectionTask(), TrackingTask(), TBDTask()


def _record_of(scenario, snr_db, trial, t, truth, z, methods, scene=None) -> TrialRecord:
    """A record as the runner builds it: the harness's fields plus a task's scene."""
    scene = scene or RecordedScene()
    return TrialRecord(scenario, snr_db, trial, t, truth, z, methods, arrays=scene.arrays, images=scene.images,
                       info=scene.info)


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
        CUM: detection.method_trace(stat_c, 6.63, alarms_c, traces={"innovation": rng.normal(size=K)}),
        INNO: detection.method_trace(stat_i, 1e3, stat_i >= 1e3),
    }
    if estimate:   # a tracker on the same trial: two tasks in one record
        methods[TRACKER] = tracking.method_trace(truth + 1.0)
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
        assert ma.threshold == mb.threshold and ma.info == mb.info
        assert list(ma.arrays) == list(mb.arrays)
        for key in ma.arrays:
            assert ma.arrays[key].dtype == mb.arrays[key].dtype
            np.testing.assert_array_equal(ma.arrays[key], mb.arrays[key])
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
    tracker = tracking.method_trace(xy + 1)
    rec = TrialRecord("glint", None, 7, t, xy, xy, {"ekf": tracker, "x[y=inf]": detection.method_trace(
        np.ones(4), float("inf"), np.zeros(4, bool))})
    _assert_records_equal(rec, TrialRecord.from_bytes(rec.to_bytes()))


def test_bad_shape_is_named():
    with pytest.raises(ValueError, match=r"methods\['m'\]\.arrays\['statistic'\]: expected shape \(3,\)"):
        TrialRecord("s", 0, 0, np.zeros(3), np.zeros((3, 2)), np.zeros((3, 2)),
                    {"m": detection.method_trace(np.zeros(4), 1.0, np.zeros(4, bool))})


@pytest.mark.parametrize("name", ["t", "header", "truth_xy", "m0_x", "1x", "a-b"])
def test_unusable_array_names_are_refused(name):
    with pytest.raises(ValueError, match="not a usable array name"):
        TrialRecord("s", 0, 0, np.zeros(3), arrays={name: np.zeros(3)})


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
    assert write_recording(out, records, _summary(), tasks=TASKS, recording_id="test-rec") == out
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
        f"{inno}/statistic", f"{inno}/threshold", f"{root}/ekf/estimate",
        "/summary/table",
        "/summary/maneuver-detection/pd_vs_snr/cumulant_window-32",
        "/summary/maneuver-detection/pd_vs_snr/innovation_window-5_variant-fading",
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
    np.testing.assert_array_equal(np.concatenate(values), trace.arrays["statistic"])

    steps, values = _column(reader, f"{base}/threshold", "Scalars:scalars")
    np.testing.assert_array_equal(np.concatenate(values), np.full(K, 6.63))

    steps, values = _column(reader, f"{base}/alarms", "Scalars:scalars")
    alarms = trace.arrays["alarms"]
    assert alarms.sum() > 0
    np.testing.assert_array_equal(steps, np.flatnonzero(alarms))
    np.testing.assert_array_equal(np.concatenate(values), trace.arrays["statistic"][alarms])


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
                          capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_failed_write_leaves_nothing(tmp_path, records, monkeypatch):
    from radarbench.bench.recording import sinks

    def boom(*_a, **_k):
        raise RuntimeError("boom")

    monkeypatch.setattr(sinks, "log_summary", boom)
    out = tmp_path / "recording.rrd"
    with pytest.raises(RuntimeError, match="boom"):
        write_recording(out, records, _summary(), tasks=TASKS, recording_id="x")
    assert list(tmp_path.iterdir()) == []


def test_empty_recording(tmp_path):
    out = write_recording(tmp_path / "empty.rrd", [], None, tasks={}, recording_id="empty")
    assert out.exists()


# -- live viewer (never spawned here: headless) ------------------------------


def test_live_viewer_without_display_raises_one_line(monkeypatch):
    from radarbench.bench.recording import sinks

    monkeypatch.setattr(sinks, "has_display", lambda: False)
    with pytest.raises(RuntimeError) as err:
        LiveViewer(tasks=TASKS, recording_id="live")
    assert "\n" not in str(err.value) and "viewer" in str(err.value)


def test_live_viewer_logs_like_the_file_writer(tmp_path, records, rrd):
    import rerun as rr
    from rerun.chunk import RrdReader

    out = tmp_path / "live.rrd"
    stream = rr.RecordingStream("radar-bench", recording_id="live")
    stream.save(out)
    viewer = LiveViewer.from_stream(stream, tasks=TASKS)
    viewer.log_records(records[:2])
    viewer.log_records(records[2:])
    viewer.log_summary(_summary())
    viewer.close()
    viewer.close()  # idempotent

    def data_paths(p):
        return {x for x in RrdReader(p).store().schema().entity_paths() if not x.startswith("/__")}

    assert data_paths(out) == data_paths(rrd)


# -- track-before-detect and tracking records ---------------------------------

H, W, KT = 32, 32, 6
GRID = {"rows": H, "cols": W, "cell_m": 25.0, "x_min_m": -400.0, "y_min_m": 1000.0}
DP = "dp-tbd[pfa=0.001]"
HOUGH = "hough[bins=64]"
EKF = "ekf"
IMM = "imm[models=3]"
#: The task of every method config label used here (the plan gives it in a run).
TASKS = {CUM: DET, INNO: DET, TRACKER: TRK, DP: TBD, HOUGH: TBD, EKF: TRK, IMM: TRK}


def _cell_xy(cells: np.ndarray) -> np.ndarray:
    return np.column_stack([GRID["x_min_m"] + (cells[:, 1] + 0.5) * GRID["cell_m"],
                            GRID["y_min_m"] + (cells[:, 0] + 0.5) * GRID["cell_m"]])


def _tbd_record(snr_db=9.0, trial=0, *, seed=5, null=False) -> TrialRecord:
    """32x32x6 frames, a target moving up-right, two TBD methods with tracks and value maps."""
    rng = np.random.default_rng(seed)
    t = np.arange(KT) * 0.8
    cells = np.column_stack([4 + 3 * np.arange(KT), 2 + 2 * np.arange(KT)])
    frames = rng.normal(size=(KT, H, W)).astype(np.float32)
    if not null:
        frames[np.arange(KT), cells[:, 0], cells[:, 1]] += 5.0
    off = cells + [0, 1]
    off[2] = -1  # a cell outside the grid: not drawn
    methods = {
        DP: tbd.method_trace(20.0, cells, rng.gamma(2.0, 3.0, (H, W)).astype(np.float32), 35.5),
        HOUGH: tbd.method_trace(50.0, off, rng.normal(size=(H, W)), float("nan")),
    }
    return _record_of("tbd-line", None if null else snr_db, trial, t, None if null else _cell_xy(cells), None,
                      methods, tbd.scene(frames, GRID, None if null else cells))


GLINT_STEPS = [5, 17, 30]


def _tracking_record(snr_db=10.0, trial=2, *, seed=7) -> TrialRecord:
    """A tracking trial: two trackers with error traces, glint outliers at GLINT_STEPS."""
    rng = np.random.default_rng(seed)
    k = 40
    t = np.arange(k) * 0.5
    truth = np.column_stack([2000 + 150.0 * t, 3000 - 80.0 * t])
    z = truth + rng.normal(0, 15, (k, 2))
    z[GLINT_STEPS] += 300.0
    z[10] = np.nan
    flags = np.zeros(k, bool)
    flags[GLINT_STEPS] = True
    methods = {}
    for label, noise in ((EKF, 20.0), (IMM, 10.0)):
        est = truth + rng.normal(0, noise, (k, 2))
        err = est - truth
        methods[label] = tracking.method_trace(est, traces={
            "error_x": err[:, 0], "error_y": err[:, 1], "error_pos": np.hypot(*err.T)})
    return _record_of("glint-cv", snr_db, trial, t, truth, z, methods, tracking.scene(flags))


def _tracking_summary() -> pd.DataFrame:
    rows = [(m, s, r) for m in (EKF, IMM) for s, r in ((0.0, 40.0), (10.0, 20.0))]
    df = pd.DataFrame(rows, columns=["method", "snr_db", "rmse_mean"])
    df["pd"] = np.nan  # a tracking summary: no detection
    df["scenario"] = "glint-cv"
    return df


def test_tbd_round_trip_quantises_frames_and_values():
    rec = _tbd_record()
    back = TrialRecord.from_bytes(rec.to_bytes())
    assert back.info["grid"] == GRID and back.snr_db == 9.0 and back.truth_xy.shape == (KT, 2)
    assert back.measurements_xy is None and "measurement_flags" not in back.arrays
    assert back.arrays["truth_cells"].dtype == np.int32
    np.testing.assert_array_equal(back.arrays["truth_cells"], rec.arrays["truth_cells"])
    frames, back_frames = rec.image("frames"), back.image("frames")
    q = Quantised.of(frames)
    assert back_frames.dtype == np.float32 and back_frames.shape == (KT, H, W)
    # Exact inside [lo, hi] up to half a code; clipped outside.
    clipped = np.clip(frames, q.lo, q.hi)
    assert np.abs(back_frames - clipped).max() <= (q.hi - q.lo) / 508 * 1.001
    mean, std = frames.mean(), frames.std()
    assert q.lo == pytest.approx(max(frames.min(), mean - 3 * std), rel=1e-5)
    assert q.hi == pytest.approx(min(frames.max(), mean + 6 * std), rel=1e-5)
    for label in (DP, HOUGH):
        a, b = rec.methods[label], back.methods[label]
        np.testing.assert_array_equal(a.arrays["track_cells"], b.arrays["track_cells"])
        value, back_value = a.image("value"), b.image("value")
        assert back_value.shape == (H, W) and back_value.dtype == np.float32
        qv = Quantised.of(value)
        assert np.abs(back_value - np.clip(value, qv.lo, qv.hi)).max() <= (qv.hi - qv.lo) / 508 * 1.001
    assert back.methods[DP].info["score"] == 35.5 and math.isnan(back.methods[HOUGH].info["score"])
    assert back.methods[DP].threshold == 20.0
    # The codes travel unchanged: a second round trip gives the same bytes.
    assert back.to_bytes() == TrialRecord.from_bytes(back.to_bytes()).to_bytes()


def test_tracking_round_trip():
    rec = _tracking_record()
    back = TrialRecord.from_bytes(rec.to_bytes())
    _assert_records_equal(rec, back)
    flags = back.arrays["measurement_flags"]
    assert flags.dtype == bool
    np.testing.assert_array_equal(np.flatnonzero(flags), GLINT_STEPS)
    assert not back.images and not back.info and list(back.arrays) == ["measurement_flags"]
    null = TrialRecord.from_bytes(_tbd_record(null=True).to_bytes())
    assert null.snr_db is None and null.truth_xy is None and "truth_cells" not in null.arrays


def test_version_1_bytes_still_load():
    """Bytes written before the TBD/tracking fields (format version 1)."""
    import io
    import json

    t, xy = np.arange(3.0), np.ones((3, 2))
    header = {"version": 1, "scenario": "cv-turn-cv", "snr_db": 5.0, "trial": 2, "methods": [
        {"label": CUM, "threshold": 6.63, "has": ["statistic", "alarms"], "traces": ["innovation"]}]}
    buf = io.BytesIO()
    np.savez_compressed(buf, t=t, truth_xy=xy, measurements_xy=xy * 2, m0_statistic=t,
                        m0_alarms=t > 1, m0_trace0=-t,
                        header=np.frombuffer(json.dumps(header).encode(), np.uint8))
    rec = TrialRecord.from_bytes(buf.getvalue())
    np.testing.assert_array_equal(rec.measurements_xy, xy * 2)
    np.testing.assert_array_equal(rec.methods[CUM].traces["innovation"], -t)
    assert not rec.images and not rec.methods[CUM].images and not rec.methods[CUM].info


def test_version_2_bytes_still_load():
    """Bytes of format version 2, which named every task's field: they map onto the containers."""
    import io
    import json

    t, cells = np.arange(3.0), np.array([[1, 2], [2, 3], [3, 4]], np.int32)
    header = {"version": 2, "scenario": "tbd", "snr_db": 6.0, "trial": 0,
              "has": ["truth_xy", "truth_cells"], "grid": GRID, "frames_range": [-1.0, 2.0],
              "methods": [{"label": DP, "threshold": 20.0, "score": 35.5, "has": ["track_cells"], "traces": [],
                           "value_range": [0.0, 4.0]},
                          {"label": CUM, "threshold": 6.63, "score": None, "has": ["statistic", "alarms"],
                           "traces": []}]}
    buf = io.BytesIO()
    np.savez_compressed(buf, t=t, truth_xy=np.ones((3, 2)), truth_cells=cells,
                        frames=np.full((3, H, W), 128, np.uint8), m0_track_cells=cells,
                        m0_value=np.full((H, W), 255, np.uint8), m1_statistic=t, m1_alarms=t > 1,
                        header=np.frombuffer(json.dumps(header).encode(), np.uint8))
    rec = TrialRecord.from_bytes(buf.getvalue())
    assert rec.info == {"grid": GRID} and list(rec.arrays) == ["truth_cells"]
    assert rec.quantised("frames").lo == -1.0 and rec.image("frames").shape == (3, H, W)
    dp, cum = rec.methods[DP], rec.methods[CUM]
    assert dp.info == {"score": 35.5} and dp.image("value").max() == pytest.approx(4.0)
    np.testing.assert_array_equal(dp.arrays["track_cells"], cells)
    assert not cum.info and not cum.images and list(cum.arrays) == ["statistic", "alarms"]


def test_quantised_edge_cases():
    q = Quantised.of(np.array([1.0, np.nan, 2.0, np.inf]))
    np.testing.assert_array_equal(q.codes, [1, 0, 255, 0])
    np.testing.assert_array_equal(q.values(), [1.0, np.nan, 2.0, np.nan])
    q = Quantised.of(np.full((2, 2), 5.0))  # constant: every value exact
    np.testing.assert_array_equal(q.values(), np.full((2, 2), 5.0))
    assert Quantised.of(np.full(3, np.nan)).codes.tolist() == [0, 0, 0]


@pytest.mark.parametrize("build, message", [
    (lambda: tbd.scene(np.zeros((KT, 4, 4)), GRID), r"grid: rows x cols = 32 x 32 does not match frames 4 x 4"),
    (lambda: tbd.scene(truth_cells=np.zeros((KT, 2))), r"truth_cells: expected an integer array"),
    (lambda: tbd.scene(grid={"rows": 32}), r"grid: missing key\(s\) cols, cell_m"),
    (lambda: _record_of("s", 0, 0, np.zeros(KT), None, None, {}, tracking.scene(np.zeros(KT + 1))),
     r"arrays\['measurement_flags'\]: expected shape \(6,\)"),
])
def test_bad_task_fields_are_named(build, message):
    with pytest.raises(ValueError, match=message):
        build()


def test_bad_value_map_is_named():
    with pytest.raises(ValueError, match=r"value: expected shape \(32, 32\)"):
        tbd.method_trace(None, value=np.zeros((4, 4)), image_shape=(H, W))


def test_large_tbd_record_is_compact():
    """A 500x500x20 TBD trial (frames + a value map) stays around 5 MB."""
    rng = np.random.default_rng(0)
    k, n = 20, 500
    frames = rng.rayleigh(1.0, (k, n, n)).astype(np.float32)
    cells = np.column_stack([100 + np.arange(k), 50 + 3 * np.arange(k)])
    frames[np.arange(k), cells[:, 0], cells[:, 1]] += 6.0
    grid = {"rows": n, "cols": n, "cell_m": 10.0, "x_min_m": 0.0, "y_min_m": 0.0}
    dp = tbd.method_trace(30.0, cells, rng.gamma(4.0, 5.0, (n, n)).astype(np.float32), 44.0)
    rec = _record_of("tbd-big", 6.0, 0, np.arange(k) * 1.0, np.zeros((k, 2)), None, {DP: dp},
                     tbd.scene(frames, grid, cells))
    data = rec.to_bytes()
    assert len(data) <= 6_000_000, len(data) / 1e6


@pytest.fixture(scope="module")
def task_records() -> list[TrialRecord]:
    return [_tbd_record(), _tbd_record(null=True, trial=1, seed=6), _tracking_record()]


@pytest.fixture(scope="module")
def task_rrd(task_records, tmp_path_factory):
    out = tmp_path_factory.mktemp("tasks") / "recording.rrd"
    # Through the bytes, as in the driver: frames and value maps arrive quantised.
    records = [TrialRecord.from_bytes(r.to_bytes()) for r in task_records]
    return write_recording(out, records, _tracking_summary(), tasks=TASKS, recording_id="test-tasks")


def _static(reader, path: str, component: str) -> list:
    chunks = reader.stream().filter(content=path, is_static=True, components=component).to_chunks()
    table = pa.Table.from_batches([c.to_record_batch() for c in chunks])
    return table.column(component).to_pylist()


def test_task_entity_paths(task_rrd):
    from rerun.chunk import RrdReader

    paths = set(RrdReader(task_rrd).store().schema().entity_paths())
    tbd = entity_root("tbd-line", 9.0, 0)
    dp, hough = f"{tbd}/dp-tbd_pfa-0.001", f"{tbd}/hough_bins-64"
    null = entity_root("tbd-line", None, 1)
    trk = entity_root("glint-cv", 10.0, 2)
    expected = [
        f"{tbd}/frames", f"{tbd}/frames/truth_track", f"{tbd}/frames/dp-tbd_pfa-0.001_track",
        f"{tbd}/frames/hough_bins-64_track", f"{tbd}/truth",
        f"{dp}/value", f"{dp}/score", f"{dp}/threshold", f"{hough}/value",
        f"{null}/frames", f"{null}/dp-tbd_pfa-0.001/value",
        f"{trk}/truth", f"{trk}/measurements", f"{trk}/measurements/all", f"{trk}/measurements/glint",
        f"{trk}/ekf/estimate", f"{trk}/ekf/error_x", f"{trk}/ekf/error_y", f"{trk}/ekf/error_pos",
        f"{trk}/imm_models-3/estimate", f"{trk}/imm_models-3/error_pos",
        "/summary/table", "/summary/tracking/rmse_vs_snr/ekf", "/summary/tracking/rmse_vs_snr/imm_models-3",
    ]
    for p in expected:
        assert rerun_path(p) in paths, p
    # NaN score: not drawn, so its threshold has nothing to compare with either.
    assert rerun_path(f"{hough}/score") not in paths
    assert rerun_path(f"{hough}/threshold") not in paths
    # Null trial: no truth at all; NaN pd everywhere: no Pd chart.
    assert rerun_path(f"{null}/frames/truth_track") not in paths
    assert rerun_path(f"{null}/truth") not in paths
    assert not any("/pd_vs_snr" in p for p in paths)


def test_frames_read_back_north_up(task_rrd, task_records):
    from rerun.chunk import RrdReader

    reader = RrdReader(task_rrd)
    rec = task_records[0]
    path = rerun_path(entity_root("tbd-line", 9.0, 0)) + "/frames"
    steps, buffers = _column(reader, path, "DepthImage:buffer")
    np.testing.assert_array_equal(steps, np.arange(KT))
    codes = np.array([np.asarray(b[0], np.uint8).reshape(H, W) for b in buffers])
    np.testing.assert_array_equal(codes, Quantised.of(rec.image("frames")).codes[:, ::-1, :])
    fmt = _static(reader, path, "DepthImage:format")[0][0]
    assert (fmt["width"], fmt["height"]) == (W, H)
    # The true cells, as pixel centres of the north-up image.
    steps, pts = _column(reader, path + "/truth_track", "Points2D:positions")
    xy = np.array([p[0] for p in pts])
    cells = rec.arrays["truth_cells"]
    np.testing.assert_allclose(xy, np.column_stack([cells[:, 1] + 0.5, H - cells[:, 0] - 0.5]))
    # The strip overlays the image: the pixel under each point is the target's (+5: bright).
    under = codes[steps, np.floor(xy[:, 1]).astype(int), np.floor(xy[:, 0]).astype(int)]
    assert (under >= 150).all(), under  # the noise median is near code 90


def test_track_cells_outside_grid_skipped(task_rrd):
    from rerun.chunk import RrdReader

    path = rerun_path(entity_root("tbd-line", 9.0, 0)) + "/frames/hough_bins-64_track"
    steps, _ = _column(RrdReader(task_rrd), path, "Points2D:positions")
    np.testing.assert_array_equal(steps, [0, 1, 3, 4, 5])


def test_score_and_value_read_back(task_rrd, task_records):
    from rerun.chunk import RrdReader

    reader = RrdReader(task_rrd)
    base = rerun_path(entity_root("tbd-line", 9.0, 0)) + "/dp-tbd_pfa-0.001"
    _, values = _column(reader, f"{base}/score", "Scalars:scalars")
    np.testing.assert_array_equal(np.concatenate(values), np.full(KT, 35.5))
    buf = _static(reader, f"{base}/value", "DepthImage:buffer")[0][0]
    q = Quantised.of(task_records[0].methods[DP].image("value"))
    np.testing.assert_array_equal(np.asarray(buf, np.uint8).reshape(H, W), q.codes[::-1])
    assert _static(reader, f"{base}/value", "code_lo")[0][0] == pytest.approx(q.lo)


def test_glint_points_read_back(task_rrd, task_records):
    from rerun.chunk import RrdReader

    rec = task_records[2]
    path = rerun_path(entity_root("glint-cv", 10.0, 2)) + "/measurements/glint"
    xy = np.array(_static(RrdReader(task_rrd), path, "Points2D:positions")[0])
    z = rec.measurements_xy[GLINT_STEPS]
    np.testing.assert_allclose(xy, np.column_stack([z[:, 0], -z[:, 1]]), rtol=1e-6)


def test_error_traces_are_time_series(task_rrd, task_records):
    from rerun.chunk import RrdReader

    rec = task_records[2]
    path = rerun_path(entity_root("glint-cv", 10.0, 2)) + "/imm_models-3/error_x"
    steps, values = _column(RrdReader(task_rrd), path, "Scalars:scalars")
    np.testing.assert_array_equal(steps, np.arange(rec.steps))
    np.testing.assert_array_equal(np.concatenate(values), rec.methods[IMM].traces["error_x"])


def test_task_rrd_verify_and_blueprint(task_rrd):
    from rerun.chunk import RrdReader

    assert len(RrdReader(task_rrd).blueprints()) == 1
    proc = subprocess.run([*_rerun_cli(), "rrd", "verify", str(task_rrd)],
                          capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_no_view_is_empty(rrd, task_rrd):
    """Every view of the default blueprint shows some entity of the recording (issue 29)."""
    from tests.rrd_blueprint import entities, read_blueprint

    for path in (rrd, task_rrd):
        blueprint, logged = read_blueprint(path), entities(path)
        assert blueprint.views and not [(v.kind, v.name) for v in blueprint.views.values() if not v.shows(logged)]


def test_summary_without_pd_column(tmp_path, task_records):
    from rerun.chunk import RrdReader

    summary = _tracking_summary().drop(columns=["pd"])
    out = write_recording(tmp_path / "r.rrd", task_records[2:], summary, tasks=TASKS, recording_id="no-pd")
    paths = set(RrdReader(out).store().schema().entity_paths())
    assert "/summary/tracking/rmse_vs_snr/ekf" in paths and "/summary/table" in paths
    with pytest.raises(ValueError, match="missing column"):
        write_recording(tmp_path / "bad.rrd", [], summary.drop(columns=["snr_db"]), tasks=TASKS, recording_id="x")


def test_live_viewer_logs_tasks_like_the_file_writer(tmp_path, task_records, task_rrd):
    import rerun as rr
    from rerun.chunk import RrdReader

    out = tmp_path / "live.rrd"
    stream = rr.RecordingStream("radar-bench", recording_id="live-tasks")
    stream.save(out)
    with LiveViewer.from_stream(stream, tasks=TASKS) as viewer:
        viewer.log_records(TrialRecord.from_bytes(r.to_bytes()) for r in task_records)
        viewer.log_summary(_tracking_summary())

    def data_paths(p):
        return {x for x in RrdReader(p).store().schema().entity_paths() if not x.startswith("/__")}

    assert data_paths(out) == data_paths(task_rrd)


def test_workers_import_neither_rerun_nor_matplotlib():
    """What a worker imports (the runner, every task, the record) stays light."""
    code = ("import sys, radarbench.bench.runner, radarbench.bench.tasks, radarbench.bench.recording; from radarbench.bench import registry; "
            "registry.discover(); print(sorted(m for m in ('rerun', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_a_method_without_a_task_is_refused_before_any_io(tmp_path, records):
    with pytest.raises(ValueError, match="no task given for method config"):
        write_recording(tmp_path / "r.rrd", records, None, tasks={CUM: DET}, recording_id="x")
    assert list(tmp_path.iterdir()) == []


def test_track_view_has_axes_and_names_every_track(task_rrd, task_records):
    """The 2-D track view reads without the side panel (issue 29): a frame in km with a
    tick at every round step covering what it draws, and the truth and each tracker named
    once on the plot, in its colour, at its own place along its track."""
    from radarbench.bench.recording.axes import frame_of, xy_extent
    from radarbench.bench.recording.layout import TRUTH_COLOR, method_colors
    from tests.rrd_blueprint import axes_of, entities, packed, read_blueprint, static_values, track_views

    rec, logged = task_records[2], entities(task_rrd)
    views = track_views(read_blueprint(task_rrd))
    assert [v.origin for v in views] == [rerun_path(entity_root("glint-cv", 10.0, 2))]   # the TBD trials draw frames
    lines, labels = axes_of(task_rrd, views[0], logged)
    extent = xy_extent(rec.truth_xy, rec.measurements_xy, *(m.arrays["estimate_xy"] for m in rec.methods.values()))
    frame = frame_of(extent)
    assert labels[-2:] == ["x east (km)", "y north (km)"]
    ticks = np.array([float(v) for v in labels[:-2]]) * 1000
    np.testing.assert_allclose(ticks, np.r_[frame.x_ticks, frame.y_ticks])
    assert lines == 1 + len(ticks)                                    # the L and a mark per tick
    assert frame.x_ticks[0] <= extent[0, 0] and frame.x_ticks[-1] >= extent[1, 0]      # covers the data
    assert frame.y_ticks[0] <= extent[0, 1] and frame.y_ticks[-1] >= extent[1, 1]
    colors = method_colors(TASKS)
    root = views[0].origin
    named = {}
    for path, color in ((f"{root}/truth", TRUTH_COLOR), (f"{root}/ekf/estimate", colors[EKF]),
                        (f"{root}/imm_models-3/estimate", colors[IMM])):
        assert f"{path}/label" in views[0].shows(logged), path
        (label,) = static_values(task_rrd, f"{path}/label", "Points2D:labels")
        assert static_values(task_rrd, f"{path}/label", "Points2D:colors") == [packed(color)]
        named[label] = tuple(static_values(task_rrd, f"{path}/label", "Points2D:positions")[0])
    assert sorted(named) == sorted(["truth", EKF, IMM])
    assert len(set(named.values())) == 3                              # each at its own place


def test_tbd_frames_have_axes_in_metres(task_rrd):
    """The frames view's axes are the grid's metres drawn over its pixels: a cell's corner
    (x_min + c·cell, y_min + r·cell) lands on the pixel corner (c, rows - r)."""
    from radarbench.bench.recording.axes import frame_of
    from tests.rrd_blueprint import static_values

    path = rerun_path(entity_root("tbd-line", 9.0, 0)) + "/frames/axes"
    labels = static_values(task_rrd, f"{path}/labels", "Points2D:labels")
    extent = np.array([[GRID["x_min_m"], GRID["y_min_m"]],
                       [GRID["x_min_m"] + W * GRID["cell_m"], GRID["y_min_m"] + H * GRID["cell_m"]]])
    frame = frame_of(extent)
    assert labels == [frame.text(v) for v in np.r_[frame.x_ticks, frame.y_ticks]] + [
        f"x east ({frame.unit})", f"y north ({frame.unit})"]
    (translation,) = static_values(task_rrd, path, "Transform3D:translation")
    (scale,) = static_values(task_rrd, path, "Transform3D:scale")
    for c, r in ((0, 0), (W, H), (5, 11)):
        x, y = GRID["x_min_m"] + c * GRID["cell_m"], GRID["y_min_m"] + r * GRID["cell_m"]
        np.testing.assert_allclose(np.multiply(scale[:2], [x, -y]) + translation[:2], [c, H - r], atol=1e-3)
