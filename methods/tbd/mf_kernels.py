"""numba kernels of ``dp-tbd-mf`` (:class:`methods.tbd.dp_tbd.DpTbdMf`): the
second-order (cell, displacement) recursion with the conditional LLR and the
turn weight.

The conventions (float32 merits, displacement numbering, first-maximum ties,
one trial at a time) and the max-only forward pass with the argmax recomputed
on the track are those of :mod:`methods.tbd.kernels`, whose row primitives
this module uses.
"""

from __future__ import annotations

import numba
import numpy as np

from radarbench.methods.tbd.kernels import (
    NEG_INF,
    _check_finite,
    _copy_rows,
    _fill,
    _first_argmax_2d,
    _fmax,
    _max1,
    _max8,
    _max_into,
)


# ------------------------------------------------------------- dp-tbd-mf
#
# Three ideas make the second-order recursion fast (see _dp_tbd_mf):
#
# 1. max-only forward pass, argmax recomputed on the track (module docstring);
# 2. heading classes: the turn weight lp[d', d] depends on d' and d only
#    through their headings, which factorises the maximum over d'
#    (_heading_classes);
# 3. a row wavefront over the frames, so each frame reads the previous
#    frame's rows from cache, and checkpoints, so only every fourth frame's
#    volume goes to memory.

@numba.njit(cache=True)
def _gcd(a, b):  # pragma: no cover - compiled
    a, b = abs(a), abs(b)
    while b:
        a, b = b, a % b
    return a


@numba.njit(cache=True)
def _direction_classes(q):  # pragma: no cover - compiled
    """Class index of each displacement: displacements with the same heading
    (the same primitive direction d / gcd(dr, dc), e.g. (0, 1) and (0, 2))
    share a class; d = 0 is a class of its own. Classes are numbered in the
    order of their first member."""
    w = 2 * q + 1
    D = w * w
    cls = np.full(D, -1, np.int64)
    C = 0
    for d in range(D):
        if cls[d] >= 0:
            continue
        cls[d] = C
        dr, dc = d // w - q, d % w - q
        g = _gcd(dr, dc)
        for e in range(d + 1, D):
            er, ec = e // w - q, e % w - q
            ge = _gcd(er, ec)
            if g > 0 and ge > 0 and er // ge == dr // g and ec // ge == dc // g:
                cls[e] = C
        C += 1
    return cls


@numba.njit(cache=True)
def _heading_classes(lp, q):  # pragma: no cover - compiled
    """Tables of the heading factorisation of max_d' [J(y, d') + lp[d', d]].

    If lp[d', d] depends on (d', d) only through their classes
    (:func:`_direction_classes`; true of any turn-angle weight, the angle
    being that of the headings, and of the uniform weight of d = 0), then for
    a class u of d

        max_(d' != -d) [J(y, d') + lp[d', d]]
            = max( CM_u(y), max_(m in class(-d), m != -d) [J(y, m) + lp[m, d]] ),
        CM_u(y) = max_(u' != class(-d)) [R_u'(y) + L[u', u]],
        R_u'(y) = max_(m in u') J(y, m),

    exactly in float32: rounding is monotone, so
    max_m fl(J_m + w) = fl(max_m J_m + w) for one weight w, and a maximum is
    exact in any order. CM_u is shared by the members of u, R by all d:
    at q = 2 (17 classes) this takes 16 weighted candidates per class instead
    of 24 per displacement. If lp does not have that structure every
    displacement is its own class and the same code is the direct maximum.

    Returns (cls (D,), members (C, M) padded with -1, nmem (C,),
    neg (C,) the class of -d, L (C, C) the weight between classes,
    cand (C, C - 1) the classes u' != neg[u] in increasing order).
    C - 1 is a multiple of 8 in both cases (the symmetry of the box).
    """
    D = lp.shape[0]
    cls = _direction_classes(q)
    rep = np.empty(D, np.int64)                 # rep[d]: the first member of d's class
    for d in range(D - 1, -1, -1):
        rep[cls == cls[d]] = d
    structured = True
    for dp in range(D):
        for d in range(D):
            structured &= lp[dp, d] == lp[rep[dp], rep[d]]
    if not structured:                          # one class per displacement
        cls = np.arange(D)
    C = cls.max() + 1
    nmem = np.zeros(C, np.int64)
    for d in range(D):
        nmem[cls[d]] += 1
    members = np.full((C, nmem.max()), -1, np.int64)
    filled = np.zeros(C, np.int64)
    for d in range(D):
        members[cls[d], filled[cls[d]]] = d
        filled[cls[d]] += 1
    neg = np.empty(C, np.int64)
    L = np.empty((C, C), np.float32)
    for u in range(C):
        neg[u] = cls[D - 1 - members[u, 0]]
        for v in range(C):
            L[v, u] = lp[members[v, 0], members[u, 0]]
    cand = np.empty((C, C - 1), np.int64)
    for u in range(C):
        i = 0
        for v in range(C):
            if v != neg[u]:
                cand[u, i] = v
                i += 1
    return cls, members, nmem, neg, L, cand


@numba.njit(cache=True, inline="always")
def _max2(a, b, out, length):  # pragma: no cover - compiled
    for c in range(length):
        out[c] = _fmax(a[c], b[c])


@numba.njit(cache=True)
def _common_maxima(J, R, CM, members, nmem, L, cand, W):  # pragma: no cover - compiled
    """For one row y of J_k (J: (D, W')): R_u = max over the members of class
    u of J (R: (C, W') scratch; a copy for one-member classes, so that every
    candidate row below is a row of R: row views chosen between two arrays
    would cost numba reference counting in the loop), then
    CM_u = max_(u' in cand[u]) R_u' + L[u', u] (CM: (C, W')), eight
    candidates per pass (:func:`_max8`; the remainder, if the number of
    candidates is not a multiple of 8, one by one); see
    :func:`_heading_classes`."""
    C = L.shape[0]
    nc = cand.shape[1]
    n8 = nc - nc % 8
    for u in range(C):
        ru = R[u, :W]
        if nmem[u] == 1:
            _copy_rows(J[members[u, 0]:members[u, 0] + 1], R[u:u + 1], 1, W)
        else:
            _max2(J[members[u, 0], :W], J[members[u, 1], :W], ru, W)
            for i in range(2, nmem[u]):
                _max_into(J[members[u, i], :W], ru, W)
    for u in range(C):
        cu = cand[u]
        cm = CM[u, :W]
        for i in range(n8, nc):                 # the candidates beyond a multiple of 8 first
            _max1(i == n8, R[cu[i], :W], L[cu[i], u], cm, W)
        for g in range(0, n8, 8):
            v0, v1, v2, v3 = cu[g], cu[g + 1], cu[g + 2], cu[g + 3]
            v4, v5, v6, v7 = cu[g + 4], cu[g + 5], cu[g + 6], cu[g + 7]
            s0, s1, s2, s3 = R[v0, :W], R[v1, :W], R[v2, :W], R[v3, :W]
            s4, s5, s6, s7 = R[v4, :W], R[v5, :W], R[v6, :W], R[v7, :W]
            w0, w1, w2, w3 = L[v0, u], L[v1, u], L[v2, u], L[v3, u]
            w4, w5, w6, w7 = L[v4, u], L[v5, u], L[v6, u], L[v7, u]
            if g == 0 and n8 == nc:
                _max8(True, s0, s1, s2, s3, s4, s5, s6, s7, w0, w1, w2, w3, w4, w5, w6, w7, cm, W)
            else:
                _max8(False, s0, s1, s2, s3, s4, s5, s6, s7, w0, w1, w2, w3, w4, w5, w6, w7, cm, W)


@numba.njit(cache=True, inline="always")
def _residual(zk, zk1, zk2, beta1, beta2):  # pragma: no cover - compiled
    """r0 = z_k - beta1 z_(k-1) - beta2 z_(k-2) of one cell. The forward pass
    and the backtrack both call it, so they round identically."""
    return zk - beta1 * zk1 - beta2 * zk2


@numba.njit(cache=True)
def _llr_row(zk, zk1, zk2, beta1, beta2, coef, const, out):  # pragma: no cover - compiled
    """out[v] = coef[v] r0 + const[v] on one row, r0 = z_k - beta1 z_(k-1)
    - beta2 z_(k-2) (same cells, earlier frames; zeros with beta = 0 where a
    frame does not exist). out has one more row than coef: scratch for r0."""
    nv = coef.shape[0]
    W = zk.shape[0]
    r0 = out[nv]
    for c in range(W):
        r0[c] = _residual(zk[c], zk1[c], zk2[c], beta1, beta2)
    for v in range(nv):
        cv, kv = coef[v], const[v]
        o = out[v]
        for c in range(W):
            o[c] = cv * r0[c] + kv


@numba.njit(cache=True, inline="always")
def _finish0(cm, src, wt, lam_generic, lam_special, out, length):  # pragma: no cover - compiled
    """out = max(cm + Lambda_generic, src + wt + Lambda_special)."""
    for c in range(length):
        out[c] = _fmax(cm[c] + lam_generic[c], src[c] + wt + lam_special[c])


@numba.njit(cache=True, inline="always")
def _finish1(cm, res, wres, src, wt, lam_generic, lam_special, out, length):  # pragma: no cover
    """out = max(max(cm, res + wres) + Lambda_generic, src + wt + Lambda_special)."""
    for c in range(length):
        out[c] = _fmax(_fmax(cm[c], res[c] + wres) + lam_generic[c], src[c] + wt + lam_special[c])


@numba.njit(cache=True, inline="always")
def _fold_into(a, src, wt, out, length):  # pragma: no cover - compiled
    """out = max(a, src + wt)."""
    for c in range(length):
        out[c] = _fmax(a[c], src[c] + wt)


@numba.njit(cache=True)
def _mf_row(jsrc, csrc, r, H, W, lam, lp, q, cls, members, nmem, neg, tmp, out):  # pragma: no cover
    """Row r of J_k, k >= 2 (out: (D, W')), from the rows of J_(k-1)
    (``jsrc``: (M, D, W'), row y at y mod M: the stored volume, M = H, or a
    ring) and their common maxima (``csrc``: ring (2q + 1, C, W'), row y at
    y mod (2q + 1), :func:`_common_maxima`):

    J_k(x, d) = max( max_(d' != -d) [J_(k-1)(x - d, d') + lp[d', d]] + Lambda_generic(x),
                     J_(k-1)(x - d, -d) + lp[-d, d] + Lambda_special(x) ),

    the first maximum by heading classes (:func:`_heading_classes`): CM of
    the class of d, and the other members of the class of -d. The generic
    candidates share one Lambda plane (new cell for d != 0, stayed since
    k-1 for d = 0), the special one d' = -d its own (back to the cell of
    k-2, stayed since k-2); ``lam``: the four planes' row r. -inf where
    x - d is off the grid."""
    D = lp.shape[0]
    M = jsrc.shape[0]
    S = csrc.shape[0]
    w = 2 * q + 1
    zero = D // 2
    for d in range(D):
        dr = d // w - q
        dc = d % w - q
        rp = r - dr
        o = out[d]
        if rp < 0 or rp >= H or abs(dc) >= W:          # no predecessor in the grid
            _fill(o, 0, W, NEG_INF)
            continue
        lo = max(0, dc)
        hi = min(W, W + dc)
        a, b, n = lo - dc, hi - dc, hi - lo
        blk = jsrc[rp % M]
        sp = D - 1 - d
        v = neg[cls[d]]
        cm = csrc[rp % S, cls[d], a:b]
        ig, is_ = (2, 3) if d == zero else (0, 1)
        lg, ls = lam[ig, lo:hi], lam[is_, lo:hi]
        if nmem[v] == 1:                                # -d is alone in its class
            _finish0(cm, blk[sp, a:b], lp[sp, d], lg, ls, o[lo:hi], n)
        elif nmem[v] == 2:
            m = members[v, 0] + members[v, 1] - sp
            _finish1(cm, blk[m, a:b], lp[m, d], blk[sp, a:b], lp[sp, d], lg, ls, o[lo:hi], n)
        else:
            t = tmp[:n]
            t[:] = cm
            for i in range(nmem[v]):
                m = members[v, i]
                if m != sp:
                    _fold_into(t, blk[m, a:b], lp[m, d], t, n)
            _finish0(t, blk[sp, a:b], lp[sp, d], lg, ls, o[lo:hi], n)
        _fill(o, 0, lo, NEG_INF)
        _fill(o, hi, W, NEG_INF)


@numba.njit(cache=True)
def _mf_row1(j0, r, lp_first, lam, q, out):  # pragma: no cover - compiled
    """Row r of J_1(x, d) = J_0(x - d) + lp_first + Lambda_1(x; [d = 0])
    (out: (D, W'); lam: the "new cell" and "stayed" planes' row r), -inf
    where x - d is off the grid."""
    H, W = j0.shape
    D = (2 * q + 1) ** 2
    w = 2 * q + 1
    zero = D // 2
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
        src = j0[rp, lo - dc:hi - dc]
        lr = lam[1 if d == zero else 0, lo:hi]      # an index, not a choice of views
        ol = o[lo:hi]
        for c in range(hi - lo):
            ol[c] = src[c] + lp_first + lr[c]
        _fill(o, 0, lo, NEG_INF)
        _fill(o, hi, W, NEG_INF)


@numba.njit(cache=True)
def _mf_state_value(P, lp, d, lam_generic, lam_special):  # pragma: no cover - compiled
    """J_k(x, d) from P = J_(k-1)(x - d, :) (D,), as :func:`_mf_row` computes
    it (the maximum is exact, so the candidates' order does not matter)."""
    D = lp.shape[0]
    sp = D - 1 - d
    best = NEG_INF
    for dp in range(D):
        if dp != sp:
            best = _fmax(best, P[dp] + lp[dp, d])
    return _fmax(best + lam_generic, P[sp] + lp[sp, d] + lam_special)


@numba.njit(cache=True)
def _mf_predecessor(P, lp, d, lam_generic, lam_special):  # pragma: no cover - compiled
    """psi_k(x, d): the d' the forward recursion maximised J_k(x, d) over,
    from P = J_(k-1)(x - d, :) (D,) and Lambda_k(x) of the two cases, with
    the tie rule of the original max + argmax pass: the generic candidates
    d' != -d in increasing order, the first maximum wins; the special
    d' = -d only if strictly larger than the generic maximum. (Same float32
    sums as the forward pass, so the same comparisons.)"""
    D = lp.shape[0]
    sp = D - 1 - d
    best = NEG_INF
    arg = -1
    for dp in range(D):
        if dp == sp:
            continue
        v = P[dp] + lp[dp, d]
        if arg < 0 or v > best:
            best = v
            arg = dp
    if P[sp] + lp[sp, d] + lam_special > best + lam_generic:
        return sp
    return arg


@numba.njit(cache=True)
def _lambda_at(zt, k, r, c, b1, b2, coef2, const2, d, zero):  # pragma: no cover - compiled
    """(Lambda_generic, Lambda_special) of frame k >= 2 at cell (r, c) for
    displacement d, with the float32 operations of :func:`_llr_row`."""
    res = _residual(zt[k, r, c], zt[k - 1, r, c], zt[k - 2, r, c], b1, b2)
    g, s = (2, 3) if d == zero else (0, 1)
    return coef2[g] * res + const2[g], coef2[s] * res + const2[s]


@numba.njit(cache=True)
def _mf_column(store, slot, j, yr, yc, zt, b1, b2, coef2, const2, lp, q):  # pragma: no cover
    """J_j(y, :) (D,) at cell y = (yr, yc). Read from the stored volume if
    frame j is a checkpoint; otherwise recomputed from the last checkpoint
    c < j on the cone of cells y depends on (box radius q (j - i) at frame
    i), with the forward pass's float32 operations (:func:`_mf_state_value`,
    :func:`_lambda_at`), so the values are the same bits."""
    D = lp.shape[0]
    H, _, W = store.shape[1:]
    if slot[j] >= 0:
        return store[slot[j], yr, :, yc].copy()
    c0 = j - 1
    while slot[c0] < 0:
        c0 -= 1
    w = 2 * q + 1
    zero = D // 2
    n = j - c0
    R = q * n
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
                        lg, ls = _lambda_at(zt, f, rr, cc, b1, b2, coef2, const2, d, zero)
                        new[i, ii, d] = _mf_state_value(loc[pr - yr + R, pc - yc + R], lp, d, lg, ls)
        loc = new
        R = Rn
    return loc[0, 0].copy()


@numba.njit(cache=True)
def _mf_start(last, vt):  # pragma: no cover - compiled
    """Last frame of a second-order DP-TBD, J_(K-1) stored as (H, D, W):
    value map vt = max over displacements, the score its maximum, and the
    first state in (d, r, c) order that attains it. Returns (score, d, r, c)."""
    H, D, W = last.shape
    for r in range(H):
        vr = vt[r]
        vr[:] = last[r, 0]
        for d in range(1, D):
            _max_into(last[r, d], vr, W)
    sb = _first_argmax_2d(vt)[0]
    for d in range(D):
        for r in range(H):
            for c in range(W):
                if last[r, d, c] == sb:
                    return sb, d, r, c
    return sb, 0, 0, 0      # not reached: sb is one of the values


@numba.njit(cache=True)
def _mf_backtrack(store, slot, zt, b1, b2, coef2, const2, lp, q, vt, track_t):  # pragma: no cover
    """Score, value map ``vt`` and track ``track_t`` (K, 2) of one trial from
    the stored volumes: start at the first maximum of J_(K-1) in (d, r, c)
    order, then x_(k-1) = x_k - d_k and d_(k-1) = psi_k(x_k, d_k), recomputed
    from the column J_(k-1)(x_k - d_k, :) (frame 1's predecessor is a cell).
    Returns the score."""
    K = track_t.shape[0]
    w = 2 * q + 1
    zero = lp.shape[0] // 2
    s, d, r, c = _mf_start(store[slot[K - 1]], vt)
    track_t[K - 1, 0] = r
    track_t[K - 1, 1] = c
    for k in range(K - 1, 0, -1):
        dn = 0
        yr = r - (d // w - q)
        yc = c - (d % w - q)
        if k >= 2:
            P = _mf_column(store, slot, k - 1, yr, yc, zt, b1, b2, coef2, const2, lp, q)
            lg, ls = _lambda_at(zt, k, r, c, b1, b2, coef2, const2, d, zero)
            dn = _mf_predecessor(P, lp, d, lg, ls)
        r, c = yr, yc
        track_t[k - 1, 0] = r
        track_t[k - 1, 1] = c
        d = dn
    return s


#: frames 1, 1 + CHECKPOINT_EVERY, 1 + 2 CHECKPOINT_EVERY, ... and the last
#: are stored; the backtrack recomputes the others on a small cone
CHECKPOINT_EVERY = 4


@numba.njit(cache=True)
def _checkpoint_slots(K):  # pragma: no cover - compiled
    """slot[k] = index of frame k's stored volume, -1 if not stored."""
    slot = np.full(max(K, 1), -1, np.int64)
    n = 0
    for k in range(1, K):
        if (k - 1) % CHECKPOINT_EVERY == 0 or k == K - 1:
            slot[k] = n
            n += 1
    return slot, n


@numba.njit(cache=True)
def _dp_tbd_mf(z, q, lp, lp_first, beta_2, beta_3, coef0, const0, coef1, const1, coef2, const2,
               score, track, value, store, ring, cring):  # pragma: no cover - compiled
    """Second-order (cell, displacement) DP-TBD with the conditional LLR, all
    trials; outputs written in place. See :class:`methods.tbd.dp_tbd.DpTbdMf`.

    Frame 0: J_0(x) = Lambda_0(x) (coef0/const0: one plane).
    Frame 1: J_1(x, d) = Lambda_1(x; [d = 0]) + lp_first + J_0(x - d)
             (coef1/const1: planes for "new cell" and "stayed"; residual with
             beta_2 = gamma1 / gamma0).
    Frame k >= 2: J_k(x, d) = max_d' [J_(k-1)(x - d, d') + lp[d', d]
             + Lambda_k(x; d, d')] (:func:`_mf_row`; coef2/const2: planes
             new, back, stay1, stay2; residual with beta_3 = (beta1, beta2)).
    score = max_(x, d) J_(K-1); value = max_d J_(K-1)(x, d); track
    backtracked from the first maximum in (d, row, col) order:
    x_(k-1) = x_k - d_k, d_(k-1) = psi_k(x_k, d_k).

    Evaluation (the values are the original recursion's, bit for bit):

    * **heading classes** (:func:`_heading_classes`): the maximum over d'
      is taken by classes of displacements with one heading, the shared
      part CM computed once per row of J_(k-1) (:func:`_common_maxima`) and
      finished per displacement (:func:`_mf_row`);
    * **wavefront**: row r of J_k needs rows r - q .. r + q of J_(k-1), so
      the frames advance together, frame k on row t - q (k - 1) at step t,
      each keeping its last 2q + 1 rows (``ring``, slot r mod (2q + 1)) and
      their CM (``cring``): a frame reads the previous frame's rows from
      cache instead of memory; the Lambda planes are computed row by row
      (:func:`_llr_row`);
    * **checkpoints**: the rows of frames 1, 1 + 4, 1 + 8, ... and K - 1 go
      to ``store`` instead of a ring ((H, D, W) float32 per frame, 25 MB at
      500 x 500, q = 2);
    * **max only**: no backpointers; backtracking recomputes them on the
      track (:func:`_mf_backtrack`).
    """
    n, K, H, W = z.shape
    S = 2 * q + 1                           # ring slots per frame
    cls, members, nmem, neg, L, cand = _heading_classes(lp, q)
    C = L.shape[0]
    slot = _checkpoint_slots(K)[0]
    R = np.empty((C, W), np.float32)
    tmp = np.empty(W, np.float32)
    j0 = np.empty((H, W), np.float32)
    lam = np.empty((5, W), np.float32)
    zrow = np.zeros(W, np.float32)
    zero32 = np.float32(0.0)
    b1, b2 = beta_3[0], beta_3[1]
    for t in range(n):
        zt = z[t]
        _check_finite(zt)
        for r in range(H):
            _llr_row(zt[0, r], zrow, zrow, zero32, zero32, coef0, const0, lam[:2])
            j0[r] = lam[0]
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
                    _llr_row(zt[1, r], zt[0, r], zrow, beta_2, zero32, coef1, const1, lam[:3])
                    _mf_row1(j0, r, lp_first, lam, q, out)
                else:
                    _llr_row(zt[k, r], zt[k - 1, r], zt[k - 2, r], b1, b2, coef2, const2, lam)
                    jsrc = store[slot[k - 1]] if slot[k - 1] >= 0 else ring[k - 1]
                    _mf_row(jsrc, cring[k - 1], r, H, W, lam, lp, q, cls, members, nmem, neg, tmp, out)
                if k < K - 1:
                    _common_maxima(out, R, cring[k, r % S], members, nmem, L, cand, W)
        score[t] = _mf_backtrack(store, slot, zt, b1, b2, coef2, const2, lp, q, value[t], track[t])


def dp_tbd_mf(z, q, lp, lp_first, beta_2, beta_3, coef0, const0, coef1, const1, coef2, const2,
              score, track, value):
    """:func:`_dp_tbd_mf` with its working memory allocated here by NumPy:
    the checkpoint volumes (25 MB each at 500 x 500, q = 2) and the rings.
    NumPy asks for transparent huge pages on large arrays, which makes their
    first touch several times cheaper than numba's allocations."""
    _, K, H, W = z.shape
    D = lp.shape[0]
    S = 2 * q + 1
    C = int(_heading_classes(lp, q)[4].shape[0])
    nstore = int(_checkpoint_slots(K)[1])
    store = np.empty((max(nstore, 1), H, D, W), np.float32)     # checkpoint frames' J
    ring = np.empty((max(K, 2), S, D, W), np.float32)           # the other frames' last rows
    cring = np.empty((max(K, 2), S, C, W), np.float32)          # CM of every frame's last rows
    _dp_tbd_mf(z, q, lp, lp_first, beta_2, beta_3, coef0, const0, coef1, const1, coef2, const2,
               score, track, value, store, ring, cring)
