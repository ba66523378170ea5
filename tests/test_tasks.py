"""Tasks: metrics of the tracking and TBD tasks, the task registry, multi-scenario sweeps."""

import numpy as np
import pandas as pd
import pytest

from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.errors import ConfigError
from radarbench.bench.metrics import per_step_rmse, time_averaged_rmse
from radarbench.bench.tasks.tbd.metrics import cell_centres_m, summarise_tbd, tbd_trial_metrics, unit_innovation_snr_offset_db
from radarbench.bench.tasks.tracking.metrics import summarise_tracking, tracking_trial_metrics

GRID = {"rows": 10, "cols": 10, "cell_m": 100.0, "x_min_m": 1000.0, "y_min_m": 2000.0}


def test_cell_centres_follow_the_grid_convention():
    assert np.allclose(cell_centres_m(np.array([[0, 0], [2, 5]]), GRID), [[1050, 2050], [1550, 2250]])


def test_tbd_detection_needs_the_threshold_and_two_hits_on_the_true_cells():
    truth_cells = np.array([[[1, 1], [2, 2], [3, 3], [4, 4]]] * 3)
    truth_xy = cell_centres_m(truth_cells, GRID)
    track = truth_cells.copy()
    track[1, :3] += 2                          # trial 1: one frame within tolerance only
    track[2, :, 1] += 1                        # trial 2: off by one column everywhere
    m = tbd_trial_metrics(np.array([5.0, 5.0, 5.0]), track, 4.0, target_cells=truth_cells, truth_xy_m=truth_xy,
                          grid=GRID, tolerance_cells=1)
    assert m["detected"].tolist() == [True, False, True]
    assert m["hits"].tolist() == [4, 1, 4]
    assert np.allclose(m["sq_err_m2"][2], 100.0 ** 2)
    assert np.allclose(m["rmse"], [0.0, np.sqrt(3 * 2 * 200.0 ** 2 / 4), 100.0])
    below = tbd_trial_metrics(np.array([3.9, 3.9, 3.9]), track, 4.0, target_cells=truth_cells,
                              truth_xy_m=truth_xy, grid=GRID, tolerance_cells=1)
    assert not below["detected"].any()


def test_time_averaged_rmse_is_the_mean_of_per_step_rmse():
    sq = np.array([[1.0, 4.0], [9.0, 16.0]])
    assert np.allclose(per_step_rmse(sq), [np.sqrt(5), np.sqrt(10)])
    assert time_averaged_rmse(sq) == pytest.approx((np.sqrt(5) + np.sqrt(10)) / 2)


def test_tbd_summary_has_the_rmse_over_detected_trials_and_over_all_runs():
    sq = np.array([[1.0, 4.0], [9.0, 16.0], [100.0, 400.0]])
    trials = pd.DataFrame({"scenario": "s", "method": "m", "config": "c", "params": "", "snr_db": 6.0,
                           "detected": [True, True, False], "threshold": 1.0, "realised_snr_db": np.nan})
    row = summarise_tbd(trials, {("s", "c", 6.0): {"sq_err_m2": sq}}).iloc[0]
    assert row.rmse_mean == pytest.approx((np.sqrt(5) + np.sqrt(10)) / 2)
    assert row.rmse_all_mean == pytest.approx((np.sqrt(110 / 3) + np.sqrt(420 / 3)) / 2)
    assert row.rmse_all_low <= row.rmse_all_mean <= row.rmse_all_high


def test_unit_innovation_snr_offset_matches_the_scenarios_innovation_scale():
    from radarbench.models.ar_noise import ar_autocovariance, ar_innovation_std
    a = (-2.0, 1.7, -0.64)
    gamma = ar_autocovariance(a, 7, 1.0)
    offset = unit_innovation_snr_offset_db(a, gamma)
    assert offset == pytest.approx(10 * np.log10(1 / ar_innovation_std(a) ** 2), abs=1e-9)
    assert offset == pytest.approx(12.67, abs=0.01)         # stationary variance ≈ 18.5 at σ_w = 1
    ar1 = (-0.5,)                                           # AR(1): γ(0) = σ_w² / (1 − 0.25)
    assert unit_innovation_snr_offset_db(ar1, ar_autocovariance(ar1, 3, 1.0)) == pytest.approx(
        10 * np.log10(1 / 0.75))
    assert unit_innovation_snr_offset_db(None, [1.0, 0.0]) == 0.0


def test_tracking_metrics_nees_and_divergence():
    rng = np.random.default_rng(1)
    n, k, d = 400, 30, 2
    cov = np.array([[4.0, 1.0], [1.0, 2.0]])
    err = rng.multivariate_normal(np.zeros(d), cov, size=(n, k))
    truth = rng.normal(size=(n, k, d))
    m = tracking_trial_metrics(truth + err, truth, position_index=(0,), labels=["x", "v"],
                               covariance=np.broadcast_to(cov, (n, k, d, d)), divergence_bound_m=6.0)
    # NEES of a consistent covariance ~ chi2(2): mean 2, sd of the grand mean sqrt(4 / (n k))
    assert abs(m["nees_mean"].mean() - 2.0) < 4.5 * np.sqrt(4.0 / (n * k))
    assert np.array_equal(m["diverged"], (np.abs(err[..., 0]) > 6.0).any(axis=1))
    assert np.allclose(m["sq_err_x"], err[..., 0] ** 2) and np.allclose(m["est_v"], truth[..., 1] + err[..., 1])
    trials = pd.DataFrame({"scenario": "s", "method": "m", "config": "m", "params": "", "snr_db": 0.0,
                           "diverged": m["diverged"], "nees_mean": m["nees_mean"], "realised_snr_db": 0.0})
    row = summarise_tracking(trials, {("s", "m", 0.0): m}).iloc[0]
    assert row.rmse_low <= row.rmse_mean <= row.rmse_high
    assert row.rmse_mean == pytest.approx(np.mean(np.sqrt((err[..., 0] ** 2).mean(axis=0))))


def _multi(**over):
    base = {"name": "multi", "trials": 10, "snr_db": [0, 5],
            "scenarios": [{"name": "cv-turn-cv"},
                          {"name": "cv-turn-cv", "params": {"steps": [120, 140]}, "snr_db": [1], "trials": 4}],
            "methods": [{"name": "innovation"}]}
    base.update(over)
    return base


def test_scenarios_tables_carry_their_own_snr_and_trials():
    plan = parse_sweep(_multi())
    assert [s.label for s in plan.scenarios] == ["cv-turn-cv", "cv-turn-cv[steps=120]", "cv-turn-cv[steps=140]"]
    assert plan.scenarios[0].snr_db == (0.0, 5.0) and plan.scenarios[0].trials == 10
    assert plan.scenarios[1].snr_db == (1.0,) and plan.scenarios[1].trials == 4
    assert plan.trial_runs == 10 * 2 + 2 * 4
    again = parse_sweep(plan.to_dict())
    assert again.fingerprint() == plan.fingerprint()


@pytest.mark.parametrize("over, field", [
    ({"scenario": "cv-turn-cv"}, "scenario"),
    ({"scenarios": []}, "scenarios"),
    ({"scenarios": [{"params": {}}]}, "scenarios[0].name"),
    ({"scenarios": [{"name": "cv-turn-cv", "bogus": 1}]}, "scenarios[0].bogus"),
    ({"scenarios": [{"name": "cv-turn-cv", "snr_db": "x"}]}, "scenarios[0].snr_db"),
    ({"scenarios": [{"name": "cv-turn-cv", "label": "../x"}]}, "scenarios[0].label"),
    ({"scenarios": [{"name": "cv-turn-cv", "label": "a"}, {"name": "cv-turn-cv", "label": "a"}]}, "scenarios"),
])
def test_bad_scenarios_tables_name_the_field(over, field):
    with pytest.raises(ConfigError) as exc:
        parse_sweep(_multi(**over))
    assert str(exc.value).startswith(f"{field}:"), str(exc.value)


# ------------------------------------------------------------------ the task registry

def test_builtin_tasks_are_registered_in_order():
    from radarbench.bench import registry
    assert list(registry.tasks())[:3] == ["maneuver-detection", "tracking", "tbd"]
    assert all(registry.get_task(name).name == name for name in registry.tasks())


def test_an_unknown_task_is_a_config_error_and_no_method_can_claim_it():
    from radarbench.bench import registry
    from radarbench.bench.core import Method
    with pytest.raises(ConfigError) as exc:
        registry.get_task("cfar", field="methods[0].task")
    assert str(exc.value).startswith("methods[0].task: unknown task 'cfar'")

    class Orphan(Method):
        name, task = "orphan", "cfar"

    with pytest.raises(TypeError, match="task 'cfar' is not one of"):
        registry.register_method(Orphan)


def _code_names_and_strings(path) -> set[str]:
    """Identifiers and string constants of a module's code, docstrings left out."""
    import ast
    tree = ast.parse(path.read_text())
    docs = {id(node.body[0].value) for node in ast.walk(tree)
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef)) and node.body
            and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            out.add(node.id)
        elif isinstance(node, ast.alias):
            out.add(node.asname or node.name)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            out.add(node.value)
    return out


def test_the_harness_never_names_a_task():
    """The report, the runner, the recording and the metrics loop over the tasks present."""
    import pathlib
    root = pathlib.Path(__file__).resolve().parents[1] / "bench"
    # every module of the harness but the tasks themselves and the protocol that names the built-ins
    files = [f for f in sorted(root.rglob("*.py"))
             if "tasks" not in f.relative_to(root).parts and f.relative_to(root) != pathlib.Path("core.py")]
    forbidden = {"MANEUVER_DETECTION", "TRACKING", "TBD", "maneuver-detection", "tracking", "tbd"}
    named = {str(f.relative_to(root)): sorted(_code_names_and_strings(f) & forbidden) for f in files}
    assert not any(named.values()), named


def _tracking_batch(scenario: str):
    from radarbench.bench import registry
    from radarbench.bench.params import build_params
    from radarbench.bench.sweep.rng import TrialRNG
    cls = registry.get_scenario(scenario)
    return cls().generate(build_params(cls.Params, cls.small_params), 10.0, 3, TrialRNG(1, 0, 1, range(3)))


@pytest.mark.parametrize("scenario", ["glint", "maneuvering-1d"])       # without and with a maneuver mask
def test_every_trace_a_tracker_returns_is_recorded(scenario):
    from radarbench.bench.core import TrackingOutput
    from radarbench.bench.registry import get_task
    task, batch = get_task("tracking"), _tracking_batch(scenario)
    gain = np.linspace(0, 1, batch.n * batch.steps).reshape(batch.n, batch.steps)
    out = task.check_output(TrackingOutput(estimate=batch.truth.copy(), traces={"gain": gain, "mode": gain}), batch)
    traces = task.recorded_method(batch, out, 1, np.nan).traces
    np.testing.assert_array_equal(traces["gain"], gain[1])
    np.testing.assert_array_equal(traces["mode"], gain[1])


@pytest.mark.parametrize("traces, words", [
    ({"gain": np.zeros(3)}, "traces['gain'] must be a real array of shape"),
    ({"gain": "high"}, "traces['gain'] must be a real array of shape"),
    ({"error_x": None}, "traces['error_x']: names starting with 'error_' or 'estimate_'"),
])
def test_a_trace_that_could_not_be_recorded_is_the_methods_failure(traces, words):
    from radarbench.bench.core import TrackingOutput
    from radarbench.bench.registry import get_task
    from radarbench.bench.tasks.base import OutputError
    task, batch = get_task("tracking"), _tracking_batch("glint")
    with pytest.raises(OutputError, match=words.replace("[", r"\[").replace("(", r"\(")):
        task.check_output(TrackingOutput(estimate=batch.truth.copy(), traces=traces), batch)
