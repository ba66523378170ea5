"""Two plain DP-TBDs: the test oracle of ``dp-tbd`` and its ``bench perf`` peer.

:func:`reference_dp_tbd`, the test oracle, is the straightforward SciPy recursion:

Per trial and frame, the Tonissen-Evans recursion written the obvious way:
the box maximum of the previous merit with ``scipy.ndimage.maximum_filter``
(``mode="constant", cval=-inf``: predecessors outside the grid are not
candidates), the backpointers with ``np.argmax`` over the stack of the
(2q + 1)^2 shifted copies of the previous merit (filled with -inf where the
shift leaves the grid), stored as int8, then backtracking. Same conventions as
:mod:`methods.tbd.kernels`: displacement d = (dr, dc) from x - d to x,
numbered ``(dr + q) (2q + 1) + (dc + q)``, first maximum wins, merits in the
frames' dtype (float32 for ``tbd-grid``), so it agrees with the numba kernel
bit for bit.

:func:`numpy_dp_tbd`, the peer ``bench perf`` times the kernel against, is the
kernel's own algorithm as a competent NumPy user would write it: the batch it is
given at once (``bench perf`` also hands it one trial per call and keeps the faster:
a large batch's merits outgrow the caches), the forward pass maxima only (the box maximum separable, 2 (2q + 1)
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


# ------------------------------------------------------------------ pf-tbd

def _residual_map(frames: np.ndarray, k: int, beta: np.ndarray) -> np.ndarray:
    """r_k(c) = z_k(c) - beta1 z_(k-1)(c) - beta2 z_(k-2)(c) at every flat cell c of frame k
    (the lags that exist), in float64 from the three frames it reads alone."""
    flat = frames.reshape(frames.shape[0], -1)
    r = flat[k].astype(np.float64)
    for lag in range(1, min(k, 2) + 1):
        r = r - beta[lag - 1] * flat[k - lag].astype(np.float64)
    return r


def _pf_log_likelihood_ratio(residuals, cells, amps, beta, var) -> np.ndarray:
    """Sum over the distinct cells of each particle's (c0, c1, c2) of (m r - m^2 / 2) / var,
    m(c) = a0 [c0 = c] - beta1 a1 [c1 = c] - beta2 a2 [c2 = c] (:class:`methods.tbd.pf_tbd.PfTbd`),
    r the frame's residual map (:func:`_residual_map`) gathered at the particles' cells."""
    coef = np.array([1.0, -beta[0], -beta[1]])
    total = np.zeros(cells.shape[1])
    for slot in range(3):
        c = cells[slot]
        first = (c >= 0) & ~np.any(cells[:slot] == c, axis=0)     # first occurrence of the cell
        m = sum(coef[s] * amps[s] * (cells[s] == c) for s in range(3))
        r = residuals[np.where(first, c, 0)]
        total += np.where(first, (m * r - 0.5 * m * m) / var, 0.0)
    return total


def reference_pf_tbd(frames, keys, geometry, model, betas, variances, flags):
    """(score (n,), track (n, K, 2)) of the particle-filter TBD (:class:`methods.tbd.pf_tbd.PfTbd`),
    the arguments of :func:`methods.tbd.pf_kernels.pf_tbd`, written with NumPy arrays over the
    particles, one trial and one frame at a time, on the same counter-based draws: each frame's
    residual map once (the measurement proposal reads it whole), gathered at the particles' cells."""
    from radarbench.methods.tbd.pf_kernels import RESAMPLE_SLOT, draws

    frames = np.asarray(frames)
    n, K, H, W = frames.shape
    x_min, y_min, cell_m, T = geometry
    nb, nc = int(model[0]), int(model[1])
    log_pb, log_not_pb, log_pd, log_not_pd, v_max, sigma_a, snr_lo, snr_hi, sigma_amp, sigma, gate = model[2:]
    P = nb + nc
    births, survivors = np.arange(nb), nb + np.arange(nc)
    score, track = np.empty(n), np.empty((n, K, 2), np.int64)
    for t in range(n):
        key, log_odds = keys[t], -np.inf
        state = np.zeros((7, nc))                     # survivors: x, y, vx, vy, a0, a1, a2
        cells = np.full((3, nc), -1)
        for k in range(K):
            beta, var = betas[min(k, 2)], variances[min(k, 2)]
            u = [draws(key, k, births, s, P) for s in range(6)]
            r_all = _residual_map(frames[t], k, beta)
            above = np.flatnonzero(r_all >= gate * np.sqrt(var)) if flags[0] == 0 else np.zeros(0, int)
            pool = above if above.size else np.arange(H * W)
            cell_b = pool[np.minimum((u[0] * pool.size).astype(np.int64), pool.size - 1)]
            state_b = np.stack([x_min + (cell_b % W + u[1]) * cell_m, y_min + (cell_b // W + u[2]) * cell_m,
                                v_max * (2 * u[3] - 1), v_max * (2 * u[4] - 1),
                                sigma * 10.0 ** ((snr_lo + (snr_hi - snr_lo) * u[5]) / 20.0),
                                np.zeros(nb), np.zeros(nb)])
            cells_b = np.stack([cell_b, np.full(nb, -1), np.full(nb, -1)])
            logw_b = np.full(nb, log_pb - np.log(nb) + (np.log(above.size / (H * W)) if above.size else 0.0))
            # continuing: Box-Muller pairs from slots (0, 1) and (2, 3)
            radius = [np.sqrt(-2 * np.log(draws(key, k, survivors, s, P))) for s in (0, 2)]
            angle = [2 * np.pi * draws(key, k, survivors, s, P) for s in (1, 3)]
            wx, wy, wa = radius[0] * np.cos(angle[0]), radius[0] * np.sin(angle[0]), radius[1] * np.cos(angle[1])
            x = state[0] + T * state[2] + 0.5 * T * T * sigma_a * wx
            y = state[1] + T * state[3] + 0.5 * T * T * sigma_a * wy
            col, row = np.floor((x - x_min) / cell_m), np.floor((y - y_min) / cell_m)
            on_grid = (row >= 0) & (row < H) & (col >= 0) & (col < W)
            cell_c = np.where(on_grid, row * W + col, -1).astype(np.int64)
            state_c = np.stack([x, y, state[2] + T * sigma_a * wx, state[3] + T * sigma_a * wy,
                                state[4] * np.exp(sigma_amp * wa), state[4], state[5]])
            cells_c = np.stack([cell_c, cells[0], cells[1]])
            alive = on_grid & (k > 0)
            logw_c = np.where(alive, log_not_pd + log_odds - np.log(nc), -np.inf)
            state, cells_all = np.concatenate([state_b, state_c], axis=1), np.concatenate([cells_b, cells_c], axis=1)
            logw = np.concatenate([logw_b, logw_c])
            live = np.isfinite(logw)
            logw[live] += _pf_log_likelihood_ratio(r_all, cells_all[:, live], state[4:7, live], beta, var)
            top = logw.max()
            weights = np.exp(logw - top)
            total = np.cumsum(weights)[-1]            # summed in particle order, as the kernel does
            log_odds = top + np.log(total) - np.logaddexp(log_not_pb, log_pd + log_odds)
            weights /= total
            mx, my = np.cumsum(weights * state[0])[-1], np.cumsum(weights * state[1])[-1]
            track[t, k] = (np.clip(np.floor((my - y_min) / cell_m), 0, H - 1),
                           np.clip(np.floor((mx - x_min) / cell_m), 0, W - 1))
            offsets = draws(key, k, np.arange(nc) if flags[1] else np.zeros(nc, int), RESAMPLE_SLOT, P)
            picks = np.minimum(np.searchsorted(np.cumsum(weights), (np.arange(nc) + offsets) / nc), P - 1)
            state, cells = state[:, picks], cells_all[:, picks]
        score[t] = log_odds
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
