"""Impossible outputs are a method's failure, parameters that
cannot work are refused up front, undefined and degenerate numbers are said to be what they
are. The documented bounds and validation bounded in time and memory:
``tests/test_reliability_bounds.py``.

Every refusal is met as in ``tests/test_reliability_validation.py``: exit code 2, one
line naming the field, nothing written.
"""

from __future__ import annotations

import contextlib
import io
import math
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from radarbench.bench import registry
from radarbench.bench.cli import main
from radarbench.bench.core import TrackingOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.sweep.listing import plugin_listing
from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.tasks.base import COVARIANCE_TOLERANCE, OutputError, check_covariance
from conftest import scaled

registry.discover()


# ======================================================================= impossible outputs

def _batch(scenario: str, n: int = 3, snr_db: float | None = 10.0):
    S = registry.get_scenario(scenario)
    return S().generate(build_params(S.Params, S.small_params), snr_db, n, TrialRNG(1, 0, 1, range(n)))


def _tracking_output(batch, **over) -> TrackingOutput:
    n, K, d = batch.truth.shape
    out = TrackingOutput(estimate=batch.truth.copy(), covariance=np.broadcast_to(np.eye(d), (n, K, d, d)).copy(),
                         traces={"mode": np.zeros((n, K)), "switch": np.zeros((n, K)), "q_k": np.ones((n, K))})
    for name, value in over.items():
        if name in out.traces:
            out.traces[name] = value
        else:
            setattr(out, name, value)
    return out


def test_a_covariance_of_minus_100_identity_is_the_methods_failure():
    """The issue's case: NEES -3 was published; now the output is refused with its cause."""
    batch = _batch("glint")
    n, K, d = batch.truth.shape
    task = registry.get_task("tracking")
    task.check_output(_tracking_output(batch), batch)                  # the identity is a covariance
    with pytest.raises(OutputError, match=rf"covariance is not a covariance .* at {n * K} of {n * K} .*"
                                          r"smallest eigenvalue -100"):
        task.check_output(_tracking_output(batch, covariance=-100.0 * np.broadcast_to(np.eye(d), (n, K, d, d))),
                          batch)


@pytest.mark.parametrize("make, says", [
    (lambda P: P * np.r_[1.0, -1.0, 1.0, 1.0, 1.0, 1.0][:, None], "not a covariance"),        # asymmetric
    (lambda P: P - 2.0 * np.eye(6) * P[..., :1, :1], "smallest eigenvalue"),                  # indefinite
    (lambda P: np.where(np.eye(6, dtype=bool), -P, P), "smallest eigenvalue -"),               # negative variances
], ids=["asymmetric", "indefinite", "negative-variance"])
def test_covariances_that_are_not_symmetric_psd_are_refused_at_one_step(make, says):
    batch = _batch("glint")
    out = _tracking_output(batch)
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    out.covariance[1, 2] = make(A @ A.T + np.eye(6))
    with pytest.raises(OutputError, match=rf"{says}.*") as err:
        registry.get_task("tracking").check_output(out, batch)
    assert " at 1 of " in str(err.value)


def test_the_tolerance_is_relative_to_each_components_variance():
    """Components in metres and radians side by side: a covariance is judged at unit
    variances, so rounding at 1e-12 of either scale passes and 1e-5 does not."""
    scales = np.array([1e6, 1e-6])
    P = np.array([[1.0, 0.999], [0.999, 1.0]]) * np.outer(scales, scales)
    check_covariance("P", P[None])
    for off, ok in ((1e-12, True), (COVARIANCE_TOLERANCE / 2, True), (1e-5, False)):
        Q = P.copy()
        Q[0, 1] += off * scales[0] * scales[1]                     # asymmetric by `off` at unit variances
        if ok:
            check_covariance("P", Q[None])
        else:
            with pytest.raises(OutputError, match="largest asymmetry 1e-05"):
                check_covariance("P", Q[None])
    singular = np.array([[1.0, 1.0], [1.0, 1.0]]) - np.array([[0.0, 0.0], [0.0, COVARIANCE_TOLERANCE / 2]])
    check_covariance("P", singular[None])                           # PSD within the tolerance
    with pytest.raises(OutputError):
        check_covariance("P", (singular - np.diag([0.0, 4 * COVARIANCE_TOLERANCE]))[None])
    check_covariance("P", np.zeros((4, 3, 3)))                       # a zero covariance is PSD


@pytest.mark.parametrize("trace, value, says", [
    ("mode", 1.5, r"traces\['mode'\] has .* outside \[0, 1\]"),
    ("switch", -1.0, r"traces\['switch'\] has .* outside \[0, 1\]"),
    ("q_k", -1e-3, r"traces\['q_k'\] has .* outside >= 0"),
    ("mode", np.nan, r"traces\['mode'\] has 1 non-finite"),
])
def test_scored_traces_outside_their_range_are_refused(trace, value, says):
    batch = _batch("maneuvering-1d")
    out = _tracking_output(batch)
    out.traces[trace] = out.traces[trace].copy()
    out.traces[trace][0, 3] = value
    with pytest.raises(OutputError, match=says):
        registry.get_task("tracking").check_output(out, batch)


def test_a_multitarget_gate_covariance_must_be_a_covariance():
    from radarbench.bench.tasks.multitarget import MultiTargetOutput
    batch = _batch("hfswr-targets", n=2)
    n, K = batch.n, batch.steps
    state = np.full((n, K, 1, 4), np.nan)
    ids = np.full((n, K, 1), -1)
    status = np.zeros((n, K, 1), np.int8)
    state[:, 0, 0], ids[:, 0, 0], status[:, 0, 0] = 0.0, 0, 2
    cov = np.zeros((n, K, 1, 2, 2))
    cov[:, 0, 0] = np.eye(2)
    task = registry.get_task("multi-target")
    task.check_output(MultiTargetOutput(state, ids, status, cov), batch)
    cov[:, 5, 0] = -np.eye(2)                          # an empty slot: never looked at
    task.check_output(MultiTargetOutput(state, ids, status, cov), batch)
    cov[1, 0, 0] = [[1.0, 2.0], [2.0, 1.0]]
    with pytest.raises(OutputError, match="position_covariance is not a covariance .* at 1 of 2 occupied slots"):
        task.check_output(MultiTargetOutput(state, ids, status, cov), batch)


def test_a_cfar_significance_below_zero_is_an_impossible_probability():
    from radarbench.bench.tasks.cells import CellDetectionOutput
    batch = _batch("rd-map", n=2)
    stat = np.zeros((2, *batch.scene.shape), np.float32)
    task = registry.get_task("cell-detection")
    task.check_output(CellDetectionOutput(stat), batch)
    stat[1, 3, 4] = -0.5
    with pytest.raises(OutputError, match=r"statistic has 1 values outside >= -1e-12 \(-log10 of a false-alarm "
                                          r"probability\), e.g. -0.5"):
        task.check_output(CellDetectionOutput(stat), batch)


@pytest.mark.slow          # a statistical test at the default scene's size (about 25 s)
def test_the_adaptive_trackers_covariances_pass_at_the_default_scene():
    """The checks refuse nothing a built-in produces: conformance runs every method on its
    small instance through ``check_output``; here the adaptive trackers, whose covariances
    drift furthest from symmetric (~1e-11), on their default 100-step scene."""
    scenario = registry.get_scenario("maneuvering-1d")
    batch = scenario().generate(scenario.Params(), 0.0, 4, TrialRNG(2, 0, 1, range(4)))
    for name in ("ar-adaptive", "imm-cv-ca", "vd-filter", "current-statistical"):
        method = registry.get_method(name)
        registry.get_task("tracking").check_output(method().run(batch, method.Params()), batch)


IMPOSSIBLE_TRACKER = '''
import numpy as np
from dataclasses import dataclass

from radarbench.bench.core import TRACKING, Method, TrackingOutput


class NegativeCovariance(Method):
    """Returns the truth with covariance -100 I (an impossible output)."""

    name = "negative-covariance"
    task = TRACKING

    @dataclass(frozen=True)
    class Params:
        pass

    def run(self, batch, params):
        n, K, d = batch.truth.shape
        return TrackingOutput(estimate=batch.truth.copy(),
                              covariance=-100.0 * np.broadcast_to(np.eye(d), (n, K, d, d)))


class HugeEstimate(Method):
    """Estimates 1e308 everywhere: finite, so an output to score (and to draw), however wrong."""

    name = "huge-estimate"
    task = TRACKING

    @dataclass(frozen=True)
    class Params:
        pass

    def run(self, batch, params):
        return TrackingOutput(estimate=np.full(batch.truth.shape, 1e308))
'''


def install_plugin(site: Path, package: str, module: str, entry_points: str) -> dict:
    """A plugin distribution under ``site`` (what ``pip install`` leaves: a package and a
    ``.dist-info`` with its entry points); the environment that has it on PYTHONPATH."""
    import os
    (site / package).mkdir(parents=True)
    (site / package / "__init__.py").write_text(module)
    info = site / f"{package}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {package}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(entry_points)
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), *filter(None, [os.environ.get("PYTHONPATH")])])}


IMPOSSIBLE_SWEEP = """
name = "impossible"
scenario = "glint"
trials = 2
seed = 1
snr_db = [0]
chunk = 2
scenario_params = { steps = 20 }

[[methods]]
name = "ekf"

[[methods]]
name = "negative-covariance"

[[methods]]
name = "huge-estimate"

[record]
trials = 1
"""


@pytest.fixture(scope="module")
def impossible_run(tmp_path_factory):
    """A run of the EKF beside a plugin tracker whose covariance is -100 I; (folder, the
    environment with the plugin)."""
    import subprocess
    import sys
    root = tmp_path_factory.mktemp("impossible")
    env = install_plugin(root / "site", "impossible_plugin", IMPOSSIBLE_TRACKER,
                         "[bench.methods]\nnegative-covariance = impossible_plugin:NegativeCovariance\n"
                         "huge-estimate = impossible_plugin:HugeEstimate\n")
    (root / "sweep.toml").write_text(IMPOSSIBLE_SWEEP)
    proc = subprocess.run([sys.executable, "-m", "radarbench.bench", "run", str(root / "sweep.toml"), "--out", str(root / "run"),
                           "--quiet", "--workers", "1"], env=env, capture_output=True, text=True,
                          timeout=scaled())
    assert proc.returncode == 6, proc.stderr                      # failed units: exit 6
    (root / "stderr.txt").write_text(proc.stderr)
    return root / "run", env


def test_an_impossible_output_is_a_failure_in_the_run_never_a_published_nees(impossible_run):
    """In a run: the config is listed as failed with the cause and the method named; no
    NEES of it reaches summary.csv (NEES -3 was published)."""
    import pandas as pd
    run, _ = impossible_run
    with contextlib.closing(sqlite3.connect(run / "results.sqlite")) as db:
        errors = dict(db.execute("SELECT method, error FROM runs WHERE error IS NOT NULL").fetchall())
    assert set(errors) == {"negative-covariance", "huge-estimate"}
    assert "covariance is not a covariance" in errors["negative-covariance"]
    summary = pd.read_csv(run / "summary.csv")
    assert "negative-covariance" not in set(summary.config)
    assert (summary.nees_mean > 0).all()
    report = (run / "report.md").read_text()
    failures = report[report.index("## Failures"):]
    assert "negative-covariance" in failures and "covariance is not a covariance" in failures


@pytest.mark.slow          # an end-to-end CLI run (or fuzzing): CI runs it, the inner loop does not
def test_the_report_of_a_run_whose_plugins_are_not_installed_names_them_and_the_store(impossible_run, tmp_path):
    """Was "methods[1].name: unknown method ..." naming no file (exit 2 all the same)."""
    import shutil
    import subprocess
    import sys
    run = tmp_path / "run"
    shutil.copytree(impossible_run[0], run)
    from tests.test_reliability_store import _tree
    before = _tree(run)
    proc = subprocess.run([sys.executable, "-m", "radarbench.bench", "report", str(run)], capture_output=True, text=True,
                          timeout=scaled())                           # this environment lacks the plugin
    assert proc.returncode == 2 and len(proc.stderr.splitlines()) == 1, proc.stderr
    assert proc.stderr.startswith(f"error: {run / 'results.sqlite'}: the run was made with plugins not installed "
                                  "here: method 'negative-covariance', method 'huge-estimate'; install them")
    assert _tree(run) == before


# ======================================================================= parameters that cannot work

@pytest.mark.parametrize("transition, prior, says", [
    ((1, 0, 0, 1), (1, 0), "mode CA is never reached from the initial probabilities"),
    ((0.5, 0.5, 0, 1), (1, 0), "mode CV is never reached again once in mode CA"),
    ((1, 0, 0, 1), (0.5, 0.5), "mode CA is never reached again once in mode CV"),
    ((0.9, 0.1, 0, 1), (0.5, 0.5), "mode CV is never reached again once in mode CA"),
    ((0.9, 0.2, 0.1, 0.9), (0.5, 0.5), "each row must sum to 1"),
], ids=["identity", "absorbing-ca", "identity-even-prior", "absorbing", "not-stochastic"])
def test_imm_transitions_that_cannot_work_are_refused_up_front(transition, prior, says):
    from tests.test_reliability_validation import refused, sweep, toml
    data = sweep(scenarios=[{"name": "maneuvering-1d", "params": {"steps": 60}}],
                 methods=[{"name": "imm-cv-ca", "params": {"transition": list(transition),
                                                            "initial_probabilities": list(prior)}}])
    del data["scenario"], data["scenario_params"]
    refused(toml(data), "methods[0].params.transition: ", says)


@pytest.mark.parametrize("transition, prior", [((0.95, 0.05, 0.05, 0.95), (0.9, 0.1)), ((0, 1, 1, 0), (0.5, 0.5)),
                                               ((0.5, 0.5, 1, 0), (1, 0))])
def test_imm_transitions_accepted_run_to_finite_estimates(transition, prior):
    """Every accepted chain is irreducible: the absorbing ones gave 1149 NaN of 1200 values."""
    method = registry.get_method("imm-cv-ca")
    batch = _batch("maneuvering-1d", n=8)
    out = method().run(batch, build_params(method.Params, {"transition": transition,
                                                           "initial_probabilities": prior}))
    registry.get_task("tracking").check_output(out, batch)


def test_ar_adaptive_state_dim_three_runs_and_two_is_refused_as_listed():
    cls = registry.get_method("ar-adaptive")
    assert "state_dim (int, default 4): state dimension M: the number of lagged positions [>= 3 and <= 12" \
        in plugin_listing(verbose=True)
    batch = _batch("maneuvering-1d")
    out = cls().run(batch, build_params(cls.Params, {"state_dim": 3}))
    registry.get_task("tracking").check_output(out, batch)
    with pytest.raises(ConfigError, match="state_dim: expected int >= 3, got 2"):
        build_params(cls.Params, {"state_dim": 2, "order_high": 1, "order_low": 0})


# ======================================================================= 4d: validation bounded



NO_TARGETS = """
name = "no-targets"
scenario = "rd-map"
trials = 4
seed = 1
snr_db = [10]
chunk = 4

[scenario_params]
range_cells = 48
doppler_cells = 96
bragg_offset_bins = 14
interference_range_start = 16
interference_range_cells = 8
interference_doppler_bins = 20.0
edge_range_cell = 34
edge_band_cells = 4
targets_per_region = 0
pairs = 0

[[methods]]
name = "ca-cfar"

[[methods]]
name = "region-adaptive"

[calibration]
pfa = 0.01
mode = "nominal"
h0_trials = 10

[record]
trials = 0
"""


def _run(tmp_path: Path, text: str, *extra: str) -> tuple[Path, str]:
    (tmp_path / "sweep.toml").write_text(text)
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(["run", str(tmp_path / "sweep.toml"), "--out", str(tmp_path / "run"), "--quiet", "--workers", "1",
                     *extra])
    assert code == 0, err.getvalue()
    return tmp_path / "run", err.getvalue()


def test_pd_on_a_map_without_targets_is_said_to_be_undefined_never_ranked(tmp_path):
    """Was: ranks 1 and 2 and "tie: ca-cfar leads region-adaptive by – [–, –]"."""
    run, _ = _run(tmp_path, NO_TARGETS, "--no-record")
    report = (run / "report.md").read_text()
    glance = report[report.index("## Results at a glance"):report.index("## What was run")]
    assert "not defined on this scene (no targets): no config is ranked." in glance
    assert "**tie**:" not in glance and "leads" not in glance and "| 1 " not in glance
    assert "– [–, –]" not in report
    assert "which detector wins where" not in report
    pairs = report[report.index("## Paired comparisons"):]
    assert "| not defined |" in pairs and "| **tie** |" not in pairs.split("##")[1]


def test_a_collapsed_interval_and_a_negative_zero_are_printed_as_what_they_are():
    from radarbench.bench.markdown import fmt
    from radarbench.bench.metrics import bootstrap_mean_ci, paired_difference
    from radarbench.bench.report.render import _interval
    assert fmt(-0.0) == "0" and fmt(0.0) == "0" and fmt(-1e-20) == "-1.00e-20"
    equal = bootstrap_mean_ci(np.full(6, 1 / 6), np.zeros(6))
    assert _interval(*equal) == "all trials equal: 0.167"                   # was 0.167 [0.167, 0.167]
    same = paired_difference(np.ones(6), np.ones(6), np.zeros(6))
    assert same == (0.0, 0.0, 0.0) and _interval(*(-x for x in same), signed=True) == "0 on every trial"
    assert _interval(0.1, 0.1, 0.1, signed=True) == "+0.1 on every trial"
    assert _interval(np.nan, np.nan, np.nan) == "–"


def test_float_noise_in_a_paired_difference_is_zero_not_a_significant_margin():
    """Means of means of 0/1 differences over three levels: 9.25e-18 where the exact value
    is 0 (the issue's [-0.1, 5.55e-18]: an end above 0 by float noise reads as a gain)."""
    from radarbench.bench.metrics import paired_difference
    a = np.array([0, 1, 0, 1, 0, 0, 0, 0, 1, 1, 0, 1, 1, 1, 1, 1, 0, 0], float)
    b = np.array([1, 0, 1, 1, 1, 1, 0, 0, 0, 0, 1, 0, 1, 0, 0, 1, 1, 0], float)
    strata = np.repeat(np.arange(3), 6)
    assert (b - a)[strata == 0].sum() + (b - a)[strata == 1].sum() + (b - a)[strata == 2].sum() == 0
    mean, low, high = paired_difference(a, b, strata)
    assert mean == 0.0 and not math.copysign(1.0, mean) < 0
    assert low < 0 < high


def test_the_glance_of_configs_equal_on_every_trial_is_a_tie_said_plainly():
    """Was "ekf leads … by -0 [-0, -0]"."""
    import pandas as pd
    from radarbench.bench.report.glance import comparisons_frame, glance
    from radarbench.bench.report.render import glance_markdown
    task = registry.get_task("tracking")
    trials = pd.DataFrame({"scenario": "glint", "config": ["ekf"] * 4 + ["viterbi"] * 4, "snr_db": 0.0,
                           "trial": list(range(4)) * 2, "rmse": [2.0, 3.0, 4.0, 5.0] * 2})
    task_of = {"ekf": task, "viterbi": task}
    text = glance_markdown(glance(trials, task_of, comparisons_frame(trials, task_of), {}))
    assert "**tie**: `ekf` and `viterbi` are equal on every trial." in text
    assert "-0" not in text


def _glance_of(rmse_a: np.ndarray, rmse_b: np.ndarray) -> tuple[str, "pd.DataFrame"]:
    import pandas as pd
    from radarbench.bench.report.glance import comparisons_frame, glance
    from radarbench.bench.report.render import glance_markdown
    task = registry.get_task("tracking")
    n = len(rmse_a)
    trials = pd.DataFrame({"scenario": "maneuvering-1d", "config": ["imm"] * n + ["filterpy-imm"] * n,
                           "snr_db": np.repeat([0.0, 10.0], n // 2).tolist() * 2, "trial": list(range(n)) * 2,
                           "rmse": np.concatenate([rmse_a, rmse_b])})
    task_of = {"imm": task, "filterpy-imm": task}
    comparisons = comparisons_frame(trials, task_of)
    return glance_markdown(glance(trials, task_of, comparisons, {})), comparisons


def test_two_implementations_equal_but_for_rounding_are_a_tie():
    """Was "winner `filterpy-imm`, by -6.06e-13 m": the same IMM twice, differing by rounding."""
    rmse = np.linspace(8.0, 14.0, 20)
    text, comparisons = _glance_of(rmse, rmse - 6.06e-13)
    assert "**tie**: `filterpy-imm` and `imm` are equal on every trial." in text and "winner **" not in text
    assert (comparisons.better == "tie").all() and (comparisons.difference == 0).all()
    assert "within a relative 1e-9 of each other count as equal" in text
    # a difference above the resolution, on every trial, still ranks
    text, comparisons = _glance_of(rmse, rmse * (1 - 1e-6))
    assert "winner **`filterpy-imm`**" in text and (comparisons.better == "filterpy-imm").all()


def test_a_tracker_estimate_of_1e308_is_a_failure_and_warns_nothing(impossible_run):
    """Was a NumPy overflow warning from the recording (and the metrics) on the terminal."""
    run, _ = impossible_run
    with contextlib.closing(sqlite3.connect(run / "results.sqlite")) as db:
        error = db.execute("SELECT error FROM runs WHERE method = 'huge-estimate'").fetchone()[0]
    assert "estimate has" in error and "outside [-1e+150, 1e+150]" in error
    assert "Warning" not in (run.parent / "stderr.txt").read_text()


def test_a_position_a_float32_cannot_hold_is_drawn_as_a_gap_without_a_warning():
    import warnings
    from radarbench.bench.recording.draw import north_up
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        xy = north_up(np.array([[1.0, 2.0], [1e100, -3.0], [4.0, -1e40]]))
    assert xy.dtype == np.float32 and xy[0].tolist() == [1.0, -2.0]
    assert np.isnan(xy[1, 0]) and xy[1, 1] == 3.0 and np.isnan(xy[2, 1])


def _every_task_sweep(folder) -> str:
    """Every scenario at its small size, with every method that serves it: all the tasks'
    summary columns at once (the frame pandas warned about), a recorded trial; recorded-tracks
    on a CSV written into ``folder`` (its small instance reads an optional extra's sample)."""
    from radarbench.bench.sweep import tomlw
    from tests.test_recorded_tracks import small_params_on_a_csv
    local = {"recorded-tracks": small_params_on_a_csv(folder)}
    scenarios = [{"name": name, "params": local.get(name, dict(cls.small_params))}
                 for name, cls in registry.scenarios().items()]
    methods = [{"name": name} for name, cls in registry.methods().items()
               if name in ("innovation", "ekf", "cv-kf", "dp-tbd", "ca-cfar", "os-cfar", "gnn-ekf", "cfar-track")]
    return tomlw.dumps({"name": "every-task", "trials": 2, "seed": 3, "snr_db": [10.0], "chunk": 2,
                        "scenarios": scenarios, "methods": methods,
                        "calibration": {"pfa": 0.05, "mode": "empirical", "h0_trials": 10}, "record": {"trials": 1}})


@pytest.mark.slow
def test_no_library_warning_reaches_the_terminal_on_a_normal_run(tmp_path):
    """Five pandas PerformanceWarning blocks came on every run and report (a summary frame
    fragmented into a block per column); Python's default filters, as a user has them."""
    import os
    import subprocess
    import sys
    (tmp_path / "sweep.toml").write_text(_every_task_sweep(tmp_path))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    proc = subprocess.run([sys.executable, "-m", "radarbench.bench", "run", "sweep.toml", "--out", "run", "--workers", "1"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=scaled())
    assert proc.returncode == 0, proc.stderr                      # `bench report` builds the same way
    assert "Warning" not in proc.stderr and "warn" not in proc.stderr.lower(), proc.stderr
