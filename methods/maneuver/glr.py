"""Method ``glr``: the generalized likelihood ratio test for a jump, on the reference filter's innovations."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np
import scipy.stats

from radarbench.bench.batched import matvec
from radarbench.bench.core import Batch, DetectionOutput
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.maneuver.base import InnovationDetector, reference_filter, steps_problem
from radarbench.models.kalman import InnovationSequence, LinearGaussianModel, covariance_sequence, filterpy_steps

#: the jumps tested: a step in each measured component's acceleration or velocity
JUMPS = ("acceleration", "velocity")
#: the longest window of candidate onsets: each step costs one quadratic form per onset
MAX_GLR_WINDOW = 1_000


def jump_response(jump: str, lag: int) -> float:
    """psi(i): the offset of a measured component ``lag`` = i steps after the onset
    step, per unit jump, for a target whose measured positions integrate its velocity.

    The jump happens between the measurements of steps theta - 1 and theta (the
    onset theta is the first step it moves), so after i + 1 sampling intervals:
    velocity jump b (measurement units per step):         psi(i) = i + 1
    acceleration jump b (measurement units per step^2):   psi(i) = (i + 1)^2 / 2
    For the per-axis DWNA constant-velocity model (Bar-Shalom, Li & Kirubarajan
    2001, sec. 6.3.2) this is H x_offset of a constant input through its noise gain
    [T^2/2, T]' (acceleration) or a velocity pulse (velocity), with b in units of T.
    The test statistic does not depend on the unit of b (only on the span of the
    signatures), so any scale would do.
    """
    return float(lag + 1) if jump == "velocity" else (lag + 1) ** 2 / 2.0


def glr_valid_from(window: int, steps: int) -> int:
    """The first step with the whole window of M onsets, t = M - 1 (the last step if
    the scene is shorter)."""
    return min(window, steps) - 1


@dataclass(frozen=True)
class Signature:
    """The signature of every candidate onset theta at one lag i (t = theta + i),
    for theta = 0 .. K-1-i: ``G[theta] = G(t; theta)`` (m, m), the innovation's
    response at step t to a unit jump with onset theta, and ``info_inverse[theta]``
    = C(t; theta)^-1, the inverse of the jump's information matrix
    C(t; theta) = sum_{j=theta..t} G(j; theta)' S_j^-1 G(j; theta)."""

    lag: int
    G: np.ndarray
    info_inverse: np.ndarray


def signatures(model: LinearGaussianModel, gains: np.ndarray, S: np.ndarray, window: int,
               jump: str) -> Iterator[Signature]:
    """The signature matrices of the reference filter (its gains ``gains`` (K, d, m) and
    innovation covariances ``S`` (K, m, m)), lag by lag for lags 0 .. window - 1, every
    onset at once. Data-independent: computed once per batch, shared by all trials. A
    filter in steady state (gains and S constant over the scene) has signatures that
    depend on the lag alone: they are computed for one onset and shared by all.

    Willsky & Jones (1976), "A generalized likelihood ratio approach to the detection
    and estimation of jumps in linear systems", IEEE Trans. Automatic Control; Bar-Shalom,
    Li & Kirubarajan (2001), sec. 11.3 (input estimation: the innovations as a linear
measurement of the unknown input). A jump b with onset theta adds
    Psi(t; theta) b = psi(t - theta) b to the measurements (:func:`jump_response`); the
    filter is linear, so it adds G(t; theta) b to the innovation and F(t; theta) b to the
    updated estimate, with F(theta - 1; theta) = 0 and

        G(t; theta) = Psi(t; theta) - H F F(t - 1; theta)        (innovation signature)
        F(t; theta) = F F(t - 1; theta) + K_t G(t; theta)        (estimate signature)

    (Willsky & Jones's G(k; theta) = H [Phi^(k-theta) - Phi F(k-1; theta)] with the
    open-loop response H Phi^(k-theta) of their state jump written as Psi).
    """
    F, H = model.F, model.H
    K, m = S.shape[0], model.dim_z
    HF = H @ F
    steady = _constant(gains) and _constant(S)
    S_inv = np.linalg.inv(S[:1] if steady else S)
    onsets = 1 if steady else K                       # steady: one onset stands for all
    estimate = np.zeros((onsets, model.dim_x, m))     # F(theta + i - 1; theta), per onset theta
    info = np.zeros((onsets, m, m))                   # C(theta + i - 1; theta)
    for i in range(min(window, K)):
        if steady:
            at_t = slice(0, 1)                        # the gain of every step
        else:                                         # theta = 0 .. K-1-i, at steps t = theta + i
            estimate, info, at_t = estimate[:K - i], info[:K - i], slice(i, None)
        G = jump_response(jump, i) * np.eye(m) - HF @ estimate
        estimate = F @ estimate + gains[at_t] @ G
        info = info + G.swapaxes(-1, -2) @ S_inv[at_t] @ G
        shape = (K - i, m, m)
        yield Signature(lag=i, G=np.broadcast_to(G, shape), info_inverse=np.broadcast_to(np.linalg.inv(info), shape))


def _constant(a: np.ndarray) -> bool:
    """Whether the per-step matrices ``a`` (K, ...) all equal the first to 1e-12 of their
    largest element (a filter started in steady state: its recursion moves them by
    rounding only, zeros included)."""
    return bool(np.max(np.abs(a - a[:1]), initial=0.0) <= 1e-12 * np.max(np.abs(a), initial=0.0))


def glr_statistic(nu: np.ndarray, S: np.ndarray, sigs: Iterator[Signature]) -> tuple[np.ndarray, np.ndarray]:
    """(l, lag): l(t) = max_theta d(t; theta)' C(t; theta)^-1 d(t; theta) over the onsets
    theta = t - i of the signatures ``sigs``, and the maximising lag t - theta, from the
    innovations ``nu`` (n, K, m) with covariances ``S`` (K, m, m):

        d(t; theta) = sum_{j=theta..t} G(j; theta)' S_j^-1 nu_j

    (Willsky & Jones 1976; Bar-Shalom, Li & Kirubarajan 2001, sec. 11.3). Under no jump
    d(t; theta) ~ N(0, C(t; theta)), so each d' C^-1 d ~ chi2(m). Lag by lag, every trial
    and onset at once. The vectors are held as component planes (m, n, K), each a
    contiguous (n, K) array, and every product is a few whole-plane multiply-adds in
    index order (as :mod:`bench.batched`), so a trial's value does not depend on its batch.
    """
    n, K, m = nu.shape
    w = np.moveaxis(matvec(np.linalg.inv(S), nu), -1, 0).copy()      # S_j^-1 nu_j, (m, n, K)
    d = np.zeros_like(w)
    best = np.zeros((n, K))
    best_lag = np.zeros((n, K))
    for sig in sigs:
        i = sig.lag
        d = d[:, :, :K - i] + _plane_product(sig.G.swapaxes(-1, -2), w[:, :, i:])
        value = _plane_inner(d, _plane_product(sig.info_inverse, d))      # at steps t = i .. K-1
        better = np.greater(value, best[:, i:])
        np.copyto(best[:, i:], value, where=better)
        np.copyto(best_lag[:, i:], float(i), where=better)
    return best, best_lag


def _plane_product(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A_t x_t for component planes: A (T, m, m) per step, x (m, n, T); summed in index order."""
    rows = []
    for a in range(A.shape[1]):
        acc = A[None, :, a, 0] * x[0]
        for c in range(1, A.shape[2]):
            acc += A[None, :, a, c] * x[c]
        rows.append(acc)
    return np.stack(rows)


def _plane_inner(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """sum_a x_a y_a of component planes (m, n, T), in index order."""
    out = x[0] * y[0]
    for a in range(1, x.shape[0]):
        out += x[a] * y[a]
    return out


def reference_glr(model: LinearGaussianModel, z: np.ndarray, x0: np.ndarray, P0: np.ndarray, window: int,
                  jump: str) -> np.ndarray:
    """The textbook online GLR, one trial and one step at a time: a filterpy
    ``KalmanFilter`` loop that keeps, per trial, a bank of the last ``window`` onsets
    and updates each one's F, d and C by the recursions of :func:`signatures` and
    :func:`glr_statistic` with the filter's own K_t, S_t and nu_t. The oracle of the
    tests; ``bench perf`` times the method against :func:`glr_statistic` on the
    filterpy loop's innovations (:class:`methods.maneuver.base.InnovationDetector`),
    the GLR vectorised as a NumPy user would write it, not this loop over onsets."""
    n, K, m = z.shape
    HF = model.H @ model.F
    out = np.zeros((n, K))
    for i, k, kf in filterpy_steps(model, z, x0, P0):
        if k == 0:
            bank = []
        bank = (bank + [[k, np.zeros((model.dim_x, m)), np.zeros(m), np.zeros((m, m))]])[-window:]
        S_inv = np.linalg.inv(kf.S)
        for entry in bank:
            onset, estimate, d, info = entry
            G = jump_response(jump, k - onset) * np.eye(m) - HF @ estimate
            entry[1:] = [model.F @ estimate + kf.K @ G, d + G.T @ S_inv @ kf.y, info + G.T @ S_inv @ G]
            out[i, k] = max(out[i, k], entry[2] @ np.linalg.solve(entry[3], entry[2]))
    return out


@register_method
class Glr(InnovationDetector):
    r"""Generalized likelihood ratio (GLR) test for a jump in acceleration or velocity, onset in a window.

    Willsky & Jones (1976), "A generalized likelihood ratio approach to the
    detection and estimation of jumps in linear systems", IEEE Trans. Automatic
    Control; Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to
    Tracking and Navigation* (2001), sec. 11.3. On the innovations of the
    scenario's reference filter (:func:`models.kalman.innovations`), the
    hypothesis "a jump $b$ (one value per measured component) in the target's
    acceleration (``jump = "acceleration"``) or velocity (``"velocity"``) with
    onset $\theta$" against "no jump": the log-likelihood ratio maximised over $b$ is
    $d' C^{-1} d / 2$, with $d = \sum G' S^{-1} \nu$ and $C = \sum G' S^{-1} G$ over the steps
    since $\theta$ (:func:`glr_statistic`), $G$ the innovation's response to a unit
    jump, from the filter's gains (:func:`signatures`, the $G(t; \theta)$, $F(t; \theta)$
    recursions, computed once per batch: they do not depend on the data). The
    statistic is maximised over the ``window`` = $M$ latest onsets:

    $$
    l(t) = \max_{t-M < \theta \le t} d(t; \theta)'\, C(t; \theta)^{-1}\, d(t; \theta)
    $$

    Before the window fills ($t < M - 1$) the onsets are $\theta = 0, \dots, t$;
    ``valid_from = M - 1``. The maximising lag $t - \theta$ (the onset estimate) is
    the trace ``onset_lag``.

    Nominal threshold: for each onset, $d' C^{-1} d \sim \chi^2(n_z)$ exactly under a
    matched model ($d$ is Gaussian with covariance $C$); the maximum over the $M$
    onsets is thresholded at the $\chi^2(n_z)$ quantile of level $P_{fa} / M$
    (Bonferroni). The onsets' statistics are strongly correlated, so this is an
    approximation that is conservative (the false-alarm rate is at most $P_{fa}$,
    usually well below): calibrate empirically for a comparison at equal Pfa.
    """

    name = "glr"

    @dataclass(frozen=True)
    class Params:
        window: int = param(20, "window M of candidate onsets (steps): theta = t-M+1 .. t", ge=1,
                            le=MAX_GLR_WINDOW,
                            why="one onset at least; each step costs M quadratic forms per trial, so at most "
                                "1 000 (25 times a 40-step maneuver); at most the scenario's steps (checked "
                                "per scenario config)")
        jump: str = param("acceleration", "the jump tested: a step in each measured component's "
                          "acceleration, or in its velocity", choices=JUMPS)

    def detect(self, batch: Batch, inn: InnovationSequence, params) -> DetectionOutput:
        statistic, lag = glr_statistic(inn.nu, inn.S, self.signatures(batch, inn, params))
        return DetectionOutput(statistic=statistic, valid_from=self.valid_from(params, batch.steps),
                               traces={"onset_lag": lag, "nis": inn.nis})

    def valid_from(self, params, steps: int) -> int:
        """Once the window of M onsets is whole (:func:`glr_valid_from`)."""
        return glr_valid_from(params.window, steps)

    @staticmethod
    def signatures(batch: Batch, inn: InnovationSequence, params) -> Iterator[Signature]:
        """The reference filter's signatures (:func:`signatures`) from its gains (those
        of the innovations, else by the data-independent covariance recursion)."""
        filt = reference_filter(batch)
        gains = inn.gain if inn.gain is not None else covariance_sequence(filt.model, filt.P0, batch.steps)[3]
        return signatures(filt.model, gains, inn.S, params.window, params.jump)

    def nominal_threshold(self, params, pfa: float, batch: Batch) -> float:
        """chi2(n_z) upper quantile at pfa / M (Bonferroni over the M onsets), by the
        survival-function inverse (finite down to the smallest pfa)."""
        return float(scipy.stats.chi2.isf(pfa / params.window, self.measurement_dim(batch)))

    def check_scenario(self, params, scenario_params) -> str | None:
        return steps_problem(params.window - 1, f"the window of {params.window} onsets", scenario_params)
