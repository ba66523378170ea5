"""The HFSWR detect-and-track chain: scenario ``hfswr-rd-scans``, method ``cfar-track``
(a registered cell detector and multi-target tracker composed by parameters), task
``detect-track`` (docs/architecture.md, 'Tasks')."""

import importlib.resources
import math
import tomllib

import numpy as np
import pandas as pd
import pytest

from radarbench.bench import registry
from radarbench.bench.sweep import tomlw
from radarbench.bench.report.claims import evaluate_folder
from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.core import Batch
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.tasks.detecttrack import DetectTrackTask
from radarbench.bench.tasks.multitarget import CLUTTER, PADDING, MultiTargetScene
from radarbench.methods.chain.chain import CfarTrack
from radarbench.methods.multitarget.trackers import JpdaUkf
from radarbench.models.hfswr import measure
from radarbench.scenarios.hfswr_rd_scans import HfswrRdScans
from tests.chain_oracle import TruthCells
from tests.rrd_blueprint import entities

SMALL = HfswrRdScans.small_params
CLEAN = {"bragg": False, "interference": False, "clutter_edge": False}


@pytest.fixture
def truth_cells():
    registry.register_method(TruthCells)
    yield
    registry._METHODS.pop("truth-cells", None)


def scans(snr_db, n=4, seed=3, **values):
    p = build_params(HfswrRdScans.Params, SMALL | values)
    return p, HfswrRdScans().generate(p, snr_db, n, TrialRNG(seed, 0, 0, range(n)))


def chain(**values):
    return build_params(CfarTrack.Params, values)


def test_maps_hold_each_target_at_its_cell_with_its_azimuth():
    p, b = scans(40.0, **CLEAN)
    sc = b.scene
    i, k, t = np.nonzero(sc.target_cells[..., 0] >= 0)
    r, d = sc.target_cells[i, k, t, 0], sc.target_cells[i, k, t, 1]
    z = measure(b.truth[i, k, t], np.zeros(2))
    assert np.all(np.abs(sc.range_start_m + (r + 0.5) * sc.range_cell_m - z[:, 0]) <= sc.range_cell_m / 2 + 1e-6)
    centre_v = sc.velocity_start_m_s + (d + 0.5) * sc.velocity_cell_m_s
    assert np.all(np.abs(centre_v - z[:, 2]) <= sc.velocity_cell_m_s / 2 + 1e-9)
    # 40 dB over unit noise: the echo (Swerling 1) is far above a noise cell's Exp(1) in most scans
    assert np.median(b.z[i, k, r, d]) > 1000
    # the DOA of a dominated cell is the target's azimuth within 5 sigma
    assert np.all(np.abs(sc.azimuth_rad[i, k, r, d] - z[:, 1])[b.z[i, k, r, d] > 100] < 5 * sc.azimuth_std_rad)
    assert HfswrRdScans().unit_memory_bytes(p, 4) == 40 * 4 * p.scans * p.range_cells * p.doppler_cells


def test_a_component_is_checked_when_the_sweep_is_read():
    sweep = {"name": "x", "scenario": "hfswr-rd-scans", "scenario_params": SMALL, "trials": 2, "snr_db": [30],
             "methods": [{"name": "cfar-track", "params": {"detector": "no-such-cfar"}}]}
    with pytest.raises(ConfigError, match=r"^methods\[0\]\.params\.detector: .*no-such-cfar"):
        parse_sweep(sweep)
    for params, match in (({"detector": "jpda-ukf"}, r"params\.detector: 'jpda-ukf' is a method of task"),
                          ({"detector": "os-cfar[k_range=99]"}, r"params\.detector: os-cfar: k_range"),
                          ({"tracker": "gnn-ekf[confirm_m=x]"}, r"params\.tracker: gnn-ekf: confirm_m"),
                          ({"tracker": "ca-cfar"}, r"params\.tracker: 'ca-cfar' is a method of task")):
        with pytest.raises(ConfigError, match=match):
            parse_sweep({**sweep, "methods": [{"name": "cfar-track", "params": params}]})
    plan = parse_sweep({**sweep, "methods": [{"name": "cfar-track", "params": {
        "detector": ["ca-cfar", "os-cfar[k_range=10,k_doppler=12]"], "tracker": ["jpda-ukf", "gnn-ekf"]}}]})
    labels = [m.label for m in plan.methods]
    assert "cfar-track[detector=os-cfar[k_range=10,k_doppler=12],tracker=gnn-ekf]" in labels and len(labels) == 4


def test_the_oracle_detector_gives_the_trackers_result_on_the_same_plots(truth_cells):
    """With the truth cells as detections, the chain's tracks are jpda-ukf's on a
    multi-target scene of the same plots, built here from the documented choices
    (sigma = cell / sqrt(12), the DOA std, lambda = Pfa R D / V, Pd = tracker_pd)."""
    _, b = scans(30.0)
    params = chain(detector="truth-cells", tracker="jpda-ukf", pfa=1e-3, tracker_pd=0.9)
    out = CfarTrack().run(b, params)
    sc = b.scene
    used = out.plot_cells[..., 0] >= 0
    present = sc.target_cells[..., 0] >= 0
    # one plot per occupied target cell: targets sharing a cell give one plot
    occupied = [len({tuple(c) for c in sc.target_cells[i, k][present[i, k]]}) for i, k in np.ndindex(used.shape[:2])]
    assert used.sum(axis=2).ravel().tolist() == occupied
    # the centroid keeps each plot within a cell of its cell's centre
    i, k, j = np.nonzero(used)
    centre = sc.range_start_m + (out.plot_cells[i, k, j, 0] + 0.5) * sc.range_cell_m
    assert np.all(np.abs(out.plots[i, k, j, 0] - centre) < sc.range_cell_m)
    R, D = sc.shape
    region = sc.surveillance_region
    counts = used.sum(axis=2)
    scene = MultiTargetScene(
        snr_definition="x", realised_snr_db=sc.realised_snr_db, n_plots=counts,
        plot_origin=np.where(used, CLUTTER, PADDING), scan_period_s=sc.scan_period_s, sensor_xy=np.zeros(2),
        measurement_std=np.array([sc.range_cell_m / math.sqrt(12), sc.azimuth_std_rad,
                                  sc.velocity_cell_m_s / math.sqrt(12)]),
        clutter_density=1e-3 * R * D / float(np.prod(region[:, 1] - region[:, 0])), surveillance_region=region,
        pd=0.9, speed_bounds_m_s=sc.speed_bounds_m_s, accel_std_m_s2=sc.accel_std_m_s2)
    direct = JpdaUkf().run(Batch(t=b.t, truth=b.truth, z=out.plots, scene=scene, trials=b.trials), JpdaUkf.Params())
    for name in ("state", "track_id", "status", "position_covariance"):
        np.testing.assert_array_equal(getattr(out, name), getattr(direct, name), err_msg=name)
    m = DetectTrackTask().trial_metrics(b, out, np.nan)
    assert np.all(m["cell_pd"] == 1.0) and np.all(m["cell_pfa"] == 0.0)
    assert m["confirmed_tracks"].sum() > 0 and np.all(m["false_tracks"] == 0)


def test_no_target_and_no_clutter_gives_no_confirmed_track():
    _, b = scans(None, n=6, **CLEAN)
    for detector in ("ca-cfar", "os-cfar", "region-adaptive"):
        out = CfarTrack().run(b, chain(detector=detector, pfa=1e-12))
        m = DetectTrackTask().trial_metrics(b, out, np.nan)
        assert np.all(out.status != 2), detector
        assert m["cell_false"].sum() == 0 and np.all(m["false_tracks"] == 0)


def test_false_tracks_increase_with_the_detectors_pfa():
    """Null maps with every clutter component, CA-CFAR at three nominal Pfa: false plots
    and false confirmed tracks (Poisson-like counts over 8 trials) grow with Pfa, each step
    by more than 3 standard deviations of the difference of two Poisson counts."""
    _, b = scans(None, n=8, seed=11, scans=30)
    false_plots, false_tracks = [], []
    for pfa in (1e-3, 1e-2, 3e-2):
        out = CfarTrack().run(b, chain(detector="ca-cfar", tracker="jpda-ukf", pfa=pfa, tracker_pd=0.7))
        m = DetectTrackTask().trial_metrics(b, out, np.nan)
        false_plots.append(m["cell_false"].sum())
        false_tracks.append(m["false_tracks"].sum())
    for counts in (false_plots, false_tracks):
        for low, high in zip(counts, counts[1:]):
            assert high - low > 3 * math.sqrt(high + low), counts


@pytest.mark.slow
def test_hfswr_chain_preset_smoke(bench_cli, tmp_path):
    """The preset's grid (detectors x trackers, both band strengths, three SNR levels) at two trials
    of short runs: every config scored, the cell and track sections and figures written, every claim
    evaluated (none 'not comparable': its configs are the sweep's)."""
    sweep = tomllib.loads((importlib.resources.files("radarbench.bench") / "presets" / "hfswr-chain.toml").read_text())
    sweep.update(trials=2, chunk=2)
    sweep["scenarios"][0]["params"] |= {"scans": 12, "targets": 3}
    path = tmp_path / "hfswr-chain.toml"
    path.write_text(tomlw.dumps(sweep))
    bench_cli("run", path, "--out", tmp_path / "out", "--quiet", "--workers", 1, check=True)
    summary = pd.read_csv(tmp_path / "out" / "summary.csv")
    report = (tmp_path / "out" / "report.md").read_text()
    assert summary.config.nunique() == 6 and len(summary) == 6 * 2 * 3
    assert summary[["gospa_mean", "cell_pd_mean", "cell_pfa_mean"]].notna().all().all()
    assert "## Detect and track: cells and tracks" in report
    assert list((tmp_path / "out" / "figures").glob("chain_gospa_vs_cell_pd_*.png"))
    recorded = entities(tmp_path / "out" / "recording.rrd")    # maps, detections, plots, tracks: one timeline
    for entity in ("/maps", "/detections", "/plots", "/tracks"):
        assert any(e.endswith(entity) for e in recorded), entity
    claims = evaluate_folder(tmp_path / "out")                 # the preset's claims, by plan.toml's name
    assert len(claims) == 12 and not claims.verdict.str.contains("not comparable").any()


@pytest.mark.parametrize("peer", ["stonesoup-jpda", "stonesoup-gmphd"])
def test_a_stone_soup_peer_is_a_tracker_of_the_chain(peer):
    """Any registered multi-target tracker composes: the Stone Soup peers (the [peers] extra)."""
    pytest.importorskip("stonesoup")
    _, b = scans(35.0, n=2)
    out = CfarTrack().run(b, chain(tracker=peer))
    DetectTrackTask().check_output(out, b)
    assert (out.status == 2).any()
