"""Every number a method or scenario declares, tried at its bounds and beyond: beyond, refused as
any hostile sweep file is (``tests/property/test_hostile_input.py``:
exit code 2, one line, nothing written); at a bound, refused up front in one line or run to
completion at a small size within a per-case time budget, with no failed unit.
"""

from __future__ import annotations

import dataclasses
import math
import signal
import tempfile
import typing
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import scaled

from radarbench.bench import registry
from radarbench.bench.sweep.capabilities import fits
from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import field_types
from tests.property.test_hostile_input import assert_rejected, run_in_process, toml_text

registry.discover()


# ------------------------------------------------------------------ parameters at their bounds and beyond
#
# Every number a method or scenario declares is bounded on both sides (bench.params). A value
# just beyond a bound, or an integer too large for a float, is refused like any bad input; a
# value at a bound is either refused up front in one line (a constraint across parameters, a
# method that cannot run on the scenario config, a unit above the memory limit) or runs to
# completion at a small size (the scenario's ``small_params``, a few trials, one worker, a
# 1 GB unit memory limit) with no failed unit. How fast is ``bench perf``'s to say; a case
# that hangs fails after CASE_HANG_S.

#: seconds after which a case at a bound counts as hung: far beyond the longest (a 10 000-step
#: scene, about 6 s once its kernels are compiled; their first compilation can take a minute)
CASE_HANG_S = round(scaled(300))
#: the cheapest method of each task, run on the scenario cases
CHEAP_METHOD = {"maneuver-detection": "innovation", "tracking": "ekf", "tbd": "dp-tbd", "multi-target": "gnn-ekf"}
HUGE_INTS = (10 ** 400, -10 ** 400)


def _fields():
    """(kind, component, field name, element type, metadata, length of a tuple value or None)."""
    for kind, table in (("method", registry.methods()), ("scenario", registry.scenarios())):
        for name, cls in table.items():
            types = field_types(cls.Params)
            for f in dataclasses.fields(cls.Params):
                tp = types[f.name]
                is_tuple = typing.get_origin(tp) is tuple
                elem = typing.get_args(tp)[0] if is_tuple else tp
                if elem in (int, float):
                    size = max(len(f.default), f.metadata.get("min_len") or 0, 1) if is_tuple else None
                    yield kind, name, f.name, elem, f.metadata, size


def _nearest(elem, bound, direction):
    return bound + direction if elem is int else math.nextafter(float(bound), direction * math.inf)


def _at_bounds(elem, meta):
    """The accepted values at the bounds: ge/le themselves, the nearest inside gt/lt."""
    low = meta["ge"] if meta.get("ge") is not None else _nearest(elem, meta["gt"], +1)
    high = meta["le"] if meta.get("le") is not None else _nearest(elem, meta["lt"], -1)
    return [("low", elem(low)), ("high", elem(high))]


def _beyond_bounds(elem, meta):
    """Values just outside each bound, and integers beyond any float."""
    low = _nearest(elem, meta["ge"], -1) if meta.get("ge") is not None else meta["gt"]
    high = _nearest(elem, meta["le"], +1) if meta.get("le") is not None else meta["lt"]
    return [("below", elem(low)), ("above", elem(high)), *(("huge", v) for v in HUGE_INTS)]


def _value(v, size):
    return v if size is None else [v] * size


def _sweep_with(kind, name, params, method=None, snr=0.0):
    """A small sweep: the component with ``params`` on (or with) the other side's small config."""
    if kind == "method":
        cls = registry.get_method(name)
        scenario = next(s for s in registry.scenarios().values() if fits(cls, s))
        scenarios = [{"name": scenario.name, "params": dict(scenario.small_params)}]
        methods = [{"name": name, "params": params}]
    else:
        scenario = registry.get_scenario(name)
        scenarios = [{"name": name, "params": dict(scenario.small_params) | params}]
        cheap = CHEAP_METHOD.get(scenario.tasks[0])
        if cheap is None or not fits(registry.get_method(cheap), scenario):
            cheap = next(m for m, c in registry.methods().items() if fits(c, scenario))
        methods = [{"name": method or cheap}]
    return {"name": "bounds", "trials": 2, "seed": 5, "chunk": 2, "snr_db": [snr], "scenarios": scenarios,
            "methods": methods, "calibration": {"pfa": 0.05, "mode": "empirical", "h0_trials": 10},
            "record": {"trials": 1}, "max_unit_memory_gb": 1.0}


AT_BOUNDS = [pytest.param(kind, name, {field: _value(v, size)}, id=f"{name}.{field}={side}")
             for kind, name, field, elem, meta, size in _fields() for side, v in _at_bounds(elem, meta)]
BEYOND_BOUNDS = [pytest.param(kind, name, field, _value(v, size), id=f"{name}.{field}={side}")
                 for kind, name, field, elem, meta, size in _fields() for side, v in _beyond_bounds(elem, meta)]


class _Hung(Exception):
    pass


def run_to_completion(data) -> str:
    """Validate ``data``; if accepted, run it (one worker, in-process) and check no unit
    failed. Returns "refused" or "ran"."""
    from radarbench.bench.run.runner import plan_record, run_sweep
    try:
        plan = parse_sweep(data, "bounds.toml")
    except ConfigError as err:
        assert "\n" not in str(err) and len(str(err)) < 600, str(err)
        return "refused"

    def hung(*_):
        raise _Hung(f"still running after {CASE_HANG_S} s")
    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(CASE_HANG_S)                        # a hang fails the case instead of the suite
    try:
        with tempfile.TemporaryDirectory() as tmp:
            store = run_sweep(plan, Path(tmp) / "out", plan_record=plan_record(plan, "bounds"), workers=1,
                              quiet=True)
            try:
                runs = store.runs()
            finally:
                store.close()
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    failed = runs[runs.error.notna()]
    assert failed.empty, sorted(set(failed.method + ": " + failed.error))[:3]
    return "ran"


@pytest.mark.parametrize("kind, name, field, value", BEYOND_BOUNDS)
def test_values_beyond_every_bound_are_refused_in_one_line(kind, name, field, value):
    data = _sweep_with(kind, name, {field: value})
    data.pop("max_unit_memory_gb")
    code, out, err, written = run_in_process(toml_text(data).encode())
    assert_rejected(code, out, err, written, f"{name}.{field}={str(value)[:40]}")
    assert f"params.{field}" in err, err


@pytest.mark.slow                     # a small sweep run per bound of every parameter
@pytest.mark.parametrize("kind, name, params", AT_BOUNDS)
def test_values_at_every_bound_run_to_completion(kind, name, params):
    run_to_completion(_sweep_with(kind, name, params))


@pytest.mark.slow
def test_the_longest_scene_runs_every_detector_at_its_largest_window():
    """On the longest accepted scene (cv-turn-cv at its largest ``steps``) the largest windows
    that can be scored (their statistic formed before the onset) run; a window at its upper
    bound, whose statistic starts at the last step, leaves no false-alarm step and is refused."""
    steps = {f.name: f.metadata for f in dataclasses.fields(registry.get_scenario("cv-turn-cv").Params)}["steps"]["le"]
    onset = steps - 100
    data = _sweep_with("scenario", "cv-turn-cv", {"steps": steps, "onset_step": onset, "turn_steps": 40})
    data["methods"] = [{"name": "cumulant", "params": {"window": onset - 1}},
                       {"name": "innovation", "params": {"window": onset - 1}},
                       {"name": "innovation", "params": {"window": 1, "delta": 0.999}},
                       {"name": "wavelet", "params": {"levels": 8, "coarsest": 8}},
                       {"name": "glr", "params": {"window": 1000}}]
    assert run_to_completion(data) == "ran"
    data["methods"] = [{"name": "cumulant", "params": {"window": steps}}]
    assert run_to_completion(data) == "refused"


@pytest.mark.slow
@settings(max_examples=12, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(case=st.sampled_from([c.values for c in AT_BOUNDS]), pick=st.integers(min_value=0, max_value=10 ** 6),
       snr=st.sampled_from([-200.0, -30.0, 0.0, 30.0, 60.0]))
def test_a_bound_runs_with_any_method_of_its_task_at_any_snr(case, pick, snr):
    """The cases above with another method of the task (scenario cases) and the SNR level drawn
    too: refused up front in one line (e.g. noise scaled below its floor) or run to completion."""
    kind, name, params = case
    method = None
    if kind == "scenario":
        scenario = registry.get_scenario(name)
        names = sorted(m for m, c in registry.methods().items() if fits(c, scenario))
        method = names[pick % len(names)]
    run_to_completion(_sweep_with(kind, name, params, method, snr))
