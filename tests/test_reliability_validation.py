"""Validation that covers what runs, numbers that stay true.

Every refusal is checked the way a user meets it: ``bench run`` (the CLI's
``main`` in-process, a fresh folder) ends with exit code 2, exactly one line
``error: FILE: FIELD: problem`` on stderr and nothing written at all.
Parameters at their bounds and beyond are fuzzed in
``tests/property/test_hostile_input.py``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
import re
import tempfile
import tomllib
import typing
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from radarbench.bench import registry
from radarbench.bench.sweep import tomlw
from radarbench.bench.cli import main
from radarbench.bench.sweep.config import MIN_PFA, SNR_KEY_DIGITS, parse_sweep, parse_sweep_text, snr_key
from radarbench.bench.errors import ConfigError
from radarbench.bench.sweep.feasibility import default_unit_memory_gb, unit_memory_bytes
from radarbench.bench.params import build_params, field_types
from radarbench.bench.sweep.rng import TrialRNG

registry.discover()

BASE = {
    "name": "rv",
    "scenario": "cv-turn-cv",
    "trials": 2,
    "seed": 3,
    "snr_db": [0, 5],
    "chunk": 2,
    "scenario_params": {"steps": 120, "onset_step": 60},
    "methods": [{"name": "innovation", "params": {"window": 5}}],
    "calibration": {"pfa": 0.05, "mode": "empirical", "h0_trials": 10},
    "record": {"trials": 0},
}


def sweep(**over) -> dict:
    data = json.loads(json.dumps(BASE))
    data.update(over)
    return data


def _tree(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def run_cli(text: str, *extra: str) -> tuple[int, str, str, set[str]]:
    """``bench run sweep.toml --out out`` in a fresh folder: (code, stdout, stderr, files written)."""
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "sweep.toml").write_text(text, encoding="utf-8")
        out, err = io.StringIO(), io.StringIO()
        argv = ["run", str(root / "sweep.toml"), "--out", str(root / "out"), "--quiet", "--workers", "1",
                "--no-record", *extra]
        with contextlib.chdir(root), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
        return code, out.getvalue(), err.getvalue(), _tree(root) - {"sweep.toml"}


def refused(text: str, *fields: str) -> str:
    """Assert ``bench run`` refuses the sweep with one line naming ``fields``; the line."""
    code, out, err, written = run_cli(text)
    lines = err.splitlines()
    assert code == 2, err
    assert len(lines) == 1 and re.match(r"error: \S*sweep\.toml: ", lines[0]), err
    assert "Traceback" not in err and out == "" and not written, (err, written)
    for field in fields:
        assert field in lines[0], (field, lines[0])
    return lines[0]


def toml(data: dict) -> str:
    return tomlw.dumps(data)


# ======================================================================= cause 6: bounds

def _numeric_fields():
    for kind, table in (("method", registry.methods()), ("scenario", registry.scenarios())):
        for name, cls in table.items():
            types = field_types(cls.Params)
            for f in dataclasses.fields(cls.Params):
                tp = types[f.name]
                elem = typing.get_args(tp)[0] if typing.get_origin(tp) is tuple else tp
                if elem in (int, float):
                    yield kind, name, f


@pytest.mark.parametrize("kind, name, field", [pytest.param(k, n, f, id=f"{n}.{f.name}")
                                               for k, n, f in _numeric_fields()])
def test_every_number_is_bounded_on_both_sides_with_a_reason(kind, name, field):
    meta = field.metadata
    assert meta.get("ge") is not None or meta.get("gt") is not None, "no lower bound"
    assert meta.get("le") is not None or meta.get("lt") is not None, "no upper bound"
    assert meta.get("why"), "the bounds carry no documented reason (param(..., why=...))"


def test_bounds_are_metadata_and_never_change_the_resolved_params():
    """The random stream of a scenario config hashes its resolved params: bounds add no field."""
    from radarbench.bench.params import params_as_dict
    for cls in [*registry.methods().values(), *registry.scenarios().values()]:
        names = [f.name for f in dataclasses.fields(cls.Params)]
        assert list(params_as_dict(cls.Params())) == names


@pytest.mark.parametrize("where, value, field", [
    ("method", {"name": "innovation", "params": {"delta": 10 ** 400}}, "methods[0].params.delta"),
    ("method", {"name": "innovation", "params": {"window": 10 ** 400}}, "methods[0].params.window"),
    ("method", {"name": "innovation", "params": {"window": -10 ** 400}}, "methods[0].params.window"),
    ("method", {"name": "viterbi", "params": {"quantisation_steps": [1e-3, 10 ** 400, 1e-3]}},
     "methods[0].params.quantisation_steps[1]"),
    ("snr", [0, 10 ** 400], "snr_db[1]"),
    ("snr", {"start": 0, "stop": 10 ** 400, "step": 1}, "snr_db.stop"),
    ("pfa", 10 ** 400, "calibration.pfa"),
    ("memory", 10 ** 400, "max_unit_memory_gb"),
], ids=["float-param", "int-param", "negative-int", "tuple-element", "snr", "snr-range", "pfa", "memory"])
def test_huge_integers_are_one_line_never_an_overflow(where, value, field):
    data = sweep()
    if where == "method":
        data["scenarios"] = [{"name": "glint" if value["name"] == "viterbi" else "cv-turn-cv",
                              "params": {"steps": 120} | ({} if value["name"] == "viterbi" else {"onset_step": 60})}]
        del data["scenario"], data["scenario_params"]
        data["methods"] = [value]
    elif where == "snr":
        data["snr_db"] = value
    elif where == "pfa":
        data["calibration"]["pfa"] = value
    else:
        data["max_unit_memory_gb"] = value
    line = refused(toml(data), field)
    assert "OverflowError" not in line and len(line) < 400


def test_an_integer_too_long_for_python_to_convert_is_invalid_toml():
    """tomllib raises a bare ValueError past 4300 digits; it is one line too."""
    refused(toml(sweep()) + "extra = " + "9" * 5000 + "\n", "invalid TOML", "4300 digits")


@pytest.mark.parametrize("method, params, field", [
    ("cumulant", {"window": 10 ** 30}, "window"),
    ("innovation", {"window": 10 ** 30}, "window"),
    ("innovation", {"window": 1, "delta": 0.9999999999999999}, "delta"),
    ("viterbi", {"sweeps": 10 ** 12}, "sweeps"),
    ("viterbi", {"gate_sigmas": 1e-300}, "gate_sigmas"),
    ("dp-tbd", {"max_speed_m_s": 1e300}, "max_speed_m_s"),
], ids=lambda x: str(x)[:30])
def test_the_issue_examples_of_unbounded_method_parameters_are_refused(method, params, field):
    task = registry.get_method(method).task
    scenario = next(s for s in registry.scenarios().values() if task in s.tasks)
    data = sweep(scenarios=[{"name": scenario.name, "params": dict(scenario.small_params)}],
                 methods=[{"name": method, "params": params}])
    del data["scenario"], data["scenario_params"]
    refused(toml(data), f"methods[0].params.{field}: expected")


@pytest.mark.parametrize("params, field", [
    ({"sigma_range_m": 1e-300}, "sigma_range_m"),
    ({"sigma_bearing_rad": 1e-300}, "sigma_bearing_rad"),
    ({"eta_range_m": 1e300}, "eta_range_m"),
    ({"eta_bearing_rad": 1e300}, "eta_bearing_rad"),
    ({"steps": 10 ** 30}, "steps"),
], ids=lambda x: str(x)[:30])
def test_the_issue_examples_of_unbounded_scenario_parameters_are_refused(params, field):
    data = sweep(scenarios=[{"name": "glint", "params": {"steps": 60} | params}], methods=[{"name": "ekf"}])
    del data["scenario"], data["scenario_params"]
    refused(toml(data), f"scenarios[0].params.{field}: expected")


# ------------------------------------------------------------------ method x scenario, after expansion

@pytest.mark.parametrize("methods, scenario_params, says", [
    ([{"name": "cumulant", "params": {"window": [16, 64]}}], {"steps": 50, "onset_step": 20,
                                                               "turn_steps": 10, "detect_window_steps": 20},
     "'cumulant[window=64]' cannot run on scenario config 'cv-turn-cv': the window of 64 steps"),
    ([{"name": "innovation", "params": {"window": 200}}], {}, "'innovation[window=200]'"),
    ([{"name": "innovation", "params": {"window": 1, "delta": 0.99}}], {},
     "the fading-memory statistic (delta = 0.99) first forms at step 458"),
    ([{"name": "wavelet", "params": {"levels": 8}}], {}, "level 8 of 'haar' (decimated) first forms at step 255"),
], ids=["cumulant-grid", "innovation", "fading", "wavelet"])
def test_a_method_that_cannot_run_on_a_scenario_config_is_refused_naming_both(methods, scenario_params, says):
    data = sweep(methods=methods, scenario_params=scenario_params)
    line = refused(toml(data), "methods[0].params: ", says)
    assert "160 steps" in line or "50 steps" in line


def test_the_pair_check_runs_after_the_scenario_grid_expands():
    """window = 64 is formed (step 63) before the onset of the grid's onset-80 config but
    not of its onset-20 one: that pair is skipped, with the reason; a window formed on the
    step before the onset runs."""
    grid = {"steps": 160, "onset_step": [80, 20], "turn_steps": 10, "detect_window_steps": 20}
    data = sweep(scenario_params=grid, methods=[{"name": "cumulant", "params": {"window": 64}},
                                                {"name": "innovation", "params": {"window": 5}}])
    plan = parse_sweep(data)
    late, early = plan.scenarios
    assert [(s, m) for s, m, _ in plan.skipped] == [(early.label, "cumulant[window=64]")]
    assert "formed from step 63 (valid_from), not before the maneuver onset at step 20" in plan.skipped[0][2]
    assert [m.label for m in plan.pairs(late)] == ["cumulant[window=64]", "innovation[window=5]"]
    assert [m.label for m in plan.pairs(early)] == ["innovation[window=5]"]
    assert plan.trial_runs == 2 * 2 * (2 + 1)
    data["scenario_params"]["onset_step"] = [80, 64]
    assert parse_sweep(data).skipped == ()
    data["scenario_params"]["onset_step"] = [64, 20]
    data["methods"] = [{"name": "cumulant", "params": {"window": 64}}]
    refused(toml(data), "no method of the sweep runs on scenario config 'cv-turn-cv[onset_step=20]'")


def test_a_skipped_pair_has_no_units_or_rows_and_is_listed():
    """A run with a skipped pair: one stderr line per pair (unless --quiet), no trials.csv
    rows for it, and the report's 'What was run' section names it with the reason."""
    grid = {"steps": 80, "onset_step": [45, 15], "turn_steps": 5, "detect_window_steps": 10}
    data = sweep(scenario_params=grid, methods=[{"name": "cumulant", "params": {"window": 40}},
                                                {"name": "innovation", "params": {"window": 5}}])
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "sweep.toml").write_text(toml(data), encoding="utf-8")
        err = io.StringIO()
        with contextlib.chdir(root), contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            code = main(["run", "sweep.toml", "--out", "out", "--workers", "1", "--no-record"])
        assert code == 0, err.getvalue()
        assert "cumulant[window=40] on cv-turn-cv[onset_step=15]: its statistic is formed from step 39" \
            in err.getvalue()
        trials = pd.read_csv(root / "out" / "trials.csv")
        pairs = set(zip(trials.scenario, trials.config))
        assert ("cv-turn-cv[onset_step=15]", "cumulant[window=40]") not in pairs
        assert {("cv-turn-cv[onset_step=45]", "cumulant[window=40]"),
                ("cv-turn-cv[onset_step=15]", "innovation[window=5]")} <= pairs
        report = (root / "out" / "report.md").read_text(encoding="utf-8")
        assert "| `cv-turn-cv[onset_step=15]` | `cumulant[window=40]` | its statistic is formed from step 39" \
            in report
        assert "None: every method config ran on every unit." in report


@pytest.mark.parametrize("method, scenario_params, says", [
    ({"name": "dp-tbd", "params": {"max_speed_m_s": 600.0}}, {"cells": 32, "frames": 8},
     "window radius of 6 cells"),
    ({"name": "dp-tbd-mf"}, {"cells": 400, "frames": 8, "cell_m": 20.0}, "window radius of 8 cells"),
    ({"name": "dp-tbd-mf"}, {"cells": 32, "frames": 2, "ar_coefficients": [-0.99]},
     "is singular or not a covariance"),
], ids=["dp-tbd-speed", "dp-tbd-mf-cells", "dp-tbd-mf-two-frames"])
def test_tbd_constraints_across_method_and_scenario_are_refused(method, scenario_params, says):
    data = sweep(scenarios=[{"name": "tbd-grid", "params": scenario_params}], methods=[method])
    del data["scenario"], data["scenario_params"]
    refused(toml(data), "methods[0].params: ", says)


def test_ar_noise_needs_more_frames_than_its_order():
    """The TBD task's noise power reads the autocovariance to lag P: with fewer frames every unit failed."""
    data = sweep(scenarios=[{"name": "tbd-grid", "params": {"cells": 32, "frames": 3}}], methods=[{"name": "dp-tbd"}])
    del data["scenario"], data["scenario_params"]
    refused(toml(data), "scenarios[0].params.frames: AR(3) noise needs more frames than its order")


def test_glint_snr_levels_keep_the_noise_above_its_floor():
    """+200 dB scaled the default bearing noise to 1e-13 rad, where the EKF's innovation
    covariance turned singular on every unit."""
    data = sweep(scenarios=[{"name": "glint", "params": {"steps": 60}}], methods=[{"name": "ekf"}],
                 snr_db=[0, 200])
    del data["scenario"], data["scenario_params"]
    refused(toml(data), "scenarios[0].snr_db: 200 dB on scenario config 'glint'", "at most 60 dB")
    data["snr_db"] = [0, 60]
    parse_sweep(data)


# ------------------------------------------------------------------ memory, before the run

TBD_HUGE = {"name": "tbd-grid", "params": {"cells": 5000, "frames": 1000}}


def test_a_unit_above_the_memory_limit_is_refused_up_front():
    """The issue's scene: 5000 x 5000 cells x 1000 frames is 93 GiB of float32 frames a trial."""
    data = sweep(scenarios=[TBD_HUGE], methods=[{"name": "dp-tbd"}])
    del data["scenario"], data["scenario_params"]
    line = refused(toml(data), "scenarios[0].params: a unit of 2 trials of 'tbd-grid' with 'dp-tbd' needs about",
                   "max_unit_memory_gb")
    assert "GB per trial" in line


def test_the_memory_limit_is_a_sweep_key_the_user_can_raise():
    data = sweep(scenarios=[TBD_HUGE], methods=[{"name": "dp-tbd"}], max_unit_memory_gb=1e6)
    del data["scenario"], data["scenario_params"]
    plan = parse_sweep(data)                        # accepted (and never run here)
    assert plan.max_unit_memory_gb == 1e6
    again = parse_sweep(tomllib.loads(tomlw.dumps(plan.to_dict())))      # plan.toml keeps it
    assert again.max_unit_memory_gb == 1e6
    # the limit does not change results: not part of the fingerprint
    small = sweep()
    assert parse_sweep(small | {"max_unit_memory_gb": 2.0}).fingerprint() == parse_sweep(small).fingerprint()
    assert "max_unit_memory_gb" not in parse_sweep(small).to_dict()       # written only when set
    # a lower limit refuses a sweep the default accepts, naming the scenario config
    data = sweep(scenarios=[{"name": "tbd-grid", "params": {"cells": 500}}], methods=[{"name": "dp-tbd-mf"}],
                 max_unit_memory_gb=0.05)
    del data["scenario"], data["scenario_params"]
    refused(toml(data), "scenarios[0].params:", "max_unit_memory_gb = 0.05, the sweep's")


def test_the_default_limit_is_a_fraction_of_this_machine_and_every_preset_fits():
    import importlib.resources
    assert 0.1 < default_unit_memory_gb() < 1e5
    root = importlib.resources.files("radarbench.bench") / "presets"
    for preset in root.iterdir():
        if preset.name.endswith(".toml") and not preset.name.endswith(".claims.toml"):   # claims: not sweeps
            try:
                plan = parse_sweep_text(preset.read_bytes(), preset.name)
            except ConfigError as err:      # real-trajectories reads the [data] extra's samples
                if "the optional extra: pip install" in err.problem or "run `bench data fetch`" in err.problem:
                    continue
                raise
            for s in plan.scenarios:
                need = unit_memory_bytes(plan, s, min(plan.chunk, s.trials), False)[0]
                assert need < 4 * 2 ** 30, (preset.name, s.label, need)     # fits a 8 GB machine's default


def test_the_memory_estimate_follows_the_array_sizes():
    data = sweep(scenarios=[{"name": "tbd-grid", "params": {"cells": 100, "frames": 20}}],
                 methods=[{"name": "dp-tbd"}, {"name": "dp-tbd-mf"}], chunk=10)
    del data["scenario"], data["scenario_params"]
    plan = parse_sweep(data)
    need, worst = unit_memory_bytes(plan, plan.scenarios[0], 10, False)
    frames = 10 * 20 * 100 * 100 * 4
    assert worst == "dp-tbd-mf"                     # its (K, 25, H, W) int8 back-pointers dominate
    assert frames + 20 * 25 * 100 * 100 < need < 3 * (frames + 20 * 25 * 100 * 100)


# ------------------------------------------------------------------ viterbi's step-0 refinement

def test_viterbi_refinement_ends_for_every_accepted_position_levels():
    """position_levels = 3 doubled the step each stage (4 / (Lp - 1) = 2) and 5 kept it,
    so the loop never ended, its list growing; now every odd value in [3, 1001] ends."""
    from radarbench.methods.glint.viterbi import MAX_REFINEMENT_STAGES, refinement_steps
    V = registry.get_method("viterbi")
    meta = {f.name: f.metadata for f in dataclasses.fields(V.Params)}["position_levels"]
    for Lp in range(meta["ge"], meta["le"] + 1, 2):
        for ratio in (1.0, 3.0, 1e3, 1e12):
            steps = refinement_steps(np.array([ratio, 0.5]), 1.0, Lp)
            assert len(steps) < 100 and steps[-1][0] == 1.0 if ratio > 1 else len(steps) == 1, (Lp, ratio)
            assert all(b[0] < a[0] for a, b in zip(steps, steps[1:]))
    assert len(refinement_steps(np.array([1.0, 1.0]), 0.0, 3)) == MAX_REFINEMENT_STAGES   # a safety net


def test_viterbi_runs_at_every_accepted_position_levels():
    """Each odd value in [3, 1001] on a 3-step active scene (one trial, one velocity level)."""
    G, V = registry.get_scenario("glint"), registry.get_method("viterbi")
    batch = G().generate(build_params(G.Params, {"steps": 3, "sensor": "active"}), 0.0, 1, TrialRNG(1, 0, 1, [0]))
    for Lp in range(3, 1002, 2):
        out = V().run(batch, build_params(V.Params, {"position_levels": Lp, "velocity_levels": 1}))
        assert np.isfinite(out.estimate).all(), Lp


def test_viterbi_results_at_seven_levels_and_more_are_unchanged():
    """The halving applies to 3 and 5 levels only: the grids of 7 and more are the old ones."""
    from radarbench.methods.glint.viterbi import refinement_steps
    for Lp in (7, 9, 41, 1001):
        old = [np.array([37.0, 2.0])]
        while old[-1][0] > 0.01:
            old.append(np.array([max(0.01, 4.0 * old[-1][0] / (Lp - 1)), 2.0]))
        new = refinement_steps(np.array([37.0, 2.0]), 0.01, Lp)
        assert len(new) == len(old) and all((a == b).all() for a, b in zip(old, new))


# ======================================================================= cause 7

def _detector_configs():
    return [("innovation", {"window": 1}), ("innovation", {"window": 10_000}), ("innovation", {"window": 1,
            "delta": 0.999}), ("cumulant", {}), ("cumulant", {"combine": "max"}), ("wavelet", {}),
            ("wavelet", {"levels": 8, "coarsest": 8}), ("wavelet", {"coefficients": "detail", "coarsest": 1})]


@pytest.mark.parametrize("name, params", _detector_configs(), ids=lambda x: str(x))
def test_nominal_thresholds_are_finite_down_to_the_smallest_accepted_pfa(name, params):
    C = registry.get_scenario("cv-turn-cv")
    batch = C().generate(C.Params(), None, 1, TrialRNG(1, 1, 1, [0]))
    method = registry.get_method(name)
    p = build_params(method.Params, params)
    pfas = [MIN_PFA, 1e-100, 1e-17, 1e-16, 1e-3, 0.01, 0.4999]
    thresholds = [method().nominal_threshold(p, pfa, batch) for pfa in pfas]
    assert all(math.isfinite(t) and t > 0 for t in thresholds), thresholds
    assert all(a > b for a, b in zip(thresholds, thresholds[1:])), thresholds    # decreasing in pfa
    assert thresholds[2] > thresholds[3]            # 1e-17 and 1e-16 differ: no 1 - pfa rounding


def test_the_smallest_pfa_is_the_documented_bound():
    refused(toml(sweep(calibration={"pfa": MIN_PFA / 10})), "calibration.pfa: expected a number in [1e-300, 0.5)")
    assert parse_sweep(sweep(calibration={"pfa": MIN_PFA})).calibration.pfa == MIN_PFA


def test_no_upper_quantile_is_taken_as_ppf_of_one_minus_pfa():
    """chi2.ppf(1 - pfa) is infinite below pfa ~ 1e-16: thresholds use isf everywhere."""
    from radarbench import bench
    from radarbench import methods
    roots = [Path(bench.__file__).parent, Path(methods.__file__).parent]
    pattern = re.compile(r"\.ppf\(\s*\(?\s*1(\.0)?\s*-|\.ppf\(\s*\(1(\.0)?\s*-")
    for root in roots:
        for path in root.rglob("*.py"):
            assert not pattern.search(path.read_text(encoding="utf-8")), path


def test_snr_levels_equal_at_the_key_precision_are_refused():
    """10.00000001 and 10.00000002 are distinct floats but one unit key: one level was dropped."""
    assert snr_key(10.00000001) == snr_key(10.00000002) == "+10"
    line = refused(toml(sweep(snr_db=[10.00000001, 10.00000002])), "snr_db:", "one level at the precision")
    assert f"{SNR_KEY_DIGITS} significant digits" in line
    refused(toml(sweep(snr_db={"start": 10, "stop": 10.00000005, "step": 1e-8})), "snr_db:", "one level")
    refused(toml(sweep(snr_db=[0.0, -0.0])), "snr_db:", "repeated SNR value")


def test_accepted_snr_levels_have_distinct_unit_keys():
    from radarbench.bench.run.runner import plan_units
    rng = np.random.default_rng(5)
    for _ in range(200):
        levels = [float(x) for x in np.round(rng.uniform(-200, 200, 5), rng.integers(0, 12))]
        try:
            plan = parse_sweep(sweep(snr_db=levels))
        except ConfigError:
            continue
        keys = [u.key for u in plan_units(plan)[1]]
        assert len(set(keys)) == len(keys), levels
        assert {snr_key(s) for s in plan.snr_db} == {k.split("/")[2] for k in keys}


GRID_OUT_OF_ORDER = """
name = "grid-order"
scenario = "cv-turn-cv"
trials = 2
seed = 1
snr_db = [0]
chunk = 2

[scenario_params]
turn_rate_deg_s = [2.0, 3.0]
steps = [150, 160]

[[methods]]
name = "innovation"

[calibration]
h0_trials = 10

[record]
trials = 0
"""


def test_a_scenario_grid_in_any_key_order_round_trips_through_plan_toml():
    plan = parse_sweep_text(GRID_OUT_OF_ORDER.encode(), "sweep.toml")
    labels = [s.label for s in plan.scenarios]
    assert labels[0] == "cv-turn-cv[turn_rate_deg_s=2,steps=150]"            # the sweep's order
    again = parse_sweep(tomllib.loads(tomlw.dumps(plan.to_dict())))
    assert [s.label for s in again.scenarios] == labels
    assert again.fingerprint() == plan.fingerprint()
    from radarbench.bench.run.runner import plan_units
    assert [u.key for part in plan_units(again) for u in part] == [u.key for part in plan_units(plan) for u in part]


def test_bench_run_plan_toml_into_the_same_folder_resumes(tmp_path):
    """Before: every unit ran again under other labels and the CSVs doubled."""
    sweep_file = tmp_path / "sweep.toml"
    sweep_file.write_text(GRID_OUT_OF_ORDER)
    out = tmp_path / "out"
    args = ["--out", str(out), "--quiet", "--workers", "1", "--no-record"]
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["run", str(sweep_file), *args]) == 0
    first = (out / "trials.csv").read_text()
    (tmp_path / "plan.toml").write_bytes((out / "plan.toml").read_bytes())
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        assert main(["run", str(tmp_path / "plan.toml"), *args]) == 0, err.getvalue()
    assert (out / "trials.csv").read_text() == first


@pytest.mark.parametrize("entry, says", [
    ({"name": "cumulant", "params": {"window": 16}, "label": "cumulant[window=64]"},
     "'cumulant[window=64]' says window=64, but this config has window=16"),
    ({"name": "cumulant", "params": {"window": 16}, "label": "cumulant[moment=raw]"}, "moment=raw"),
    ({"name": "cumulant", "params": {"window": 16}, "label": "innovation[window=16]"},
     "looks like the label of a innovation config"),
    ({"name": "cumulant", "params": {"window": 16}, "label": "wavelet"}, "is the label of a wavelet config"),
    ({"name": "cumulant", "params": {"window": 16}, "label": "cumulant"}, "the default cumulant config"),
], ids=["other-value", "other-param", "other-method", "other-name", "default-name"])
def test_a_label_that_looks_like_another_configs_is_refused(entry, says):
    refused(toml(sweep(methods=[entry])), "methods[0].label: ", says)


def test_labels_that_tell_the_truth_or_nothing_checkable_are_kept():
    for label in ("cumulant[window=16]", "cumulant[ window = 16 ]", "cumulant[window=16,moment=centred]",
                  "cumulant[small window]", "cumulant-16", "my cumulant", "cumulant-paper[M=16]"):
        plan = parse_sweep(sweep(methods=[{"name": "cumulant", "params": {"window": 16}, "label": label}]))
        assert plan.methods[0].label == label
    assert parse_sweep(sweep(methods=[{"name": "cumulant", "label": "cumulant"}])).methods[0].label == "cumulant"
    # scenario labels: a bare name is fine (a scenario's label names its grid axes only)
    data = sweep(scenarios=[{"name": "cv-turn-cv", "params": {"steps": 150}, "label": "cv-turn-cv"}])
    del data["scenario"], data["scenario_params"]
    parse_sweep(data)
    data["scenarios"][0]["label"] = "cv-turn-cv[steps=140]"
    refused(toml(data), "scenarios[0].label: ", "says steps=140, but this config has steps=150")


def test_bench_perf_with_an_unknown_size_is_one_line_and_writes_nothing(tmp_path):
    err = io.StringIO()
    with contextlib.chdir(tmp_path), contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(["perf", "--sizes", "small", "bogus", "--out", str(tmp_path / "perf")])
    lines = err.getvalue().splitlines()
    assert code == 2 and len(lines) == 1, err.getvalue()
    assert lines[0] == "error: --sizes: unknown size 'bogus' (known: default, large, paper, replay, segments, small)"
    assert not list(tmp_path.iterdir())


def test_bench_list_shows_the_bounds_and_their_reason():
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["list", "-v"]) == 0
    assert "sweeps (int, default 1): passes over the axes within a block (block coordinate ascent) " \
           "[>= 1 and <= 16: one pass at least" in out.getvalue()
