"""False tracks of ``jpda-ukf`` in clutter alone (Pd = 0) against the M/N
logic's prediction from the gate volumes.

**Derivation.** With no target, every plot is clutter: Poisson with density λ
per unit volume of (range, azimuth, radial velocity), uniform over the box B,
independent from scan to scan. A tentative track at M/N frame f has the
validation gate G_f = {z : (z − ẑ)' S⁻¹ (z − ẑ) ≤ γ}, an ellipsoid of volume
V_f = (4/3) π γ^{3/2} √det S, fixed by the track's past. It has a hit iff at
least one plot falls in A_f = G_f ∩ B outside every confirmed track's gate
(plots in confirmed gates are used up first; those gates, too, are fixed by
the past), so given the past

    P(hit at frame f | past) = p_f = 1 − exp(−λ |A_f|).

1. *Hits.* The hits minus the p_f, summed over every tentative frame of every
   track, is a martingale: its mean is 0 and its variance Σ p_f (1 − p_f)
   (the increments are uncorrelated). The observed hits must lie within
   ±4.5 standard deviations of Σ p_f (p_f computed from each realised gate;
   |A_f| by 1 000+ fixed points of the unit ball mapped into the gate).
2. *Confirmations.* A tentative track is confirmed iff it has at least M
   hits in its N frames, and dropped early only when M hits are out of reach:
   checked track by track on the recorded hits, so the confirmed count is
   exactly the M/N function of hit sequences whose rate (1.) is the gate
   volumes'. A closed-form interval for the count itself follows by coupling:
   with every p_f in [p_lo, p_hi] a track's hits lie between Bin(N, p_lo) and
   Bin(N, p_hi) in the stochastic order, so its confirmation probability lies
   in [q(p_lo), q(p_hi)], q(p) = P(Bin(N, p) ≥ M). Here, as in any HFSWR
   scene, the gates of two-point tracks vary too much for it to say anything
   (p_f from 0 at the region's edges to ~1 for the first, widest gates: the
   interval is [0, n]), so the test checks 1. and the decision rule instead.
   Rules 2 and 3 are switched off (their bounds out of reach) so that only M/N
   decides.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.stats

from radarbench.methods.multitarget import kernels as kern
from radarbench.methods.multitarget.track_management import TrackerParams, tracker_models

REGION = np.array([[50e3, 150e3], [-math.radians(30), math.radians(30)], [-20.0, 20.0]])
SIGMA = np.array([300.0, math.radians(1.0), 0.2])


def _ball_points(per_axis: int = 14) -> np.ndarray:
    g = (np.arange(per_axis) + 0.5) / per_axis * 2 - 1
    u = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    return u[np.sum(u * u, axis=1) <= 1.0]


def _free_gate_volume(zhat, S, gamma, ball, taken) -> float:
    """|A| = |G ∩ B minus the confirmed gates| of the gate of (ẑ, S); ``taken``: (ẑ, S⁻¹) of the confirmed tracks."""
    L = np.linalg.cholesky(S)
    pts = zhat + math.sqrt(gamma) * ball @ L.T
    free = np.all((pts >= REGION[:, 0]) & (pts <= REGION[:, 1]), axis=1)
    for zc, Sinv in taken:
        nu = pts - zc
        nu[:, 1] = (nu[:, 1] + math.pi) % (2 * math.pi) - math.pi
        free &= np.einsum("pi,ij,pj->p", nu, Sinv, nu) > gamma
    return 4.0 / 3.0 * math.pi * gamma ** 1.5 * math.sqrt(np.linalg.det(S)) * free.mean()


@pytest.mark.slow                     # a false-track count large enough for its binomial tolerance
@pytest.mark.parametrize("M, N, clutter_per_scan", [(2, 3, 300.0), (3, 4, 600.0)])
def test_false_confirmations_follow_the_mn_prediction(M, N, clutter_per_scan):
    volume = float(np.prod(np.diff(REGION, axis=1)))
    lam = clutter_per_scan / volume
    scene = type("Scene", (), dict(scan_period_s=60.0, measurement_std=SIGMA, pd=0.0, clutter_density=lam,
                                   speed_bounds_m_s=(1.0, 15.0), sensor_xy=np.zeros(2), accel_std_m_s2=0.002))
    params = TrackerParams(confirm_m=M, confirm_n=N, max_speed_m_s=1e4, max_position_std_m=1e7, max_tracks=4096)
    models = tracker_models(scene, params, kern.UKF)
    ball = _ball_points()
    rng = np.random.default_rng(20240 + M)
    frames: dict[tuple[int, int], list] = {}            # (trial, track id) -> [(p_f, hit)]
    outcome: dict[tuple[int, int], bool] = {}           # decided tracks: confirmed?
    for trial in range(2):
        tab = kern.new_table(params.max_tracks, 2000)
        kern.reset_table(tab)
        for _k in range(25):
            m = rng.poisson(clutter_per_scan)
            z = REGION[:, 0] + np.diff(REGION, axis=1)[:, 0] * rng.random((m, 3))
            free = np.ones(m, np.bool_)
            kern.predict_all(tab, models.F, models.Q, models.R, models.Wm, models.Wc, models.cfg, models.icfg)
            tentative = np.nonzero(tab.status == kern.TENTATIVE)[0]
            taken = [(tab.zhat[s].copy(), tab.Sinv[s].copy()) for s in np.nonzero(tab.status == kern.CONFIRMED)[0]]
            p_now = [1.0 - math.exp(-lam * _free_gate_volume(tab.zhat[s], tab.S[s], models.gamma, ball, taken))
                     for s in tentative]
            kern.jpda_stage(tab, kern.CONFIRMED, z, m, free, models.cfg, models.icfg)
            kern.jpda_stage(tab, kern.TENTATIVE, z, m, free, models.cfg, models.icfg)
            for s, p in zip(tentative, p_now):
                frames.setdefault((trial, int(tab.tid[s])), []).append((p, bool(tab.hit[s])))
            kern.manage(tab, models.cfg, models.icfg)
            for s in tentative:
                if tab.status[s] != kern.TENTATIVE:
                    outcome[(trial, int(tab.tid[s]))] = tab.status[s] == kern.CONFIRMED
            kern.initiate(tab, z, m, free, models.cfg, models.icfg)
            tab.status[tab.status == kern.TERMINATED] = kern.EMPTY
    assert len(outcome) > 300
    p = np.array([pf for track in frames.values() for pf, _ in track])
    hits = sum(h for track in frames.values() for _, h in track)
    assert abs(hits - p.sum()) <= 4.5 * math.sqrt(np.sum(p * (1 - p))), (hits, p.sum())
    for key, confirmed in outcome.items():                  # the M/N decision from the hits
        h = [hit for _, hit in frames[key]]
        assert confirmed == (sum(h) >= M and len(h) == N), (key, h, confirmed)
        assert len(h) == N or sum(h) + N - len(h) < M       # early only when M is out of reach
