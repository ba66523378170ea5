"""Compiled scan loop of the multi-target trackers (``jpda-ukf``, ``gnn-ekf``;
:mod:`methods.multitarget.trackers`): prediction, gating, JPDA association, track
management (M/N initiation, the three termination rules), recording.

After the HFSWR tracking chapter ("目标检测与跟踪方法 (Target detection and
tracking methods), 海洋遥感技术应用"), section 2(2) (航迹管理, track
management). One scan k of one trial:

1. **Predict** every live track: the UKF of :mod:`models.ukf` (``jpda-ukf``'s
   default) or an EKF (``gnn-ekf``'s default; the ``filter`` parameter:
   x⁻ = F x, P⁻ = F P F' + Q, H = ∂h/∂x at x⁻, ẑ = h(x⁻), S = H P⁻ H' + R,
   P_xz = P⁻ H'), giving ẑ_t, S_t, P_xz per track.
2. **Gate** (eq. 6.72, the ellipsoidal validation region): plot z_i is
   validated for track t when ν' S_t⁻¹ ν ≤ γ, ν = z_i − ẑ_t (azimuth
   wrapped), γ the χ²(3) quantile of the gate probability P_G.
3. **Associate and update**, confirmed tracks first on every plot, then
   tentative tracks on the plots no confirmed gate holds (Stone Soup's
   ``MultiMeasurementInitiator`` does the same: its holding tracks see only
   the plots the main tracker left). JPDA (:mod:`methods.multitarget.jpda`, per cluster
   of tracks sharing plots) weights the UKF updates (eq. 6.73):
   x_t = Σ_{i=0}^{m_t} β_it x̂_t(i), x̂_t(0) = x⁻, and (eq. 6.74)
   P_t = Σ_i β_it [P_t(i) + (x̂_t(i) − x_t)(x̂_t(i) − x_t)'], P_t(0) = P⁻.
   GNN (``gnn-ekf``) assigns plots to tracks with
   ``scipy.optimize.linear_sum_assignment`` in Python between two compiled
   calls (:func:`stage_gate`, :func:`apply_assignment`). A track has a *hit*
   when a plot fell in its gate (JPDA) or was assigned to it (GNN); every
   plot inside a gate of the stage is used up.
4. **Manage**: a tentative track counts its hits over the N frames after its
   two initial plots (frames 3 … N + 2, "从第三次扫描开始, 采用 M/N 逻辑") and
   is confirmed at frame N + 2 with at least M hits, else dropped (early, as
   soon as M hits are out of reach: the same tracks are confirmed); our
   variant ``confirmation = "kth-plot"`` (Stone Soup's
   ``MultiMeasurementInitiator``) confirms on the (M + 2)-th plot with no
   frame deadline and drops after N − M + 1 consecutive misses. A track
   ends (status 3) when ① M_t of its last N_t frames had no plot (confirmed
   tracks), ② its position uncertainty, the square root of the largest
   eigenvalue of its (x, y) covariance, exceeds a bound, or ③ its speed
   exceeds an impossible v_max: the rules of "一条确认航迹被终结" (a *confirmed*
   track is terminated); a tentative track answers to M/N alone (its
   two-point velocity, with a cross-range std of ~40 m/s at 100 km, would
   often fail rule ③ before its first update).
5. **Initiate**: every plot left over at scan k − 1 is a track head ("每一个
   未关联的量测都作为新的航迹头"); a plot of scan k left over by steps 3 forms
   an initial track with a head when their distance d satisfies
   v_min T − g σ_d ≤ d ≤ v_max T + g σ_d (the gate from the minimum and
   maximum target speed and the noise), σ_d² = σ_p,1² + σ_p,2², σ_p of a plot
   the larger semi-axis max(σ_r, r σ_az) of its position error. Pairs are taken
   greedily in order of range-rate consistency |Δr / T − (v_r,1 + v_r,2)/2|
   (our choice: the chapter does not say which plot a head takes when several
   fall in its gate), each plot and head once. The two plots initialise the
   filter ("这两个点可以用来初始化无味卡尔曼滤波器") by two-point differencing
   (Bar-Shalom, Li & Kirubarajan 2001, sec. 5.5.3): position from the second
   plot, velocity (p₂ − p₁)/T, covariance from the plots' Cartesian error
   covariances R₁, R₂: P_pp = R₂, P_vv = (R₁ + R₂)/T², P_pv = R₂/T (at
   100 km with σ_az = 1° the cross-range velocity std is ~40 m/s; our variant
   ``initial_velocity = "two-point+speed-prior"`` fuses it with N(0, v_max² I),
   :func:`speed_prior`, the prior Stone Soup's initiator starts from). Plots
   still unused become the heads of scan k + 1; a head that takes no plot is
   dropped ("否则, 该航迹被撤销").
6. **Record** every occupied slot; a terminated slot is shown once (status 3)
   and freed.

Tracks live in a fixed-capacity table (:class:`TrackTable`); a new track
takes the lowest free slot, or is dropped and counted when the table is full.
docs/architecture.md, 'Performance': one trial at a time in compiled code.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from radarbench.methods.multitarget.jpda import jpda_marginals
from radarbench.models.ukf import (
    inverse_and_logdet,
    kalman_gain,
    sigma_points,
    unscented_covariance,
    unscented_mean,
    updated_covariance,
    wrap,
)

# Constants a kernel passes to another are NumPy scalars, not Python ints: numba types a Python
# int constant as its literal value and compiles the callee once per value (jpda_stage for
# CONFIRMED and again for TENTATIVE), where a typed scalar shares one compilation.
EMPTY, TENTATIVE, CONFIRMED, TERMINATED = (np.int8(status) for status in range(4))     # TrackTable.status
UKF, EKF = 0, 1
CONFIRM_AT_FRAME_N_PLUS_2, CONFIRM_ON_KTH_PLOT = 0, 1     # TrackerParams' confirmation rules
AZIMUTH = np.int64(1)             # the angle component of a plot [range, azimuth, radial velocity]
NO_ANGLE = np.int64(-1)           # a state: no component is an angle (models.ukf.unscented_mean)

# cfg (float64) entries
C_DT, C_LOG_PD, C_LOG_MISS, C_LOG_LAMBDA, C_GAMMA, C_VMIN, C_VMAX, C_INIT_SIGMAS, C_MAX_POS_STD, \
    C_MAX_SPEED, C_SX, C_SY, C_SIG_R, C_SIG_AZ, C_ZETA = range(15)
N_CFG = 15
# icfg (int64) entries
I_CONFIRM_M, I_CONFIRM_N, I_TERM_M, I_TERM_N, I_MAX_CLUSTER, I_FILTER, I_SPEED_PRIOR, I_CONFIRM_RULE = range(8)
N_ICFG = 8
# counters (int64) entries: the trace of a trial
K_HEADS, K_NEXT_ID, K_PDA_CLUSTERS, K_EXACT_CLUSTERS, K_DROPPED, K_SLOTS, K_LARGEST_CLUSTER, K_BAD_COV, \
    K_CONFIRMED, K_END_MISSES, K_END_COVARIANCE, K_END_SPEED = range(12)
N_COUNTERS = 12
COUNTER_NAMES = ("heads", "tracks_started", "pda_fallback_clusters", "exact_clusters", "dropped_tracks",
                 "slots_used", "largest_cluster", "nonpositive_covariance", "tracks_confirmed",
                 "ended_by_misses", "ended_by_covariance", "ended_by_speed")


class TrackTable(NamedTuple):
    """The tracks of one trial (capacity C) and their per-scan predictions."""

    x: np.ndarray            # (C, 4) state [x, vx, y, vy]
    P: np.ndarray            # (C, 4, 4) covariance
    status: np.ndarray       # (C,) int8 EMPTY / TENTATIVE / CONFIRMED / TERMINATED
    tid: np.ndarray          # (C,) int64 identity
    miss_history: np.ndarray  # (C,) int64: bit b set = no plot b scans ago (bit 0: this scan)
    mn_frames: np.ndarray    # (C,) int64 M/N frames seen (tentative)
    mn_hits: np.ndarray      # (C,) int64 M/N frames with a plot (tentative)
    hit: np.ndarray          # (C,) bool: a plot this scan
    zhat: np.ndarray         # (C, 3) predicted measurement
    S: np.ndarray            # (C, 3, 3) its covariance
    Sinv: np.ndarray         # (C, 3, 3)
    logdet: np.ndarray       # (C,) log det S
    Pxz: np.ndarray          # (C, 4, 3) state-measurement cross covariance
    heads: np.ndarray        # (H, 3) plots left over at the previous scan
    counters: np.ndarray     # (N_COUNTERS,) int64


def new_table(capacity: int, max_plots: int) -> TrackTable:
    C = int(capacity)
    return TrackTable(x=np.zeros((C, 4)), P=np.zeros((C, 4, 4)), status=np.zeros(C, np.int8),
                      tid=np.full(C, -1, np.int64), miss_history=np.zeros(C, np.int64),
                      mn_frames=np.zeros(C, np.int64), mn_hits=np.zeros(C, np.int64),
                      hit=np.zeros(C, np.bool_), zhat=np.zeros((C, 3)), S=np.zeros((C, 3, 3)),
                      Sinv=np.zeros((C, 3, 3)), logdet=np.zeros(C), Pxz=np.zeros((C, 4, 3)),
                      heads=np.zeros((max(int(max_plots), 1), 3)), counters=np.zeros(N_COUNTERS, np.int64))


@numba.njit(cache=True)
def reset_table(tab):  # pragma: no cover - compiled
    tab.status[:] = EMPTY
    tab.tid[:] = -1
    tab.counters[:] = 0


# --------------------------------------------------------------------- measurement (models/hfswr.py)

@numba.njit(cache=True)
def measure_one(x, sx, sy, out):  # pragma: no cover - compiled
    """h(x) of :func:`models.hfswr.measure` for one state: [range, azimuth
    atan2(dx, dy) clockwise from north, radial velocity positive receding]."""
    dx = x[0] - sx
    dy = x[2] - sy
    r = math.sqrt(dx * dx + dy * dy)
    out[0] = r
    out[1] = math.atan2(dx, dy)
    out[2] = (dx * x[1] + dy * x[3]) / r


@numba.njit(cache=True)
def jacobian_one(x, sx, sy, H):  # pragma: no cover - compiled
    """∂h/∂x (3, 4) of :func:`models.hfswr.measure_jacobian` for one state."""
    dx = x[0] - sx
    dy = x[2] - sy
    r2 = dx * dx + dy * dy
    r = math.sqrt(r2)
    vr = (dx * x[1] + dy * x[3]) / r
    H[:, :] = 0.0
    H[0, 0] = dx / r
    H[0, 2] = dy / r
    H[1, 0] = dy / r2
    H[1, 2] = -dx / r2
    H[2, 0] = (x[1] - vr * dx / r) / r
    H[2, 1] = dx / r
    H[2, 2] = (x[3] - vr * dy / r) / r
    H[2, 3] = dy / r


@numba.njit(cache=True)
def plot_position(z, sx, sy, out):  # pragma: no cover - compiled
    """(x, y) of a plot [range, azimuth, ...] (:func:`models.hfswr.plot_to_cartesian`)."""
    out[0] = sx + z[0] * math.sin(z[1])
    out[1] = sy + z[0] * math.cos(z[1])


@numba.njit(cache=True)
def plot_position_covariance(z, sig_r, sig_az, out):  # pragma: no cover - compiled
    """J diag(σ_r², σ_az²) J' (2, 2), J = ∂(x, y)/∂(r, az) at the plot."""
    s, c, r = math.sin(z[1]), math.cos(z[1]), z[0]
    j00, j01, j10, j11 = s, r * c, c, -r * s
    a, b = sig_r * sig_r, sig_az * sig_az
    out[0, 0] = j00 * j00 * a + j01 * j01 * b
    out[0, 1] = j00 * j10 * a + j01 * j11 * b
    out[1, 0] = out[0, 1]
    out[1, 1] = j10 * j10 * a + j11 * j11 * b


# --------------------------------------------------------------------- prediction

@numba.njit(cache=True)
def ukf_predict(tab, s, F, Q, R, Wm, Wc, zeta, sx, sy):  # pragma: no cover - compiled
    """UKF prediction of slot ``s`` (models/ukf.py): x⁻, P⁻ into the table,
    then ẑ, S, P_xz from sigma points redrawn from (x⁻, P⁻). False if a
    covariance is not positive definite."""
    n = 4
    npts = 2 * n + 1
    L = np.zeros((n, n))
    chi = np.empty((npts, n))
    if not sigma_points(tab.x[s], tab.P[s], zeta, L, chi):
        return False
    chif = chi @ F.T                                      # χ_i⁻ = F χ_i (the CV transition)
    xm = np.empty(n)
    unscented_mean(chif, Wm, NO_ANGLE, xm)
    Pm = np.empty((n, n))
    unscented_covariance(chif, xm, chif, xm, Wc, NO_ANGLE, Pm)
    Pm = 0.5 * (Pm + Pm.T) + Q
    tab.x[s] = xm
    tab.P[s] = Pm
    if not sigma_points(xm, Pm, zeta, L, chi):          # redrawn around the prediction
        return False
    Z = np.empty((npts, 3))
    for i in range(npts):
        measure_one(chi[i], sx, sy, Z[i])
    unscented_mean(Z, Wm, AZIMUTH, tab.zhat[s])
    unscented_covariance(Z, tab.zhat[s], Z, tab.zhat[s], Wc, AZIMUTH, tab.S[s])
    for a in range(3):
        for b in range(3):
            tab.S[s, a, b] += R[a, b]
    unscented_covariance(Z, tab.zhat[s], chi, xm, Wc, AZIMUTH, tab.Pxz[s])
    return True


@numba.njit(cache=True)
def ekf_predict(tab, s, F, Q, R, sx, sy):  # pragma: no cover - compiled
    """EKF prediction of slot ``s``: x⁻ = F x, P⁻ = F P F' + Q, ẑ = h(x⁻),
    S = H P⁻ H' + R, P_xz = P⁻ H' with H = ∂h/∂x at x⁻ (models/hfswr.py)."""
    xm = F @ tab.x[s]
    Pm = F @ tab.P[s] @ F.T + Q
    Pm = 0.5 * (Pm + Pm.T)
    tab.x[s] = xm
    tab.P[s] = Pm
    H = np.empty((3, 4))
    jacobian_one(xm, sx, sy, H)
    measure_one(xm, sx, sy, tab.zhat[s])
    tab.Pxz[s] = Pm @ H.T
    tab.S[s] = H @ tab.Pxz[s] + R
    return True


@numba.njit(cache=True)
def predict_all(tab, F, Q, R, Wm, Wc, cfg, icfg):  # pragma: no cover - compiled
    """Step 1 for every live slot; a slot whose covariance is not positive
    definite is terminated (counted)."""
    for s in range(tab.status.shape[0]):
        if tab.status[s] != TENTATIVE and tab.status[s] != CONFIRMED:
            continue
        tab.hit[s] = False
        if icfg[I_FILTER] == UKF:
            ok = ukf_predict(tab, s, F, Q, R, Wm, Wc, cfg[C_ZETA], cfg[C_SX], cfg[C_SY])
        else:
            ok = ekf_predict(tab, s, F, Q, R, cfg[C_SX], cfg[C_SY])
        if ok:
            tab.logdet[s] = inverse_and_logdet(tab.S[s], tab.Sinv[s])
            ok = tab.logdet[s] > -np.inf
        if not ok:
            tab.status[s] = TERMINATED
            tab.counters[K_BAD_COV] += 1


# --------------------------------------------------------------------- gating and association

@numba.njit(cache=True)
def innovation(tab, s, z, nu):  # pragma: no cover - compiled
    for a in range(3):
        nu[a] = z[a] - tab.zhat[s, a]
    nu[AZIMUTH] = wrap(nu[AZIMUTH])


@numba.njit(cache=True)
def mahalanobis2(tab, s, nu):  # pragma: no cover - compiled
    d2 = 0.0
    for a in range(3):
        for b in range(3):
            d2 += nu[a] * tab.Sinv[s, a, b] * nu[b]
    return d2


@numba.njit(cache=True)
def stage_gate(tab, stage, z, n_plots, free, gamma):  # pragma: no cover - compiled
    """Step 2 for the tracks of ``stage`` (status) and the free plots:
    ``(slots (t,), plots (m,), d2 (t, m))``, d2 = ν' S⁻¹ ν where ν' S⁻¹ ν ≤ γ,
    +inf outside the gate; only plots inside some gate are listed."""
    C = tab.status.shape[0]
    nslots = 0
    slots_all = np.empty(C, np.int64)
    for s in range(C):
        if tab.status[s] == stage:
            slots_all[nslots] = s
            nslots += 1
    slots = slots_all[:nslots]
    d2_all = np.full((nslots, n_plots), np.inf)
    nu = np.empty(3)
    gated_plot = np.zeros(n_plots, np.bool_)
    for j in range(nslots):
        s = slots[j]
        for i in range(n_plots):
            if not free[i]:
                continue
            innovation(tab, s, z[i], nu)
            d2 = mahalanobis2(tab, s, nu)
            if d2 <= gamma:
                d2_all[j, i] = d2
                gated_plot[i] = True
    plots = np.nonzero(gated_plot)[0]
    return slots, plots, d2_all[:, plots].copy()


@numba.njit(cache=True)
def _find(parent, a):  # pragma: no cover - compiled
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@numba.njit(cache=True)
def jpda_stage(tab, stage, z, n_plots, free, cfg, icfg):  # pragma: no cover - compiled
    """Step 3 by JPDA for the tracks of ``stage``: clusters of tracks linked
    by shared plots (union-find), their marginals (:func:`methods.multitarget.jpda.jpda_marginals`),
    the mixture update of eqs. 6.73–6.74 for each track."""
    slots, plots, d2 = stage_gate(tab, stage, z, n_plots, free, cfg[C_GAMMA])
    t, m = d2.shape
    parent = np.arange(t)
    for i in range(m):
        first = np.int64(-1)                         # typed: a literal -1 would compile _find for it
        for j in range(t):
            if d2[j, i] < np.inf:
                if first < 0:
                    first = j
                else:
                    ra, rb = _find(parent, first), _find(parent, j)
                    if ra != rb:
                        parent[rb] = ra
    for j in range(t):
        parent[j] = _find(parent, j)
    log_norm = -1.5 * math.log(2.0 * math.pi)
    for root in range(t):
        members = np.nonzero(parent == root)[0]
        if members.shape[0] == 0:
            continue
        cols = np.zeros(m, np.bool_)
        for j in members:
            for i in range(m):
                if d2[j, i] < np.inf:
                    cols[i] = True
        cplots = np.nonzero(cols)[0]
        tc, mc = members.shape[0], cplots.shape[0]
        beta = np.zeros((tc, mc + 1))
        if mc == 0:
            beta[:, 0] = 1.0
        else:
            valid = np.zeros((tc, mc), np.bool_)
            loglik = np.full((tc, mc), -np.inf)
            for a in range(tc):
                s = slots[members[a]]
                for b in range(mc):
                    v = d2[members[a], cplots[b]]
                    if v < np.inf:
                        valid[a, b] = True
                        loglik[a, b] = log_norm - 0.5 * tab.logdet[s] - 0.5 * v
            exact = jpda_marginals(valid, loglik, cfg[C_LOG_PD], cfg[C_LOG_MISS], cfg[C_LOG_LAMBDA],
                                   icfg[I_MAX_CLUSTER], beta)
            tab.counters[K_EXACT_CLUSTERS if exact else K_PDA_CLUSTERS] += 1
            tab.counters[K_LARGEST_CLUSTER] = max(tab.counters[K_LARGEST_CLUSTER], tc * mc)
        for a in range(tc):
            s = slots[members[a]]
            idx = np.empty(mc, np.int64)
            nvalid = 0
            for b in range(mc):
                if d2[members[a], cplots[b]] < np.inf:
                    idx[nvalid] = b
                    nvalid += 1
            tab.hit[s] = nvalid > 0
            if nvalid > 0:
                rows = np.empty(nvalid, np.int64)
                weights = np.empty(nvalid)
                for v in range(nvalid):
                    rows[v] = plots[cplots[idx[v]]]
                    weights[v] = beta[a, 1 + idx[v]]
                mixture_update(tab, s, z, rows, beta[a, 0], weights)
    for i in range(m):
        free[plots[i]] = False


@numba.njit(cache=True)
def mixture_update(tab, s, z, plot_rows, beta0, betas):  # pragma: no cover - compiled
    """Eqs. 6.73–6.74: x = Σ β_i x̂(i), P = Σ β_i [P(i) + (x̂(i) − x)(x̂(i) − x)'],
    i = 0 the prediction (x⁻, P⁻), i ≥ 1 the UKF/EKF update with plot i."""
    K = kalman_gain(tab.Pxz[s], tab.Sinv[s])
    Pupd = updated_covariance(tab.P[s], K, tab.S[s])
    n = plot_rows.shape[0]
    xs = np.empty((n + 1, 4))
    xs[0] = tab.x[s]
    nu = np.empty(3)
    for i in range(n):
        innovation(tab, s, z[plot_rows[i]], nu)
        xs[i + 1] = tab.x[s] + K @ nu
    w = np.empty(n + 1)
    w[0] = beta0
    w[1:] = betas
    x = np.zeros(4)
    for i in range(n + 1):
        x += w[i] * xs[i]
    P = beta0 * tab.P[s] + (1.0 - beta0) * Pupd
    for i in range(n + 1):
        d = xs[i] - x
        P += w[i] * np.outer(d, d)
    tab.x[s] = x
    tab.P[s] = 0.5 * (P + P.T)


@numba.njit(cache=True)
def apply_assignment(tab, slots, plots, assigned, z, free):  # pragma: no cover - compiled
    """Step 3 by GNN: the track in ``slots[j]`` is updated with plot
    ``plots[assigned[j]]`` (−1: none, the prediction stands); every plot of
    ``plots`` (all inside some gate) is used up."""
    for j in range(slots.shape[0]):
        s = slots[j]
        a = assigned[j]
        tab.hit[s] = a >= 0
        if a >= 0:
            rows = np.empty(1, np.int64)
            rows[0] = plots[a]
            mixture_update(tab, s, z, rows, 0.0, np.ones(1))
    for i in range(plots.shape[0]):
        free[plots[i]] = False


# --------------------------------------------------------------------- management

@numba.njit(cache=True)
def _popcount(v):  # pragma: no cover - compiled
    c = 0
    while v:
        v &= v - 1
        c += 1
    return c


@numba.njit(cache=True)
def position_std(P):  # pragma: no cover - compiled
    """√ of the largest eigenvalue of the (x, y) block of P [x, vx, y, vy]."""
    a, b, d = P[0, 0], P[0, 2], P[2, 2]
    half_tr = 0.5 * (a + d)
    disc = math.sqrt(max(0.25 * (a - d) * (a - d) + b * b, 0.0))
    return math.sqrt(max(half_tr + disc, 0.0))


@numba.njit(cache=True)
def mn_rule(hits, frames, M, N):  # pragma: no cover - compiled
    """The chapter's step ⑤: (confirm, drop) of a tentative track with ``hits``
    in its first ``frames`` of the N frames 3 … N + 2; confirmed at frame N + 2
    with M hits, dropped there otherwise or as soon as M is out of reach."""
    if hits >= M and frames == N:
        return True, False
    return False, hits + (N - frames) < M or frames >= N


@numba.njit(cache=True)
def kth_plot_rule(hits, miss_history, M, N):  # pragma: no cover - compiled
    """Our variant (``confirmation = "kth-plot"``, the rule of Stone Soup's
    ``MultiMeasurementInitiator`` with ``min_points = M + 2`` and an
    ``UpdateTimeStepsDeleter`` of N − M + 1 steps): (confirm, drop) of a
    tentative track, confirmed on its (M + 2)-th plot (the two initial plots
    and M hits) whenever it comes, dropped after N − M + 1 consecutive misses
    (bit 0 of ``miss_history`` is this frame)."""
    if hits >= M:
        return True, False
    run = N - M + 1
    window = (1 << run) - 1
    return False, (miss_history & window) == window


@numba.njit(cache=True)
def manage(tab, cfg, icfg):  # pragma: no cover - compiled
    """Step 4: confirmation of tentative tracks (:func:`mn_rule`, or our
    :func:`kth_plot_rule`), the three termination rules."""
    M, N = icfg[I_CONFIRM_M], icfg[I_CONFIRM_N]
    term_mask = (1 << icfg[I_TERM_N]) - 1
    for s in range(tab.status.shape[0]):
        st = tab.status[s]
        if st != TENTATIVE and st != CONFIRMED:
            continue
        tab.miss_history[s] = ((tab.miss_history[s] << 1) | (0 if tab.hit[s] else 1)) & ((1 << 62) - 1)
        if st == TENTATIVE:
            tab.mn_frames[s] += 1
            tab.mn_hits[s] += 1 if tab.hit[s] else 0
            if icfg[I_CONFIRM_RULE] == CONFIRM_ON_KTH_PLOT:
                confirm, drop = kth_plot_rule(tab.mn_hits[s], tab.miss_history[s], M, N)
            else:
                confirm, drop = mn_rule(tab.mn_hits[s], tab.mn_frames[s], M, N)
            if confirm:
                tab.status[s] = CONFIRMED
                tab.counters[K_CONFIRMED] += 1
            elif drop:
                tab.status[s] = TERMINATED
            continue                                        # the termination rules are for confirmed tracks
        if _popcount(tab.miss_history[s] & term_mask) >= icfg[I_TERM_M]:      # rule ①
            tab.status[s] = TERMINATED
            tab.counters[K_END_MISSES] += 1
            continue
        if position_std(tab.P[s]) > cfg[C_MAX_POS_STD]:                           # rule ②
            tab.status[s] = TERMINATED
            tab.counters[K_END_COVARIANCE] += 1
        elif math.sqrt(tab.x[s, 1] ** 2 + tab.x[s, 3] ** 2) > cfg[C_MAX_SPEED]:  # rule ③
            tab.status[s] = TERMINATED
            tab.counters[K_END_SPEED] += 1


@numba.njit(cache=True)
def _free_slot(tab):  # pragma: no cover - compiled
    for s in range(tab.status.shape[0]):
        if tab.status[s] == EMPTY:
            return s
    return -1


@numba.njit(cache=True)
def speed_prior(tab, s, vmax):  # pragma: no cover - compiled
    """Our variant (``initial_velocity = "two-point+speed-prior"``): the
    two-point state fused with a velocity prior N(0, v_max² I), as a Kalman
    update with the pseudo-measurement v = 0 (H picks vx, vy; noise v_max² I)."""
    P = tab.P[s]
    S = np.empty((2, 2))
    PHt = np.empty((4, 2))
    for a in range(4):
        PHt[a, 0] = P[a, 1]
        PHt[a, 1] = P[a, 3]
    S[0, 0], S[0, 1], S[1, 0], S[1, 1] = P[1, 1] + vmax * vmax, P[1, 3], P[3, 1], P[3, 3] + vmax * vmax
    det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    Sinv = np.array([[S[1, 1], -S[0, 1]], [-S[1, 0], S[0, 0]]]) / det
    K = PHt @ Sinv
    v = np.array([tab.x[s, 1], tab.x[s, 3]])
    tab.x[s] = tab.x[s] - K @ v
    Pn = P - K @ S @ K.T
    tab.P[s] = 0.5 * (Pn + Pn.T)


@numba.njit(cache=True)
def start_track(tab, z1, z2, cfg, icfg):  # pragma: no cover - compiled
    """A tentative track from two plots (two-point differencing); False if
    the table is full (the track is dropped and counted)."""
    s = _free_slot(tab)
    if s < 0:
        tab.counters[K_DROPPED] += 1
        return False
    T, sx, sy = cfg[C_DT], cfg[C_SX], cfg[C_SY]
    p1, p2 = np.empty(2), np.empty(2)
    R1, R2 = np.empty((2, 2)), np.empty((2, 2))
    plot_position(z1, sx, sy, p1)
    plot_position(z2, sx, sy, p2)
    plot_position_covariance(z1, cfg[C_SIG_R], cfg[C_SIG_AZ], R1)
    plot_position_covariance(z2, cfg[C_SIG_R], cfg[C_SIG_AZ], R2)
    pos = (0, 2)
    for a in range(2):
        tab.x[s, pos[a]] = p2[a]
        tab.x[s, pos[a] + 1] = (p2[a] - p1[a]) / T
        for b in range(2):
            tab.P[s, pos[a], pos[b]] = R2[a, b]
            tab.P[s, pos[a], pos[b] + 1] = R2[a, b] / T
            tab.P[s, pos[a] + 1, pos[b]] = R2[a, b] / T
            tab.P[s, pos[a] + 1, pos[b] + 1] = (R1[a, b] + R2[a, b]) / (T * T)
    if icfg[I_SPEED_PRIOR]:
        speed_prior(tab, s, cfg[C_VMAX])
    tab.status[s] = TENTATIVE
    tab.tid[s] = tab.counters[K_NEXT_ID]
    tab.counters[K_NEXT_ID] += 1
    tab.miss_history[s] = 0
    tab.mn_frames[s] = 0
    tab.mn_hits[s] = 0
    tab.hit[s] = True
    tab.counters[K_SLOTS] = max(tab.counters[K_SLOTS], s + 1)
    return True


@numba.njit(cache=True)
def initiate(tab, z, n_plots, free, cfg, icfg):  # pragma: no cover - compiled
    """Step 5: heads of the previous scan × free plots of this one, the speed
    gate, greedy pairing by range-rate consistency; leftover plots become the
    next heads."""
    T, sx, sy = cfg[C_DT], cfg[C_SX], cfg[C_SY]
    g, sr, saz = cfg[C_INIT_SIGMAS], cfg[C_SIG_R], cfg[C_SIG_AZ]
    nh = tab.counters[K_HEADS]
    cand_h = np.empty(nh * n_plots, np.int64)
    cand_p = np.empty(nh * n_plots, np.int64)
    score = np.empty(nh * n_plots)
    nc = 0
    p1, p2 = np.empty(2), np.empty(2)
    for h in range(nh):
        plot_position(tab.heads[h], sx, sy, p1)
        s1 = max(sr, tab.heads[h, 0] * saz)
        for i in range(n_plots):
            if not free[i]:
                continue
            plot_position(z[i], sx, sy, p2)
            s2 = max(sr, z[i, 0] * saz)
            sd = g * math.sqrt(s1 * s1 + s2 * s2)
            d = math.sqrt((p2[0] - p1[0]) ** 2 + (p2[1] - p1[1]) ** 2)
            if cfg[C_VMIN] * T - sd <= d <= cfg[C_VMAX] * T + sd:
                cand_h[nc] = h
                cand_p[nc] = i
                score[nc] = abs((z[i, 0] - tab.heads[h, 0]) / T - 0.5 * (z[i, 2] + tab.heads[h, 2]))
                nc += 1
    order = np.argsort(score[:nc], kind="mergesort")
    head_used = np.zeros(nh, np.bool_)
    for c in order:
        h, i = cand_h[c], cand_p[c]
        if head_used[h] or not free[i]:
            continue
        head_used[h] = True
        free[i] = False
        start_track(tab, tab.heads[h], z[i], cfg, icfg)
    nh = 0
    for i in range(n_plots):
        if free[i]:
            tab.heads[nh] = z[i]
            nh += 1
    tab.counters[K_HEADS] = nh


@numba.njit(cache=True)
def record(tab, k, out_state, out_id, out_status, out_cov):  # pragma: no cover - compiled
    """Step 6: occupied slots at scan k into the outputs; terminated slots freed."""
    for s in range(tab.status.shape[0]):
        st = tab.status[s]
        if st == EMPTY:
            continue
        out_status[k, s] = st
        out_id[k, s] = tab.tid[s]
        out_state[k, s] = tab.x[s]
        out_cov[k, s, 0, 0] = tab.P[s, 0, 0]
        out_cov[k, s, 0, 1] = tab.P[s, 0, 2]
        out_cov[k, s, 1, 0] = tab.P[s, 2, 0]
        out_cov[k, s, 1, 1] = tab.P[s, 2, 2]
        if st == TERMINATED:
            tab.status[s] = EMPTY


@numba.njit(cache=True)
def jpda_trial(z, n_plots, F, Q, R, Wm, Wc, cfg, icfg, tab, out_state, out_id, out_status, out_cov):  # pragma: no cover
    """One trial of ``jpda-ukf`` (or JPDA with the EKF): steps 1–6 at every scan.
    z (K, P, 3), n_plots (K,); outputs (K, C, ...) pre-filled empty."""
    reset_table(tab)
    for k in range(z.shape[0]):
        m = n_plots[k]
        zk = z[k]
        free = np.ones(m, np.bool_)
        predict_all(tab, F, Q, R, Wm, Wc, cfg, icfg)
        jpda_stage(tab, CONFIRMED, zk, m, free, cfg, icfg)
        jpda_stage(tab, TENTATIVE, zk, m, free, cfg, icfg)
        manage(tab, cfg, icfg)
        initiate(tab, zk, m, free, cfg, icfg)
        record(tab, k, out_state, out_id, out_status, out_cov)
