"""Frozen copy of the DP-TBD numba kernels as they were before the max-only
forward pass: the bit-for-bit oracle of :mod:`methods.tbd.kernels` and
:mod:`methods.tbd.alongtrack` (``tests/test_tbd_kernels_identity.py``).

These kernels compute the maximum *and* the first argmax of every transition
in the forward pass and store int8 backpointers (K, D, H, W). They are kept
unchanged (only this docstring and the merge of the two modules are new) so
that the faster kernels can be checked against them: same score, track and
value map for every trial, ties included. Not used by any method.
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba.extending import intrinsic

NEG_INF = np.float32(-np.inf)


@intrinsic
def _fmax(typingctx, a, b):
    """max(a, b) for floats as ``llvm.maxnum`` with the ``nnan`` flag: one
    ``vmaxps`` once vectorised. Written as ``b if b > a else a`` and stored
    back to where ``a`` was loaded from, LLVM turns the store into a masked
    store (``vmaskmovps``), which is several times slower on AMD cores. The
    kernels check that the frames are finite, so no NaN reaches it."""
    sig = a(a, b)

    def codegen(context, builder, signature, args):
        x, y = args
        fn = builder.module.declare_intrinsic("llvm.maxnum", [x.type],
                                              ir.FunctionType(x.type, [x.type, x.type]))
        return builder.call(fn, [x, y], fastmath=("nnan",))
    return sig, codegen


# ---------------------------------------------------------------- dp-tbd
#
# The hot loops are written as small helpers over contiguous 1-D views that
# are indexed by the loop counter from 0 only: numba adds negative-index
# wraparound logic to an index like ``c - dc``, which stops LLVM from
# vectorising; with views and non-negative counters the compare/select loops
# become AVX2 code (about 8x faster on the max + argmax pass).

@numba.njit(cache=True, inline="always")
def _max_arg(src, m, a, j, length):  # pragma: no cover - compiled
    """m = max(m, src), a = j where src is strictly larger (first max wins)."""
    for c in range(length):
        v = src[c]
        mc = m[c]
        ac = a[c]
        m[c] = _fmax(mc, v)
        a[c] = j if v > mc else ac


@numba.njit(cache=True, inline="always")
def _max_arg_add(src, wt, m, a, j, length):  # pragma: no cover - compiled
    """m = max(m, src + wt), a = j where src + wt is strictly larger."""
    for c in range(length):
        v = src[c] + wt
        mc = m[c]
        ac = a[c]
        m[c] = _fmax(mc, v)
        a[c] = j if v > mc else ac


@numba.njit(cache=True, inline="always")
def _max_arg_rows(src, src_arg, base, m, a, length):  # pragma: no cover - compiled
    """m = max(m, src), a = base + src_arg where src is strictly larger."""
    for c in range(length):
        v = src[c]
        mc = m[c]
        ac = a[c]
        sa = base + src_arg[c]      # loaded unconditionally: no masked load
        m[c] = _fmax(mc, v)
        a[c] = sa if v > mc else ac


@numba.njit(cache=True, inline="always")
def _copy_rows(src, src_arg, base, m, a, length):  # pragma: no cover - compiled
    """m = src, a = base + src_arg."""
    for c in range(length):
        m[c] = src[c]
        a[c] = base + src_arg[c]


@numba.njit(cache=True)
def _box_max_argmax(prev, q, m1, a1, z_k, cur, bp_k, best, besti):  # pragma: no cover - compiled
    """cur = z_k + box max of ``prev`` over the window, bp_k = its argmax.

    The box maximum is separable: first along columns, m1(r, c) =
    max_dc prev(r, c - dc) with a1 the first maximising dc index, then along
    rows, max_dr m1(r - dr, c), whose first maximising dr together with
    a1(r - dr, c) is the lexicographically first (dr, dc) maximiser, i.e. the
    first in the window numbering. 2 (2q + 1) compare/selects per cell
    instead of (2q + 1)^2, with contiguous inner loops over columns.
    Predecessors outside the grid are not candidates (d = 0 always is).
    """
    H, W = prev.shape
    w = 2 * q + 1
    for r in range(H):
        pr = prev[r]
        mr = m1[r]
        ar = a1[r]
        for c in range(W):
            mr[c] = NEG_INF
            ar[c] = 0
        for j in range(w):
            dc = j - q
            if abs(dc) >= W:
                continue
            lo = max(0, dc)
            hi = min(W, W + dc)
            _max_arg(pr[lo - dc:hi - dc], mr[lo:hi], ar[lo:hi], np.int32(j), hi - lo)
    for r in range(H):
        # valid dr = i - q: 0 <= r - dr < H; the first valid row initialises
        i_lo = max(0, r + q - H + 1)
        i_hi = min(w, r + q + 1)
        _copy_rows(m1[r - (i_lo - q)], a1[r - (i_lo - q)], np.int32(i_lo * w), best, besti, W)
        for i in range(i_lo + 1, i_hi):
            rp = r - (i - q)
            _max_arg_rows(m1[rp], a1[rp], np.int32(i * w), best, besti, W)
        zr = z_k[r]
        cr = cur[r]
        br = bp_k[r]
        for c in range(W):
            cr[c] = zr[c] + best[c]
            br[c] = besti[c]


@numba.njit(cache=True)
def _check_finite(frames):  # pragma: no cover - compiled
    """Raise if any frame value is NaN or infinite (one vectorised pass)."""
    flat = frames.reshape(-1)
    bad = 0
    for i in range(flat.shape[0]):
        v = flat[i]
        bad += v - v != 0.0     # False for NaN and +-inf
    if bad:
        raise ValueError("TBD frames must be finite (found NaN or infinite values)")


@numba.njit(cache=True)
def _first_argmax_2d(a):  # pragma: no cover - compiled
    H, W = a.shape
    best = a[0, 0]
    br, bc = 0, 0
    for r in range(H):
        for c in range(W):
            if a[r, c] > best:
                best = a[r, c]
                br, bc = r, c
    return best, br, bc


@numba.njit(cache=True)
def dp_tbd(z, q, score, track, value):  # pragma: no cover - compiled
    """Tonissen-Evans DP-TBD, all trials; outputs written in place.

    I_0(x) = z_0(x); I_k(x) = z_k(x) + max_(d in box q) I_(k-1)(x - d);
    score = max_x I_(K-1)(x); track backtracked from its first argmax;
    value = I_(K-1).

    z (n, K, H, W) float32; score (n,) float64; track (n, K, 2) int64;
    value (n, H, W) float32.
    """
    n, K, H, W = z.shape
    w = 2 * q + 1
    a = np.empty((H, W), np.float32)
    b = np.empty((H, W), np.float32)
    m1 = np.empty((H, W), np.float32)
    a1 = np.empty((H, W), np.int32)
    best = np.empty(W, np.float32)
    besti = np.empty(W, np.int32)
    bp = np.empty((max(K, 1), H, W), np.int8)
    for t in range(n):
        _check_finite(z[t])
        prev, cur = a, b
        prev[:, :] = z[t, 0]
        for k in range(1, K):
            _box_max_argmax(prev, q, m1, a1, z[t, k], cur, bp[k], best, besti)
            prev, cur = cur, prev
        s, r, c = _first_argmax_2d(prev)
        score[t] = s
        value[t] = prev
        track[t, K - 1, 0] = r
        track[t, K - 1, 1] = c
        for k in range(K - 1, 0, -1):
            j = bp[k, r, c]
            r -= j // w - q
            c -= j % w - q
            track[t, k - 1, 0] = r
            track[t, k - 1, 1] = c


# ------------------------------------------------------------- dp-tbd-mf

@numba.njit(cache=True)
def _llr_planes(z_k, z_k1, z_k2, beta1, beta2, coef, const, out):  # pragma: no cover - compiled
    """out[v] = coef[v] * r0 + const[v] for the residual
    r0 = z_k - beta1 z_(k-1) - beta2 z_(k-2) of each cell (same cell, earlier
    frames; pass zeros with beta = 0 where a frame does not exist)."""
    H, W = z_k.shape
    nv = coef.shape[0]
    for r in range(H):
        for c in range(W):
            r0 = z_k[r, c] - beta1 * z_k1[r, c] - beta2 * z_k2[r, c]
            for v in range(nv):
                out[v, r, c] = coef[v] * r0 + const[v]


@numba.njit(cache=True, inline="always")
def _special(src, wt, lam_generic, lam_special, best, besti, j, out, out_bp, length):  # pragma: no cover
    """out = max(best + lam_generic, src + wt + lam_special) and its pointer."""
    for c in range(length):
        g = best[c] + lam_generic[c]
        v = src[c] + wt + lam_special[c]
        out[c] = _fmax(g, v)
        out_bp[c] = j if v > g else besti[c]


@numba.njit(cache=True, inline="always")
def _first4(s0, s1, s2, s3, w0, w1, w2, w3, j0, j1, j2, j3, m, a, length):  # pragma: no cover
    """m, a = max and first argmax over four shifted predecessor rows (+ weights)."""
    for c in range(length):
        mc = s0[c] + w0
        ac = j0
        v = s1[c] + w1
        ac = j1 if v > mc else ac
        mc = _fmax(mc, v)
        v = s2[c] + w2
        ac = j2 if v > mc else ac
        mc = _fmax(mc, v)
        v = s3[c] + w3
        ac = j3 if v > mc else ac
        mc = _fmax(mc, v)
        m[c] = mc
        a[c] = ac


@numba.njit(cache=True, inline="always")
def _next4(s0, s1, s2, s3, w0, w1, w2, w3, j0, j1, j2, j3, m, a, length):  # pragma: no cover
    """Fold four more predecessor rows into m, a (strictly larger wins)."""
    for c in range(length):
        mc = m[c]
        ac = a[c]
        v = s0[c] + w0
        ac = j0 if v > mc else ac
        mc = _fmax(mc, v)
        v = s1[c] + w1
        ac = j1 if v > mc else ac
        mc = _fmax(mc, v)
        v = s2[c] + w2
        ac = j2 if v > mc else ac
        mc = _fmax(mc, v)
        v = s3[c] + w3
        ac = j3 if v > mc else ac
        mc = _fmax(mc, v)
        m[c] = mc
        a[c] = ac


@numba.njit(cache=True)
def _mf_frame(prev, cur, bp_k, lp, q, lam_new, lam_back, lam_stay1, lam_stay2, best, besti):  # pragma: no cover
    """One frame k >= 2 of the second-order recursion.

    J_k(x, d) = max_d' [ J_(k-1)(x - d, d') + lp[d', d] + Lambda_k(x; d, d') ]

    where Lambda depends on (d, d') only through whether the path sat in cell
    x at k-1 (d = 0) and at k-2 (d + d' = 0). For each d the candidates split
    into the generic ones (d' != -d), sharing one Lambda plane
    (``lam_new`` for d != 0, ``lam_stay1`` for d = 0), and the single special
    one d' = -d (``lam_back`` for d != 0, ``lam_stay2`` for d = d' = 0).
    Loop order r, d, d', c: the rows of J_(k-1) a row r touches (2q + 1 rows
    per d') stay in L2 across d, and the inner loops are contiguous. The
    D - 1 = 4 q (q + 1) generic predecessors (a multiple of 4) are folded four
    at a time, so the running max and argmax of a row are loaded and stored
    once per four candidates; they are taken in increasing d' order, so the
    first maximum wins.
    """
    D, H, W = prev.shape
    w = 2 * q + 1
    zero = D // 2
    gen = np.empty(D - 1, np.int64)
    for r in range(H):
        for d in range(D):
            dr = d // w - q
            dc = d % w - q
            rp = r - dr
            cr = cur[d, r]
            br = bp_k[d, r]
            if rp < 0 or rp >= H or abs(dc) >= W:      # no predecessor in the grid
                for c in range(W):
                    cr[c] = NEG_INF
                    br[c] = 0
                continue
            lo = max(0, dc)
            hi = min(W, W + dc)
            L = hi - lo
            sp = D - 1 - d
            i = 0
            for dp in range(D):
                if dp != sp:
                    gen[i] = dp
                    i += 1
            bl = best[lo:hi]
            bil = besti[lo:hi]
            for g in range(0, D - 1, 4):
                p0, p1, p2, p3 = gen[g], gen[g + 1], gen[g + 2], gen[g + 3]
                s0 = prev[p0, rp, lo - dc:hi - dc]
                s1 = prev[p1, rp, lo - dc:hi - dc]
                s2 = prev[p2, rp, lo - dc:hi - dc]
                s3 = prev[p3, rp, lo - dc:hi - dc]
                if g == 0:
                    _first4(s0, s1, s2, s3, lp[p0, d], lp[p1, d], lp[p2, d], lp[p3, d], np.int32(p0),
                            np.int32(p1), np.int32(p2), np.int32(p3), bl, bil, L)
                else:
                    _next4(s0, s1, s2, s3, lp[p0, d], lp[p1, d], lp[p2, d], lp[p3, d], np.int32(p0),
                           np.int32(p1), np.int32(p2), np.int32(p3), bl, bil, L)
            if d == zero:
                lg = lam_stay1[r]
                ls = lam_stay2[r]
            else:
                lg = lam_new[r]
                ls = lam_back[r]
            _special(prev[sp, rp, lo - dc:hi - dc], lp[sp, d], lg[lo:hi], ls[lo:hi], bl, bil,
                     np.int32(sp), cr[lo:hi], br[lo:hi], L)
            for c in range(lo):
                cr[c] = NEG_INF
                br[c] = 0
            for c in range(hi, W):
                cr[c] = NEG_INF
                br[c] = 0


@numba.njit(cache=True, inline="always")
def _max_into(src, m, length):  # pragma: no cover - compiled
    for c in range(length):
        m[c] = _fmax(m[c], src[c])


@numba.njit(cache=True)
def dp_tbd_mf(z, q, lp, lp_first, beta_2, beta_3, coef0, const0, coef1, const1, coef2, const2,
              score, track, value):  # pragma: no cover - compiled
    """Second-order (cell, displacement) DP-TBD with the conditional LLR, all
    trials; outputs written in place. See :class:`methods.tbd.dp_tbd.DpTbdMf`.

    Frame 0: J_0(x) = Lambda_0(x) (coef0/const0: one plane).
    Frame 1: J_1(x, d) = Lambda_1(x; [d = 0]) + lp_first + J_0(x - d)
             (coef1/const1: planes for "new cell" and "stayed"; residual with
             beta_2 = gamma1 / gamma0).
    Frame k >= 2: :func:`_mf_frame` (coef2/const2: planes new, back, stay1,
             stay2; residual with beta_3 = (beta1, beta2)).
    score = max_(x, d) J_(K-1); value = max_d J_(K-1)(x, d); track
    backtracked: x_(k-1) = x_k - d_k, d_(k-1) = bp_k(x_k, d_k).
    """
    n, K, H, W = z.shape
    D = lp.shape[0]
    w = 2 * q + 1
    zero = D // 2
    prev = np.empty((D, H, W), np.float32)
    cur = np.empty((D, H, W), np.float32)
    j0 = np.empty((H, W), np.float32)
    lam = np.empty((4, H, W), np.float32)
    zeros = np.zeros((H, W), np.float32)
    bp = np.empty((max(K, 3), D, H, W), np.int8)
    best = np.empty(W, np.float32)
    besti = np.empty(W, np.int32)
    for t in range(n):
        zt = z[t]
        _check_finite(zt)
        _llr_planes(zt[0], zeros, zeros, np.float32(0.0), np.float32(0.0), coef0, const0, lam[:1])
        j0[:, :] = lam[0]
        if K == 1:
            s, r, c = _first_argmax_2d(j0)
            score[t] = s
            value[t] = j0
            track[t, 0, 0] = r
            track[t, 0, 1] = c
            continue
        # frame 1: from single-cell states to (cell, displacement) states
        _llr_planes(zt[1], zt[0], zeros, beta_2, np.float32(0.0), coef1, const1, lam[:2])
        for d in range(D):
            dr = d // w - q
            dc = d % w - q
            lamd = lam[1] if d == zero else lam[0]
            for r in range(H):
                rp = r - dr
                for c in range(W):
                    cp = c - dc
                    if rp < 0 or rp >= H or cp < 0 or cp >= W:
                        prev[d, r, c] = NEG_INF
                    else:
                        prev[d, r, c] = j0[rp, cp] + lp_first + lamd[r, c]
        for k in range(2, K):
            _llr_planes(zt[k], zt[k - 1], zt[k - 2], beta_3[0], beta_3[1], coef2, const2, lam)
            _mf_frame(prev, cur, bp[k], lp, q, lam[0], lam[1], lam[2], lam[3], best, besti)
            prev, cur = cur, prev
        score[t] = _mf_score_and_backtrack(prev, bp, value[t], track[t], q)


@numba.njit(cache=True)
def _mf_score_and_backtrack(prev, bp, vt, track_t, q):  # pragma: no cover - compiled
    """Last frame of a second-order DP-TBD: value map = max over displacements
    (contiguous passes), the score its maximum, backtracking from the first
    (d, r, c) state that attains it through the displacement backpointers
    ``bp[k]`` (k >= 2; frame 1's predecessor is the single-cell state).
    Returns the score; writes ``vt`` (H, W) and ``track_t`` (K, 2)."""
    D, H, W = prev.shape
    K = track_t.shape[0]
    w = 2 * q + 1
    vt[:, :] = prev[0]
    for d in range(1, D):
        for r in range(H):
            _max_into(prev[d, r], vt[r], W)
    sb = _first_argmax_2d(vt)[0]
    d, r, c = 0, 0, 0
    found = False
    for d2 in range(D):
        for r2 in range(H):
            for c2 in range(W):
                if prev[d2, r2, c2] == sb:
                    d, r, c = d2, r2, c2
                    found = True
                    break
            if found:
                break
        if found:
            break
    track_t[K - 1, 0] = r
    track_t[K - 1, 1] = c
    for k in range(K - 1, 0, -1):
        dn = bp[k, d, r, c] if k >= 2 else 0
        r -= d // w - q
        c -= d % w - q
        track_t[k - 1, 0] = r
        track_t[k - 1, 1] = c
        d = dn
    return sb


# ------------------------------------------------ dp-tbd-mf, along-track


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
    outputs written in place. See :class:`methods.tbd.dp_tbd.DpTbdMf`.

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
