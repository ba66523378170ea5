"""The cell-detection task: its scene and output checks, its metrics on
hand-built outputs (Pd, Pfa, false alarms, masking), the ideal detector's closed
forms, the per-cell calibration, and the plumbing end to end with an oracle
method (the known-noise detector, tests/cells_oracle.py) run by ``bench run``."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from radarbench.bench.calibration import calibrate, cell_order_statistics
from radarbench.bench.core import Batch, SceneError
from radarbench.bench.tasks.base import OutputError
from radarbench.bench.tasks.cells import CellDetectionOutput, CellDetectionTask, MapScene
from radarbench.bench.tasks.cells.metrics import (PAIRED_GROUP, REGION_NAMES, cell_trial_metrics, guard_mask, ideal_pd, ideal_snr_at_pd,
                                       summarise_cells)
from conftest import scaled

HERE = Path(__file__).resolve().parent


def hand_scene(n=2, R=8, D=10):
    """A map whose right half (columns >= 5) is 'bragg'; targets at (2, 2)
    (isolated, homogeneous), (5, 7) (isolated, bragg) and a pair (6, 1), (6, 3)."""
    labels = np.zeros((R, D), np.int8)
    labels[:, 5:] = 1
    cells = np.broadcast_to(np.array([[2, 2], [5, 7], [6, 1], [6, 3]]), (n, 4, 2)).copy()
    return MapScene(region_labels=labels, region_names=("homogeneous", "bragg"),
                    noise_power=np.ones((n, R, D)), target_cells=cells, target_snr_db=np.full((n, 4), 10.0),
                    target_paired=np.broadcast_to(np.array([False, False, True, True]), (n, 4)).copy(),
                    guard_cells=(1, 1))


def hand_batch(n=2, R=8, D=10):
    return Batch(t=np.zeros(1), truth=np.zeros((n, 1, 2)), z=np.ones((n, 1, R, D), np.float32),
                 scene=hand_scene(n, R, D), trials=np.arange(n))


def test_scene_checks_name_the_field():
    sc = hand_scene()
    with pytest.raises(SceneError, match="region_names"):
        MapScene(region_labels=sc.region_labels, region_names=("sea",), noise_power=sc.noise_power,
                 target_cells=sc.target_cells, target_snr_db=sc.target_snr_db, target_paired=sc.target_paired)
    with pytest.raises(SceneError, match="region_labels"):
        Batch(t=np.zeros(1), truth=np.zeros((2, 1, 2)), z=np.ones((2, 1, 8, 9), np.float32), scene=sc,
              trials=np.arange(2))


def test_output_checks():
    task, b = CellDetectionTask(), hand_batch()
    with pytest.raises(OutputError, match="statistic has shape"):
        task.check_output(CellDetectionOutput(statistic=np.zeros((2, 8, 9))), b)
    bad = np.zeros((2, 8, 10), np.float32)
    bad[0, 0, 0] = np.nan
    with pytest.raises(OutputError, match="non-finite"):
        task.check_output(CellDetectionOutput(statistic=bad), b)
    with pytest.raises(OutputError, match="CellDetectionOutput"):
        task.check_output(np.zeros((2, 8, 10)), b)


def test_guard_mask_boxes_every_target_and_clips_at_the_border():
    cells = np.array([[[0, 0], [4, 5]]])
    mask = guard_mask((1, 6, 8), cells, (1, 2))
    assert mask[0].sum() == 2 * 3 + 3 * 5           # a clipped corner box and a full box
    assert mask[0, 3:6, 3:8].all() and not mask[0, 2, 5]


def test_metrics_on_a_hand_built_output():
    """Map 0: targets (2,2) and (6,1) detected, (5,7) and (6,3) missed; false
    alarms at (0,8) (bragg) and (4,0) (homogeneous); (3,3) is declared but lies in
    the guard box of (2,2), so it is no false alarm. Map 1: nothing declared."""
    b = hand_batch()
    stat = np.zeros((2, 8, 10), np.float32)
    for r, d in [(2, 2), (6, 1), (0, 8), (4, 0), (3, 3)]:
        stat[0, r, d] = 5.0
    stat[0, 5, 7] = 2.9                               # just below the threshold
    m = CellDetectionTask().trial_metrics(b, CellDetectionOutput(statistic=stat), 3.0)
    assert m["hits"].tolist() == [2, 0] and m["targets"].tolist() == [4, 4]
    assert m["hits_homogeneous"].tolist() == [1, 0] and m["targets_homogeneous"].tolist() == [1, 1]
    assert m["hits_bragg"].tolist() == [0, 0] and m["targets_bragg"].tolist() == [1, 1]
    assert m["hits_paired"].tolist() == [1, 0] and m["targets_paired"].tolist() == [2, 2]
    assert m["false_alarms"].tolist() == [2, 0]
    assert m["false_alarms_bragg"].tolist() == [1, 0] and m["false_alarms_homogeneous"].tolist() == [1, 0]
    guard = guard_mask((2, 8, 10), b.scene.target_cells, (1, 1))
    assert m["clear_cells"].tolist() == [80 - guard[0].sum()] * 2
    assert m["clear_cells_homogeneous"][0] + m["clear_cells_bragg"][0] == m["clear_cells"][0]
    assert m["targets_interference"].tolist() == [0, 0] and m["clear_cells_interference"].tolist() == [0, 0]
    np.testing.assert_allclose(m["target_statistic"][0], [5.0, 2.9, 5.0, 0.0])
    assert m["target_group"][0].tolist() == [0, 1, PAIRED_GROUP, PAIRED_GROUP]

    trials = pd.DataFrame({k: v for k, v in m.items() if v.ndim == 1})
    trials = trials.assign(scenario="s", method="m", config="m", params="", snr_db=10.0, threshold=3.0,
                           realised_snr_db=10.0, trial=[0, 1])
    row = summarise_cells(trials, {}).iloc[0]
    assert row.pd == pytest.approx(2 / 8) and row.pd_paired == pytest.approx(1 / 4)
    assert row.pd_homogeneous == pytest.approx(1 / 2) and np.isnan(row.pd_interference)
    assert row.pfa == pytest.approx(2 / m["clear_cells"].sum())
    assert row.false_alarms_per_map == pytest.approx(1.0)
    assert row.pd_low <= row.pd <= row.pd_high and row.pfa_low <= row.pfa <= row.pfa_high
    # masking: the paired targets' Pd against the isolated homogeneous ones'
    assert (row.pd_paired, row.pd_homogeneous) == (0.25, 0.5)


def test_ideal_detector_closed_forms():
    """Swerling 1: pfa^(1/(1+S)); non-fluctuating: Marcum Q against a simulation
    (200 000 draws, 5 standard errors); the SNR at Pd = 0.5 inverts both."""
    pfa = 1e-3
    assert ideal_pd(10.0, pfa, 1) == pytest.approx(pfa ** (1 / 11))
    rng = np.random.default_rng(4)
    s, n = 10 ** 1.2, 200_000
    w = (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / np.sqrt(2)
    sim = np.mean(np.abs(np.sqrt(s) + w) ** 2 >= -np.log(pfa))
    p = ideal_pd(12.0, pfa, 0)
    assert abs(sim - p) < 5 * np.sqrt(p * (1 - p) / n)
    for swerling in (0, 1):
        assert ideal_pd(ideal_snr_at_pd(pfa, swerling), pfa, swerling) == pytest.approx(0.5, abs=1e-8)


def test_per_cell_calibration_on_exponential_maps():
    """The exact statistic of 300 null maps of 64 x 64 Exp(1) cells: the nominal
    threshold's per-cell Pfa and the empirical threshold's are within 5 standard
    errors of the request (1.2 million cells, 1229 expected exceedances)."""
    rng = np.random.default_rng(9)
    maps = rng.exponential(size=(300, 64, 64)) * np.log10(np.e)
    pfa = 1e-3
    cal = calibrate("s", "m", maps.reshape(300, -1).max(axis=1), -np.log10(pfa), pfa, "empirical",
                    null_peaks=maps.reshape(300, -1).max(axis=1), null_cells=cell_order_statistics(maps),
                    per_cell=True)
    se = np.sqrt(pfa / maps.size)
    assert abs(cal.nominal_pfa - pfa) < 5 * se and cal.nominal_pfa_low < pfa < cal.nominal_pfa_high
    assert abs(cal.used_pfa - pfa) < 5 * se and cal.used == pytest.approx(-np.log10(pfa), abs=0.05)
    assert cal.null_values == 300
    # the chance Pd is the fraction of maps with a false alarm: 1 - (1 - pfa)^4096
    q = 1 - (1 - pfa) ** 4096
    assert abs(cal.chance_pd - q) < 5 * np.sqrt(q * (1 - q) / 300)


SWEEP = """
name = "oracle"
scenario = "rd-map"
trials = 60
chunk = 30
seed = 13
snr_db = [4, 10, 16]

[scenario_params]
{params}

[[methods]]
name = "known-noise"

[calibration]
pfa = 0.002
mode = "nominal"
h0_trials = 60

[record]
trials = 1
"""


@pytest.fixture(scope="module")
def oracle_run(tmp_path_factory):
    """``bench run`` of the known-noise oracle on a small rd-map (Swerling 1)."""
    from radarbench.scenarios.rd_map import RdMap

    tmp = tmp_path_factory.mktemp("oracle")
    site = tmp / "site"
    (site / "cells_oracle_plugin-0.1.dist-info").mkdir(parents=True)
    shutil.copy(HERE / "cells_oracle.py", site / "cells_oracle.py")
    info = site / "cells_oracle_plugin-0.1.dist-info"
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: cells-oracle-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[bench.methods]\nknown-noise = cells_oracle:KnownNoise\n")
    params = "\n".join(f"{k} = {list(v) if isinstance(v, tuple) else v}" for k, v in RdMap.small_params.items())
    (tmp / "sweep.toml").write_text(SWEEP.format(params=params))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), *filter(None, [env.get("PYTHONPATH")])])
    run = subprocess.run([sys.executable, "-m", "radarbench.bench", "run", str(tmp / "sweep.toml"), "--out", str(tmp / "run"),
                          "--workers", "1", "--quiet"], env=env, capture_output=True, text=True, timeout=scaled())
    assert run.returncode == 0, run.stderr
    return tmp / "run"


def test_oracle_end_to_end_pfa_and_pd_match_the_closed_forms(oracle_run):
    """The known-noise detector's Pfa is exactly the nominal in every region and
    its Pd the closed form: each within 4 binomial standard errors (targets and
    cells of a map are independent for this detector)."""
    summary = pd.read_csv(oracle_run / "summary.csv")
    cal = pd.read_csv(oracle_run / "calibration.csv").iloc[0]
    pfa = 0.002
    for row in summary.itertuples():
        targets = row.targets_per_map * row.n_trials
        p = float(ideal_pd(row.snr_db, pfa, 1))
        assert abs(row.pd - p) < 4 * np.sqrt(p * (1 - p) / targets), row.snr_db
        cells = (48 * 96 - 6 * 9) * row.n_trials    # clear cells: six disjoint 3 x 3 guard boxes a map
        assert abs(row.pfa - pfa) < 4 * np.sqrt(pfa / cells), row.snr_db
    null_cells = 60 * 48 * 96
    assert abs(cal.nominal_pfa - pfa) < 4 * np.sqrt(pfa / null_cells)
    report = (oracle_run / "report.md").read_text()
    for heading in ("Pd by clutter region", "measured per-cell Pfa", "CFAR loss", "masking", "ROC at",
                    "which detector wins where", "Fig. 6.24"):
        assert heading in report
    assert (oracle_run / "figures" / "cells_rd_map_detections.png").exists()


def test_oracle_recording_has_the_maps(oracle_run):
    from rerun.chunk import RrdReader

    from radarbench.bench.recording import entity_root, rerun_path

    paths = set(RrdReader(oracle_run / "recording.rrd").store().schema().entity_paths())
    root = entity_root("rd-map", 16.0, 0)
    for child in ("map", "regions", "map/targets", "known-noise/statistic", "known-noise/threshold_map",
                  "known-noise/detections"):
        assert rerun_path(f"{root}/{child}") in paths, child


def test_a_threshold_just_above_a_capped_statistic_declares_nothing():
    """The calibration reads the statistic in float64: a threshold just above a
    float32 cap (e.g. 300) must not be rounded down onto it."""
    from radarbench.bench.tasks.cells.metrics import declared_cells

    stat = np.array([299.0, 300.0, 2.5], np.float32)
    assert declared_cells(stat, np.nextafter(300.0, np.inf)).tolist() == [False, False, False]
    assert declared_cells(stat, 300.0).tolist() == [False, True, False]
    assert declared_cells(stat, 2.5).tolist() == [True, True, True]
    assert declared_cells(stat.astype(np.float64), np.nextafter(300.0, np.inf)).tolist() == [False] * 3
