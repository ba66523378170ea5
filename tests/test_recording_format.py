"""Tests of the recording's trial records: byte round trips, old versions, quantisation, field and name checks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from radarbench.bench.recording import (
    Quantised,
    TrialRecord,
    entity_name,
    entity_root,
    method_entity_names,
    rerun_path,
    snr_part,
)
from radarbench.bench.tasks import detection, tbd, tracking

from tests.recording_records import (  # noqa: F401 - records: a fixture
    CUM,
    INNO,
    _record_of,
    records,
    _assert_records_equal,
    H,
    W,
    KT,
    GRID,
    DP,
    HOUGH,
    _tbd_record,
    GLINT_STEPS,
    _tracking_record,
)

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


# -- track-before-detect and tracking records ------------------------------

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
