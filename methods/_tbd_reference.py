"""A straightforward SciPy DP-TBD: the speed baseline and test oracle of ``dp-tbd``.

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
