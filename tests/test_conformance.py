"""Every registered method on every scenario that provides what it needs (its small
instance; :mod:`bench.sweep.capabilities`) and whose config it accepts: shapes, no NaN, determinism; every scenario's
batch carries the scene type of each of its tasks."""

import dataclasses

import numpy as np
import pytest

from radarbench.bench import registry
from radarbench.bench.sweep.capabilities import CAPABILITIES, fits, missing
from radarbench.bench.core import DetectionOutput, Scene
from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.registry import get_task
from tests.test_recorded_tracks import small_params_on_a_csv


def _accepts(mcls, scls) -> bool:
    """The method's default config runs on the scenario's small instance: it fits its
    capabilities and its ``check_scenario`` refuses nothing (a sweep skips a refused pair)."""
    params = build_params(scls.Params, scls.small_params)
    return fits(mcls, scls, params) and mcls().check_scenario(build_params(mcls.Params, {}), params) is None


PAIRS = [(s, m) for s, scls in registry.scenarios().items() for m, mcls in registry.methods().items()
         if _accepts(mcls, scls)]


def test_every_method_has_a_scenario_and_nothing_is_unavailable():
    """Every built-in plugin imports, except a peer whose optional extra is not
    installed here (``[peers]``: CI installs ``[test]`` only), which says so."""
    broken = [u for u in registry.unavailable() if "extra (pip install" not in u.error]
    assert broken == []
    runnable = {m for _, m in PAIRS}
    assert runnable == set(registry.methods())


def test_built_in_capabilities_are_named_in_the_vocabulary():
    """Every capability a built-in plugin needs, handles or provides is one of
    :data:`bench.sweep.capabilities.CAPABILITIES` (a misspelt name would pair nothing)."""
    used = set()
    for cls in registry.methods().values():
        used |= set(cls.needs) | set(cls.handles)
    for cls in registry.scenarios().values():
        used |= set(cls.provides) | set(cls().requires(build_params(cls.Params, cls.small_params)))
    assert used and used <= set(CAPABILITIES)


#: scenario -> parameters replacing its ``small_params``: a data file this module writes
#: (recorded-tracks: a CSV, where its small instance reads a sample of the optional extra)
LOCAL_DATA: dict[str, dict] = {}


@pytest.fixture(autouse=True, scope="module")
def _local_data(tmp_path_factory):
    LOCAL_DATA["recorded-tracks"] = small_params_on_a_csv(tmp_path_factory.mktemp("data"))


def _params(cls):
    """A small instance of the scenario (``small_params``), so the test stays quick."""
    return build_params(cls.Params, {**cls.small_params, **LOCAL_DATA.get(cls.name, {})})


def _batch(scenario, snr_db, seed=3):
    cls = registry.get_scenario(scenario)
    return cls().generate(_params(cls), snr_db, 3, TrialRNG(seed, 0, 11, range(5, 8)))


def _arrays(out) -> dict:
    """The arrays of an output in any form a task may take: a dataclass's array fields (the
    built-in output types), a dict of arrays, or an array (the peak-finding
    task of tests/test_task_plugin.py, the example docs/extending.md points to)."""
    if dataclasses.is_dataclass(out):
        return {f.name: getattr(out, f.name) for f in dataclasses.fields(out)
                if isinstance(getattr(out, f.name), np.ndarray)}
    if isinstance(out, dict):
        return {str(k): np.asarray(v) for k, v in out.items()}
    return {"output": np.asarray(out)}


@pytest.mark.parametrize("scenario, method", PAIRS)
def test_method_conforms(scenario, method):
    cls = registry.get_method(method)
    task = get_task(cls.task)
    levels = (None, 0.0, 10.0) if task.calibrated else (0.0, 10.0)     # null trials only where calibrated
    for snr in levels:
        batch = _batch(scenario, snr)
        out = task.check_output(cls().run(batch, cls.Params()), batch)      # shape and finiteness
        again = cls().run(_batch(scenario, snr), cls.Params())
        first, second = _arrays(out), _arrays(again)
        assert first and first.keys() == second.keys()
        for name in first:                                                  # pure and deterministic
            np.testing.assert_array_equal(first[name], second[name], err_msg=name)
        if isinstance(out, DetectionOutput):      # what the plan-time check reads is what it returns
            assert out.valid_from == cls().valid_from(cls.Params(), batch.steps)
        if snr is not None:
            metrics = task.trial_metrics(batch, out, 1.0)
            assert all(len(v) == batch.n for v in metrics.values())
        if task.calibrated:           # the contract of bench.core.Method.nominal_threshold
            nominal = cls().nominal_threshold(cls.Params(), 0.01, batch)
            assert np.isfinite(nominal) if cls.has_nominal_threshold() else np.isnan(nominal)


@pytest.mark.parametrize("scenario", list(registry.scenarios()))
def test_scenario_streams_are_per_trial(scenario):
    """A trial's draws do not depend on which other trials share its batch."""
    cls = registry.get_scenario(scenario)
    whole = cls().generate(_params(cls), 5.0, 4, TrialRNG(9, 0, 1, range(4)))
    part = cls().generate(_params(cls), 5.0, 2, TrialRNG(9, 0, 1, range(2, 4)))
    _equal_up_to_padding(whole.z[2:], part.z)
    np.testing.assert_array_equal(whole.truth[2:], part.truth)


def _equal_up_to_padding(a: np.ndarray, b: np.ndarray) -> None:
    """Equal on their common extent, NaN beyond it: measurements padded to the
    batch's largest count (multi-target plots) may be wider in a larger batch."""
    assert a.ndim == b.ndim
    common = tuple(slice(0, min(x, y)) for x, y in zip(a.shape, b.shape))
    np.testing.assert_array_equal(a[common], b[common])
    for arr in (a, b):
        rest = np.array(arr, float)
        rest[common] = np.nan
        assert np.isnan(rest).all(), "values beyond the common extent are not padding"


@pytest.mark.parametrize("scenario", list(registry.scenarios()))
def test_scenario_batches_carry_the_scene_of_each_task(scenario):
    """The scene is a frozen instance of each task's ``scene_type``, built (and
    so validated) in generate(), at every SNR and under the null."""
    cls = registry.get_scenario(scenario)
    assert cls.tasks
    for snr in (None, 0.0, 10.0):
        batch = _batch(scenario, snr)
        assert isinstance(batch.scene, Scene)
        for name in cls.tasks:
            task = get_task(name)
            assert task.scene_type is not Scene, f"task {name} defines no scene type"
            assert isinstance(batch.scene, task.scene_type), (scenario, name)
            task.check_scene(batch)
        with pytest.raises(dataclasses.FrozenInstanceError):
            batch.scene.snr_definition = "changed"
        assert not hasattr(batch, "meta")


@pytest.mark.parametrize("scenario", list(registry.scenarios()))
def test_a_declared_timeline_is_the_generated_scenes(scenario):
    """``Scenario.timeline`` (what the plan-time checks read) states the steps, the
    earliest onset and the warm-up of the scenes ``generate`` makes."""
    cls = registry.get_scenario(scenario)
    timeline = cls().timeline(_params(cls))
    if timeline is None:
        return
    batch = _batch(scenario, 10.0)
    assert timeline.steps == batch.steps
    assert timeline.onset_step == int(np.min(batch.scene.onset_step))
    assert timeline.warmup_steps == batch.scene.warmup_steps


@pytest.mark.parametrize("scenario, method", PAIRS)
def test_a_trials_numbers_do_not_depend_on_its_batch(scenario, method):
    """A trial's output and metrics are bit-identical in a batch of three and alone
    (docs/architecture.md, 'Portable numbers'); ``tests/property/test_chunk_invariance.py``
    checks the same through the CSVs of whole runs."""
    cls, scls = registry.get_method(method), registry.get_scenario(scenario)
    task = get_task(cls.task)
    for snr in (None, 10.0) if task.calibrated else (10.0,):
        batch = _batch(scenario, snr)
        alone = scls().generate(_params(scls), snr, 1, TrialRNG(3, 0, 11, [batch.trials[1]]))
        out, out_alone = cls().run(batch, cls.Params()), cls().run(alone, cls.Params())
        for name, value in _arrays(out).items():
            if value.ndim and value.shape[0] == batch.n:
                _equal_on_common_extent(value[1], _arrays(out_alone)[name][0], name)
        if snr is not None:
            metrics, metrics_alone = task.trial_metrics(batch, out, 1.0), task.trial_metrics(alone, out_alone, 1.0)
            for name, value in metrics.items():
                _equal_on_common_extent(np.asarray(value)[1], np.asarray(metrics_alone[name])[0], name)


def _equal_on_common_extent(a: np.ndarray, b: np.ndarray, name: str) -> None:
    """Equal where both are defined: a batch pads to its largest trial (plots, tracks)."""
    common = tuple(slice(0, min(x, y)) for x, y in zip(np.shape(a), np.shape(b)))
    np.testing.assert_array_equal(np.asarray(a)[common], np.asarray(b)[common], err_msg=name)


@pytest.fixture(scope="module")
def outside_scenario(tmp_path_factory):
    """A tracking scenario from a module on a temporary path (tests/kinematic_plugin.py):
    it provides ``kinematic-model`` and, ragged, requires ``valid-step-masks``."""
    from tests.kinematic_plugin import load
    return load(tmp_path_factory.mktemp("plugin"))


@pytest.mark.parametrize("ragged", [{}, {"min_steps": 12, "gap_probability": 0.2}])
def test_an_outside_scenario_gets_the_trackers_that_need_what_it_provides(outside_scenario, ragged):
    """With no edit anywhere: every built-in method whose needs the outside scenario
    provides (and, on a ragged config, that handles its valid-step masks) runs on it
    and scores finite metrics; the others are refused naming what is missing."""
    cls = outside_scenario
    params = build_params(cls.Params, cls.small_params | ragged)
    paired = {m for m, mcls in registry.methods().items() if fits(mcls, cls, params)}
    kinematic = {m for m, mcls in registry.methods().items() if "kinematic-model" in mcls.needs}
    assert kinematic and paired == kinematic
    batch = cls().generate(params, 10.0, 4, TrialRNG(2, 0, 1, range(4)))
    assert (batch.scene.valid_steps is None) == (not ragged)
    task = get_task("tracking")
    for name in sorted(paired):
        mcls = registry.get_method(name)
        out = task.check_output(mcls().run(batch, mcls.Params()), batch)
        metrics = task.trial_metrics(batch, out, 1.0)
        assert np.isfinite(metrics["rmse"]).all() and np.isfinite(metrics["nees_mean"]).all(), name
    for name, mcls in registry.methods().items():
        if name not in paired and mcls.task == "tracking":
            assert "glint-model" in missing(mcls, cls, params), name
