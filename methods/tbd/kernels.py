"""numba kernels of the DP track-before-detect methods (:mod:`methods.tbd.dp_tbd`):
the shared row primitives and ``dp-tbd`` here, ``dp-tbd-mf`` in
:mod:`methods.tbd.mf_kernels`, the along-track likelihood in
:mod:`methods.tbd.alongtrack`.

Conventions shared by every kernel:

* frames ``z`` are (n, K, H, W) float32; merits are accumulated in float32
  (a sum of K frame values: float32 keeps ~7 significant digits, ample for a
  threshold comparison, and halves the memory traffic and doubles the SIMD
  width of the hot loops);
* a displacement d = (dr, dc) moves a target from cell x - d at frame k-1 to
  cell x at frame k; the window is the box |dr|, |dc| <= q, and displacements
  are numbered row-major, ``j = (dr + q) (2q + 1) + (dc + q)``, so index
  ``D // 2`` is d = 0 and the index of -d is ``D - 1 - j``;
* ties are broken towards the first candidate in that numbering (the first
  maximum wins, as ``np.argmax`` does); backtracking starts from the first
  maximum of the last frame in row-major order (``dp-tbd``) or in
  (displacement, row, column) order (``dp-tbd-mf``);
* trials are processed one at a time inside a kernel, so the working memory
  does not grow with n; single-threaded (parallelism comes from the
  harness's worker processes). The public functions allocate the working
  memory with NumPy and call the compiled kernel.

**Max-only forward pass, argmax recomputed on the track.** The recursions
(:class:`methods.tbd.dp_tbd.DpTbd`, :class:`methods.tbd.dp_tbd.DpTbdMf`) are

    J_k(s) = max_(s' in P(s)) [ J_(k-1)(s') + w_k(s', s) ],

with backpointers psi_k(s) = the first maximising s'. The forward pass
computes only the maxima (an add and a ``vmaxps`` per candidate, no compare
and select for the argmax) and stores no backpointers: they are needed at
one state per frame only, the state s_k the track visits, and backtracking
recomputes them there,

    psi_k(s_k) = first argmax_(s' in P(s_k)) [ J_(k-1)(s') + w_k(s', s_k) ],

scanning the candidates in the original order with "strictly larger wins".
That is the backpointer the original max + argmax pass stored
(``tests/tbd_kernels_oracle.py``): the candidate values are the same float32
sums of the same operands, J_(k-1) being the forward pass's own values, and
a float32 maximum is exact, so the maxima do not depend on the order or the
grouping in which the forward pass takes the candidates (which it changes
freely for speed: separable box maxima, heading classes below). The price is
that J_(k-1)(s') must be available at the track's states: ``dp-tbd`` keeps
I_k of every frame (K H W float32, 20 MB at 500 x 500 x 20); ``dp-tbd-mf``
keeps checkpoints (:func:`methods.tbd.mf_kernels._dp_tbd_mf`).

The kernels are compiled with ``cache=True`` (compiled once per machine).
No global ``fastmath``: the merits use -inf for inadmissible states and the
comparisons must respect it; the only fast-math flag is ``nnan`` on the
float maximum (:func:`_fmax`), and the kernels reject non-finite frames
before any recursion (:func:`_check_finite`).
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


# ------------------------------------------------------------ row helpers
#
# The hot loops are small helpers over contiguous 1-D views that are indexed
# by the loop counter from 0 only: numba adds negative-index wraparound logic
# to an index like ``c - dc``, which stops LLVM from vectorising; with views
# and non-negative counters the loops become SIMD code (AVX2 / AVX-512). At
# most eight rows are read per loop: LLVM vectorises a loop only if its
# runtime overlap checks (one per row read against the row written) number
# at most eight.

@numba.njit(cache=True, inline="always")
def _max_into(src, m, length):  # pragma: no cover - compiled
    """m = max(m, src)."""
    for c in range(length):
        m[c] = _fmax(m[c], src[c])


@numba.njit(cache=True, inline="always")
def _max8(first, s0, s1, s2, s3, s4, s5, s6, s7, w0, w1, w2, w3, w4, w5, w6, w7, m,
          length):  # pragma: no cover - compiled
    """m = max(m, s0 + w0, ..., s7 + w7) (``first``: m = max(s0 + w0, ...)).

    Eight predecessor rows per pass, so the running maximum is loaded and
    stored once per eight candidates; folded left to right, as the
    one-candidate-at-a-time recursion would. ``first`` is a constant at each
    call site, so the branch is resolved outside the loop.
    """
    for c in range(length):
        mc = s0[c] + w0
        if not first:
            mc = _fmax(m[c], mc)
        mc = _fmax(mc, s1[c] + w1)
        mc = _fmax(mc, s2[c] + w2)
        mc = _fmax(mc, s3[c] + w3)
        mc = _fmax(mc, s4[c] + w4)
        mc = _fmax(mc, s5[c] + w5)
        mc = _fmax(mc, s6[c] + w6)
        mc = _fmax(mc, s7[c] + w7)
        m[c] = mc


@numba.njit(cache=True, inline="always")
def _max1(first, s0, w0, m, length):  # pragma: no cover - compiled
    """m = max(m, s0 + w0) (``first``: m = s0 + w0)."""
    for c in range(length):
        v = s0[c] + w0
        m[c] = v if first else _fmax(m[c], v)


@numba.njit(cache=True, inline="always")
def _copy_rows(src, dst, rows, length):  # pragma: no cover - compiled
    """dst[i, :length] = src[i, :length] for i < rows (an explicit loop:
    vectorised, unlike a numba slice assignment)."""
    for i in range(rows):
        s, t = src[i], dst[i]
        for c in range(length):
            t[c] = s[c]


@numba.njit(cache=True, inline="always")
def _fill(out, lo, hi, value):  # pragma: no cover - compiled
    for c in range(lo, hi):
        out[c] = value


# ---------------------------------------------------------------- dp-tbd

@numba.njit(cache=True, inline="always")
def _max5(first, s0, s1, s2, s3, s4, m, length):  # pragma: no cover - compiled
    """m = max(s0, ..., s4) (``first``) or max(m, s0, ..., s4)."""
    for c in range(length):
        v = _fmax(_fmax(_fmax(_fmax(s0[c], s1[c]), s2[c]), s3[c]), s4[c])
        m[c] = v if first else _fmax(m[c], v)


@numba.njit(cache=True, inline="always")
def _plus_max5(zr, s0, s1, s2, s3, s4, out, length):  # pragma: no cover - compiled
    """out = zr + max(s0, ..., s4)."""
    for c in range(length):
        out[c] = zr[c] + _fmax(_fmax(_fmax(_fmax(s0[c], s1[c]), s2[c]), s3[c]), s4[c])


@numba.njit(cache=True, inline="always")
def _add_into(zr, out, length):  # pragma: no cover - compiled
    for c in range(length):
        out[c] = zr[c] + out[c]


@numba.njit(cache=True)
def _box_max(prev, q, ring, z_k, cur):  # pragma: no cover - compiled
    """cur = z_k + box max of ``prev`` over the window (the forward pass of
    :func:`_dp_tbd`; no argmax, see the module docstring).

    ``prev`` and ``cur`` are (H, W + 2q) with q columns of -inf on each
    side, so a shifted row is a plain slice and off-grid predecessors lose
    every maximum (d = 0 is always a candidate). The box maximum is
    separable: along columns, m1(y, c) = max_dc prev(y, c - dc), then along
    rows, cur(r, c) = z_k(r, c) + max_dr m1(r - dr, c), 2 (2q + 1) maxima per
    cell. One pass over the rows: m1 of row r + q goes into ``ring`` (2q + 1
    rows, row y in slot y mod (2q + 1)) just before row r needs it. Rows off
    the grid are clipped to the nearest one inside it and windows are padded
    to groups of five by repeating a row or column: a repeated candidate
    changes no maximum.
    """
    H, W = z_k.shape
    w = 2 * q + 1
    S = ring.shape[0]
    ng = (w + 4) // 5                        # groups of five candidates
    for rr in range(H + q):
        if rr < H:                           # m1 of row rr: shifts q - j, j = 0 .. 2q
            pr = prev[rr]
            mr = ring[rr % S]
            for g in range(ng):
                o0, o1 = 2 * q - min(5 * g, w - 1), 2 * q - min(5 * g + 1, w - 1)
                o2, o3 = 2 * q - min(5 * g + 2, w - 1), 2 * q - min(5 * g + 3, w - 1)
                o4 = 2 * q - min(5 * g + 4, w - 1)
                s0, s1, s2 = pr[o0:o0 + W], pr[o1:o1 + W], pr[o2:o2 + W]
                s3, s4 = pr[o3:o3 + W], pr[o4:o4 + W]
                if g == 0:
                    _max5(True, s0, s1, s2, s3, s4, mr, W)
                else:
                    _max5(False, s0, s1, s2, s3, s4, mr, W)
        r = rr - q
        if r < 0:
            continue
        lo, hi = max(0, r - q), min(H - 1, r + q)          # predecessor rows in the grid
        cr = cur[r, q:q + W]
        for g in range(ng):
            # rows r + q - i for i = 5 g .. 5 g + 4, clipped to [lo, hi]
            y0, y1 = min(max(r + q - 5 * g, lo), hi), min(max(r + q - 5 * g - 1, lo), hi)
            y2, y3 = min(max(r + q - 5 * g - 2, lo), hi), min(max(r + q - 5 * g - 3, lo), hi)
            y4 = min(max(r + q - 5 * g - 4, lo), hi)
            s0, s1, s2, s3, s4 = ring[y0 % S], ring[y1 % S], ring[y2 % S], ring[y3 % S], ring[y4 % S]
            if ng == 1:
                _plus_max5(z_k[r], s0, s1, s2, s3, s4, cr, W)
            elif g == 0:
                _max5(True, s0, s1, s2, s3, s4, cr, W)
            else:
                _max5(False, s0, s1, s2, s3, s4, cr, W)
        if ng > 1:
            _add_into(z_k[r], cr, W)


@numba.njit(cache=True)
def _box_argmax_at(prev, q, r, c):  # pragma: no cover - compiled
    """The backpointer of cell (r, c): the first displacement j (window
    numbering) maximising I(r - dr, c - dc) over the predecessors in the
    grid (``prev``: I padded as in :func:`_box_max`), the one the separable
    max + argmax recursion stored (its lexicographically first (dr, dc)
    maximiser is the first in the row-major numbering)."""
    H = prev.shape[0]
    W = prev.shape[1] - 2 * q
    w = 2 * q + 1
    best = NEG_INF
    arg = -1
    for j in range(w * w):
        rp = r - (j // w - q)
        cp = c - (j % w - q)
        if 0 <= rp < H and 0 <= cp < W:
            v = prev[rp, q + cp]
            if arg < 0 or v > best:
                best = v
                arg = j
    return arg


@numba.njit(cache=True)
def _dp_tbd(z, q, score, track, value, merit, ring):  # pragma: no cover - compiled
    """Tonissen-Evans DP-TBD, all trials; outputs written in place.
    See :class:`methods.tbd.dp_tbd.DpTbd`.

    I_0(x) = z_0(x); I_k(x) = z_k(x) + max_(d in box q) I_(k-1)(x - d);
    score = max_x I_(K-1)(x); track backtracked from its first argmax;
    value = I_(K-1).

    The forward pass (:func:`_box_max`) keeps I_k of every frame and
    computes no argmax; backtracking recomputes the first maximising
    displacement at the track's cell of each frame (:func:`_box_argmax_at`),
    x_(k-1) = x_k - psi_k(x_k).

    z (n, K, H, W) float32; score (n,) float64; track (n, K, 2) int64;
    value (n, H, W) float32; working memory: merit (K, H, W + 2q) float32
    whose q first and last columns are -inf, ring (2q + 1, W) float32.
    """
    n, K, H, W = z.shape
    w = 2 * q + 1
    for t in range(n):
        _check_finite(z[t])
        _copy_rows(z[t, 0], merit[0, :, q:q + W], H, W)
        for k in range(1, K):
            _box_max(merit[k - 1], q, ring, z[t, k], merit[k])
        last = merit[K - 1, :, q:q + W]
        s, r, c = _first_argmax_2d(last)
        score[t] = s
        _copy_rows(last, value[t], H, W)
        track[t, K - 1, 0] = r
        track[t, K - 1, 1] = c
        for k in range(K - 1, 0, -1):
            j = _box_argmax_at(merit[k - 1], q, r, c)
            r -= j // w - q
            c -= j % w - q
            track[t, k - 1, 0] = r
            track[t, k - 1, 1] = c


def dp_tbd(z, q, score, track, value):
    """:func:`_dp_tbd` with its working memory allocated by NumPy (see
    :func:`dp_tbd_mf`)."""
    _, K, H, W = z.shape
    merit = np.empty((max(K, 1), H, W + 2 * q), np.float32)
    merit[:, :, :q] = -np.inf
    merit[:, :, q + W:] = -np.inf
    _dp_tbd(z, q, score, track, value, merit, np.empty((2 * q + 1, W), np.float32))
