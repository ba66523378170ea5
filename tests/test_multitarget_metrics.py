"""Multi-target metrics: GOSPA is a metric (identity, symmetry, triangle
inequality on random sets) and equals Stone Soup's GOSPA and OSPA on the same
sets; the decomposition adds up; the track-level metrics on hand-made cases."""

import datetime
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.bench.tasks.multitarget.metrics import (gospa_assignment, multitarget_trial_metrics, pairwise_distances,
                                             summarise_multitarget)


def gospa(X, Y, c=5.0, p=2.0):
    """GOSPA, localisation, missed, false, OSPA of point sets X (m, 2) and Y (j, 2)."""
    T, J = max(len(X), 1), max(len(Y), 1)
    tx, ty = np.full((1, 1, T, 2), np.nan), np.full((1, 1, J, 2), np.nan)
    tx[0, 0, :len(X)], ty[0, 0, :len(Y)] = X, Y
    out = gospa_assignment(pairwise_distances(tx, ty), np.isfinite(tx).all(-1), np.isfinite(ty).all(-1), c, p)
    return {k: float(v[0, 0]) for k, v in out.items() if k != "assigned"}


points = st.lists(st.tuples(st.floats(-20, 20), st.floats(-20, 20)), max_size=6).map(
    lambda xs: np.array(xs, float).reshape(-1, 2))


@settings(max_examples=150, deadline=None, derandomize=True)
@given(points, points, points, st.floats(0.5, 30.0), st.sampled_from([1.0, 2.0, 3.0]))
def test_gospa_is_a_metric(X, Y, Z, c, p):
    assert gospa(X, X, c, p)["gospa"] == pytest.approx(0.0, abs=1e-9)
    dxy, dyx = gospa(X, Y, c, p)["gospa"], gospa(Y, X, c, p)["gospa"]
    assert dxy == pytest.approx(dyx, rel=1e-9, abs=1e-9)
    if dxy < 1e-12:                                           # identity of indiscernibles
        rows = lambda A: A[np.lexsort(A.T[::-1])]
        assert len(X) == len(Y) and np.allclose(rows(X), rows(Y))
    assert dxy <= gospa(X, Z, c, p)["gospa"] + gospa(Z, Y, c, p)["gospa"] + 1e-9


@settings(max_examples=100, deadline=None, derandomize=True)
@given(points, points, st.floats(0.5, 30.0), st.sampled_from([1.0, 2.0]))
def test_decomposition_adds_up_and_ospa_bounds(X, Y, c, p):
    g = gospa(X, Y, c, p)
    assert g["gospa"] ** p == pytest.approx(g["gospa_loc"] + c ** p / 2 * (g["gospa_missed"] + g["gospa_false"]),
                                            rel=1e-9, abs=1e-9)
    assert g["gospa_missed"] >= max(len(X) - len(Y), 0) and g["gospa_false"] >= max(len(Y) - len(X), 0)
    assert 0.0 <= g["ospa"] <= c + 1e-12


def test_gospa_by_hand():
    X = np.array([[0.0, 0.0], [10.0, 0.0]])
    Y = np.array([[0.0, 3.0], [50.0, 50.0], [11.0, 0.0]])
    g = gospa(X, Y, c=5.0, p=2.0)
    assert g["gospa_loc"] == pytest.approx(9.0 + 1.0)
    assert (g["gospa_missed"], g["gospa_false"]) == (0.0, 1.0)
    assert g["gospa"] == pytest.approx(math.sqrt(10.0 + 12.5))
    assert g["ospa"] == pytest.approx(math.sqrt((10.0 + 25.0) / 3))


# ------------------------------------------------------------------ Stone Soup as the oracle

def _stonesoup_sets(X, Y):
    from stonesoup.types.state import State
    t = datetime.datetime(2024, 1, 1)
    return ([State(np.array([[x], [0.0], [y], [0.0]]), timestamp=t) for x, y in Y],
            [State(np.array([[x], [0.0], [y], [0.0]]), timestamp=t) for x, y in X])


@settings(max_examples=80, deadline=None, derandomize=True)
@given(points, points, st.floats(0.5, 30.0), st.sampled_from([1.0, 2.0, 3.0]))
def test_gospa_equals_stonesoup(X, Y, c, p):
    ospametric = pytest.importorskip("stonesoup.metricgenerator.ospametric",
                                     reason="Stone Soup (the [peers] extra) is not installed")
    from stonesoup.measures import Euclidean
    tracks, truths = _stonesoup_sets(X, Y)
    if not tracks and not truths:
        return
    gen = ospametric.GOSPAMetric(c=c, p=p, measure=Euclidean(mapping=(0, 2)))
    theirs = gen.compute_gospa_metric(tracks, truths)[0].value
    ours = gospa(X, Y, c, p)
    assert ours["gospa"] == pytest.approx(theirs["distance"], rel=1e-9, abs=1e-9)
    assert ours["gospa_loc"] == pytest.approx(theirs["localisation"], rel=1e-9, abs=1e-9)
    assert ours["gospa_missed"] * c ** p / 2 == pytest.approx(theirs["missed"], rel=1e-9, abs=1e-9)
    assert ours["gospa_false"] * c ** p / 2 == pytest.approx(theirs["false"], rel=1e-9, abs=1e-9)


@settings(max_examples=80, deadline=None, derandomize=True)
@given(points, points, st.floats(0.5, 30.0), st.sampled_from([1.0, 2.0]))
def test_ospa_equals_stonesoup(X, Y, c, p):
    """Equal at p = 1. At p > 1 Stone Soup assigns by the sum of the distances,
    not of their p-th powers as the OSPA definition does, so ours (the optimum)
    is at most theirs."""
    ospametric = pytest.importorskip("stonesoup.metricgenerator.ospametric",
                                     reason="Stone Soup (the [peers] extra) is not installed")
    from stonesoup.measures import Euclidean
    tracks, truths = _stonesoup_sets(X, Y)
    if not tracks and not truths:
        return
    theirs = ospametric.OSPAMetric(c=c, p=p, measure=Euclidean(mapping=(0, 2))).compute_OSPA_distance(
        tracks, truths).value
    ours = gospa(X, Y, c, p)["ospa"]
    if p == 1.0:
        assert ours == pytest.approx(theirs, rel=1e-9, abs=1e-9)
    else:
        assert ours <= theirs + 1e-9


# ------------------------------------------------------------------ track-level metrics

def _scene(K=6):
    """Two targets: 0 present at every scan, 1 from scan 2 on."""
    truth = np.full((1, K, 2, 4), np.nan)
    truth[0, :, 0] = [0.0, 0.0, 0.0, 0.0]
    truth[0, 2:, 1] = [100.0, 0.0, 0.0, 0.0]
    return truth


def test_track_metrics_by_hand():
    K, J = 6, 3
    truth = _scene(K)
    state = np.full((1, K, J, 4), np.nan)
    ids = np.full((1, K, J), -1, np.int64)
    status = np.zeros((1, K, J), np.int8)

    def put(k, j, tid, x, st=2):
        state[0, k, j] = [x, 0.0, 0.0, 0.0]
        ids[0, k, j], status[0, k, j] = tid, st

    for k in range(K):                        # target 0: track 7 at scans 0-2, lost at 3, track 8 from 4 on
        if k <= 2:
            put(k, 0, 7, 1.0)
        elif k >= 4:
            put(k, 0, 8, -1.0)
    put(2, 1, 9, 100.0, st=1)                 # target 1: tentative at 2 (not scored), confirmed from 3 on
    for k in range(3, K):
        put(k, 1, 9, 101.0)
    for k in range(1, 4):                     # a false track
        put(k, 2, 11, 500.0)
    m = multitarget_trial_metrics(truth, state, ids, status, position_index=(0, 2), cutoff=10.0, order=2.0,
                                  scan_period_s=600.0)
    assert m["targets"][0] == 2 and m["targets_initiated"][0] == 2
    assert m["init_delay_sum"][0] == 0 + 1 and m["init_delay_scans"][0] == 0.5
    assert m["confirmed_tracks"][0] == 4 and m["false_tracks"][0] == 1
    assert m["false_track_rate_per_h"][0] == pytest.approx(1.0)          # one in 6 x 600 s = 1 h
    assert m["track_breaks"][0] == 1 and m["id_switches"][0] == 1
    assert m["purity"][0] == pytest.approx(1.0)
    np.testing.assert_array_equal(m["gospa_missed"][0], [0, 0, 1, 1, 0, 0])
    np.testing.assert_array_equal(m["gospa_false"][0], [0, 1, 1, 1, 0, 0])
    assert m["gospa_m"][0] == pytest.approx(math.sqrt(np.mean(m["gospa"][0] ** 2)))


def test_purity_of_a_track_that_jumps_targets():
    K = 4
    truth = np.full((1, K, 2, 4), np.nan)
    truth[0, :, 0] = [0.0, 0.0, 0.0, 0.0]
    truth[0, :, 1] = [100.0, 0.0, 0.0, 0.0]
    state = np.full((1, K, 1, 4), np.nan)
    state[0, :, 0, 0] = [0.0, 0.0, 0.0, 100.0]
    state[0, :, 0, 1:] = 0.0
    ids, status = np.zeros((1, K, 1), np.int64), np.full((1, K, 1), 2, np.int8)
    m = multitarget_trial_metrics(truth, state, ids, status, position_index=(0, 2), cutoff=10.0, order=2.0,
                                  scan_period_s=60.0)
    assert m["purity"][0] == pytest.approx(0.75) and m["false_tracks"][0] == 0
    assert m["id_switches"][0] == 0 and m["track_breaks"][0] == 1        # target 0 lost at scan 3
    assert m["init_delay_scans"][0] == 1.5 and m["targets_initiated"][0] == 2      # delays 0 and 3


def test_summary_columns():
    import pandas as pd
    rng = np.random.default_rng(0)
    n = 30
    trials = pd.DataFrame({"scenario": "s", "method": "m", "config": "c", "params": "{}", "snr_db": 0.0,
                           "realised_snr_db": np.nan, "gospa_m": rng.uniform(1, 2, n),
                           "gospa_loc_m": 1.0, "missed_per_scan": 0.1, "false_per_scan": 0.2, "ospa_m": 1.0,
                           "false_track_rate_per_h": 0.5, "track_breaks": 1, "id_switches": 0, "purity": 1.0,
                           "init_delay_sum": 6.0, "targets_initiated": 3, "targets": 4})
    s = summarise_multitarget(trials, {}).iloc[0]
    assert s.n_trials == n and s.gospa_low <= s.gospa_mean <= s.gospa_high
    assert s.init_delay_mean == 2.0 and s.initiated_fraction == 0.75
