"""Issue 30, points 3 and 4d: impossible outputs are a method's failure, parameters that
cannot work are refused up front, the documented bounds are the enforced ones, and
validation is bounded in time and memory.

Every refusal is met as in ``tests/test_reliability_validation.py``: exit code 2, one
line naming the field, nothing written.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import re
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from bench import registry
from bench.cli import main
from bench.core import TrackingOutput
from bench.errors import ConfigError
from bench.listing import plugin_listing
from bench.params import build_params
from bench.rng import TrialRNG
from bench.tasks.base import COVARIANCE_TOLERANCE, OutputError, check_covariance

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
    from bench.tasks.multitarget import MultiTargetOutput
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
    from bench.tasks.cells import CellDetectionOutput
    batch = _batch("rd-map", n=2)
    stat = np.zeros((2, *batch.scene.shape), np.float32)
    task = registry.get_task("cell-detection")
    task.check_output(CellDetectionOutput(stat), batch)
    stat[1, 3, 4] = -0.5
    with pytest.raises(OutputError, match=r"statistic has 1 values outside >= -1e-12 \(-log10 of a false-alarm "
                                          r"probability\), e.g. -0.5"):
        task.check_output(CellDetectionOutput(stat), batch)


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

from bench.core import TRACKING, Method, TrackingOutput


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
    proc = subprocess.run([sys.executable, "-m", "bench", "run", str(root / "sweep.toml"), "--out", str(root / "run"),
                           "--quiet", "--workers", "1"], env=env, capture_output=True, text=True,
                          timeout=300)
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


def test_the_report_of_a_run_whose_plugins_are_not_installed_names_them_and_the_store(impossible_run, tmp_path):
    """Was "methods[1].name: unknown method ..." naming no file (exit 2 all the same)."""
    import shutil
    import subprocess
    import sys
    run = tmp_path / "run"
    shutil.copytree(impossible_run[0], run)
    from tests.test_reliability_store import _tree
    before = _tree(run)
    proc = subprocess.run([sys.executable, "-m", "bench", "report", str(run)], capture_output=True, text=True,
                          timeout=300)                                # this environment lacks the plugin
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


# ------------------------------------------------------------------ documented bounds == enforced ones

#: ``bench list -v`` prints each bound as ``[>= 2 and <= 12: why]`` after the doc.
_BOUNDS = re.compile(r"\[((?:[<>]=? -?[\d.e+-]+)(?: and [<>]=? -?[\d.e+-]+)*)[:\]]")
_PARAM_LINE = re.compile(r"^      (\w+) \(([^,]+), default .*?\): (.*)$")


def listed_bounds() -> list[tuple[str, str, str, str, str, float]]:
    """(kind, plugin, field, type, operator, value) of every bound ``bench list -v`` prints."""
    rows, kind, plugin = [], None, None
    for line in plugin_listing(verbose=True).splitlines():
        if line in ("scenarios:", "methods:", "unavailable:", "tasks:"):
            kind = line[:-1]
            continue
        if kind in ("scenarios", "methods") and (m := re.match(r"^  (\S+)\s", line)):
            plugin = m.group(1)
        elif kind in ("scenarios", "methods") and (m := _PARAM_LINE.match(line)):
            found = _BOUNDS.findall(m.group(3))
            for part in (found[-1].split(" and ") if found else []):
                op, value = part.split(" ")
                rows.append((kind, plugin, m.group(1), m.group(2), op, value))
    return rows


#: The other values under which a bound holds where another field constrains it (a
#: cross-field check: the bound itself is reached, with these companions). Keyed by
#: (plugin, field, bound as printed).
COMPANIONS = {
    ("cv-turn-cv", "steps", "2"): {"onset_step": 1, "turn_steps": 1, "warmup_steps": 0, "detect_window_steps": 1},
    ("cv-turn-cv", "onset_step", "1"): {"warmup_steps": 0},
    ("cv-turn-cv", "onset_step", "9999"): {"steps": 10000, "turn_steps": 1, "detect_window_steps": 1},
    ("cv-turn-cv", "warmup_steps", "9998"): {"steps": 10000, "onset_step": 9999, "turn_steps": 1,
                                             "detect_window_steps": 1},
    **{("cv-turn-cv", f, v): {"steps": 10000, "onset_step": 1, "turn_steps": 1, "warmup_steps": 0,
                              "detect_window_steps": 1}
       for f, v in (("turn_steps", "9999"), ("detect_window_steps", "9999"), ("onset_jitter_steps", "9998"))},
    ("recorded-tracks", "steps", "5"): {"onset_step": 1, "warmup_steps": 0, "detect_window_steps": 1},
    ("recorded-tracks", "onset_step", "1"): {"warmup_steps": 0},
    ("recorded-tracks", "onset_step", "9999"): {"steps": 10000, "detect_window_steps": 1},
    ("recorded-tracks", "detect_window_steps", "9999"): {"steps": 10000, "onset_step": 1, "warmup_steps": 0},
    ("recorded-tracks", "warmup_steps", "9998"): {"steps": 10000, "onset_step": 9999, "detect_window_steps": 1},
    ("glint", "initial_range_m", "10.0"): {"initial_range_std_m": 1.0},
    ("glint", "initial_range_std_m", "100000.0"): {"initial_range_m": 1e6},
    ("glint", "process_noise_los_m_s2", "0.0"): {"process_noise_los_m_s2": (0.0, 0.0, 0.0)},
    ("glint", "process_noise_los_m_s2", "100.0"): {"process_noise_los_m_s2": (100.0, 100.0, 100.0)},
    ("glint", "initial_angle_std_rad", "1e-06"): {"initial_angle_std_rad": (1e-6, 1e-6)},
    ("glint", "initial_angle_std_rad", "0.1"): {"initial_angle_std_rad": (0.1, 0.1)},
    ("hfswr-targets", "targets", "1"): {"crossing": False},
    ("hfswr-targets", "crossing_targets", "100"): {"targets": 100},
    ("maneuvering-1d", "steps", "2"): {"dt_s": 100.0},
    ("maneuvering-1d", "dt_s", "0.001"): {"maneuver_start_s": 0.0},
    ("maneuvering-1d", "maneuver_start_s", "1000000.0"): {"profile": "singer"},
    **{("cusum", "window", v): {"score": "glr"} for v in ("1", "1000")},      # the GLR score's window
    ("recorded-tracks", "min_steps", "10000"): {"steps": 10000},             # at most steps
    ("ar-adaptive", "order_low", "5"): {"order_high": 6, "state_dim": 7},
    ("ar-adaptive", "order_high", "1"): {"order_low": 0},
    ("ar-adaptive", "order_high", "6"): {"state_dim": 7},
    ("current-statistical", "accel_std_floor_m_s2", "1000.0"): {"a_max_m_s2": 1000.0},
    ("imm-cv-ca", "transition", "0.0"): {"transition": (0.0, 1.0, 0.5, 0.5)},
    ("imm-cv-ca", "transition", "1.0"): {"transition": (0.0, 1.0, 0.5, 0.5)},
    ("imm-cv-ca", "initial_probabilities", "0.0"): {"initial_probabilities": (0.0, 1.0)},
    ("imm-cv-ca", "initial_probabilities", "1.0"): {"initial_probabilities": (1.0, 0.0)},
    ("innovation", "delta", "0.999"): {"window": 1},
    **{(m, f, v): c for m in ("gnn-ekf", "jpda-ukf", "stonesoup-jpda", "stonesoup-mfa") for f, v, c in (
        ("confirm_m", "20", {"confirm_n": 20}), ("confirm_n", "1", {"confirm_m": 1}),
        ("terminate_m", "60", {"terminate_n": 60}), ("terminate_n", "1", {"terminate_m": 1}))},
    **{(m, f, v): c for m in ("os-cfar", "region-adaptive") for f, v, c in (
        ("reference_range", "1", {"k_range": 1}), ("reference_doppler", "1", {"k_doppler": 1}),
        ("k_range", "512", {"reference_range": 256}), ("k_doppler", "512", {"reference_doppler": 256}))},
    ("wavelet", "levels", "1"): {"coarsest": 1},
    ("wavelet", "coarsest", "8"): {"levels": 8},
    ("tbd-grid", "cells", "8"): {"frames": 4, "cell_m": 1e5},
    ("tbd-grid", "frames", "2"): {"noise": "white"},
    ("tbd-grid", "frames", "1000"): {"cell_m": 1e5},
    ("tbd-grid", "frame_period_s", "100.0"): {"cell_m": 1e5},
    ("tbd-grid", "cell_m", "1.0"): {"frame_period_s": 1e-3},
    ("rd-map", "range_cells", "16"): {"interference_range_start": 0, "edge_range_cell": 8, "margin_cells": 0},
    ("rd-map", "doppler_cells", "16"): {"bragg_offset_bins": 4, "margin_cells": 0},
    ("rd-map", "bragg_offset_bins", "8191"): {"doppler_cells": 16384},
    ("rd-map", "interference_range_start", "4095"): {"range_cells": 4096, "interference_range_cells": 1},
    ("rd-map", "interference_range_cells", "4096"): {"range_cells": 4096, "interference_range_start": 0},
    ("rd-map", "edge_range_cell", "4095"): {"range_cells": 4096},
    ("rd-map", "margin_cells", "2047"): {"range_cells": 4096, "doppler_cells": 16384},
}


def _plugin(kind: str, name: str):
    return (registry.get_scenario if kind == "scenarios" else registry.get_method)(name)


def _number(tp: str, text: str):
    return int(text) if "int" in tp else float(text)


def _beyond(op: str, value, is_int: bool):
    """The nearest value on the wrong side of ``op value`` (``>``/``<``: the bound itself)."""
    if op in (">", "<"):
        return value
    if is_int:
        return value - 1 if op == ">=" else value + 1
    return math.nextafter(value, -math.inf if op == ">=" else math.inf)


def _with(cls, field: str, value, lower: bool, companions: dict):
    """``{field: value}`` with the companions; in a tuple field the value replaces the
    default's first element for a lower bound, its last for an upper one ([min, max] pairs)."""
    default = getattr(cls.Params(), field)
    if isinstance(default, tuple):
        value = (value,) if not default else (value, *default[1:]) if lower else (*default[:-1], value)
    return {field: value} | companions


@pytest.mark.parametrize("kind, plugin, field, tp, op, text", listed_bounds(),
                         ids=lambda x: str(x) if not isinstance(x, str) or len(x) < 30 else x[:30])
def test_every_listed_bound_is_the_enforced_one(kind, plugin, field, tp, op, text):
    """``bench list -v`` prints each bound; at it the value is accepted (with the
    companions a cross-field check needs, :data:`COMPANIONS`), just beyond it refused
    naming the field. state_dim = 2 of ar-adaptive was listed as allowed and refused."""
    cls = _plugin(kind, plugin)
    is_int = "int" in tp
    value = _number(tp, text)
    companions = COMPANIONS.get((plugin, field, text), {})
    if op in (">=", "<="):
        values = _with(cls, field, value, op == ">=", companions)
        try:
            build_params(cls.Params, values)
        except ConfigError as err:
            pytest.fail(f"{plugin}.{field} = {values[field]!r} (listed {op} {text}) refused: {err}")
    beyond = _beyond(op, value, is_int)
    values = _with(cls, field, beyond, op[0] == ">", {k: v for k, v in companions.items() if k != field})
    with pytest.raises(ConfigError) as err:
        build_params(cls.Params, values)
    assert err.value.field.split("[")[0] == field and "expected" in err.value.problem, err.value


def test_the_listing_holds_every_numeric_bound():
    """The parse above misses nothing: every declared ge/gt/le/lt appears in the listing."""
    listed = {(p, f, op) for _, p, f, _, op, _ in listed_bounds()}
    declared = set()
    for table in (registry.scenarios(), registry.methods()):
        for name, cls in table.items():
            for f in dataclasses.fields(cls.Params):
                for key, op in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")):
                    if f.metadata.get(key) is not None:
                        declared.add((name, f.name, op))
    assert declared == listed


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

def _old_place_targets(labels, names, *, per_region, pairs, pair_offset, spacing, margin, seed):
    """The straightforward layout search (a Python loop over every candidate, a distance
    test against every placed target): the oracle of :func:`models.rd_map.place_targets`."""
    def far_enough(cell, placed):
        return not placed or int(np.abs(np.asarray(placed) - cell).max(axis=1).min()) >= spacing
    R, D = labels.shape
    rng = np.random.default_rng(seed)
    inside = np.zeros(labels.shape, bool)
    inside[margin:R - margin, margin:D - margin] = True
    placed, paired, missing = [], [], []
    present = [k for k in range(len(names)) if np.any(labels == k)]
    for k in sorted(present, key=lambda k: int(np.count_nonzero(labels == k))):
        candidates = np.argwhere((labels == k) & inside)
        got = 0
        for cell in candidates[rng.permutation(len(candidates))]:
            if got == per_region:
                break
            if far_enough(cell, placed):
                placed.append(cell)
                paired.append(False)
                got += 1
        if got < per_region:
            missing.append(f"{per_region - got} of {per_region} targets in region {names[k]!r}")
    home, offset = names.index("homogeneous"), np.asarray(pair_offset, np.int64)
    candidates = np.argwhere((labels == home) & inside)
    got = 0
    for cell in candidates[rng.permutation(len(candidates))]:
        if got == pairs:
            break
        mate = cell + offset
        if not (margin <= mate[0] < R - margin and margin <= mate[1] < D - margin) or labels[tuple(mate)] != home:
            continue
        if far_enough(cell, placed) and far_enough(mate, placed):
            placed += [cell, mate]
            paired += [True, True]
            got += 1
    if got < pairs:
        missing.append(f"{pairs - got} of {pairs} pairs in region 'homogeneous'")
    return np.asarray(placed, np.int64).reshape(-1, 2), np.asarray(paired, bool), "; ".join(missing)


@pytest.mark.parametrize("chunks", [(4096, 1 << 20), (2, 8)], ids=["as-run", "tiny-chunks"])
def test_the_vectorised_layout_search_places_every_target_where_the_loop_did(chunks, monkeypatch):
    """The same cells, flags and shortfall as the loop it replaces, on random label maps
    (tiny chunks: the growth and the early stop on maps this small)."""
    import models.rd_map as rd
    monkeypatch.setattr(rd, "_SCAN_CHUNK", chunks[0])
    monkeypatch.setattr(rd, "_SCAN_CHUNK_MAX", chunks[1])
    names = ("homogeneous", "bragg", "interference", "clutter-edge")
    rng = np.random.default_rng(0)
    for case in range(150):
        R, D = (int(x) for x in rng.integers(16, 64, 2))
        labels = rng.integers(0, 4, (R, D)).astype(np.int8)
        if case % 3 == 0:
            labels[:] = 0
            labels[:R // 3] = 1
        offset = (int(rng.integers(-3, 4)), int(rng.integers(1, 4)))
        kw = dict(per_region=int(rng.integers(0, 6)), pairs=int(rng.integers(0, 5)), pair_offset=offset,
                  spacing=int(rng.integers(1, 40)), margin=int(rng.integers(0, 6)), seed=int(rng.integers(0, 100)))
        new, old = rd.place_targets(labels, names, **kw), _old_place_targets(labels, names, **kw)
        assert np.array_equal(new[0], old[0]) and np.array_equal(new[1], old[1]) and new[2] == old[2], (case, kw)


HUGE_MAP = {"range_cells": 4096, "doppler_cells": 16384, "targets_per_region": 64, "pairs": 32,
            "target_spacing_cells": 4096}


def test_a_huge_map_above_the_memory_limit_is_refused_before_any_layout_search(monkeypatch):
    """The issue's case ran > 420 s and reached 4.4 GB before the memory check: now the
    memory check comes first and the layout is never built."""
    import models.rd_map as rd
    from tests.test_reliability_validation import refused, sweep, toml

    def no_layout(*args, **kwargs):
        raise AssertionError("the layout was searched before the memory check")
    monkeypatch.setattr(rd, "background_power", no_layout)
    monkeypatch.setattr(rd, "place_targets", no_layout)
    import scenarios.rd_map as scenario
    monkeypatch.setattr(scenario, "background_power", no_layout)
    monkeypatch.setattr(scenario, "place_targets", no_layout)
    scenario.scene_layout.cache_clear()
    data = sweep(scenarios=[{"name": "rd-map", "params": HUGE_MAP}], methods=[{"name": "ca-cfar"}],
                 max_unit_memory_gb=2.0, chunk=1)
    del data["scenario"], data["scenario_params"]
    refused(toml(data), "scenarios[0].params: a unit of 1 trials of 'rd-map'", "max_unit_memory_gb = 2")


def test_a_large_map_without_room_is_refused_in_one_pass(tmp_path):
    """8 M cells whose targets cannot fit: the loop examined every candidate against every
    placed target (minutes); the refusal now comes from one pass. A hang guard, not a
    timing: 60 s is ten times what the pass takes on a loaded machine."""
    import signal
    from tests.test_reliability_validation import refused, sweep, toml

    def hung(*_):
        raise TimeoutError("the layout search still runs after 60 s")
    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(60)
    try:
        data = sweep(scenarios=[{"name": "rd-map", "params": HUGE_MAP | {"range_cells": 512}}],
                     methods=[{"name": "ca-cfar"}], chunk=1, trials=1)
        del data["scenario"], data["scenario_params"]
        refused(toml(data), "scenarios[0].params.targets_per_region: no room for every target: ",
                "32 of 32 pairs in region 'homogeneous'")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def test_the_memory_estimate_of_a_map_counts_its_layout():
    from models.rd_map import LAYOUT_BYTES_PER_CELL
    S = registry.get_scenario("rd-map")
    p = build_params(S.Params, HUGE_MAP)
    assert S().unit_memory_bytes(p, 2) == (48 + LAYOUT_BYTES_PER_CELL) * 4096 * 16384


# ======================================================================= 5: undefined and degenerate numbers

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
    from bench.markdown import fmt
    from bench.metrics import bootstrap_mean_ci, paired_difference
    from bench.report.render import _interval
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
    from bench.metrics import paired_difference
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
    from bench.report.glance import comparisons_frame, glance
    from bench.report.render import glance_markdown
    task = registry.get_task("tracking")
    trials = pd.DataFrame({"scenario": "glint", "config": ["ekf"] * 4 + ["viterbi"] * 4, "snr_db": 0.0,
                           "trial": list(range(4)) * 2, "rmse": [2.0, 3.0, 4.0, 5.0] * 2})
    task_of = {"ekf": task, "viterbi": task}
    text = glance_markdown(glance(trials, task_of, comparisons_frame(trials, task_of), {}))
    assert "**tie**: `ekf` and `viterbi` are equal on every trial." in text
    assert "-0" not in text


def test_a_tracker_estimate_of_1e308_is_a_failure_and_warns_nothing(impossible_run):
    """Was a NumPy overflow warning from the recording (and the metrics) on the terminal."""
    run, _ = impossible_run
    with contextlib.closing(sqlite3.connect(run / "results.sqlite")) as db:
        error = db.execute("SELECT error FROM runs WHERE method = 'huge-estimate'").fetchone()[0]
    assert "estimate has" in error and "outside [-1e+150, 1e+150]" in error
    assert "Warning" not in (run.parent / "stderr.txt").read_text()


def test_a_position_a_float32_cannot_hold_is_drawn_as_a_gap_without_a_warning():
    import warnings
    from bench.recording.draw import north_up
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        xy = north_up(np.array([[1.0, 2.0], [1e100, -3.0], [4.0, -1e40]]))
    assert xy.dtype == np.float32 and xy[0].tolist() == [1.0, -2.0]
    assert np.isnan(xy[1, 0]) and xy[1, 1] == 3.0 and np.isnan(xy[2, 1])


def _every_task_sweep(folder) -> str:
    """Every scenario at its small size, with every method that serves it: all the tasks'
    summary columns at once (the frame pandas warned about), a recorded trial; recorded-tracks
    on a CSV written into ``folder`` (its small instance reads an optional extra's sample)."""
    from bench import tomlw
    from tests.test_recorded_tracks import small_params_on_a_csv
    local = {"recorded-tracks": small_params_on_a_csv(folder)}
    scenarios = [{"name": name, "params": local.get(name, dict(cls.small_params))}
                 for name, cls in registry.scenarios().items()]
    methods = [{"name": name} for name, cls in registry.methods().items()
               if name in ("innovation", "ekf", "cv-kf", "dp-tbd", "ca-cfar", "os-cfar", "gnn-ekf")]
    return tomlw.dumps({"name": "every-task", "trials": 2, "seed": 3, "snr_db": [10.0], "chunk": 2,
                        "scenarios": scenarios, "methods": methods,
                        "calibration": {"pfa": 0.05, "mode": "empirical", "h0_trials": 10}, "record": {"trials": 1}})


def test_no_library_warning_reaches_the_terminal_on_a_normal_run(tmp_path):
    """Five pandas PerformanceWarning blocks came on every run and report (a summary frame
    fragmented into a block per column); Python's default filters, as a user has them."""
    import os
    import subprocess
    import sys
    (tmp_path / "sweep.toml").write_text(_every_task_sweep(tmp_path))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    proc = subprocess.run([sys.executable, "-m", "bench", "run", "sweep.toml", "--out", "run", "--workers", "1"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr                      # `bench report` builds the same way
    assert "Warning" not in proc.stderr and "warn" not in proc.stderr.lower(), proc.stderr
