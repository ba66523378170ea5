"""The trellis of method ``viterbi`` (:mod:`methods.glint.viterbi`): max-plus steps over
candidate edges, the successor expansion of a quantised state, backtracking (Demirbas;
Song & Sun). Split from the tracker, which builds the trellis per axis and block; the
trellis knows no glint model, only gains and cells."""

from __future__ import annotations

import numpy as np

try:                                    # numba is optional: NumPy versions are the fallback
    import numba
except ImportError:                     # pragma: no cover - depends on the environment
    numba = None


def _jit(fn):
    return numba.njit(cache=True, nogil=True)(fn) if numba is not None else None


# --------------------------------------------------------------------------- trellis core
#
# A trellis step is a set of *candidates* (edges): candidate c of trial i
# leaves a node of the previous step and enters node cell[i, c] of this step
# (-1: it leaves the trellis) with the score gain[i, c] of the path it ends
# (the parent's score plus the branch metric). Each node keeps its best
# incoming candidate (ties: the lowest candidate index). The tracker's
# candidates are the successors of every node under every disturbance level
# (:func:`expand`); :func:`trellis_step` is expand followed by max_plus_step,
# fused into one compiled loop.

def _max_plus_step_numpy(cell: np.ndarray, gain: np.ndarray, ncells: int):
    n, C = cell.shape
    valid = (cell >= 0) & (gain > -np.inf)
    flat = (np.arange(n)[:, None] * ncells + cell)[valid]
    g = gain[valid]
    best = np.full(n * ncells, -np.inf)
    np.maximum.at(best, flat, g)
    winner = g == best[flat]
    back = np.full(n * ncells, C, dtype=np.int64)
    np.minimum.at(back, flat[winner], np.broadcast_to(np.arange(C), (n, C))[valid][winner])
    back[back == C] = -1
    return best.reshape(n, ncells), back.reshape(n, ncells)


def _max_plus_step_loops(cell, gain, ncells):
    n, C = cell.shape
    best = np.full((n, ncells), -np.inf)
    back = np.full((n, ncells), -1, dtype=np.int64)
    for i in range(n):
        for c in range(C):
            j = cell[i, c]
            if j >= 0 and gain[i, c] > best[i, j]:
                best[i, j] = gain[i, c]
                back[i, j] = c
    return best, back


_max_plus_step_jit = _jit(_max_plus_step_loops)


def max_plus_step(cell: np.ndarray, gain: np.ndarray, ncells: int):
    """One Viterbi recursion step, batched over trials.

    cell : (n, C) int — node of this step each candidate enters (-1: none)
    gain : (n, C) float — score of the path ending with that candidate
    Returns ``score`` (n, ncells), the best gain entering each node (-inf if
    none), and ``back`` (n, ncells), the winning candidate index (-1 if none).
    """
    cell = np.ascontiguousarray(cell, dtype=np.int64)
    gain = np.ascontiguousarray(gain, dtype=np.float64)
    if _max_plus_step_jit is not None:
        return _max_plus_step_jit(cell, gain, int(ncells))
    return _max_plus_step_numpy(cell, gain, int(ncells))


def backtrack(backs: list[np.ndarray], fanout: int, last: np.ndarray) -> np.ndarray:
    """Node indices (n, L) of the paths ending at nodes ``last`` (n,).

    ``backs[k]`` (n, ncells_k) is the winning candidate of each node of step
    k; candidate c left node ``c // fanout`` of step k - 1 (for k = 0, of the
    seeds the steps started from).
    """
    n, L = last.shape[0], len(backs)
    rows = np.arange(n)
    path = np.empty((n, L), dtype=np.int64)
    node = np.asarray(last, dtype=np.int64)
    for k in range(L - 1, -1, -1):
        path[:, k] = node
        node = backs[k][rows, node] // fanout
    return path


def viterbi_path(initial: np.ndarray, cells: list[np.ndarray], gains: list[np.ndarray], last_size: int):
    """Best path through a synthetic trellis, with the tracker's core.

    initial : (n, N_0) scores of the first step's nodes. ``cells[k]``,
    ``gains[k]`` (n, N_k, J): edge (a, m) leaves node a of step k and enters
    node ``cells[k][:, a, m]`` (in [0, N_k+1), -1: none) of step k + 1,
    adding ``gains[k][:, a, m]`` to the score; the last step has
    ``last_size`` nodes. Returns (best score (n,), nodes (n, K + 1)) of the
    best path (by :func:`max_plus_step` and :func:`backtrack`). The tests
    check it against brute force.
    """
    score = np.asarray(initial, float)
    backs, fanout = [], 1
    for k, (cell, gain) in enumerate(zip(cells, gains)):
        n, N, fanout = cell.shape
        ncells = cells[k + 1].shape[1] if k + 1 < len(cells) else int(last_size)
        total = score[:, :, None] + gain
        score, back = max_plus_step(cell.reshape(n, N * fanout), total.reshape(n, N * fanout), ncells)
        backs.append(back)
    last = np.argmax(score, axis=1)
    best = score[np.arange(score.shape[0]), last]
    if not backs:
        return best, last[:, None]
    path = backtrack(backs, fanout, last)
    first = backs[0][np.arange(len(last)), path[:, 0]] // fanout
    return best, np.concatenate([first[:, None], path], axis=1)


def expand(parent_state, parent_score, F2, g2, u, w, logpi, centre, step, Lp, Lv, metric, snap):
    """Candidates of one axis's trellis step (NumPy).

    parent_state (n, N, 2) (position, velocity) and parent_score (n, N)
    (-inf: empty node). Candidate c = a J + m is the successor of node a under
    disturbance level m: state F2 s_a + g2 (u + w_m); it enters the grid node
    (ip, iv) nearest to it on the grid of ``Lp`` x ``Lv`` levels around
    ``centre`` (n, 2) with steps ``step`` (2,) (node ip Lv + iv; -1 outside
    the gate or from an empty node), with gain score_a + logpi_m + the
    position metric (n, Lp) interpolated linearly at the candidate's position
    (taken at its level when ``snap``). Returns ``(cell, gain, cand)``:
    (n, N J), (n, N J), (n, N J, 2).
    """
    n, N = parent_score.shape
    J = len(w)
    hp, hv = (Lp - 1) // 2, (Lv - 1) // 2
    cand = (parent_state @ F2.T)[:, :, None, :] + (u + np.asarray(w))[:, None] * g2     # (n, N, J, 2)
    fp = (cand[..., 0] - centre[:, 0, None, None]) / step[0] + hp                        # fractional level
    ip = np.floor(fp + 0.5).astype(np.int64)
    iv = np.floor((cand[..., 1] - centre[:, 1, None, None]) / step[1] + hv + 0.5).astype(np.int64)
    inside = (ip >= 0) & (ip < Lp) & (iv >= 0) & (iv < Lv) & (parent_score[:, :, None] > -np.inf)
    at = np.clip(ip, 0, Lp - 1).astype(float) if snap else fp
    i0 = np.clip(np.floor(at), 0, Lp - 2).astype(np.int64)
    frac = np.clip(at - i0, 0.0, 1.0)
    flat = i0.reshape(n, -1)
    m0 = np.take_along_axis(metric, flat, axis=1).reshape(at.shape)
    m1 = np.take_along_axis(metric, flat + 1, axis=1).reshape(at.shape)
    gain = np.where(inside, parent_score[:, :, None] + logpi + m0 + frac * (m1 - m0), -np.inf)
    cell = np.where(inside, ip * Lv + iv, -1)
    return cell.reshape(n, N * J), gain.reshape(n, N * J), cand.reshape(n, N * J, 2)


def _grid_state(centre, step, Lp, Lv, cell):
    ip, iv = cell // Lv, cell % Lv
    return centre[0] + (ip - (Lp - 1) // 2) * step[0], centre[1] + (iv - (Lv - 1) // 2) * step[1]


def _trellis_step_loops(parent_state, parent_score, F2, g2, u, w, logpi, centre, step, Lp, Lv, metric, snap):
    n, N = parent_score.shape
    J = w.shape[0]
    ncells = Lp * Lv
    hp, hv = (Lp - 1) // 2, (Lv - 1) // 2
    best = np.full((n, ncells), -np.inf)
    back = np.full((n, ncells), -1, dtype=np.int64)
    state = np.zeros((n, ncells, 2))
    for i in range(n):
        for a in range(N):
            s = parent_score[i, a]
            if s == -np.inf:
                continue
            p, v = parent_state[i, a, 0], parent_state[i, a, 1]
            fp0 = F2[0, 0] * p + F2[0, 1] * v
            fv0 = F2[1, 0] * p + F2[1, 1] * v
            for m in range(J):
                uw = u + w[m]
                cp = fp0 + g2[0] * uw
                cv = fv0 + g2[1] * uw
                fp = (cp - centre[i, 0]) / step[0] + hp
                ip = int(np.floor(fp + 0.5))
                iv = int(np.floor((cv - centre[i, 1]) / step[1] + hv + 0.5))
                if ip < 0 or ip >= Lp or iv < 0 or iv >= Lv:
                    continue
                at = float(ip) if snap else fp
                i0 = min(max(int(np.floor(at)), 0), Lp - 2)
                frac = min(max(at - i0, 0.0), 1.0)
                g = s + logpi[m] + metric[i, i0] + frac * (metric[i, i0 + 1] - metric[i, i0])
                c = ip * Lv + iv
                if g > best[i, c]:
                    best[i, c] = g
                    back[i, c] = a * J + m
                    if snap:
                        state[i, c, 0] = centre[i, 0] + (ip - hp) * step[0]
                        state[i, c, 1] = centre[i, 1] + (iv - hv) * step[1]
                    else:
                        state[i, c, 0] = cp
                        state[i, c, 1] = cv
    return best, back, state


_trellis_step_jit = _jit(_trellis_step_loops)


def trellis_step(parent_state, parent_score, F2, g2, u, w, logpi, centre, step, Lp, Lv, metric, snap):
    """One step of an axis's trellis: :func:`expand` then :func:`max_plus_step`.

    Returns ``score`` (n, Lp Lv) (-inf: empty node), ``back`` (n, Lp Lv)
    (winning candidate a J + m, -1 if none) and ``state`` (n, Lp Lv, 2): the
    exact state of the winning candidate, or the node's grid value when
    ``snap``. Compiled with numba when available (one fused loop, no
    candidate arrays); otherwise NumPy, the same arithmetic.
    """
    args = (np.ascontiguousarray(parent_state, dtype=np.float64),
            np.ascontiguousarray(parent_score, dtype=np.float64),
            np.ascontiguousarray(F2, dtype=np.float64), np.ascontiguousarray(g2, dtype=np.float64),
            float(u), np.ascontiguousarray(w, dtype=np.float64), np.ascontiguousarray(logpi, dtype=np.float64),
            np.ascontiguousarray(centre, dtype=np.float64), np.ascontiguousarray(step, dtype=np.float64),
            int(Lp), int(Lv), np.ascontiguousarray(metric, dtype=np.float64), bool(snap))
    if _trellis_step_jit is not None:
        return _trellis_step_jit(*args)
    return _trellis_step_numpy(*args)


def _trellis_step_numpy(parent_state, parent_score, F2, g2, u, w, logpi, centre, step, Lp, Lv, metric, snap):
    n = parent_score.shape[0]
    cell, gain, cand = expand(parent_state, parent_score, F2, g2, u, w, logpi, centre, step, Lp, Lv,
                              metric, snap)
    score, back = max_plus_step(cell, gain, Lp * Lv)
    if snap:
        p, v = _grid_state(centre.T[:, :, None], step, Lp, Lv, np.arange(Lp * Lv)[None, :])
        state = np.stack([p, v], axis=-1)
    else:
        state = cand[np.arange(n)[:, None], np.maximum(back, 0)]
    return score, back, np.where(back[..., None] >= 0, state, 0.0)
