"""Ragged batches (docs/architecture.md, 'Ragged batches'): trials of different
lengths and with gaps, padded to one time axis and masked by ``Scene.valid_steps``.

A tracker on a padded, masked batch gives each trial what it gives that trial
alone; the metrics ignore the padding; a method that does not handle masks is
refused on a ragged config, naming why; a run from outside the repository
(entry points on a temporary path) tracks and records a ragged scenario."""

import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from radarbench.bench import registry
from radarbench.bench.sweep.capabilities import VALID_STEP_MASKS, fits
from radarbench.bench.cli import main
from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.core import Batch
from radarbench.bench.errors import ConfigError
from radarbench.bench.metrics import per_step_rmse, time_averaged_rmse
from radarbench.bench.recording.record import MethodTrace, TrialRecord
from radarbench.bench.tasks.tracking import TrackingScene
from radarbench.bench.tasks.tracking.metrics import tracking_trial_metrics
from radarbench.methods.kinematic.kinematic_kf import ConstantVelocityKF
from radarbench.models.kalman import LinearGaussianModel, kalman_filter
from radarbench.models.kinematics import KinematicModel, position_index, state_labels
from tests.kinematic_plugin import install, load
from conftest import scaled

FIXED = settings(derandomize=True, deadline=None, max_examples=6, database=None)

registry.discover()
#: the built-in methods that handle ragged batches (found by capability, never by name)
MASKED = sorted(m for m, cls in registry.methods().items() if VALID_STEP_MASKS in cls.handles)


def _batch(z: np.ndarray, valid: np.ndarray | None, dims: int) -> Batch:
    """A kinematic tracking batch of measurements ``z`` (n, K, dims), NaN where not ``valid``."""
    n, K, _ = z.shape
    model = KinematicModel(dt_s=0.5, noise_std_m=3.0, dims=dims, x0=np.zeros(3 * dims),
                           P0=np.diag([1e4, 1e2, 10.0] * dims))
    scene = TrackingScene(model=model, state_labels=state_labels(dims), position_index=position_index(dims),
                          valid_steps=valid)
    return Batch(t=0.5 * np.arange(K), truth=np.zeros((n, K, 3 * dims)), z=z, scene=scene, trials=np.arange(n))


@st.composite
def ragged(draw):
    """(z, valid, dims): a few trials of random lengths with random gaps (step 0 always there)."""
    n, K, dims = draw(st.integers(1, 4)), draw(st.integers(12, 30)), draw(st.integers(1, 2))
    lengths = draw(st.lists(st.integers(1, K), min_size=n, max_size=n))
    gaps = np.array(draw(st.lists(st.booleans(), min_size=n * K, max_size=n * K))).reshape(n, K)
    valid = (np.arange(K)[None, :] < np.array(lengths)[:, None]) & ~(gaps & (np.arange(K) % 3 == 1))
    valid[:, 0] = True
    seed = draw(st.integers(0, 2 ** 31))
    t = 0.5 * np.arange(K)
    rng = np.random.default_rng(seed)
    # a turning target per trial, so the maneuver models have something to do
    pos = np.stack([100.0 * np.sin(0.1 * t + j) + 20.0 * t * (j + 1) for j in range(dims)], axis=-1)
    z = pos[None] + 3.0 * rng.standard_normal((n, K, dims))
    return np.where(valid[..., None], z, np.nan), valid, dims


@pytest.mark.parametrize("method", MASKED)
@FIXED
@given(case=ragged())
def test_a_padded_masked_batch_gives_each_trial_what_it_gets_alone(method, case):
    z, valid, dims = case
    cls = registry.get_method(method)
    assume(cls().check_scenario(cls.Params(), SimpleNamespace(dims=dims)) is None)   # e.g. a turn needs two axes
    out = cls().run(_batch(z, valid, dims), cls.Params())
    for i in range(len(z)):
        length = int(np.flatnonzero(valid[i])[-1]) + 1
        alone = cls().run(_batch(z[i:i + 1, :length], valid[i:i + 1, :length], dims), cls.Params())
        np.testing.assert_array_equal(out.estimate[i, :length], alone.estimate[0])
        np.testing.assert_array_equal(out.covariance[i, :length], alone.covariance[0])
        for name, trace in alone.traces.items():
            np.testing.assert_array_equal(out.traces[name][i, :length], trace[0], err_msg=name)
    assert np.isfinite(out.estimate).all() and np.isfinite(out.covariance).all()


@pytest.mark.parametrize("method", MASKED)
def test_a_mask_of_every_step_is_the_unmasked_filter(method):
    """The masked branches are the same filter: with every step valid they give the
    unmasked results (to rounding: another order of the same operations)."""
    dims, rng = 2, np.random.default_rng(4)
    t = 0.5 * np.arange(40)
    z = (np.stack([30.0 * t, 50.0 * np.sin(0.2 * t)], axis=-1)[None] + 3.0 * rng.standard_normal((3, 40, 2)))
    cls = registry.get_method(method)
    plain = cls().run(_batch(z, None, dims), cls.Params())
    masked = cls().run(_batch(z, np.ones(z.shape[:2], bool), dims), cls.Params())
    np.testing.assert_allclose(masked.estimate, plain.estimate, rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(masked.covariance, plain.covariance, rtol=1e-9, atol=1e-9)


def test_the_masked_kalman_filter_predicts_through_a_missing_step():
    """At a missing step the state and covariance are the prediction of the step
    before (x_k|k = F x_k-1|k-1, P_k|k = F P F' + Q), nu is NaN and the gain 0."""
    F, Q = np.array([[1.0, 1.0], [0.0, 1.0]]), 0.1 * np.eye(2)
    model = LinearGaussianModel(F=F, H=np.array([[1.0, 0.0]]), Q=Q, R=np.array([[4.0]]))
    z = np.array([[[0.0], [1.0], [np.nan], [3.2]]])
    valid = np.isfinite(z[..., 0])
    res = kalman_filter(model, z, np.zeros(2), 100.0 * np.eye(2), valid=valid)
    np.testing.assert_allclose(res.x_post[0, 2], F @ res.x_post[0, 1])
    np.testing.assert_allclose(res.P_post[0, 2], F @ res.P_post[0, 1] @ F.T + Q)
    assert np.isnan(res.nu[0, 2]).all() and not res.gain[0, 2].any()
    plain = kalman_filter(model, z[:, :2], np.zeros(2), 100.0 * np.eye(2))
    np.testing.assert_allclose(res.x_post[:, :2], plain.x_post, rtol=1e-12)


def test_padding_and_gaps_do_not_change_the_metrics():
    """A trial's RMSE, NEES, final error and divergence over its own steps, whatever the
    padding holds; per-step RMSE over the trials that have the step."""
    rng = np.random.default_rng(7)
    K, L = 30, 18
    est, truth = rng.normal(size=(1, L, 3)), rng.normal(size=(1, L, 3))
    cov = np.broadcast_to(np.eye(3), (1, L, 3, 3))
    kwargs = dict(position_index=(0,), labels=["x", "vx", "ax"], divergence_bound_m=2.5)
    alone = tracking_trial_metrics(est, truth, covariance=cov, **kwargs)
    pad = np.concatenate([est, 1e6 * rng.normal(size=(1, K - L, 3))], axis=1)
    pad_truth = np.concatenate([truth, np.full((1, K - L, 3), np.nan)], axis=1)
    valid = np.arange(K)[None, :] < L
    padded = tracking_trial_metrics(pad, pad_truth, covariance=np.broadcast_to(np.eye(3), (1, K, 3, 3)),
                                    valid=valid, **kwargs)
    for name in ("rmse", "final_error_m", "nees_mean", "diverged"):
        np.testing.assert_allclose(padded[name], alone[name], rtol=1e-12, err_msg=name)
    assert np.isnan(padded["sq_err_position"][0, L:]).all()
    gap = valid.copy()
    gap[0, 5] = False
    with_gap = tracking_trial_metrics(pad, pad_truth, covariance=None, valid=gap, **kwargs)
    kept = np.delete(np.arange(L), 5)
    np.testing.assert_allclose(with_gap["rmse"], np.sqrt(np.mean((est[0, kept, 0] - truth[0, kept, 0]) ** 2)))
    sq = np.array([[1.0, 4.0, np.nan], [9.0, np.nan, np.nan]])
    np.testing.assert_allclose(per_step_rmse(sq), [np.sqrt(5.0), 2.0, np.nan])
    assert time_averaged_rmse(sq) == pytest.approx((np.sqrt(5.0) + 2.0) / 2)


def test_a_record_keeps_the_steps_a_trial_has():
    keep = np.array([True, False, True, True])
    trace = MethodTrace(traces={"error_x": np.arange(4.0)}, arrays={"estimate_xy": np.ones((4, 2))})
    rec = TrialRecord("s", 0.0, 0, np.arange(4.0), truth_xy=np.zeros((4, 2)), methods={"m": trace},
                      arrays={"flags": np.array([1, 2, 3, 4])}).at_steps(keep)
    assert rec.steps == 3 and rec.t.tolist() == [0.0, 2.0, 3.0] and rec.arrays["flags"].tolist() == [1, 3, 4]
    assert rec.methods["m"].traces["error_x"].tolist() == [0.0, 2.0, 3.0]
    assert rec.methods["m"].arrays["estimate_xy"].shape == (3, 2)


class Unmasked(ConstantVelocityKF):
    """A kinematic tracker that does not declare it handles ragged batches."""

    name = "cv-kf-unmasked"
    handles = frozenset()


def _sweep(params: dict, method: str) -> dict:
    return {"name": "ragged", "trials": 4, "snr_db": [10], "scenarios": [{"name": "cv-replay", "params": params}],
            "methods": [{"name": method}]}


def test_a_method_that_does_not_handle_masks_is_refused_on_a_ragged_config(tmp_path, monkeypatch, capsys):
    cls = load(tmp_path)
    monkeypatch.setitem(registry._SCENARIOS, cls.name, cls)
    monkeypatch.setitem(registry._METHODS, Unmasked.name, Unmasked)
    ragged_params = {"steps": 30, "min_steps": 10}
    assert parse_sweep(_sweep({"steps": 30}, Unmasked.name), "t").methods[0].name == Unmasked.name
    with pytest.raises(ConfigError) as err:
        parse_sweep(_sweep(ragged_params, Unmasked.name), "t")
    assert err.value.field == "methods[0].name"
    assert "'cv-replay'" in str(err.value) and VALID_STEP_MASKS in str(err.value) and Unmasked.name in str(err.value)
    assert parse_sweep(_sweep(ragged_params, "cv-kf"), "t").methods[0].name == "cv-kf"
    sweep = tmp_path / "s.toml"
    sweep.write_text('name = "r"\ntrials = 2\nsnr_db = [0]\n[[scenarios]]\nname = "cv-replay"\n'
                     'params = {steps = 30, min_steps = 10}\n[[methods]]\nname = "ekf"\n')
    assert main(["run", str(sweep), "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "methods[0].name" in lines[0] and "'ekf' needs glint-model" in lines[0]
    assert not (tmp_path / "out").exists()
    assert fits(registry.get_method("cv-kf"), cls, cls.default_params())


RUN = """
name = "ragged"
trials = 6
chunk = 3
seed = 1
snr_db = [0, 10]
[[scenarios]]
name = "cv-replay"
params = {steps = 30, min_steps = 8, gap_probability = 0.15}
[[methods]]
name = "cv-kf"
[[methods]]
name = "imm-cv-ca"
[record]
trials = 1
"""


@pytest.mark.slow
def test_an_outside_ragged_scenario_runs_end_to_end(tmp_path):
    """Installed as a plugin (entry point on a temporary path): the built-in trackers run
    on it with no edit, every trial scored over its own steps."""
    env = install(tmp_path / "site")
    (tmp_path / "run.toml").write_text(RUN)
    run = subprocess.run([sys.executable, "-m", "radarbench.bench", "run", str(tmp_path / "run.toml"), "--out",
                          str(tmp_path / "out"), "--workers", "1", "--quiet"], env=env, capture_output=True,
                         text=True, timeout=scaled())
    assert run.returncode == 0, run.stderr
    summary = pd.read_csv(tmp_path / "out" / "summary.csv")
    assert len(summary) == 4 and np.isfinite(summary["rmse_mean"]).all()
    by = summary.set_index(["method", "snr_db"])["rmse_mean"]
    assert (by.xs(0.0, level="snr_db") > by.xs(10.0, level="snr_db")).all()      # more noise, more error
    assert "## Failures\n\nNone" in (tmp_path / "out" / "report.md").read_text()


def test_a_ragged_batch_from_an_undeclared_config_fails_the_methods_that_do_not_handle_it():
    """The run-time guard behind ``requires``: a method that does not handle masks never
    runs on NaN padding, whatever the scenario declared."""
    from radarbench.bench.sweep.capabilities import check_batch

    z = np.zeros((2, 5, 1))
    valid = np.ones((2, 5), bool)
    valid[1, 3:] = False
    check_batch(registry.get_method("cv-kf"), _batch(z, valid, 1))
    check_batch(Unmasked, _batch(z, None, 1))
    with pytest.raises(ValueError, match="cv-kf-unmasked.*valid-step-masks"):
        check_batch(Unmasked, _batch(z, valid, 1))


def test_a_ragged_config_no_method_of_the_sweep_handles_is_refused_naming_why(tmp_path, monkeypatch):
    cls = load(tmp_path)
    monkeypatch.setitem(registry._SCENARIOS, cls.name, cls)
    monkeypatch.setitem(registry._METHODS, Unmasked.name, Unmasked)
    data = _sweep({"steps": 30}, Unmasked.name)
    data["scenarios"].append({"name": "cv-replay", "label": "ragged", "params": {"steps": 30, "gap_probability": 0.1}})
    with pytest.raises(ConfigError) as err:
        parse_sweep(data, "t")
    assert err.value.field == "methods" and "'ragged'" in str(err.value) and VALID_STEP_MASKS in str(err.value)
