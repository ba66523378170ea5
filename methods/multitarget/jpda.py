"""Exact JPDA marginal association probabilities of one cluster (compiled).

The HFSWR tracking chapter ("目标检测与跟踪方法, 海洋遥感技术应用"), section
2(2), JPDA steps ①–⑤: a validation matrix Ω (which plot may come from which
track), the feasible joint events θ under the two rules "a measurement comes
from one target or is clutter" and "a target gives at most one measurement"
(detection probability P_D), the event probabilities from Gaussian plots
around each track's predicted measurement and Poisson clutter of density λ,
and the marginal probabilities from the joint ones. In the parametric form of
Bar-Shalom & Fortmann (Tracking and Data Association, 1988, sec. 9.3), with
the plots truncated to the gate of probability P_G:

    P{θ | Z} ∝ λ^φ(θ) ∏_{(i,t) ∈ θ} P_D N(z_i; ẑ_t, S_t) ∏_{t undetected in θ} (1 − P_D P_G)

with φ(θ) the plots θ calls clutter. The marginals are
β_it = Σ_{θ ∋ (i,t)} P{θ | Z} and β_0t = 1 − Σ_i β_it (track t undetected):
per track they sum to 1 by construction. Computed in logarithms with the
common factor λ^m taken out (λ = 0 is allowed: every plot in a gate is then
a target's), so no product under- or overflows.

**Cluster size.** The events of a cluster of t tracks and m plots are
enumerated exactly (a depth-first walk over the plots, each plot clutter or
one of its unused gated tracks) when t · m ≤ ``max_size``; a fully connected
7 × 7 cluster has 130 922 events. A larger cluster falls back to
single-target PDA for each of its tracks (each track's marginals as if it
were alone in its gate, the one-track case of the formula above), and the
caller counts the cluster in its trace.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True)
def jpda_marginals(valid, loglik, log_pd, log_miss, log_lambda, max_size, beta):  # pragma: no cover - compiled
    """Marginals of one cluster into ``beta`` (t, m + 1): column 0 the
    no-detection event β_0t, column 1 + i plot i. ``valid`` (t, m) bool is the
    validation matrix, ``loglik`` (t, m) log N(z_i; ẑ_t, S_t) where valid;
    ``log_miss`` = log(1 − P_D P_G). Returns True when enumerated exactly,
    False when the cluster exceeded ``max_size`` (t · m) and PDA was used."""
    t, m = valid.shape
    beta[:, :] = 0.0
    if t * m > max_size:
        for j in range(t):
            single_target_pda(valid[j], loglik[j], log_pd, log_miss, log_lambda, beta[j])
        return False
    # log-weight of assigning plot i to track j, relative to calling it clutter
    gain = np.empty((t, m))
    offset = 0.0                                   # an upper bound of every event's log-weight
    for j in range(t):
        best = log_miss
        for i in range(m):
            gain[j, i] = log_pd + loglik[j, i] - log_lambda
            if valid[j, i] and gain[j, i] > best:
                best = gain[j, i]
        offset += best
    option = np.full(m, -2)                        # per plot: -2 not started, -1 clutter, j track
    used = np.zeros(t, dtype=np.bool_)
    logw = np.zeros(m + 1)
    total = 0.0
    level = 0
    while level >= 0:
        if level == m:                             # a complete joint event
            lw = logw[m]
            for j in range(t):
                if not used[j]:
                    lw += log_miss
            w = math.exp(lw - offset)
            total += w
            for i in range(m):
                if option[i] >= 0:
                    beta[option[i], 1 + i] += w
            for j in range(t):
                if not used[j]:
                    beta[j, 0] += w
            level -= 1
            continue
        a = option[level]
        if a >= 0:
            used[a] = False
        a += 1
        if a >= 0:                                 # the next track that may claim this plot
            while a < t and (used[a] or not valid[a, level]):
                a += 1
        if a >= t:
            option[level] = -2
            level -= 1
            continue
        option[level] = a
        if a >= 0:
            used[a] = True
            logw[level + 1] = logw[level] + gain[a, level]
        else:
            logw[level + 1] = logw[level]
        level += 1
    if total > 0.0:
        for j in range(t):
            for c in range(m + 1):
                beta[j, c] /= total
    else:                                          # every event underflowed: keep the predictions
        for j in range(t):
            beta[j, 0] = 1.0
    return True


@numba.njit(cache=True)
def single_target_pda(valid, loglik, log_pd, log_miss, log_lambda, beta):  # pragma: no cover - compiled
    """PDA of one track (the JPDA formula with t = 1) into ``beta`` (m + 1,)."""
    m = valid.shape[0]
    best = log_miss
    for i in range(m):
        if valid[i]:
            best = max(best, log_pd + loglik[i] - log_lambda)
    total = 0.0
    beta[0] = math.exp(log_miss - best) if log_miss > -np.inf else 0.0
    total += beta[0]
    for i in range(m):
        w = math.exp(log_pd + loglik[i] - log_lambda - best) if valid[i] else 0.0
        beta[1 + i] = w
        total += w
    if total > 0.0:
        for c in range(m + 1):
            beta[c] /= total
    else:
        beta[:] = 0.0
        beta[0] = 1.0
