"""Two plain DP-TBDs: the test oracle of ``dp-tbd`` and its ``bench perf`` peer.

:func:`reference_dp_tbd`, the test oracle, is the straightforward SciPy recursion:

Per trial and frame, the Tonissen-Evans recursion written the obvious way:
the box maximum of the previous merit with ``scipy.ndimage.maximum_filter``
(``mode="constant", cval=-inf``: predecessors outside the grid are not
candidates), the backpointers with ``np.argmax`` over the stack of the
(2q + 1)^2 shifted copies of the previous merit (filled with -inf where the
shift leaves the grid), stored as int8, then backtracking. Same conventions as
:mod:`methods._tbd_kernels`: displacement d = (dr, dc) from x - d to x,
numbered ``(dr + q) (2q + 1) + (dc + q)``, first maximum wins, merits in the
frames' dtype (float32 for ``tbd-grid``), so it agrees with the numba kernel
bit for bit.

:func:`numpy_dp_tbd`, the peer ``bench perf`` times the kernel against, is the
kernel's own algorithm as a competent NumPy user would write it: the whole batch
at once, the forward pass maxima only (the box maximum separable, 2 (2q + 1)
``np.maximum`` passes over -inf-padded planes), every frame's merit kept, the
backpointers recomputed along the track only. Same outputs, bit for bit.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage


def _shifted_stack(prev: np.ndarray, q: int, out: np.ndarray) -> np.ndarray:
    """out[j] (r, c) = prev(r - dr, c - dc) for displacement j, -inf off-grid."""
    H, W = prev.shape
    w = 2 * q + 1
    out.fill(-np.inf)
    for j in range(w * w):
        dr, dc = j // w - q, j % w - q
        if abs(dr) >= H or abs(dc) >= W:
            continue
        out[j, max(0, dr):H + min(0, dr), max(0, dc):W + min(0, dc)] = \
            prev[max(0, -dr):H - max(0, dr), max(0, -dc):W - max(0, dc)]
    return out


def reference_dp_tbd(frames: np.ndarray, window_radius: int) -> tuple[np.ndarray, np.ndarray]:
    """(score (n,), track (n, K, 2) int64 (row, col)) of the DP-TBD recursion
    I_1 = z_1, I_k(x) = z_k(x) + max_(|d|_inf <= q) I_(k-1)(x - d) on frames
    (n, K, H, W), window radius q = ``window_radius`` cells."""
    frames = np.asarray(frames)
    n, K, H, W = frames.shape
    q = int(window_radius)
    w = 2 * q + 1
    score = np.empty(n)
    track = np.empty((n, K, 2), np.int64)
    stack = np.empty((w * w, H, W), frames.dtype)
    for t in range(n):
        merit = frames[t, 0].copy()
        pointers = np.zeros((K, H, W), np.int8)
        for k in range(1, K):
            best = scipy.ndimage.maximum_filter(merit, size=w, mode="constant", cval=-np.inf)
            pointers[k] = np.argmax(_shifted_stack(merit, q, stack), axis=0)
            merit = frames[t, k] + best
        flat = int(np.argmax(merit))
        r, c = divmod(flat, W)
        score[t] = merit[r, c]
        track[t, K - 1] = (r, c)
        for k in range(K - 1, 0, -1):
            j = int(pointers[k, r, c])
            r, c = r - (j // w - q), c - (j % w - q)
            track[t, k - 1] = (r, c)
    return score, track


def _box_max(merit: np.ndarray, q: int, padded: np.ndarray) -> np.ndarray:
    """max over |d|_inf <= q of merit(x - d) per plane of ``merit`` (n, H, W), -inf off-grid:
    along columns then along rows, in ``padded`` (n, H + 2q, W + 2q), already -inf."""
    n, H, W = merit.shape
    padded[:, q:q + H, q:q + W] = merit
    along_cols = padded[:, :, :W].copy()
    for dc in range(1, 2 * q + 1):
        np.maximum(along_cols, padded[:, :, dc:dc + W], out=along_cols)
    best = along_cols[:, :H].copy()
    for dr in range(1, 2 * q + 1):
        np.maximum(best, along_cols[:, dr:dr + H], out=best)
    return best


def _first_best_step(merit: np.ndarray, r: np.ndarray, c: np.ndarray, q: int) -> tuple[np.ndarray, np.ndarray]:
    """(dr, dc) per trial: the first displacement, in the window numbering, whose predecessor
    (r - dr, c - dc) in ``merit`` (n, H, W) is the window's maximum (off-grid: -inf)."""
    n, H, W = merit.shape
    steps = np.arange(-q, q + 1)
    dr, dc = np.repeat(steps, 2 * q + 1), np.tile(steps, 2 * q + 1)       # j = (dr + q)(2q + 1) + (dc + q)
    rows, cols = r[:, None] - dr, c[:, None] - dc
    inside = (rows >= 0) & (rows < H) & (cols >= 0) & (cols < W)
    values = np.where(inside, merit[np.arange(n)[:, None], rows.clip(0, H - 1), cols.clip(0, W - 1)], -np.inf)
    j = np.argmax(values, axis=1)                                          # the first maximum wins
    return dr[j], dc[j]


def numpy_dp_tbd(frames: np.ndarray, window_radius: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`reference_dp_tbd`'s outputs by the kernel's algorithm in vectorised NumPy (module docstring)."""
    frames = np.asarray(frames)
    n, K, H, W = frames.shape
    q = int(window_radius)
    merits = np.empty_like(frames)
    merits[:, 0] = frames[:, 0]
    padded = np.full((n, H + 2 * q, W + 2 * q), -np.inf, frames.dtype)
    for k in range(1, K):
        np.add(frames[:, k], _box_max(merits[:, k - 1], q, padded), out=merits[:, k])
    flat = np.argmax(merits[:, K - 1].reshape(n, -1), axis=1)
    r, c = np.divmod(flat, W)
    score = merits[np.arange(n), K - 1, r, c].astype(float)
    track = np.empty((n, K, 2), np.int64)
    track[:, K - 1, 0], track[:, K - 1, 1] = r, c
    for k in range(K - 1, 0, -1):
        dr, dc = _first_best_step(merits[:, k - 1], r, c, q)
        r, c = r - dr, c - dc
        track[:, k - 1, 0], track[:, k - 1, 1] = r, c
    return score, track
