"""numba kernel of ``dp-tbd-mf`` with ``likelihood = "along-track"`` (:mod:`methods.tbd.dp_tbd`).

The paper's index term at frame k is the log-ratio of the 3-D and 2-D joint
Gaussian densities of the values *along the hypothesised track*,
z_k(x_k), z_(k-1)(x_(k-1)), z_(k-2)(x_(k-2)) (eqs. 11-14). For a Gaussian the
ratio p3 / p2 is the conditional density of z_k(x_k) given the two earlier
values, so the H1-minus-H0 term is affine in the along-track residual

    r0 = z_k(x_k) - beta1 z_(k-1)(x_(k-1)) - beta2 z_(k-2)(x_(k-2)),
    Lambda_k = A r0 + B,   A = s c / sigma_c^2,   B = -(s c)^2 / (2 sigma_c^2),

c = 1 - beta1 - beta2 (all three values carry the mean s under H1). r0 reads
the cell of frame k-2, x_k - d_k - d_(k-1): the term depends on the
transition (d_(k-1), d_k), not only on the state (x_k, d_k). It separates:

    J_k(x, d) = A z_k(x) - A beta1 z_(k-1)(x - d) + B + M_k(x - d, d),
    M_k(y, d) = max_d' [G_k(y, d') + lp(d', d)],
    G_k(y, d') = J_(k-1)(y, d') - A beta2 z_(k-2)(y - d'),

so the cost per frame is that of the maximum over d' of a (D, H, W) volume
plus a weight table, (2q + 1)^4 additions and maxima per cell, fewer with
the heading classes: M_k(y, d) = CM_u(y) for every d of heading class u,
CM_u = max_(u') [max_(m in u') G_k(y, m) + L[u', u]] over *all* classes u'
(no d' is special here; :func:`methods.tbd.mf_kernels._heading_classes`).

Evaluation as in :func:`methods.tbd.mf_kernels._dp_tbd_mf`: max-only, a row
wavefront over the frames with rings of the last 2q + 1 rows, checkpoint
volumes of frames 1, 5, 9, ... and K - 1, and backtracking that recomputes
psi_k(x, d) = the first maximising d' (:func:`_predecessor`) from the column
J_(k-1)(x - d, :) (:func:`_column`), with the same float32 operations as the
forward pass, so the same bits. Conventions as in
:mod:`methods.tbd.kernels` (displacement numbering, float32 merits, first
maximum wins, one trial at a time).
"""

from __future__ import annotations

import numba
import numpy as np

from radarbench.methods.tbd.kernels import (
    NEG_INF,
    _check_finite,
    _fill,
    _first_argmax_2d,
    _fmax,
)
from radarbench.methods.tbd.mf_kernels import (
    _checkpoint_slots,
    _common_maxima,
    _heading_classes,
    _mf_start,
)


@numba.njit(cache=True, inline="always")
def _g_value(prev_v, a2b2, zk2_v):  # pragma: no cover - compiled
    """G = J_(k-1) - (a2 beta2) z_(k-2): the forward pass and the backtrack
    both call it, so they round identically."""
    return prev_v - a2b2 * zk2_v


@numba.njit(cache=True, inline="always")
def _j_value(a2, zk_v, a2b1, zk1_v, b2, m_v):  # pragma: no cover - compiled
    """J_k = a2 z_k(x) - (a2 beta1) z_(k-1)(x - d) + b2 + M, in that order."""
    return a2 * zk_v - a2b1 * zk1_v + b2 + m_v


@numba.njit(cache=True)
def _g_rows(J, zk2, y, H, W, a2b2, q, G):  # pragma: no cover - compiled
    """G[d', :] = G_k(y, d', :) = J_(k-1)(y, d', :) - a2 beta2 z_(k-2)(y - d')
    for one row y (J: (D, W') row y of J_(k-1)), -inf where y - d' is off
    the grid."""
    D = G.shape[0]
    w = 2 * q + 1
    for dp in range(D):
        dr = dp // w - q
        dc = dp % w - q
        lo = max(0, dc)
        hi = min(W, W + dc)
        o = G[dp]
        yp = y - dr
        if yp < 0 or yp >= H or lo >= hi:
            _fill(o, 0, W, NEG_INF)
            continue
        pr = J[dp, lo:hi]
        zr = zk2[yp, lo - dc:hi - dc]
        ol = o[lo:hi]
        for c in range(hi - lo):
            ol[c] = _g_value(pr[c], a2b2, zr[c])
        _fill(o, 0, lo, NEG_INF)
        _fill(o, hi, W, NEG_INF)


@numba.njit(cache=True)
def _at_row(zk, zk1, csrc, r, H, W, a2, a2b1, b2, q, cls, out):  # pragma: no cover - compiled
    """Row r of J_k, k >= 2 (out: (D, W')): J_k(x, d) = a2 z_k(x)
    - a2 beta1 z_(k-1)(x - d) + b2 + CM_(class of d)(x - d), ``csrc`` the
    ring (2q + 1, C, W') of the CM rows of frame k (row y in slot
    y mod (2q + 1)); -inf where x - d is off the grid."""
    D = out.shape[0]
    S = csrc.shape[0]
    w = 2 * q + 1
    zr = zk[r]
    for d in range(D):
        dr = d // w - q
        dc = d % w - q
        rp = r - dr
        o = out[d]
        lo = max(0, dc)
        hi = min(W, W + dc)
        if rp < 0 or rp >= H or lo >= hi:
            _fill(o, 0, W, NEG_INF)
            continue
        z1 = zk1[rp, lo - dc:hi - dc]
        m = csrc[rp % S, cls[d], lo - dc:hi - dc]
        zl = zr[lo:hi]
        ol = o[lo:hi]
        for c in range(hi - lo):
            ol[c] = _j_value(a2, zl[c], a2b1, z1[c], b2, m[c])
        _fill(o, 0, lo, NEG_INF)
        _fill(o, hi, W, NEG_INF)


@numba.njit(cache=True)
def _at_row1(zt, j0, r, a1, rho1, b1, lp_first, q, out):  # pragma: no cover - compiled
    """Row r of J_1(x, d) = a1 (z_1(x) - rho1 z_0(x - d)) + b1 + lp_first
    + J_0(x - d), -inf where x - d is off the grid."""
    H, W = j0.shape
    D = out.shape[0]
    w = 2 * q + 1
    for d in range(D):
        dr = d // w - q
        dc = d % w - q
        rp = r - dr
        o = out[d]
        lo = max(0, dc)
        hi = min(W, W + dc)
        if rp < 0 or rp >= H or lo >= hi:
            _fill(o, 0, W, NEG_INF)
            continue
        z1 = zt[1, r, lo:hi]
        z0 = zt[0, rp, lo - dc:hi - dc]
        jr = j0[rp, lo - dc:hi - dc]
        ol = o[lo:hi]
        for c in range(hi - lo):
            ol[c] = a1 * (z1[c] - rho1 * z0[c]) + b1 + lp_first + jr[c]
        _fill(o, 0, lo, NEG_INF)
        _fill(o, hi, W, NEG_INF)


@numba.njit(cache=True)
def _g_column(P, zk2, yr, yc, a2b2, q, H, W):  # pragma: no cover - compiled
    """G_k(y, :) (D,) from P = J_(k-1)(y, :); -inf where y - d' is off the grid."""
    D = P.shape[0]
    w = 2 * q + 1
    g = np.full(D, NEG_INF, np.float32)
    for dp in range(D):
        sr = yr - (dp // w - q)
        sc = yc - (dp % w - q)
        if 0 <= sr < H and 0 <= sc < W:
            g[dp] = _g_value(P[dp], a2b2, zk2[sr, sc])
    return g


@numba.njit(cache=True)
def _predecessor(g, lp, d):  # pragma: no cover - compiled
    """psi_k(x, d) from g = G_k(x - d, :): the first d' maximising
    g[d'] + lp[d', d] (increasing d', strictly larger wins, as the original
    max + argmax pass)."""
    D = lp.shape[0]
    best = NEG_INF
    arg = 0
    for dp in range(D):
        v = g[dp] + lp[dp, d]
        if v > best:
            best = v
            arg = dp
    return arg


@numba.njit(cache=True)
def _column(store, slot, j, yr, yc, zt, a2, a2b1, a2b2, b2, lp, q):  # pragma: no cover - compiled
    """J_j(y, :) (D,) at y = (yr, yc): stored, or recomputed from the last
    checkpoint c < j on the cone of cells it depends on (box radius
    q (j - i) at frame i) with the forward pass's float32 operations; see
    :func:`methods.tbd.mf_kernels._mf_column`."""
    D = lp.shape[0]
    H, _, W = store.shape[1:]
    if slot[j] >= 0:
        return store[slot[j], yr, :, yc].copy()
    c0 = j - 1
    while slot[c0] < 0:
        c0 -= 1
    w = 2 * q + 1
    R = q * (j - c0)
    loc = np.full((2 * R + 1, 2 * R + 1, D), NEG_INF, np.float32)
    for i in range(2 * R + 1):
        for ii in range(2 * R + 1):
            rr, cc = yr - R + i, yc - R + ii
            if 0 <= rr < H and 0 <= cc < W:
                loc[i, ii] = store[slot[c0], rr, :, cc]
    for f in range(c0 + 1, j + 1):
        Rn = R - q
        new = np.full((2 * Rn + 1, 2 * Rn + 1, D), NEG_INF, np.float32)
        for i in range(2 * Rn + 1):
            for ii in range(2 * Rn + 1):
                rr, cc = yr - Rn + i, yc - Rn + ii
                if not (0 <= rr < H and 0 <= cc < W):
                    continue
                for d in range(D):
                    pr, pc = rr - (d // w - q), cc - (d % w - q)
                    if 0 <= pr < H and 0 <= pc < W:
                        g = _g_column(loc[pr - yr + R, pc - yc + R], zt[f - 2], pr, pc, a2b2, q, H, W)
                        m = NEG_INF
                        for dp in range(D):
                            m = _fmax(m, g[dp] + lp[dp, d])
                        new[i, ii, d] = _j_value(a2, zt[f, rr, cc], a2b1, zt[f - 1, pr, pc], b2, m)
        loc = new
        R = Rn
    return loc[0, 0].copy()


@numba.njit(cache=True)
def _backtrack(store, slot, zt, a2, a2b1, a2b2, b2, lp, q, vt, track_t):  # pragma: no cover - compiled
    """Score, value map and track of one trial from the stored volumes, as
    :func:`methods.tbd.mf_kernels._mf_backtrack`, with psi_k from G_k. Returns
    the score."""
    K = track_t.shape[0]
    H, _, W = store.shape[1:]
    w = 2 * q + 1
    s, d, r, c = _mf_start(store[slot[K - 1]], vt)
    track_t[K - 1, 0] = r
    track_t[K - 1, 1] = c
    for k in range(K - 1, 0, -1):
        dn = 0
        yr = r - (d // w - q)
        yc = c - (d % w - q)
        if k >= 2:
            P = _column(store, slot, k - 1, yr, yc, zt, a2, a2b1, a2b2, b2, lp, q)
            dn = _predecessor(_g_column(P, zt[k - 2], yr, yc, a2b2, q, H, W), lp, d)
        r, c = yr, yc
        track_t[k - 1, 0] = r
        track_t[k - 1, 1] = c
        d = dn
    return s


@numba.njit(cache=True)
def _dp_tbd_mf_along_track(z, q, lp, lp_first, rho1, beta1, beta2, a0, b0, a1, b1, a2, b2,
                           score, track, value, store, ring, cring):  # pragma: no cover - compiled
    """Second-order DP-TBD with the along-track Gaussian term, all trials;
    outputs written in place. See :class:`methods.tbd.dp_tbd.DpTbdMf`.

    J_0(x) = a0 z_0(x) + b0
    J_1(x, d) = a1 (z_1(x) - rho1 z_0(x - d)) + b1 + lp_first + J_0(x - d)
    J_k(x, d), k >= 2: see the module docstring (a2, b2, beta1, beta2).
    score = max_(x, d) J_(K-1); value = max_d J_(K-1)(x, d); the track is
    backtracked from the first maximum in (d, row, col) order,
    x_(k-1) = x_k - d_k, d_(k-1) = psi_k(x_k, d_k) recomputed on the track.
    Working memory (:func:`dp_tbd_mf_along_track`): store (checkpoints,
    H, D, W), ring (K, 2q + 1, D, W), cring (K, 2q + 1, C, W).
    """
    n, K, H, W = z.shape
    D = lp.shape[0]
    S = 2 * q + 1                               # ring slots per frame
    cls, members, nmem, _, L, _ = _heading_classes(lp, q)
    C = L.shape[0]
    every = np.empty((C, C), np.int64)          # M takes every class, -d included
    for u in range(C):
        every[u] = np.arange(C)
    slot = _checkpoint_slots(K)[0]
    G = np.empty((D, W), np.float32)
    Rs = np.empty((C, W), np.float32)
    j0 = np.empty((H, W), np.float32)
    a2b1 = a2 * beta1
    a2b2 = a2 * beta2
    for t in range(n):
        zt = z[t]
        _check_finite(zt)
        for r in range(H):
            for c in range(W):
                j0[r, c] = a0 * zt[0, r, c] + b0
        if K == 1:
            s, r, c = _first_argmax_2d(j0)
            score[t] = s
            value[t] = j0
            track[t, 0, 0] = r
            track[t, 0, 1] = c
            continue
        for step in range(H + q * (K - 2)):
            for k in range(1, K):
                r = step - q * (k - 1)
                if r < 0:
                    break
                if r >= H:
                    continue
                out = store[slot[k], r] if slot[k] >= 0 else ring[k, r % S]     # where row r lives
                if k == 1:
                    _at_row1(zt, j0, r, a1, rho1, b1, lp_first, q, out)
                else:
                    _at_row(zt[k], zt[k - 1], cring[k], r, H, W, a2, a2b1, b2, q, cls, out)
                if k < K - 1:                   # M_(k+1) of row r: G, then the class maxima
                    _g_rows(out, zt[k - 1], r, H, W, a2b2, q, G)
                    _common_maxima(G, Rs, cring[k + 1, r % S], members, nmem, L, every, W)
        score[t] = _backtrack(store, slot, zt, a2, a2b1, a2b2, b2, lp, q, value[t], track[t])


def dp_tbd_mf_along_track(z, q, lp, lp_first, rho1, beta1, beta2, a0, b0, a1, b1, a2, b2,
                          score, track, value):
    """:func:`_dp_tbd_mf_along_track` with its working memory allocated by
    NumPy (see :func:`methods.tbd.mf_kernels.dp_tbd_mf`)."""
    _, K, H, W = z.shape
    D = lp.shape[0]
    S = 2 * q + 1
    C = int(_heading_classes(lp, q)[4].shape[0])
    nstore = int(_checkpoint_slots(K)[1])
    store = np.empty((max(nstore, 1), H, D, W), np.float32)
    ring = np.empty((max(K, 2), S, D, W), np.float32)
    cring = np.empty((max(K, 2), S, C, W), np.float32)
    _dp_tbd_mf_along_track(z, q, lp, lp_first, rho1, beta1, beta2, a0, b0, a1, b1, a2, b2,
                           score, track, value, store, ring, cring)
