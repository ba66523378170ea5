"""Synthetic trial records shared by the recording tests (tests/test_recording.py,
tests/test_recording_format.py): detector, tracker and TBD trials as the runner builds them."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from radarbench.bench.recording import TrialRecord
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
    df["pd_equal_chance"] = df["pd"] / 2
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


