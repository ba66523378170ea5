"""The Stone Soup peers (``[peers]`` extra): unavailable with the reason without it; the
GM-PHD and MFA peers find the targets of a clean scene; ``bench perf`` times the JPDA peer's
initiator apart."""

import importlib
import sys

import numpy as np
import pytest

from radarbench.bench import registry
from radarbench.bench.params import build_params
from radarbench.bench.registry import PluginError
from radarbench.bench.sweep.rng import TrialRNG

PEERS = {"radarbench.methods.multitarget.stonesoup_peer": "stonesoup-jpda", "radarbench.methods.multitarget.stonesoup_gmphd": "stonesoup-gmphd",
         "radarbench.methods.multitarget.stonesoup_mht": "stonesoup-mfa"}


@pytest.mark.parametrize("module, name", PEERS.items())
def test_a_peer_without_the_extra_is_unavailable_with_the_reason(monkeypatch, module, name):
    """Stone Soup failing to import (None in ``sys.modules`` makes ``import`` raise
    ImportError) makes the peer's module raise the registry's PluginError naming
    the method and the extra: ``bench list`` shows it unavailable, a sweep with
    ``optional = true`` skips it with that line."""
    for loaded in [m for m in sys.modules if m == "stonesoup" or m.startswith("stonesoup.")] + list(PEERS):
        monkeypatch.delitem(sys.modules, loaded, raising=False)
    monkeypatch.setitem(sys.modules, "stonesoup", None)
    with pytest.raises(PluginError, match=r'needs the \[peers\] extra \(pip install -e "\.\[peers\]"\)') as err:
        importlib.import_module(module)
    assert err.value.name == name


def test_the_mfa_peer_without_ortools_is_unavailable_with_the_reason(monkeypatch):
    """Stone Soup without OR-Tools (its MFA's primal solver): the MFA peer alone is
    unavailable, its reason Stone Soup's line naming the package."""
    pytest.importorskip("stonesoup")
    for loaded in [m for m in sys.modules if m.startswith("stonesoup.dataassociator.mfa")
                   or m == "ortools" or m.startswith("ortools.")] + ["radarbench.methods.multitarget.stonesoup_mht"]:
        monkeypatch.delitem(sys.modules, loaded, raising=False)
    monkeypatch.setitem(sys.modules, "ortools", None)
    with pytest.raises(PluginError, match=r"\[peers\] extra.*'ortools'") as err:
        importlib.import_module("radarbench.methods.multitarget.stonesoup_mht")
    assert err.value.name == "stonesoup-mfa"


def _clean_scene(seed: int, clutter_per_scan: float = 0.0, pd: float = 0.95):
    cls = registry.get_scenario("hfswr-targets")
    params = build_params(cls.Params, {"detection": "fixed", "pd": pd, "clutter_per_scan": clutter_per_scan,
                                       "scans": 30, "targets": 3, "crossing": False})
    return cls().generate(params, 15.0, 1, TrialRNG(seed, 0, 1, range(1)))


@pytest.mark.parametrize("cardinality, clutter", [("phd", 0.0), ("lcc", 0.5)])
def test_gmphd_finds_the_targets_of_a_clean_scene(cardinality, clutter):
    """3 ships, Pd 0.95, no clutter, 30 scans (seed fixed). A tracker reporting nothing
    scores GOSPA = c sqrt(T_k / 2) at a scan with T_k targets (each one missed costs
    c^2 / 2); the GM-PHD peer must score under half of that on average: every target
    found on most scans, within a few km (its errors: the cross-range noise r sigma_az
    ~ 1.7 km of one plot before filtering, a scan missed at each missed detection,
    whose weight (1 - Pd) w falls below the extraction threshold, and 2-3 scans to
    build up a new target's weight). Nothing is false in a clean scene. The same for the
    GM-LCC update (its second-order cardinality changes the missed-detection weights) in a
    nearly clean one (0.5 clutter plots per scan: it refuses a scene without clutter, whose
    cumulants it divides by)."""
    pytest.importorskip("stonesoup")
    method = registry.get_method("stonesoup-gmphd")
    task = registry.get_task("multi-target")
    batch = _clean_scene(1, clutter)
    metrics = task.trial_metrics(batch, method().run(batch, method.Params(cardinality=cardinality)), 1.0)
    present = np.isfinite(batch.truth[0, :, :, 0]).sum(axis=1)
    empty_tracker = batch.scene.gospa_cutoff_m * np.sqrt(present / 2.0)
    assert present.sum() > 40                                         # the scene holds targets to find
    assert np.mean(metrics["gospa"][0]) < 0.5 * np.mean(empty_tracker)
    assert np.sum(metrics["gospa_missed"][0]) < 0.25 * present.sum()
    assert np.sum(metrics["gospa_false"][0]) <= clutter * present.size / 10     # at most 1 in 10 clutter plots


@pytest.mark.parametrize("seed", [1, 2])
def test_mfa_follows_every_target_of_a_clean_scene(seed):
    """3 ships, Pd = 1, no clutter, 30 scans (seeds fixed): the MHT peer's GOSPA is
    what initiation and termination cost, nothing more. Every ship is confirmed
    exactly M + 1 scans after its first plot (``MultiMeasurementInitiator``'s
    M + 2 plots at Pd = 1) and missed on no other scan; no confirmed track is
    false but for the M_t - 1 scans a track coasts after its ship leaves
    before the termination rule ends it; no break, no identity switch; and the
    tracks' positions are closer to the truth than the plots are (RMS over the
    assigned pairs against the plots' own RMS error): the UKF filters."""
    pytest.importorskip("stonesoup")
    pytest.importorskip("ortools", reason="the MFA peer needs OR-Tools (the [peers] extra)")
    from radarbench.models.hfswr import plot_to_cartesian

    method = registry.get_method("stonesoup-mfa")
    params = method.Params()
    batch = _clean_scene(seed, pd=1.0)
    metrics = registry.get_task("multi-target").trial_metrics(batch, method().run(batch, params), 1.0)
    present = np.isfinite(batch.truth[0, :, :, 0])
    targets = int(present.any(axis=0).sum())
    assert targets == 3 and metrics["targets_initiated"][0] == targets
    assert metrics["init_delay_scans"][0] == params.confirm_m + 1
    assert metrics["gospa_missed"][0].sum() == targets * (params.confirm_m + 1)
    assert metrics["gospa_false"][0].sum() <= targets * (params.terminate_m - 1)
    assert metrics["false_tracks"][0] == metrics["track_breaks"][0] == metrics["id_switches"][0] == 0
    scene, (k, j) = batch.scene, np.nonzero(batch.scene.plot_origin[0] >= 0)
    plots = np.array([plot_to_cartesian(batch.z[0, a, b, :2], scene.sensor_xy) for a, b in zip(k, j)])
    plot_rms = np.sqrt(np.mean(np.sum((plots - batch.truth[0, k, scene.plot_origin[0, k, j]][:, [0, 2]]) ** 2,
                                      axis=1)))
    assigned = present.sum() - metrics["gospa_missed"][0].sum()
    assert np.sqrt(metrics["gospa_loc"][0].sum() / assigned) < plot_rms


def test_the_jpda_reference_times_its_initiator_apart():
    """``jpda-ukf``'s reference (the Stone Soup JPDA peer) leaves its initiator's CPU
    seconds for ``bench perf``'s second row: positive, and less than the whole run's."""
    pytest.importorskip("stonesoup")
    import time

    method = registry.get_method("jpda-ukf")()
    assert set(method.reference_parts) == {"initiation"}
    batch = _clean_scene(2)
    t0 = time.thread_time()
    method.reference_run(batch, method.Params())
    whole = time.thread_time() - t0
    assert 0.0 < method.reference_part_seconds["initiation"] < whole


def test_gmlcc_refuses_a_scene_without_clutter():
    pytest.importorskip("stonesoup")
    method = registry.get_method("stonesoup-gmphd")
    scenario = registry.get_scenario("hfswr-targets")
    no_clutter = build_params(scenario.Params, {"clutter_per_scan": 0.0})
    assert "needs clutter" in method().check_scenario(method.Params(cardinality="lcc"), no_clutter)
    assert method().check_scenario(method.Params(), no_clutter) is None
