"""The multi-target task end to end with a tests-only oracle tracker (truth plus
noise, with false tracks): output checks, per-trial metrics, summary, report
sections, recording; optional methods that are unavailable are skipped and
reported."""

import numpy as np
import pandas as pd
import pytest

from radarbench.bench import registry
from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.recording import TrialRecord
from radarbench.bench.report import build_outputs
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.run.runner import plan_record, run_sweep
from radarbench.bench.tasks.base import OutputError
from radarbench.bench.tasks.multitarget import MultiTargetOutput, MultiTargetTask
from radarbench.scenarios.hfswr_targets import HFSWRTargets
from tests.mtt_oracle import OracleTracker


@pytest.fixture
def oracle():
    registry.register_method(OracleTracker)
    yield
    registry._METHODS.pop("mtt-oracle", None)


def batch(n=4, **values):
    p = build_params(HFSWRTargets.Params, {"targets": 3, "scans": 20, "clutter_per_scan": 5.0} | values)
    return HFSWRTargets().generate(p, 15.0, n, TrialRNG(5, 0, 0, range(n)))


def oracle_output(b, **values):
    return OracleTracker().run(b, build_params(OracleTracker.Params, values))


def test_check_output_accepts_the_oracle_and_refuses_malformed_outputs():
    b = batch()
    task = MultiTargetTask()
    out = oracle_output(b)
    assert task.check_output(out, b) is out
    with pytest.raises(OutputError, match="MultiTargetOutput"):
        task.check_output(np.zeros(3), b)
    bad = MultiTargetOutput(out.state[:, :-1], out.track_id, out.status)
    with pytest.raises(OutputError, match="state has shape"):
        task.check_output(bad, b)
    ids = out.track_id.copy()
    ids[out.status > 0] = -1
    with pytest.raises(OutputError, match="track_id is -1 exactly where"):
        task.check_output(MultiTargetOutput(out.state, ids, out.status), b)
    twice = out.track_id.copy()
    k = np.argwhere((out.status[0, :, 0] > 0) & (out.status[0, :, 1] > 0))[0, 0]
    twice[0, k, 1] = twice[0, k, 0]
    with pytest.raises(OutputError, match="two slots"):
        task.check_output(MultiTargetOutput(out.state, twice, out.status), b)
    nan = out.state.copy()
    nan[out.status > 0] = np.nan
    with pytest.raises(OutputError, match="non-finite"):
        task.check_output(MultiTargetOutput(nan, out.track_id, out.status), b)


def test_trial_metrics_of_the_oracle():
    b = batch(n=6)
    task = MultiTargetTask()
    clean = task.trial_metrics(b, oracle_output(b, position_noise_m=0.0, false_slots=0, delay_scans=0), np.nan)
    # a perfect tracker with no delay and no false track: GOSPA 0, nothing missed, nothing false
    assert np.all(clean["gospa_m"] == 0) and np.all(clean["false_tracks"] == 0)
    assert np.all(clean["init_delay_sum"] == 0) and np.all(clean["track_breaks"] == 0)
    np.testing.assert_array_equal(clean["targets_initiated"], clean["targets"])
    noisy = task.trial_metrics(b, oracle_output(b, position_noise_m=300.0, false_probability=1.0), np.nan)
    assert np.all(noisy["gospa_m"] > clean["gospa_m"])
    assert np.all(noisy["false_tracks"] > 0) and np.all(noisy["gospa_false"] > 0)
    # two scans tentative: each target that is first present before the last two scans waits two
    assert np.nanmax(noisy["init_delay_scans"]) == pytest.approx(2.0)
    assert noisy["gospa_m"].shape == (6,) and noisy["gospa"].shape == (6, 20)
    assert np.all(noisy["scene_pd"] == b.scene.pd)


def test_end_to_end_with_an_optional_unavailable_peer(oracle, tmp_path, monkeypatch):
    monkeypatch.setattr(registry, "_UNAVAILABLE", registry.unavailable() + [
        registry.Unavailable("methods.peer_missing", "ModuleNotFoundError: No module named 'stonesoup'",
                             "peer-missing")])
    sweep = {"name": "mtt", "scenario": "hfswr-targets", "trials": 6, "chunk": 3, "snr_db": [15],
             "scenario_params": {"targets": 3, "scans": 20, "clutter_per_scan": 5.0, "detection": "fixed",
                                 "pd": [0.6, 0.9]},
             "methods": [{"name": "mtt-oracle", "params": {"position_noise_m": 100.0}, "label": "sharp"},
                         {"name": "mtt-oracle", "params": {"position_noise_m": 600.0}, "label": "blurred"},
                         {"name": "peer-missing", "optional": True}],
             "record": {"trials": 1}}
    with pytest.raises(ConfigError, match="peer-missing.*unavailable"):
        parse_sweep({**sweep, "methods": sweep["methods"][:2] + [{"name": "peer-missing"}]})
    plan = parse_sweep(sweep)
    assert [m.label for m in plan.methods] == ["sharp", "blurred"]
    assert plan.to_dict()["methods"][-1] == {"name": "peer-missing", "optional": True}
    store = run_sweep(plan, tmp_path, plan_record=plan_record(plan, "test"), workers=1, quiet=True,
                      executor="serial")
    store.close()
    build_outputs(tmp_path, recording=True)
    trials = pd.read_csv(tmp_path / "trials.csv")
    assert len(trials) == 2 * 2 * 6 and trials.gospa_m.notna().all()
    sharp, blurred = (trials[trials.config == c].sort_values(["scenario", "trial"]) for c in ("sharp", "blurred"))
    assert np.all(sharp.gospa_loc_m.to_numpy() < blurred.gospa_loc_m.to_numpy())
    summary = pd.read_csv(tmp_path / "summary.csv")
    assert sorted(summary.scene_pd.unique()) == [0.6, 0.9]
    assert (summary.gospa_low <= summary.gospa_mean).all() and (summary.gospa_mean <= summary.gospa_high).all()
    report = (tmp_path / "report.md").read_text()
    for heading in ("## Multi-target tracking: GOSPA", "## Multi-target tracking: paired comparison",
                    "## Multi-target tracking: against Pd and clutter", "## Multi-target tracking: track initiation",
                    "## Multi-target tracking: GOSPA per scan"):
        assert heading in report
    assert "`sharp` against `blurred`: lower GOSPA in 2 of 2 cells" in report
    assert "`peer-missing` (peer-missing): ModuleNotFoundError: No module named 'stonesoup'" in report
    _check_recording(tmp_path)
    steps = pd.read_csv(tmp_path / "steps.csv")
    assert {"gospa", "gospa_missed", "gospa_false", "n_truth", "n_tracks"} <= set(steps.columns)


def test_recorded_trial_keeps_plots_truths_and_tracks():
    b = batch(n=2)
    task = MultiTargetTask()
    out = oracle_output(b)
    scene = task.recorded_scene(b, 1)
    assert scene.arrays["truths_xy"].shape == (20, 3, 2) and scene.arrays["plot_origin"].shape == b.z.shape[1:3]
    trace = task.recorded_method(b, out, 1, np.nan)
    assert trace.arrays["track_xy"].shape == (20, out.state.shape[2], 2)
    assert trace.arrays["track_cov"].shape == (20, out.state.shape[2], 2, 2)
    rec = TrialRecord("hfswr-targets", 15.0, 1, b.t, methods={"oracle": trace}, arrays=scene.arrays)
    back = TrialRecord.from_bytes(rec.to_bytes())
    np.testing.assert_array_equal(back.methods["oracle"].arrays["track_status"], trace.arrays["track_status"])
    np.testing.assert_allclose(back.arrays["plots_xy"], scene.arrays["plots_xy"])


def _check_recording(folder):
    """The recorded trial's entities, and per scan as many plots as the scan had (its stored record)."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    from radarbench.bench.recording.paths import entity_root, rerun_path
    from radarbench.bench.results.store import Store

    store = Store(folder / "results.sqlite")
    rec = next(r for r in map(TrialRecord.from_bytes, store.records()) if "pd=0.9" in r.scenario)
    store.close()
    reader = RrdReader(folder / "recording.rrd")
    paths = set(reader.store().schema().entity_paths())
    root = rerun_path(entity_root(rec.scenario, rec.snr_db, rec.trial))
    for child in ("truths/target_0", "truths/target_2", "plots", "sharp/tracks", "sharp/gates", "sharp/track_lines",
                  "sharp/gospa_m", "blurred/tracks"):
        assert f"{root}/{child}" in paths, child
    chunks = reader.stream().filter(content=f"{root}/plots", is_static=False,
                                    components="Points2D:positions").to_chunks()
    table = pa.Table.from_batches([c.to_record_batch() for c in chunks])
    counts = dict(zip(table.column("step").to_pylist(),
                      (len(v or []) for v in table.column("Points2D:positions").to_pylist())))
    expected = (rec.arrays["plot_origin"] != -2).sum(axis=1)
    assert [counts.get(k, 0) for k in range(len(expected))] == expected.tolist()
