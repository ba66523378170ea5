"""The paper's 1-D trellis of method ``viterbi`` (``trellis = "paper-1d"``; Song & Sun, section 2).

Split from :mod:`methods.glint.viterbi`, which holds the method, its parameters and
our 2-D (position, velocity) trellis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from radarbench.models.glint import GlintModel, glint_logpdf
from radarbench.models.spherical import measurement_jacobian, spherical, wrap_angle

try:                                    # numba is optional: NumPy versions are the fallback
    import numba
except ImportError:                     # pragma: no cover - depends on the environment
    numba = None


def _jit(fn):
    return numba.njit(cache=True, nogil=True)(fn) if numba is not None else None


# --------------------------------------------------------------------------- the paper's 1-D trellis
#
# trellis = "paper-1d" (Song & Sun, section 2): each measured spherical
# component s_i (range, bearing, elevation) has its own 1-D trellis whose
# nodes are the quantised values q * delta_i (integers q; the quantiser Q of
# eq. (6) with gates of width delta_i). A step's nodes are a dense window of
# integers [base, base + W) per trial (-inf: unreachable node).

def gauss_hermite_levels(std: float) -> tuple[np.ndarray, np.ndarray]:
    """The three-point Gauss-Hermite approximation of N(0, std^2): levels
    (-sqrt(3) std, 0, +sqrt(3) std) with probabilities (1/6, 2/3, 1/6) — the
    discrete law of three levels that matches the moments up to the fifth
    (the paper's section 3 uses "discrete variables with three possible
    values"; its ref. [5] for the optimal levels is not at hand)."""
    return std * np.array([-math.sqrt(3.0), 0.0, math.sqrt(3.0)]), np.log([1 / 6, 2 / 3, 1 / 6])


def merged_transitions(offsets: np.ndarray, logpi: np.ndarray) -> np.ndarray:
    """(n, J) log transition probability of each disturbance level's branch:
    log of the summed probabilities of the levels whose node offsets
    ``offsets`` (n, J) are equal (levels landing in the same node merge,
    pi_ijl of the paper = Pr(s_q(k+1) = s_ql | s_q(k) = s_qj))."""
    same = offsets[:, :, None] == offsets[:, None, :]
    return np.log(np.sum(np.where(same, np.exp(logpi)[None, None, :], 0.0), axis=2))


def _shift_step_loops(score, offsets, logp):
    n, W = score.shape
    J = offsets.shape[1]
    lo = np.empty(n, dtype=np.int64)
    width = W
    for i in range(n):
        lo[i] = offsets[i, 0]
        hi = offsets[i, 0]
        for m in range(1, J):
            lo[i] = min(lo[i], offsets[i, m])
            hi = max(hi, offsets[i, m])
        width = max(width, W + hi - lo[i])
    new = np.full((n, width), -np.inf)
    back = np.full((n, width), -1, dtype=np.int64)
    for i in range(n):
        for a in range(W):
            s = score[i, a]
            if s == -np.inf:
                continue
            for m in range(J):
                t = a + offsets[i, m] - lo[i]
                g = s + logp[i, m]
                if g > new[i, t]:
                    new[i, t] = g
                    back[i, t] = a
    return new, back, lo


_shift_step_jit = _jit(_shift_step_loops)


def shift_step(score: np.ndarray, offsets: np.ndarray, logp: np.ndarray):
    """One Viterbi step of a 1-D trellis whose branches shift a node by an integer.

    score (n, W): path scores of the window's nodes (-inf: none); offsets
    (n, J) int: node shift of each disturbance level's branch; logp (n, J):
    its log transition probability. Returns ``(new, back, lo)``: scores
    (n, W') of the next window, which starts ``lo`` (n,) nodes after this one,
    and the winning parent (index in this window, -1: none) of each node.
    """
    args = (np.ascontiguousarray(score, dtype=np.float64), np.ascontiguousarray(offsets, dtype=np.int64),
            np.ascontiguousarray(logp, dtype=np.float64))
    return (_shift_step_jit or _shift_step_loops)(*args)


@dataclass(frozen=True)
class Component:
    """One measured spherical component's trellis: gate, disturbance, prior."""

    delta: float             # quantisation step (gate width), component units
    T: float                 # sampling interval (s)
    P2: float                # gain of the disturbance into the component per step (s^2)
    w: np.ndarray            # (J,) disturbance levels (component units / s^2)
    logpi: np.ndarray        # (J,) their log probabilities
    mean0: float             # prior mean of s(0)
    std0: float              # prior std of s(0)
    rate0: float             # the prior derivative ds/dt(0) (the paper's s_d(0), one value)
    initial_nodes: int       # values of s(0) (see _initial_window)


def _initial_window(c: Component, n: int):
    """Step 0: the window of s(0) nodes and their log prior (the paper's
    pi_i0; s(0) is "a discrete random variable with n_i0 possible values").
    ``initial_nodes`` = 3: the three-point Gauss-Hermite law of the prior
    N(mean0, std0^2) (:func:`gauss_hermite_levels`; the paper approximates
    the random variables of its state equation by three values); 1: the
    prior mean; otherwise that many values equally spaced on +-3 std0 with
    the normal density, normalised. Values are quantised (levels falling in
    the same node merge, their probabilities add)."""
    N = c.initial_nodes
    if N == 1:
        t, logp = np.zeros(1), np.zeros(1)
    elif N == 3:
        t, logp = gauss_hermite_levels(1.0)
    else:
        t = np.linspace(-3.0, 3.0, N)
        logp = -0.5 * t ** 2 - np.log(np.sum(np.exp(-0.5 * t ** 2)))
    q = np.floor((c.mean0 + c.std0 * t) / c.delta + 0.5).astype(np.int64)
    prior = np.full(int(q.max() - q.min()) + 1, -np.inf)
    np.logaddexp.at(prior, q - q.min(), logp)
    return np.full(n, q.min(), dtype=np.int64), np.broadcast_to(prior, (n, len(prior))).copy()


def _add_metric(score, base, delta, metric, k):
    """score + log p(z(k) | node) at the reachable nodes (finite scores) only:
    the first block's window is mostly empty."""
    trials, cols = np.nonzero(score > -np.inf)
    out = np.full_like(score, -np.inf)
    out[trials, cols] = score[trials, cols] + metric(k, (base[trials] + cols) * delta, trials)
    return out


def paper_1d_component(c: Component, metric, K: int, n: int, Lb: int, start_nodes: int) -> np.ndarray:
    """Block Viterbi estimates (n, K) of one spherical component (Song & Sun, section 2).

    ``metric(k, values, trials)`` -> log p(z(k) | s(k) = values) of trials
    ``trials`` (flat arrays of the same length; evaluated at reachable nodes only).
    Trellis, eq. (6) with a constant-rate prediction: a node s_q(k) has the
    successors Q(s_q(k) + T sdot(k) + P2 w_m) for the disturbance levels w_m
    (probabilities pi_m), i.e. the node shifted by round((T sdot(k) +
    P2 w_m) / delta); levels landing in the same node merge (their
    probabilities add). sdot(k) is the derivative of the paper:
    [s(k) - s(k-1)]/T for k > 1, [s(1) - s(0|1)]/T for k = 1 and the prior
    rate for k = 0, where s(k) is the estimate from the measurements up to k
    (the best node of step k) and s(0|1) the node the best path to step 1
    leaves from. Branch metric eq. (8-2): log pi + log p(z(k) | s_q(k)); path
    metric eq. (8-1), with log pi_0 the prior of s(0).

    Blocks of ``Lb`` steps: at the block's last step the best node is
    backtracked and that path is the estimate of the block's steps (never
    revised). The ``start_nodes`` best end nodes (n = 1: Demirbas, the single
    end-of-block estimate; n > 1: the paper's modification, "n values as the
    most likely estimates, including the previous block's end estimate")
    start the next block, each with its path metric (relative to the best),
    since the paper ranks them by likelihood.
    """
    est = np.empty((n, K))
    filtered = np.empty((n, K))                 # s(k): the best node of step k when k is processed
    s01 = np.empty(n)                           # s(0|1)
    rows = np.arange(n)
    seeds = None
    for b0 in range(0, K, Lb):
        b1 = min(b0 + Lb, K)
        if seeds is None:                       # the block's trellis starts at step `origin`
            origin = 0
            base, score = _initial_window(c, n)
            score = _add_metric(score, base, c.delta, metric, 0)
            filtered[:, 0] = (base + np.argmax(score, axis=1)) * c.delta
        else:                                   # ... at the previous block's last step
            origin = b0 - 1
            nodes, seed_score = seeds
            base = nodes.min(axis=1)
            score = np.full((n, int((nodes.max(axis=1) - base).max()) + 1), -np.inf)
            score[rows[:, None], nodes - base[:, None]] = seed_score
        bases, backs = [base], []
        for k in range(origin + 1, b1):         # transition k-1 -> k with the derivative at k-1
            if k == 1:
                rate = np.full(n, c.rate0)
            elif k == 2:
                rate = (filtered[:, 1] - s01) / c.T
            else:
                rate = (filtered[:, k - 1] - filtered[:, k - 2]) / c.T
            offsets = np.floor((c.T * rate[:, None] + c.P2 * c.w[None, :]) / c.delta + 0.5).astype(np.int64)
            new, back, lo = shift_step(score, offsets, merged_transitions(offsets, c.logpi))
            base = base + lo
            score = _add_metric(new, base, c.delta, metric, k)
            best = np.argmax(score, axis=1)
            if k == 1:
                s01 = (bases[-1] + back[rows, best]) * c.delta
            filtered[:, k] = (base + best) * c.delta
            bases.append(base)
            backs.append(back)
        node = np.argmax(score, axis=1)
        for j in range(len(bases) - 1, b0 - origin - 1, -1):
            est[:, origin + j] = (bases[j] + node) * c.delta
            if j > 0:
                node = backs[j - 1][rows, node]
        top = np.argsort(-score, axis=1, kind="stable")[:, :start_nodes]
        top_score = np.take_along_axis(score, top, axis=1)
        seeds = (base[:, None] + top, top_score - top_score[:, :1])
    return est


def spherical_prior(model: GlintModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Prior mean, std and rate (3,) of (range, bearing, elevation) at step 0,
    from the Cartesian prior (x0, P0) linearised at its mean."""
    x0, P0 = np.asarray(model.x0, float), np.asarray(model.P0, float)
    Jac = measurement_jacobian(x0[:3], "active")
    std = np.sqrt(np.diag(Jac @ P0[:3, :3] @ Jac.T))
    return spherical(x0[:3]), std, Jac @ x0[3:]


def prior_prediction(model: GlintModel, K: int) -> np.ndarray:
    """(K, 6) zero-disturbance prediction of the prior mean, x(k+1) = F x(k) + G u."""
    out = np.empty((K, 6))
    x = np.asarray(model.x0, float)
    for k in range(K):
        out[k] = x
        x = model.F @ x + model.Bu
    return out


def cartesian_from_spherical(s: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """(..., 6) position and velocity from (range, bearing, elevation) ``s`` and
    their rates ``rate`` (..., 3): p = r u_r, v = rdot u_r + r cos(e) bdot u_b
    + r edot u_e (u_r, u_b, u_e the line-of-sight basis at (b, e))."""
    r, b, e = s[..., 0], s[..., 1], s[..., 2]
    sb, cb, se, ce = np.sin(b), np.cos(b), np.sin(e), np.cos(e)
    u_r = np.stack([ce * sb, ce * cb, se], axis=-1)
    u_b = np.stack([cb, -sb, np.zeros_like(b)], axis=-1)
    u_e = np.stack([-se * sb, -se * cb, ce], axis=-1)
    vel = (rate[..., 0, None] * u_r + (r * ce * rate[..., 1])[..., None] * u_b
           + (r * rate[..., 2])[..., None] * u_e)
    return np.concatenate([r[..., None] * u_r, vel], axis=-1)


def paper_1d_track(z: np.ndarray, model: GlintModel, params) -> np.ndarray:
    """Estimates (n, K, 6) of the paper's 1-D trellis (:func:`paper_1d_component`).

    Each measured component (bearing and elevation; range too for an active
    sensor) is estimated on its own trellis from its own measurement: with
    the constant-rate prediction the other components' estimates do not enter
    its successors, and each measurement depends on its component only
    (eq. 7), so the components decouple. The paper's spherical motion model
    (its appendix) would couple them through the other components' estimates;
    over a 0.1 s step that coupling (the centripetal terms, the control
    ~1e-5 rad) is far below the gates, so the simplest reading is kept: the
    control is left out of the prediction, the disturbance of each component
    enters as P2 w (eq. 2), with the variances ``component_disturbance_variance``
    on three Gauss-Hermite levels (:func:`gauss_hermite_levels`). Rates of
    the output: differences of the block estimates, [s(k) - s(k-1)]/T (the
    prior rate at k = 0). A passive sensor does not measure range: range and
    range rate are the prior mean's zero-disturbance prediction (as the
    pv-grid trellis's radial axis).
    """
    z = np.asarray(z, float)
    n, K, _ = z.shape
    T, P2 = float(model.dt_s), float(model.G[0, 0])
    mean0, std0, rate0 = spherical_prior(model)
    labels = list(model.measurement_labels)
    sph = np.empty((n, K, 3))
    rate = np.empty((n, K, 3))
    pred = prior_prediction(model, K)
    r = np.linalg.norm(pred[:, :3], axis=1)
    sph[..., 0] = r
    rate[..., 0] = np.sum(pred[:, :3] * pred[:, 3:], axis=1) / r
    for i, label in enumerate(("range", "bearing", "elevation")):
        if label not in labels:
            continue
        col = labels.index(label)
        w, logpi = gauss_hermite_levels(math.sqrt(params.component_disturbance_variance[i]))
        comp = Component(delta=params.quantisation_steps[i], T=T, P2=P2, w=w, logpi=logpi,
                         mean0=float(mean0[i]), std0=float(std0[i]), rate0=float(rate0[i]),
                         initial_nodes=params.initial_nodes)
        sigma, eta = float(model.sigma[col]), float(model.eta[col])

        def metric(k, values, trials, col=col, sigma=sigma, eta=eta, wrap=label == "bearing"):
            res = z[trials, k, col] - values
            return glint_logpdf(wrap_angle(res) if wrap else res, sigma, eta, float(model.epsilon),
                                model.glint_model)

        sph[..., i] = paper_1d_component(comp, metric, K, n, params.Lb, params.start_nodes)
        rate[:, 0, i] = rate0[i]
        rate[:, 1:, i] = np.diff(sph[..., i], axis=1) / T
    return cartesian_from_spherical(sph, rate)
