"""The optional members of the plugin protocol (``bench.core``) as plugins declare them."""

from types import SimpleNamespace

import numpy as np
import pytest

from radarbench.bench import registry
from radarbench.bench.sweep.capabilities import fits
from radarbench.bench.core import Method, Scenario
from radarbench.bench.params import build_params
from radarbench.bench.cli.perf import reference_of, scaling_plan
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.methods.maneuver import base as innovation_base
from radarbench.methods.maneuver.base import InnovationDetector

METHODS = list(registry.methods().items())


@pytest.mark.parametrize("name, cls", METHODS)
def test_a_declared_reference_is_implemented_and_an_implemented_one_declared(name, cls):
    overrides = cls.reference_run is not Method.reference_run
    assert overrides == (cls.reference_name is not None), name
    assert cls.reference_trials is None or cls.reference_trials >= 1
    assert not cls.reference_parts or cls.reference_name is not None, name     # parts of a declared reference
    for size, targets in cls.perf_targets.items():
        for measure in targets:
            assert measure in {"speedup", "seconds_per_trial"} or measure.endswith("_per_second"), (name, size)


@pytest.mark.parametrize("cls", list(registry.scenarios().values()))
def test_scenario_perf_sizes_are_valid_params(cls):
    assert isinstance(cls.perf_snr_db, float | int)
    for params, trials in cls.perf_sizes.values():
        build_params(cls.Params, params)
        assert trials >= 1
    build_params(cls.Params, cls.small_params)


def test_defaults_mean_not_provided():
    assert Method.reference_name is None and Method.reference_trials is None and Method.perf_targets == {}
    assert Method.reference_parts == {} and Method.reference_part_seconds is None
    assert Method().work(SimpleNamespace(n=7), None) == ("trials", 7.0)
    assert reference_of(Method()) is None
    assert Scenario.small_params == {} and Scenario.perf_sizes == {"default": ({}, 100)}


def test_innovation_detectors_share_the_filterpy_reference(monkeypatch):
    detectors = [cls for cls in registry.methods().values() if issubclass(cls, InnovationDetector)]
    assert {cls.name for cls in detectors} == {"innovation", "cumulant", "wavelet", "glr", "cusum"}
    scenario = registry.get_scenario("cv-turn-cv")
    batch = scenario().generate(build_params(scenario.Params, scenario.small_params), 5.0, 3,
                                TrialRNG(1, 0, 0, range(3)))
    scene = batch.scene
    outs = {cls: cls().run(batch, cls.Params()) for cls in detectors}

    def batched(*args):
        raise AssertionError("the reference must not run the batched filter")

    # the reference calls the filterpy loop itself: with the batched filter gone it still runs
    monkeypatch.setattr(innovation_base, "innovations", batched)
    for cls in detectors:
        name, run = reference_of(cls())
        assert name == InnovationDetector.reference_name, cls.name    # the detector's own NumPy code on filterpy
        ref = run(batch, cls.Params())
        np.testing.assert_allclose(ref.statistic, outs[cls].statistic, rtol=1e-7, atol=1e-9, err_msg=cls.name)
        assert batch.scene is scene                             # nothing patched on the batch


def test_the_scaling_sweep_is_a_packaged_preset():
    plan = scaling_plan()
    assert plan.name == "perf-scaling" and plan.record_trials == 0


@pytest.mark.parametrize("name, cls", METHODS)
def test_work_is_a_unit_and_a_positive_count(name, cls):
    """``Method.work`` on the small instance of each scenario the method serves: a plural
    unit name and a positive count (``bench perf`` reports ``<unit>_per_second``)."""
    for scenario in registry.scenarios().values():
        params = build_params(scenario.Params, scenario.small_params)
        method_params = cls.Params()
        if not fits(cls, scenario, params) or cls().check_scenario(method_params, params) is not None:
            continue
        batch = scenario().generate(params, float(scenario.perf_snr_db), 2, TrialRNG(1, 0, 0, range(2)))
        unit, count = cls().work(batch, method_params)
        assert unit.isidentifier() and unit.endswith("s") and count > 0, (name, scenario.name, unit, count)
        break


@pytest.mark.parametrize("name, cls", METHODS)
def test_least_cost_is_work_of_known_kinds_or_a_reason(name, cls):
    """``Method.least_cost`` on the small instance of the first scenario the method serves: positive
    amounts of the kinds ``bench perf`` has a limit for, or a reason (a phrase), or None."""
    from radarbench.bench.run.limits import RESOURCES

    for scenario in registry.scenarios().values():
        params = build_params(scenario.Params, scenario.small_params)
        method, method_params = cls(), cls.Params()
        if not fits(cls, scenario, params) or method.check_scenario(method_params, params) is not None:
            continue
        batch = scenario().generate(params, float(scenario.perf_snr_db), 2, TrialRNG(1, 0, 0, range(2)))
        cost = method.least_cost(batch, method_params, method.run(batch, method_params))
        if isinstance(cost, dict):
            assert cost and set(cost) <= set(RESOURCES) and all(v > 0 for v in cost.values()), (name, cost)
        else:
            assert cost is None or (isinstance(cost, str) and cost.strip()), (name, cost)
        break
