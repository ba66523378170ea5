"""Scenario recorded-tracks on a small CSV each test writes itself: the resampled truth,
the onset truth, the segments, the trackers and detectors on it, common random numbers,
the file's content in the config's identity, and bad files refused in one line (exit 2,
nothing written). The traffic samples are tried only where the package is installed."""

import gzip
import hashlib
import importlib.util
import json
import os
import re
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from radarbench.bench import registry
from radarbench.bench.sweep.capabilities import VALID_STEP_MASKS, fits
from radarbench.bench.core import Batch
from radarbench.bench.errors import ConfigError
from radarbench.bench.run.identity import config_identity
from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.tasks.tracking import TrackingScene
from radarbench.scenarios.recorded_tracks import RecordedTracks, files
from tests.conftest import run_bench

SPEED = 100.0                     # m/s
TURN = np.deg2rad(3.0)            # rad/s: |a| = SPEED * TURN = 5.2 m/s^2
#: a small config: 5 s steps, 40 per trial, the onset at step 10
SMALL = {"dt_s": 5.0, "steps": 40, "onset_step": 10, "detect_window_steps": 10, "smoothing_s": 20.0,
         "maneuver_threshold_m_s2": 2.0}


def turn_track(t: np.ndarray, turn_start: float, turn_s: float) -> np.ndarray:
    """(len(t), 2) east/north of a target flying east at SPEED, turning left at TURN from
    ``turn_start`` for ``turn_s`` seconds, straight again after."""
    tau = np.clip(t - turn_start, 0.0, turn_s)                  # time spent turning so far
    before = np.minimum(t, turn_start)
    after = np.clip(t - turn_start - turn_s, 0.0, None)
    heading_end = TURN * turn_s
    x = SPEED * before + SPEED / TURN * np.sin(TURN * tau) + SPEED * np.cos(heading_end) * after
    y = SPEED / TURN * (1.0 - np.cos(TURN * tau)) + SPEED * np.sin(heading_end) * after
    return np.stack([x, y], axis=-1)


def tracks_table(seed: int = 0) -> pd.DataFrame:
    """Two tracks sampled about every 2 s (jittered), one with a 60 s gap."""
    rng = np.random.default_rng(seed)
    rows = []
    for name, length, turn_start, gap in (("A", 700.0, 250.0, None), ("B", 900.0, 400.0, (600.0, 660.0))):
        t = np.cumsum(rng.uniform(1.5, 2.5, int(length / 2)))
        if gap:
            t = t[(t < gap[0]) | (t > gap[1])]
        xy = turn_track(t, turn_start, 60.0) + [1000.0, -500.0]
        rows.append(pd.DataFrame({"track": name, "time_s": t, "x_m": xy[:, 0], "y_m": xy[:, 1]}))
    return pd.concat(rows, ignore_index=True)


def small_params_on_a_csv(folder) -> dict:
    """A small config of the scenario on tracks_table() written into ``folder``: for the
    tests that run every scenario's small instance without the optional [data] extra."""
    path = folder / "tracks.csv"
    tracks_table().to_csv(path, index=False)
    return {**SMALL, "path": str(path)}


@pytest.fixture
def csv(tmp_path):
    path = tmp_path / "tracks.csv"
    tracks_table().to_csv(path, index=False)
    return path


def params_for(path, **changes):
    return build_params(RecordedTracks.Params, {**SMALL, "path": str(path), **changes})


def generate(p, snr_db, trials=range(6), seed=5):
    return RecordedTracks().generate(p, snr_db, len(trials), TrialRNG(seed, 0, 1, list(trials)))


def test_truth_is_the_recorded_motion_with_the_onset_at_onset_step(csv):
    p = params_for(csv)
    RecordedTracks().check_config(p)
    batch = generate(p, 10.0)
    n, K = 6, p.steps
    assert batch.truth.shape == (n, K, 6) and batch.z.shape == (n, K, 2)
    speed = np.hypot(batch.truth[..., 1], batch.truth[..., 4])
    np.testing.assert_allclose(speed, SPEED, rtol=0.02)               # the smoothing keeps the speed
    accel = np.hypot(batch.truth[..., 2], batch.truth[..., 5])
    scene = batch.scene
    assert scene.onset_step == p.onset_step and (scene.maneuver_onset_steps == p.onset_step).all()
    assert not scene.maneuver_mask[:, :p.onset_step].any() and scene.maneuver_mask[:, p.onset_step].all()
    # the turn's steps carry its acceleration; the quiet steps far from it almost none
    turning = scene.maneuver_mask
    assert np.median(accel[turning]) == pytest.approx(SPEED * TURN, rel=0.1)
    assert np.median(accel[:, :p.onset_step - 3]) < 0.2
    np.testing.assert_array_equal(scene.offset_step, np.argmax(~turning[:, p.onset_step:], axis=1) + p.onset_step)
    # each segment starts at the prior mean (the origin) up to a draw of the prior's position std
    assert np.all(np.abs(batch.truth[:, 0, [0, 3]]) < 5 * p.initial_position_std_m)
    noise = batch.z - batch.truth[..., [0, 3]]
    assert np.std(noise) == pytest.approx(50.0 * 10 ** (-0.5), rel=0.15)


def test_turn_rate_marks_turns_and_not_speed_changes():
    """maneuver_size on three states (position, velocity, acceleration per axis): a turn at
    3 deg/s and 100 m/s, a speed change along the track, a hover (no heading)."""
    from radarbench.scenarios.recorded_tracks.bank import maneuver_size
    turn = [[0, 0], [SPEED, 0], [0, SPEED * TURN]]
    speeding_up = [[0, 0], [SPEED, 0], [3.0, 0]]
    hover = [[0, 0], [0.1, 0], [0, 3.0]]
    states = np.array([turn, speeding_up, hover], float)
    np.testing.assert_allclose(maneuver_size(states, "acceleration"), [SPEED * TURN, 3.0, 3.0])
    np.testing.assert_allclose(maneuver_size(states, "turn-rate"), [3.0, 0.0, 0.0], atol=1e-12)


def test_the_turn_rate_measure_finds_the_same_turns(csv):
    p = params_for(csv, maneuver_measure="turn-rate", turn_rate_threshold_deg_s=1.5)
    batch = generate(p, 10.0)
    mask = batch.scene.maneuver_mask
    assert not mask[:, :p.onset_step].any() and mask[:, p.onset_step].all()
    from radarbench.scenarios.recorded_tracks.bank import maneuver_size
    states = batch.truth.reshape(*batch.truth.shape[:2], 2, 3).transpose(0, 1, 3, 2).reshape(-1, 3, 2)
    rate = maneuver_size(states, "turn-rate").reshape(mask.shape)
    assert np.median(rate[mask]) == pytest.approx(3.0, rel=0.1)


def test_null_trials_are_quiet_segments_with_the_same_draws(csv):
    p = params_for(csv)
    null, alt = generate(p, None), generate(p, 0.0)
    assert null.scene.onset_step is None and null.scene.maneuver_onset_steps.shape == (6, 0)
    assert not null.scene.maneuver_mask.any()
    # common random numbers: the noise draws are the same; the noise std is 0 dB's under the null
    np.testing.assert_allclose(null.z - null.truth[..., [0, 3]], alt.z - alt.truth[..., [0, 3]])


def test_a_trial_is_the_same_alone_and_in_a_batch(csv):
    p = params_for(csv)
    whole, part = generate(p, 5.0, range(8)), generate(p, 5.0, range(5, 8))
    np.testing.assert_array_equal(whole.truth[5:], part.truth)
    np.testing.assert_array_equal(whole.z[5:], part.z)


def test_geodetic_columns_are_converted_to_metres(tmp_path):
    """A track along the equator at 3 km, 0.001 degree of longitude a second: in the tangent
    plane at its first point, east = (a + h) sin(lon - lon0) exactly, north 0."""
    t = np.arange(0.0, 600.0, 1.0)
    table = pd.DataFrame({"track": "eq", "time_s": t, "latitude": 0.0, "longitude": 10.0 + 1e-3 * t,
                          "altitude_m": 3000.0})
    path = tmp_path / "geo.csv"
    table.to_csv(path, index=False)
    from radarbench.scenarios.recorded_tracks.files import checked_tracks
    enu = checked_tracks(pd.read_csv(path), str(path))
    np.testing.assert_allclose(enu["east"], (6_378_137.0 + 3000.0) * np.sin(np.deg2rad(1e-3 * t)), atol=1e-6)
    assert np.abs(enu["north"]).max() < 1.0


@pytest.mark.parametrize("method", ["cv-kf", "imm-cv-ca", "ar-adaptive", "innovation", "cumulant"])
def test_builtin_methods_run_on_it(csv, method):
    """The kinematic trackers and the innovation detectors pair with it and give finite
    output; a tracker does not lose the target (its error within ten noise stds)."""
    cls = registry.get_method(method)
    assert fits(cls, RecordedTracks)
    batch = generate(params_for(csv), 10.0)
    out = cls().run(batch, cls.Params())
    if cls.task == "tracking":
        err = out.estimate[..., [0, 3]] - batch.truth[..., [0, 3]]
        assert np.sqrt(np.mean(err[:, 5:] ** 2)) < 10 * 50.0 * 10 ** (-0.5)
    else:
        assert np.isfinite(out.statistic).all()


def test_a_changed_file_is_a_different_config(csv):
    p = params_for(csv)
    before = config_identity(RecordedTracks, p)["identity"]
    table = pd.read_csv(csv)
    table.loc[3, "x_m"] += 1.0
    table.to_csv(csv, index=False)
    assert config_identity(RecordedTracks, p)["identity"] != before
    assert str(csv) in config_identity(RecordedTracks, p)["data"]


def _broken(table: pd.DataFrame, how: str) -> pd.DataFrame:
    if how == "missing column":
        return table.drop(columns="y_m")
    if how == "time not increasing":
        table.loc[10, "time_s"] = table.loc[8, "time_s"]
        return table
    if how == "NaN position":
        table.loc[12, "x_m"] = np.nan
        return table
    if how == "empty track":
        return pd.concat([table, pd.DataFrame({"track": ["C"], "time_s": [1.0], "x_m": [0.0], "y_m": [0.0]})])
    if how == "no rows":
        return table.iloc[:0]
    raise AssertionError(how)


PROBLEMS = {"missing column": "missing column(s) y_m", "time not increasing": "time does not increase",
            "NaN position": "column x_m has 1 missing", "empty track": "track 'C' has 1 point",
            "no rows": "no rows"}


@pytest.mark.parametrize("how", list(PROBLEMS))
def test_a_bad_file_is_refused_naming_the_file_and_the_problem(tmp_path, how):
    path = tmp_path / "bad.csv"
    _broken(tracks_table(), how).to_csv(path, index=False)
    with pytest.raises(ConfigError) as err:
        RecordedTracks().check_config(params_for(path))
    assert str(path) in err.value.problem and PROBLEMS[how] in err.value.problem
    assert "\n" not in str(err.value)


def test_a_file_over_the_size_limit_is_refused_unread(tmp_path):
    """A 2 GB file (sparse: nothing is written to disk) fails on its size alone."""
    path = tmp_path / "huge.csv"
    with open(path, "wb") as f:
        f.truncate(2 * 10 ** 9)
    with pytest.raises(ConfigError, match=r"huge.csv: 2000 MB is over max_file_mb = 500 MB"):
        params_for(path)


SWEEP = """
name = "mine"
scenario = "recorded-tracks"
trials = 4
seed = 1
snr_db = [10]
[scenario_params]
path = "{path}"
dt_s = 5.0
steps = 40
onset_step = 10
detect_window_steps = 10
smoothing_s = 20.0
[[methods]]
name = "cv-kf"
"""


def test_the_cli_refuses_a_bad_file_in_one_line_and_writes_nothing(tmp_path):
    (tmp_path / "data").mkdir()
    _broken(tracks_table(), "time not increasing").to_csv(tmp_path / "data" / "bad.csv", index=False)
    (tmp_path / "sweeps").mkdir()
    sweep = tmp_path / "sweeps" / "mine.toml"
    sweep.write_text(SWEEP.format(path="../data/bad.csv"))       # relative to the sweep's folder, via ..
    out = tmp_path / "out"
    proc = run_bench("run", sweep, "--out", out, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad.csv" in lines[0] and "time does not increase" in lines[0], lines
    assert not out.exists()


def test_a_path_via_dotdot_or_a_symlink_is_read_and_left_unchanged(tmp_path, csv):
    """Outside the sweep's folder is allowed (read-only): the file is read, never written."""
    link = tmp_path / "sub" / "link.csv"
    link.parent.mkdir()
    os.symlink(csv, link)
    before = csv.read_bytes(), csv.stat().st_mtime_ns
    for value in ("../tracks.csv", "link.csv"):
        p = build_params(RecordedTracks.Params, {**SMALL, "path": value}, tmp_path / "sub")
        RecordedTracks().check_config(p)
        assert generate(p, 0.0).truth.shape == (6, 40, 6)
    assert (csv.read_bytes(), csv.stat().st_mtime_ns) == before


def test_a_parquet_file_with_timestamps_reads_as_the_csv(tmp_path, csv):
    """The same tracks as Parquet, their times as UTC timestamps: the same truth."""
    pytest.importorskip("pyarrow", reason="Parquet needs pyarrow")
    table = tracks_table()
    table["time_s"] = pd.Timestamp("2026-01-01", tz="UTC") + pd.to_timedelta(table["time_s"], unit="s")
    path = tmp_path / "tracks.parquet"
    table.to_parquet(path)
    from_csv, from_parquet = generate(params_for(csv), 0.0), generate(params_for(path), 0.0)
    # float64 seconds since 1970 resolve 0.2 us: 20 um at 100 m/s
    np.testing.assert_allclose(from_parquet.truth, from_csv.truth, atol=1e-3)


def test_too_short_tracks_are_refused(csv):
    with pytest.raises(ConfigError, match="no gap-free span"):
        RecordedTracks().check_config(params_for(csv, steps=400, onset_step=10))


def _samples_here() -> bool:
    return importlib.util.find_spec("traffic") is not None or files.samples_folder().is_dir()


@pytest.mark.skipif(importlib.util.find_spec("traffic") is not None, reason="the traffic package is installed")
def test_without_the_samples_they_say_how_to_get_them(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "nothing"))
    p = build_params(RecordedTracks.Params, {"traffic_samples": ["calibration/ajaccio"]})
    for check in (RecordedTracks().data_files, RecordedTracks().check_config):
        with pytest.raises(ConfigError, match=r"the traffic samples are not here: run `bench data fetch`"):
            check(p)


def _wheel(path: Path, samples: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in samples.items():
            archive.writestr(f"{files.SAMPLES_DIR}/{name}.json.gz", data)
        archive.writestr("traffic/__init__.py", "")
    return path


def _sample(lat0: float) -> bytes:
    rows = [{"icao24": "4ca1fa", "timestamp": f"2024-01-01T00:00:{i:02d}Z", "latitude": lat0 + 1e-4 * i,
             "longitude": 8.0, "altitude": 3000.0} for i in range(40)]
    return gzip.compress(json.dumps(rows).encode())


@pytest.mark.skipif(importlib.util.find_spec("traffic") is not None, reason="the traffic package is installed")
def test_data_fetch_keeps_the_samples_of_a_wheel_it_has_checked(tmp_path, monkeypatch, capsys):
    from radarbench.bench.cli import main
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    wheel = _wheel(tmp_path / "traffic-2.13-py3-none-any.whl", {"calibration/ajaccio": _sample(41.9)})
    assert main(["data", "fetch", "--from", str(wheel)]) == 2          # not the pinned wheel
    err = capsys.readouterr().err
    assert err.startswith("error: --from: traffic-2.13-py3-none-any.whl: SHA-256") and err.count("\n") == 1
    assert not files.samples_folder().exists()
    digest = hashlib.sha256(wheel.read_bytes()).hexdigest()
    monkeypatch.setattr(files, "TRAFFIC_WHEEL", (*files.TRAFFIC_WHEEL[:2], digest))
    assert main(["data", "fetch", "--from", str(wheel)]) == 0
    assert "1 sample trajectories in" in capsys.readouterr().out
    assert files.sample_file("calibration/ajaccio") == files.samples_folder() / "calibration" / "ajaccio.json.gz"
    table = files.read_sample("calibration/ajaccio")
    assert len(table) == 40 and set(table["track"]) == {"calibration/ajaccio:4ca1fa"}
    with pytest.raises(ConfigError, match="no sample 'calibration/cardiff' in the fetched samples"):
        files.sample_file("calibration/cardiff")
    # fetched again from another wheel: the folder is replaced whole
    other = _wheel(tmp_path / "other.whl", {"calibration/cardiff": _sample(51.0)})
    monkeypatch.setattr(files, "TRAFFIC_WHEEL", (*files.TRAFFIC_WHEEL[:2], hashlib.sha256(other.read_bytes()).hexdigest()))
    assert main(["data", "fetch", "--from", str(other)]) == 0
    assert sorted(p.name for p in files.samples_folder().rglob("*.json.gz")) == ["cardiff.json.gz"]


@pytest.mark.skipif(not _samples_here(), reason="needs the traffic samples (bench data fetch)")
def test_a_traffic_sample_gives_real_turns():
    p = build_params(RecordedTracks.Params, RecordedTracks.small_params)
    RecordedTracks().check_config(p)
    batch = generate(p, 0.0)
    accel = np.hypot(batch.truth[..., 2], batch.truth[..., 5])
    assert (accel[:, p.onset_step] >= p.maneuver_threshold_m_s2).all()
    assert all(f.name.endswith(".json.gz") for f in RecordedTracks().data_files(p))


@pytest.mark.slow
def test_the_documented_example_runs_the_builtin_methods_on_a_users_csv(tmp_path):
    """docs/recorded-tracks.md, the how-to: its TOML as printed (fewer trials), a CSV beside
    it, no harness edit: the trackers and a detector run, and the report draws a trial in the plane."""
    page = (Path(__file__).parents[1] / "docs" / "recorded-tracks.md").read_text()
    sweep = re.search(r"```toml\n(.*?)```", page, re.S).group(1)
    (tmp_path / "my.toml").write_text(sweep + 'trials = 6\n[calibration]\nh0_trials = 50\n[record]\ntrials = 1\n')
    small_params_on_a_csv(tmp_path)
    run_bench("run", "my.toml", "--out", "out", "--quiet", cwd=tmp_path, check=True)
    summary = pd.read_csv(tmp_path / "out" / "summary.csv")
    assert {"cv-kf", "imm-cv-ca", "innovation"} <= set(summary.config) and summary.n_trials.min() == 6
    assert (tmp_path / "out" / "figures" / "tracking_trial_plane_recorded-tracks.png").exists()


# Ragged trials (the scenario's 'Ragged trials'): a track with a 40 s gap inside a span
# (masked_gap_s), another shorter one, and trials of random lengths (min_steps).
GAP = (320.0, 360.0)              # s: no point strictly between; 40 s is over max_gap_s, under masked_gap_s
RAGGED = {"masked_gap_s": 60.0, "min_steps": 20}
NORTH = np.array([[0.0, 1.0], [-1.0, 0.0]])     # a row (x, y) times this: (-y, x), east becomes north


def turn_velocity(t: np.ndarray, turn_start: float, turn_s: float) -> np.ndarray:
    """(len(t), 2) the velocity of turn_track."""
    heading = TURN * np.clip(t - turn_start, 0.0, turn_s)
    return SPEED * np.stack([np.cos(heading), np.sin(heading)], axis=-1)


def ragged_csv(folder) -> Path:
    """Track 'gap', east then turning at 250 s, recorded every second for 600 s but never
    inside GAP; track 'short', 450 s, flying north, turning at 150 s, no gap."""
    t_gap = np.arange(0.0, 601.0)
    t_gap = t_gap[(t_gap <= GAP[0]) | (t_gap >= GAP[1])]
    t_short = np.arange(0.0, 451.0)
    rows = [pd.DataFrame({"track": name, "time_s": t, "x_m": xy[:, 0], "y_m": xy[:, 1]})
            for name, t, xy in (("gap", t_gap, turn_track(t_gap, 250.0, 60.0)),
                                ("short", t_short, turn_track(t_short, 150.0, 60.0) @ NORTH))]
    path = folder / "ragged.csv"
    pd.concat(rows, ignore_index=True).to_csv(path, index=False)
    return path


def expected_gap_steps(truth_velocity: np.ndarray, dt: float) -> np.ndarray:
    """(K,) bool, by hand: the steps of a trial of track 'gap' strictly inside GAP. The
    segment's first grid step s (time s dt from the track's start) is the one whose
    analytic velocity best matches the trial's truth."""
    K = len(truth_velocity)
    candidates = np.arange(0, 120 - K + 1)
    times = dt * (candidates[:, None] + np.arange(K))
    misfit = [np.sum((turn_velocity(row, 250.0, 60.0) - truth_velocity) ** 2) for row in times]
    t = times[int(np.argmin(misfit))]
    return (t > GAP[0]) & (t < GAP[1])


def test_a_gap_and_different_lengths_make_a_ragged_batch(tmp_path):
    p = params_for(ragged_csv(tmp_path), **RAGGED)
    RecordedTracks().check_config(p)
    assert RecordedTracks().requires(p) == {VALID_STEP_MASKS}
    batch = generate(p, 10.0, range(16))
    valid, K = batch.scene.valid_steps, p.steps
    assert valid.shape == (16, K)
    steps = np.arange(K)
    east = batch.truth[:, 0, 1] > 0.5 * SPEED                      # track 'gap' flies east first, 'short' north
    assert east.any() and (~east).any()
    seen_gap = 0
    for i in range(16):
        gap = expected_gap_steps(batch.truth[i][:, [1, 4]], p.dt_s) if east[i] else np.zeros(K, bool)
        lengths = [L for L in range(p.min_steps, K + 1) if np.array_equal(valid[i], ~gap & (steps < L))]
        assert lengths, (i, valid[i].astype(int))
        seen_gap += bool((gap & (steps < lengths[-1])).any())
    assert seen_gap and len({int(np.flatnonzero(v)[-1]) for v in valid}) > 3    # gaps seen, lengths differ
    # the measurements are NaN exactly at the missing steps; the maneuvers only at steps a trial has
    np.testing.assert_array_equal(np.isnan(batch.z).any(axis=-1), ~valid)
    scene = batch.scene
    assert not (scene.maneuver_mask & ~valid).any()
    assert valid[:, p.onset_step].all() and scene.maneuver_mask[:, p.onset_step].all()
    assert not scene.maneuver_mask[:, :p.onset_step].any()
    np.testing.assert_array_equal(generate(p, 10.0, range(12, 16)).scene.valid_steps, valid[12:])
    null = generate(p, None, range(16)).scene
    assert null.valid_steps[:, 0].all() and not (null.valid_steps[:, p.min_steps:].all(axis=1)).all()


def test_default_params_keep_every_step(csv):
    p = params_for(csv)
    assert RecordedTracks().requires(p) == frozenset() and generate(p, 0.0).scene.valid_steps is None
    assert RecordedTracks().requires(params_for(csv, min_steps=p.steps)) == frozenset()


@pytest.mark.parametrize("changes, field", [({"min_steps": 10}, "min_steps"), ({"min_steps": 41}, "min_steps"),
                                            ({"masked_gap_s": 15.0}, "masked_gap_s")])
def test_ragged_options_out_of_their_range_are_refused(csv, changes, field):
    with pytest.raises(ConfigError) as err:
        params_for(csv, **changes)
    assert err.value.field == field


def _trial_alone(batch: Batch, i: int, length: int) -> Batch:
    """Trial ``i`` of ``batch`` as a batch of one, cut to its ``length`` steps."""
    sc = batch.scene
    scene = TrackingScene(model=sc.model, state_labels=sc.state_labels, position_index=sc.position_index,
                          valid_steps=sc.valid_steps[i:i + 1, :length])
    return Batch(t=batch.t[:length], truth=batch.truth[i:i + 1, :length], z=batch.z[i:i + 1, :length],
                 scene=scene, trials=batch.trials[i:i + 1])


@pytest.mark.parametrize("method", ["cv-kf", "imm-cv-ca"])
def test_a_tracker_on_the_ragged_batch_gives_each_trial_what_it_gets_alone(tmp_path, method):
    batch = generate(params_for(ragged_csv(tmp_path), **RAGGED), 10.0, range(10))
    valid = batch.scene.valid_steps
    lengths = [int(np.flatnonzero(v)[-1]) + 1 for v in valid]
    assert any((~valid[i, :L]).any() for i, L in enumerate(lengths))          # a gap inside some trial
    cls = registry.get_method(method)
    out = cls().run(batch, cls.Params())
    assert np.isfinite(out.estimate).all()
    for i, L in enumerate(lengths):
        alone = cls().run(_trial_alone(batch, i, L), cls.Params())
        np.testing.assert_array_equal(out.estimate[i, :L], alone.estimate[0])
        np.testing.assert_array_equal(out.covariance[i, :L], alone.covariance[0])


@pytest.mark.slow
def test_the_cli_runs_the_trackers_on_ragged_tracks_and_refuses_a_detector(tmp_path):
    ragged_csv(tmp_path)
    sweep = SWEEP.format(path="ragged.csv").replace(
        "[[methods]]", "masked_gap_s = 60.0\nmin_steps = 20\n[[methods]]") + '[[methods]]\nname = "imm-cv-ca"\n'
    (tmp_path / "with_detector.toml").write_text(sweep + '[[methods]]\nname = "innovation"\n')
    proc = run_bench("run", "with_detector.toml", "--out", "refused", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "'innovation'" in lines[0] and VALID_STEP_MASKS in lines[0], lines
    assert not (tmp_path / "refused").exists()
    (tmp_path / "trackers.toml").write_text(sweep)
    run_bench("run", "trackers.toml", "--out", "out", "--quiet", cwd=tmp_path, check=True)
    summary = pd.read_csv(tmp_path / "out" / "summary.csv")
    assert set(summary.method) == {"cv-kf", "imm-cv-ca"} and (summary.n_trials == 4).all()
    assert np.isfinite(summary.rmse_mean).all()


# Replayed measurements (the scenario's 'Measurements', measurements = "recorded"): a track
# turning at 300 s, a sample near every 5 s grid step but none at the steps j = 3 mod 7 and
# two at the steps j = 5 mod 11 (the second 1.5 s later: dropped), measured in N(0, MEAS_STD^2).
MEAS_STD = 30.0                   # m
REPLAY = {**SMALL, "measurements": "recorded", "noise_std_m": MEAS_STD}


def replay_csv(folder, jitter_s: float = 0.5, seed: int = 3) -> tuple[Path, np.ndarray]:
    """The file, and by hand the (J, 2) measurement each grid step j (time 5 j) replays:
    the first sample falling on it, NaN where none. Sample j is at 5 j + U(-jitter_s, jitter_s)
    (the first exactly at 0, where the grid starts), always nearest to step j."""
    rng = np.random.default_rng(seed)
    j = np.arange(200)
    j = j[j % 7 != 3]
    t = SMALL["dt_s"] * j + np.r_[0.0, rng.uniform(-jitter_s, jitter_s, len(j) - 1)]
    second = j % 11 == 5
    times = np.sort(np.r_[t, t[second] + 1.5])
    truth = turn_track(times, 300.0, 60.0)
    z = truth + MEAS_STD * rng.standard_normal(truth.shape)
    path = folder / "replay.csv"
    pd.DataFrame({"track": "A", "time_s": times, "x_m": truth[:, 0], "y_m": truth[:, 1],
                  "x_meas_m": z[:, 0], "y_meas_m": z[:, 1]}).to_csv(path, index=False)
    on_grid = np.full((200, 2), np.nan)
    on_grid[j] = z[np.searchsorted(times, t)]                 # the sample at t, not the one 1.5 s after
    return path, on_grid


def segment_start(z: np.ndarray, on_grid: np.ndarray) -> int:
    """The one grid step s whose replayed measurements, moved by a constant, are ``z``
    (K, 2): the same missing steps and the same differences to the first."""
    K = len(z)
    found = [s for s in range(len(on_grid) - K + 1)
             if np.array_equal(np.isnan(on_grid[s:s + K]), np.isnan(z)) and not np.isnan(z[0]).any()
             and np.allclose(on_grid[s:s + K] - on_grid[s], z - z[0], atol=1e-6, equal_nan=True)]
    assert len(found) == 1, found
    return found[0]


def test_replay_puts_the_files_measurements_on_the_grid(tmp_path):
    path, on_grid = replay_csv(tmp_path)
    p = params_for(path, **REPLAY)
    RecordedTracks().check_config(p)
    assert RecordedTracks().requires(p) == {VALID_STEP_MASKS}
    for snr_db in (0.0, None):
        batch = generate(p, snr_db, range(12))
        valid = batch.scene.valid_steps
        assert batch.scene.model.noise_std_m == MEAS_STD and not (valid.all(axis=1)).any()
        for i in range(12):
            s = segment_start(batch.z[i], on_grid)
            np.testing.assert_array_equal(valid[i], ~np.isnan(on_grid[s:s + p.steps, 0]))
        # the replayed error about the truth: the file's noise, and the motion during the
        # sample's time off its step (uniform within 0.5 s at SPEED along the track)
        err = (batch.z - batch.truth[..., [0, 3]])[valid]
        assert np.sqrt(np.mean(err ** 2)) == pytest.approx(np.sqrt(MEAS_STD ** 2 + (SPEED * 0.5) ** 2 / 6),
                                                           rel=0.2)
    np.testing.assert_array_equal(generate(p, 0.0, range(8, 12)).z, generate(p, 0.0, range(12)).z[8:])


def _position_rmse(batch: Batch, out) -> float:
    err = (out.estimate[..., [0, 3]] - batch.truth[..., [0, 3]])[:, 5:]
    valid = np.ones(batch.z.shape[:2], bool) if batch.scene.valid_steps is None else batch.scene.valid_steps
    return float(np.sqrt(np.mean(err[valid[:, 5:]] ** 2)))


def test_cv_kf_on_replayed_measurements_matches_the_known_noise(tmp_path):
    """Samples on the grid (no jitter): cv-kf's position RMSE on the replayed measurements
    equals its RMSE on measurements drawn at the same std about the same truth, on segments
    with the turn and on quiet ones (the null), within the spread of one file's noise (about
    100 to 190 samples per axis, correlated a few steps by the filter: 5 to 8 % in RMSE; 25 %
    allows three standard errors); on quiet segments filtering beats one measurement."""
    path, _ = replay_csv(tmp_path, jitter_s=0.0)
    cls = registry.get_method("cv-kf")
    for snr_db in (0.0, None):
        rmse = {}
        for measurements in ("recorded", "synthetic"):
            batch = generate(params_for(path, **{**REPLAY, "measurements": measurements}), snr_db, range(200))
            rmse[measurements] = _position_rmse(batch, cls().run(batch, cls.Params()))
        assert rmse["recorded"] == pytest.approx(rmse["synthetic"], rel=0.25), snr_db
    assert rmse["recorded"] < MEAS_STD


@pytest.mark.parametrize("column", ["x_meas_m", "y_meas_m"])
def test_replay_refuses_a_file_without_or_with_nan_measurements(tmp_path, column):
    path, _ = replay_csv(tmp_path)
    table = pd.read_csv(path)
    for how, broken, problem in (("missing", table.drop(columns=column), f"missing column(s) {column}"),
                                 ("nan", table.assign(**{column: table[column].where(table.index != 7)}),
                                  f"column {column} has 1 missing")):
        bad = tmp_path / f"{how}.csv"
        broken.to_csv(bad, index=False)
        with pytest.raises(ConfigError) as err:
            RecordedTracks().check_config(params_for(bad, **REPLAY))
        assert str(bad) in err.value.problem and problem in err.value.problem and "\n" not in str(err.value)


@pytest.mark.slow
def test_the_cli_refuses_a_replay_with_an_snr_axis_and_runs_it_at_0_db(tmp_path):
    replay_csv(tmp_path)
    sweep = SWEEP.format(path="replay.csv").replace(
        "[[methods]]", f'measurements = "recorded"\nnoise_std_m = {MEAS_STD}\n[[methods]]')
    (tmp_path / "axis.toml").write_text(sweep.replace("snr_db = [10]", "snr_db = [0, 10]"))
    proc = run_bench("run", "axis.toml", "--out", "refused", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "10 dB" in lines[0] and "no SNR axis" in lines[0], lines
    assert not (tmp_path / "refused").exists()
    (tmp_path / "replay.toml").write_text(sweep.replace("snr_db = [10]", "snr_db = [0]"))
    run_bench("run", "replay.toml", "--out", "out", "--quiet", cwd=tmp_path, check=True)
    summary = pd.read_csv(tmp_path / "out" / "summary.csv")
    assert set(summary.method) == {"cv-kf"} and (summary.n_trials == 4).all() and np.isfinite(summary.rmse_mean).all()


def test_the_perf_sizes_run_on_the_racetracks_the_scenario_writes(tmp_path):
    """``bench perf`` times every size without the optional extra: the racetracks hold
    segments with an onset and quiet ones, and the replay misses the lost samples' steps."""
    scenario = RecordedTracks()
    for size, (params, _) in RecordedTracks.perf_sizes.items():
        p = build_params(RecordedTracks.Params, {**params, **scenario.perf_data(size, tmp_path)})
        scenario.check_config(p)
        batch = generate(p, RecordedTracks.perf_snr_db, range(4))
        assert batch.scene.maneuver_mask[:, p.onset_step].all()
        valid = batch.scene.valid_steps
        assert (valid is None) == (p.measurements == "synthetic")
        if valid is not None:
            assert 0.9 < valid.mean() < 1.0
