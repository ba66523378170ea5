"""numba kernel of ``dp-tbd-mf`` with ``likelihood = "along-track"`` (:mod:`methods.dp_tbd`).

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

    J_k(x, d) = A z_k(x) - A beta1 z_(k-1)(x - d) + B
                + max_d' [G(x - d, d') + lp(d', d)],
    G(y, d')  = J_(k-1)(y, d') - A beta2 z_(k-2)(y - d'),

so the cost per frame is that of the maximum over d' of a (D, H, W) volume
plus a weight table, (2q + 1)^4 compare/selects per cell.

Conventions as in :mod:`methods._tbd_kernels` (displacement numbering, int8
backpointers, float32 merits, first maximum wins, one trial at a time).
"""

from __future__ import annotations

import numba
import numpy as np

from methods._tbd_kernels import NEG_INF, _check_finite, _first_argmax_2d, _mf_score_and_backtrack


@numba.njit(cache=True)
def _best_predecessor(g, lp, m, arg):  # pragma: no cover - compiled
    """m[d, y] = max_d' g[d', y] + lp[d', d], arg[d, y] = the first maximising d'."""
    D, H, W = g.shape
    for d in range(D):
        md = m[d]
        ad = arg[d]
        md[:, :] = NEG_INF
        ad[:, :] = 0
        for dp in range(D):
            w = lp[dp, d]
            gd = g[dp]
            for r in range(H):
                gr = gd[r]
                mr = md[r]
                ar = ad[r]
                for c in range(W):
                    v = gr[c] + w
                    if v > mr[c]:
                        mr[c] = v
                        ar[c] = dp


@numba.njit(cache=True)
def dp_tbd_mf_along_track(z, q, lp, lp_first, rho1, beta1, beta2, a0, b0, a1, b1, a2, b2,
                          score, track, value):  # pragma: no cover - compiled
    """Second-order DP-TBD with the along-track Gaussian term, all trials;
    outputs written in place. See :class:`methods.dp_tbd.DpTbdMf`.

    J_0(x) = a0 z_0(x) + b0
    J_1(x, d) = a1 (z_1(x) - rho1 z_0(x - d)) + b1 + lp_first + J_0(x - d)
    J_k(x, d), k >= 2: see the module docstring (a2, b2, beta1, beta2).
    score = max_(x, d) J_(K-1); value = max_d J_(K-1)(x, d); the track is
    backtracked from the first maximum in (d, row, col) order.
    """
    n, K, H, W = z.shape
    D = lp.shape[0]
    w = 2 * q + 1
    prev = np.empty((D, H, W), np.float32)
    cur = np.empty((D, H, W), np.float32)
    g = np.empty((D, H, W), np.float32)
    m = np.empty((D, H, W), np.float32)
    arg = np.empty((D, H, W), np.int8)
    j0 = np.empty((H, W), np.float32)
    bp = np.zeros((max(K, 3), D, H, W), np.int8)
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
        for d in range(D):
            dr = d // w - q
            dc = d % w - q
            for r in range(H):
                rp = r - dr
                for c in range(W):
                    cp = c - dc
                    if rp < 0 or rp >= H or cp < 0 or cp >= W:
                        prev[d, r, c] = NEG_INF
                    else:
                        prev[d, r, c] = (a1 * (zt[1, r, c] - rho1 * zt[0, rp, cp]) + b1 + lp_first
                                         + j0[rp, cp])
        for k in range(2, K):
            zk, zk1, zk2 = zt[k], zt[k - 1], zt[k - 2]
            # G(y, d') = J_(k-1)(y, d') - a2 beta2 z_(k-2)(y - d'); -inf states stay -inf
            for dp in range(D):
                dr = dp // w - q
                dc = dp % w - q
                for r in range(H):
                    rp = r - dr
                    for c in range(W):
                        cp = c - dc
                        if rp < 0 or rp >= H or cp < 0 or cp >= W:
                            g[dp, r, c] = NEG_INF
                        else:
                            g[dp, r, c] = prev[dp, r, c] - a2 * beta2 * zk2[rp, cp]
            _best_predecessor(g, lp, m, arg)
            for d in range(D):
                dr = d // w - q
                dc = d % w - q
                for r in range(H):
                    rp = r - dr
                    for c in range(W):
                        cp = c - dc
                        if rp < 0 or rp >= H or cp < 0 or cp >= W:
                            cur[d, r, c] = NEG_INF
                            bp[k, d, r, c] = 0
                        else:
                            cur[d, r, c] = (a2 * zk[r, c] - a2 * beta1 * zk1[rp, cp] + b2
                                            + m[d, rp, cp])
                            bp[k, d, r, c] = arg[d, rp, cp]
            prev, cur = cur, prev
        score[t] = _mf_score_and_backtrack(prev, bp, value[t], track[t], q)
