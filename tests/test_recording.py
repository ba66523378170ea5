"""Tests of bench.recording and of the tasks' recording hooks: entity paths, the .rrd file, the live viewer, axes and names."""

from __future__ import annotations

import shutil
import subprocess
import sys

import numpy as np
import pyarrow as pa
import pytest

from radarbench.bench.recording import (
    LiveViewer,
    Quantised,
    TrialRecord,
    entity_root,
    rerun_path,
    write_recording,
)
from radarbench.bench.tasks import tbd

from tests.recording_records import (  # noqa: F401 - records: a fixture
    K,
    CUM,
    DET,
    records,
    _summary,
    H,
    W,
    KT,
    GRID,
    DP,
    EKF,
    IMM,
    TASKS,
    _tbd_record,
    GLINT_STEPS,
    _tracking_record,
    _tracking_summary,
)
from conftest import scaled

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
        "/summary/maneuver-detection/pd_equal_chance_vs_snr/cumulant_window-32",
        "/summary/maneuver-detection/pd_equal_chance_vs_snr/innovation_window-5_variant-fading",
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
                          capture_output=True, text=True, timeout=scaled(), check=False)
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
                          capture_output=True, text=True, timeout=scaled(), check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_no_view_is_empty(rrd, task_rrd):
    """Every view of the default blueprint shows some entity of the recording."""
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
    code = ("import sys, radarbench.bench.run.runner, radarbench.bench.tasks, radarbench.bench.recording; from radarbench.bench import registry; "
            "registry.discover(); print(sorted(m for m in ('rerun', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=scaled())
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_a_method_without_a_task_is_refused_before_any_io(tmp_path, records):
    with pytest.raises(ValueError, match="no task given for method config"):
        write_recording(tmp_path / "r.rrd", records, None, tasks={CUM: DET}, recording_id="x")
    assert list(tmp_path.iterdir()) == []


def test_track_view_has_axes_and_names_every_track(task_rrd, task_records):
    """The 2-D track view reads without the side panel: a frame in km with a
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
