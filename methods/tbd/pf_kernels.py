"""numba kernel of the particle-filter track-before-detect (:class:`methods.tbd.pf_tbd.PfTbd`),
and the counter-based random numbers it shares with its NumPy reference
(:func:`methods.tbd.reference.reference_pf_tbd`).

**Random numbers.** A particle filter draws; a method must be deterministic and a
trial's output must not depend on the batch it is in (docs/architecture.md,
'Portable numbers'). Each trial gets a 64-bit key (:func:`trial_keys`, from the
method's ``seed`` and the trial number), and draw number c of that trial is the
c-th output of SplitMix64 seeded with the key (Steele, Lea & Flood, "Fast
splittable pseudorandom number generators", OOPSLA 2014):

    u(key, c) = (mix64(key + c * 0x9E3779B97F4A7C15) >> 11 + 1/2) 2^-53   in (0, 1),

c = ((k (P + 1) + i) SLOTS + slot) for frame k, particle i of P and a slot per
draw (:data:`SLOTS`). Integer arithmetic only, so the kernel (scalar) and the
reference (arrays over particles) draw the same numbers bit for bit, in any
order; normals by Box-Muller from two of them.

Slots of particle i at frame k: a birth (i < N_b) draws its cell (0), its
position in the cell (1, 2), velocity (3, 4) and SNR (5); a continuing particle
(i = N_b + j) four normals from slots 0-3 (accelerations along x and y, the
log-amplitude step, one unused). Slot 7 is the resampling's: systematic
resampling reads particle 0's, stratified output j's.

Conventions of the TBD kernels (:mod:`methods.tbd.kernels`): frames (n, K, H,
W) float32, checked finite before anything runs, trials one at a time inside
the kernel so the working memory (a few arrays of P particles and one of H W
candidate cells) does not grow with n; compiled with ``cache=True``, no
fast-math.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from radarbench.methods.tbd.kernels import _check_finite

#: draws per particle and frame (see the module docstring)
SLOTS = 8
#: the slot of the resampling draws
RESAMPLE_SLOT = 7
#: SplitMix64's increment (2^64 / golden ratio) and its finaliser's multipliers
GOLDEN = np.uint64(0x9E3779B97F4A7C15)
MIX1 = np.uint64(0xBF58476D1CE4E5B9)
MIX2 = np.uint64(0x94D049BB133111EB)
#: the codes of the ``birth_proposal`` and ``resampling`` parameters in the kernel
PROPOSALS = ("measurement", "uniform")
RESAMPLERS = ("systematic", "stratified")


def mix64(x):
    """SplitMix64's finaliser on uint64 (scalar in numba, arrays in NumPy; wraps mod 2^64)."""
    x = (x ^ (x >> np.uint64(30))) * MIX1
    x = (x ^ (x >> np.uint64(27))) * MIX2
    return x ^ (x >> np.uint64(31))


def draws(key, k: int, index: np.ndarray, slot: int, P: int) -> np.ndarray:
    """u(key, c) in (0, 1) for frame k, particles ``index`` (uint64 array) and ``slot``,
    when a frame has P particles: NumPy's side of :func:`_draw` (arrays wrap mod 2^64)."""
    c = (np.uint64(k) * np.uint64(P + 1) + index.astype(np.uint64)) * np.uint64(SLOTS) + np.uint64(slot)
    bits = mix64(np.uint64(key) + c * GOLDEN) >> np.uint64(11)
    return bits.astype(np.float64) * 2.0 ** -53 + 2.0 ** -54


def trial_keys(seed: int, trials) -> np.ndarray:
    """(n,) uint64 keys mix64(seed 2^32 + trial + 1): mix64 is a bijection, so distinct
    (seed, trial) pairs (seed < 2^32, trial < 2^32 - 1) get distinct keys."""
    return mix64((np.uint64(seed) << np.uint64(32)) + np.asarray(trials, np.uint64) + np.uint64(1))


mix64_compiled = numba.njit(cache=True, inline="always")(mix64)


@numba.njit(cache=True, inline="always")
def _draw(key, k, i, slot, P):  # pragma: no cover - compiled
    """u(key, c) of (frame k, particle i, slot): the module docstring's formula."""
    c = (np.uint64(k) * np.uint64(P + 1) + np.uint64(i)) * np.uint64(SLOTS) + np.uint64(slot)
    return float(mix64_compiled(key + c * GOLDEN) >> np.uint64(11)) * 2.0 ** -53 + 2.0 ** -54


@numba.njit(cache=True, inline="always")
def _normal_pair(key, k, i, slot, P):  # pragma: no cover - compiled
    """Box-Muller on the draws of ``slot`` and ``slot + 1``."""
    radius = math.sqrt(-2.0 * math.log(_draw(key, k, i, slot, P)))
    angle = 2.0 * math.pi * _draw(key, k, i, slot + 1, P)
    return radius * math.cos(angle), radius * math.sin(angle)


@numba.njit(cache=True, inline="always")
def _residual(frames, k, cell, W, b1, b2):  # pragma: no cover - compiled
    """r_k(c) = z_k(c) - b1 z_(k-1)(c) - b2 z_(k-2)(c), the lags that exist (b = 0 otherwise)."""
    r, c = cell // W, cell % W
    value = float(frames[k, r, c])
    if k >= 1:
        value -= b1 * float(frames[k - 1, r, c])
    if k >= 2:
        value -= b2 * float(frames[k - 2, r, c])
    return value


@numba.njit(cache=True, inline="always")
def _cell_term(m, residual, var):  # pragma: no cover - compiled
    return (m * residual - 0.5 * m * m) / var


@numba.njit(cache=True)
def _log_likelihood_ratio(frames, k, W, c0, c1, c2, a0, a1, a2, b1, b2, var):  # pragma: no cover - compiled
    """lambda of one particle (:class:`methods.tbd.pf_tbd.PfTbd`, 'Likelihood'): the sum over the
    distinct cells among (c0, c1, c2) (-1: none) of (m r - m^2 / 2) / var, with the
    residual's mean shift m(c) = a0 [c0 = c] - b1 a1 [c1 = c] - b2 a2 [c2 = c]."""
    m0 = a0 - (b1 * a1 if c1 == c0 else 0.0) - (b2 * a2 if c2 == c0 else 0.0)
    total = _cell_term(m0, _residual(frames, k, c0, W, b1, b2), var)
    if c1 >= 0 and c1 != c0:
        m1 = -b1 * a1 - (b2 * a2 if c2 == c1 else 0.0)
        total += _cell_term(m1, _residual(frames, k, c1, W, b1, b2), var)
    if c2 >= 0 and c2 != c0 and c2 != c1:
        total += _cell_term(-b2 * a2, _residual(frames, k, c2, W, b1, b2), var)
    return total


@numba.njit(cache=True)
def _cell_of(x, y, x_min, y_min, cell_m, H, W):  # pragma: no cover - compiled
    """Flat index r W + c of the cell holding (x, y), -1 off the grid."""
    c = math.floor((x - x_min) / cell_m)
    r = math.floor((y - y_min) / cell_m)
    if r < 0 or r >= H or c < 0 or c >= W:
        return -1
    return int(r) * W + int(c)


@numba.njit(cache=True)
def _candidates(frames, k, W, b1, b2, var, threshold, out):  # pragma: no cover - compiled
    """Cells whose residual r_k(c) / sqrt(var) reaches ``threshold``, in row-major
    order, into ``out``; returns their number M."""
    H = frames.shape[1]
    limit = threshold * math.sqrt(var)
    m = 0
    for cell in range(H * W):
        if _residual(frames, k, cell, W, b1, b2) >= limit:
            out[m] = cell
            m += 1
    return m


@numba.njit(cache=True)
def _logaddexp(a, b):  # pragma: no cover - compiled
    if a == -np.inf:
        return b
    if b == -np.inf:
        return a
    hi, lo = max(a, b), min(a, b)
    return hi + math.log1p(math.exp(lo - hi))


@numba.njit(cache=True)
def pf_tbd(frames_all, keys, geometry, model, betas, variances, flags, score, track):  # pragma: no cover
    """Every trial of ``frames_all`` (n, K, H, W): ``score`` (n,) the log-odds of
    existence at the last frame, ``track`` (n, K, 2) the existence-conditioned mean
    cell per frame. ``geometry`` = (x_min, y_min, cell_m, T); ``model`` = (N_b, N_c,
    log P_b, log(1 - P_b), log P_d, log(1 - P_d), v_max, sigma_a, snr_lo_db,
    snr_hi_db, sigma_log_amp, sigma, birth threshold); ``betas`` (3, 2) and
    ``variances`` (3,) the residual predictor of frames 0, 1 and >= 2; ``flags`` =
    (proposal code, resampling code) (:data:`PROPOSALS`, :data:`RESAMPLERS`)."""
    _check_finite(frames_all)
    n, K, H, W = frames_all.shape
    nb, nc = int(model[0]), int(model[1])
    P = nb + nc
    cur = np.empty((7, P))              # x, y, vx, vy, a0, a1, a2
    cur_cells = np.empty((3, P), np.int64)
    kept = np.empty((7, nc))
    kept_cells = np.empty((3, nc), np.int64)
    logw = np.empty(P)
    weight = np.empty(P)
    candidates = np.empty(H * W, np.int64)
    for t in range(n):
        score[t] = _trial(frames_all[t], keys[t], geometry, model, betas, variances, flags, cur, cur_cells,
                          kept, kept_cells, logw, weight, candidates, track[t])


@numba.njit(cache=True)
def _trial(frames, key, geometry, model, betas, variances, flags, cur, cur_cells, kept, kept_cells, logw,
           weight, candidates, track):  # pragma: no cover - compiled
    K, H, W = frames.shape
    x_min, y_min, cell_m, T = geometry[0], geometry[1], geometry[2], geometry[3]
    nb, nc = int(model[0]), int(model[1])
    log_pb, log_not_pb, log_pd, log_not_pd = model[2], model[3], model[4], model[5]
    v_max, sigma_a, snr_lo, snr_hi, sigma_amp, sigma, birth_threshold = (
        model[6], model[7], model[8], model[9], model[10], model[11], model[12])
    P = nb + nc
    log_odds = -np.inf                 # no target before frame 0
    for k in range(K):
        row = min(k, 2)
        b1, b2, var = betas[row, 0], betas[row, 1], variances[row]
        # births: the proposal's cell, uniform position in it, velocity and SNR from the prior
        span = _candidates(frames, k, W, b1, b2, var, birth_threshold, candidates) if flags[0] == 0 else 0
        measured = span > 0
        log_ratio = math.log(span / (H * W)) if measured else 0.0    # log p_b(cell) / q_b(cell)
        span = span if measured else H * W
        for i in range(nb):
            pick = min(int(_draw(key, k, i, 0, P) * span), span - 1)
            cell = candidates[pick] if measured else pick
            cur[0, i] = x_min + (cell % W + _draw(key, k, i, 1, P)) * cell_m
            cur[1, i] = y_min + (cell // W + _draw(key, k, i, 2, P)) * cell_m
            cur[2, i] = v_max * (2.0 * _draw(key, k, i, 3, P) - 1.0)
            cur[3, i] = v_max * (2.0 * _draw(key, k, i, 4, P) - 1.0)
            cur[4, i] = sigma * 10.0 ** ((snr_lo + (snr_hi - snr_lo) * _draw(key, k, i, 5, P)) / 20.0)
            cur[5, i] = 0.0
            cur[6, i] = 0.0
            cur_cells[0, i] = cell
            cur_cells[1, i] = -1
            cur_cells[2, i] = -1
            logw[i] = log_pb - math.log(nb) + log_ratio
        # continuing particles: nearly constant velocity, log-amplitude random walk
        for j in range(nc):
            i = nb + j
            if k == 0:
                logw[i] = -np.inf
                continue
            wx, wy = _normal_pair(key, k, i, 0, P)
            wa, _ = _normal_pair(key, k, i, 2, P)
            cur[0, i] = kept[0, j] + T * kept[2, j] + 0.5 * T * T * sigma_a * wx
            cur[1, i] = kept[1, j] + T * kept[3, j] + 0.5 * T * T * sigma_a * wy
            cur[2, i] = kept[2, j] + T * sigma_a * wx
            cur[3, i] = kept[3, j] + T * sigma_a * wy
            cur[4, i] = kept[4, j] * math.exp(sigma_amp * wa)
            cur[5, i] = kept[4, j]
            cur[6, i] = kept[5, j]
            cur_cells[0, i] = _cell_of(cur[0, i], cur[1, i], x_min, y_min, cell_m, H, W)
            cur_cells[1, i] = kept_cells[0, j]
            cur_cells[2, i] = kept_cells[1, j]
            logw[i] = log_not_pd + log_odds - math.log(nc) if cur_cells[0, i] >= 0 else -np.inf
        # weights: prior mass times the likelihood ratio of the frame
        top = -np.inf
        for i in range(P):
            if logw[i] > -np.inf:
                logw[i] += _log_likelihood_ratio(frames, k, W, cur_cells[0, i], cur_cells[1, i], cur_cells[2, i],
                                                 cur[4, i], cur[5, i], cur[6, i], b1, b2, var)
                top = max(top, logw[i])
        total = 0.0
        for i in range(P):
            weight[i] = math.exp(logw[i] - top)
            total += weight[i]
        log_odds = top + math.log(total) - _logaddexp(log_not_pb, log_pd + log_odds)
        # existence-conditioned mean position, and its cell (clipped to the grid)
        mx, my = 0.0, 0.0
        for i in range(P):
            weight[i] /= total
            if logw[i] > -np.inf:        # unborn or off the grid: no state to average
                mx += weight[i] * cur[0, i]
                my += weight[i] * cur[1, i]
        track[k, 0] = min(max(math.floor((my - y_min) / cell_m), 0), H - 1)
        track[k, 1] = min(max(math.floor((mx - x_min) / cell_m), 0), W - 1)
        _resample(key, k, P, nc, flags[1], weight, cur, cur_cells, kept, kept_cells)
    return log_odds


@numba.njit(cache=True)
def _resample(key, k, P, nc, scheme, weight, cur, cur_cells, kept, kept_cells):  # pragma: no cover
    """nc survivors from the P particles of normalised ``weight``: output j takes the
    first particle whose cumulative weight reaches (j + u_j) / nc, u_j one draw
    (systematic: the same for every j) or one per j (stratified)."""
    cumulative = weight[0]
    i = 0
    u0 = _draw(key, k, 0, RESAMPLE_SLOT, P)
    for j in range(nc):
        u = (j + (u0 if scheme == 0 else _draw(key, k, j, RESAMPLE_SLOT, P))) / nc
        while cumulative < u and i < P - 1:
            i += 1
            cumulative += weight[i]
        for s in range(7):
            kept[s, j] = cur[s, i]
        for s in range(3):
            kept_cells[s, j] = cur_cells[s, i]
