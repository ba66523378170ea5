"""Scenario ``tbd-grid``: the DP track-before-detect surveillance scene.

The scene of the multi-frame DP-TBD paper (Zheng, Wang, Yang & Du, multi-frame
data-association DP-TBD in AR-correlated noise, the seed of ``dp-tbd-mf``): a
50 km x 50 km surveillance area (x 150-200 km, y 120-170 km) in 100 m cells
(500 x 500), 20 frames at T = 1 s, one target with a non-fluctuating (or
Swerling-1) amplitude, and noise that is correlated over frames within each
cell by an autoregressive model and independent across cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from radarbench.bench.core import TBD, Batch, Scenario
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_scenario
from radarbench.bench.tasks.tbd import Grid, TBDScene
from radarbench.models.ar_noise import ar_autocovariance, ar_innovation_std, ar_stationarity_problem, stationary_predictors

#: the paper's surveillance area (m): x and y ranges
PAPER_X_RANGE_M = (150e3, 200e3)
PAPER_Y_RANGE_M = (120e3, 170e3)
#: the paper's initial target position (m) and velocity (m/s)
START_M = (180e3, 160e3)
VELOCITY_M_S = (100.0, 100.0)
#: 0-based index of the first frame moved by the turn (frame 11 of 1..20) and
#: the number of turning transitions (frames 11..15)
TURN_ONSET_FRAME = 10
TURN_FRAMES = 5
#: free cells kept between the true track and the grid edge on small grids
EDGE_MARGIN_CELLS = 2
#: stationary noise standard deviation sigma (the noise is scaled to it)
NOISE_STD = 1.0
#: the coefficients as printed in the source paper (explosive; see the Params)
PAPER_PRINTED_AR = (-2.0, 1.7, 0.64)

SNR_DEFINITION = (
    "SNR = 10 log10(s^2 / sigma^2), s the target amplitude added to the "
    "target's cell (its mean-square value over the frames for Swerling-1) and "
    "sigma^2 the stationary variance of the per-cell noise (sigma = noise_std = 1)."
)


# --------------------------------------------------------------------- noise

def ar_coefficients_problem(a) -> str | None:
    """None if the AR coefficients are usable (stationary), else a one-line
    reason (:func:`models.ar_noise.ar_stationarity_problem`), which says so
    when ``a`` is the paper's printed set."""
    why = ar_stationarity_problem(a)
    if why is not None and len(a) == len(PAPER_PRINTED_AR) and np.allclose(a, PAPER_PRINTED_AR):
        why += ("; these are the paper's printed coefficients, explosive in this convention and in "
                "v_k = a1 v_(k-1) + ... too; the default (-2, 1.7, -0.64) flips the sign of a3")
    return why


def generate_noise(rng, shape_hw: tuple[int, int], frames: int, a: tuple[float, ...] | None,
                   sigma: float = NOISE_STD) -> np.ndarray:
    """(n, K, H, W) float32 noise, independent across cells, AR(P) over frames
    (``a`` None: white), started from the stationary distribution.

    Frame k is drawn from its exact conditional law given the frames before
    it: v_k = sum_j phi_j v_(k-j) + sqrt(nu_k) e_k with e_k ~ N(0, 1). For
    k < P, (phi, nu) come from the stationary autocovariance
    (:func:`stationary_predictors`), so (v_0, ..., v_(P-1)) ~ N(0, Gamma_P)
    exactly; from k = P on it is the AR recursion v_k = sigma_w e_k -
    sum_i a_i v_(k-i). The process is therefore stationary from frame 0: no
    burn-in transient. White noise is v_k = sigma e_k.

    The standard normals are numpy's, from each trial's own stream: for
    trial t, e = G_t.standard_normal((K, H, W)) (frame by frame, row by
    row), G_t its Generator, so a trial's noise does not depend on the batch
    it is in. They are drawn one at a time inside the compiled recursion
    (:func:`_noise_trial`): numba runs numpy's own ``standard_normal``
    algorithm on the Generator's bits, so the values and the Generator's final
    state are numpy's (the tests compare them bit for bit), while the draws
    cost about a third of numpy's bulk call and no (K, H, W) float64 array of
    normals is stored (``bench perf`` times the scene). The recursion runs in
    float64 on a ring of the trial's last P frames (P H W float64, reused from
    trial to trial) and only its result is stored as float32.
    """
    H, W = shape_hw
    coeffs, scales = _predictor_table(tuple(a) if a else (), sigma)
    P = coeffs.shape[1]
    z = np.empty((rng.n, frames, H, W), dtype=np.float32)
    ring = np.empty((P, H, W))
    for t, gen in enumerate(rng.generators):
        _noise_trial(gen, coeffs, scales, ring, z[t])
    return z


def _predictor_table(a: tuple[float, ...], sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """(coeffs (P + 1, P), scales (P + 1,)) such that frame k, with
    j = min(k, P), is v_k = scales[j] e_k - sum_(i=1..j) coeffs[j, i-1] v_(k-i).

    Rows j < P are the start-up predictors of :func:`stationary_predictors`
    (coeffs = -phi_j, zero-padded; scales = sqrt(nu_j)); row P is the AR
    recursion itself (coeffs = a, scales = sigma_w). White noise (a = ()):
    one row, scales = (sigma,).
    """
    P = len(a)
    coeffs = np.zeros((P + 1, P))
    scales = np.empty(P + 1)
    if P == 0:
        scales[0] = sigma
        return coeffs, scales
    for j, (phi, nu) in enumerate(stationary_predictors(a, sigma)):
        coeffs[j, :j] = -phi
        scales[j] = np.sqrt(nu)
    coeffs[P] = a
    scales[P] = ar_innovation_std(a, sigma ** 2)
    return coeffs, scales


@numba.njit(cache=True)
def _noise_trial(gen, coeffs, scales, ring, out):  # pragma: no cover - compiled
    """One trial's noise into ``out`` (K, H, W) float32 (:func:`generate_noise`).

    For frame k, j = min(k, P), each grid row r: e = the next W normals of
    ``gen`` (the trial's numpy Generator), v_k = scales[j] e - sum_(i=1..j)
    coeffs[j, i-1] v_(k-i) in float64, where v_(k-i) is ring slot
    (k - i) % P; v_k then overwrites slot k % P (it held v_(k-P), already
    read) and is stored in ``out`` as float32. The normals of a row are drawn
    first and the lags applied row-wise, so the lag loops run over contiguous
    memory; the draws stay in frame, row, column order.
    """
    P = ring.shape[0]
    K, H, W = out.shape
    row = np.empty(W)
    for k in range(K):
        j = min(k, P)
        scale = scales[j]
        for r in range(H):
            for x in range(W):
                row[x] = scale * gen.standard_normal()
            for i in range(1, j + 1):
                ci = coeffs[j, i - 1]
                past = ring[(k - i) % P, r]
                for x in range(W):
                    row[x] -= ci * past[x]
            dst = out[k, r]
            for x in range(W):
                dst[x] = row[x]
            if P > 0:
                ring[k % P, r, :] = row


# ------------------------------------------------------------------ geometry

def true_track(frames: int, period_s: float, turn_rate_rad_s: float) -> np.ndarray:
    """The paper's trajectory (K, 4) [x_m, y_m, vx_m_s, vy_m_s].

    Start at (180 km, 160 km) with v = (100, 100) m/s; straight (constant
    velocity) into frames 2..10 (1-based), a clockwise coordinated turn at
    ``turn_rate_rad_s`` on the transitions into frames 11..15, straight again
    from frame 16. The transitions are exact (closed-form constant-velocity and
    constant-turn-rate motion), and the straight leg before the turn is
    computed as start + v t so the paper's cell-corner positions stay exact.
    """
    x = np.empty((frames, 4))
    x[0] = (*START_M, *VELOCITY_M_S)
    omega = -float(turn_rate_rad_s)          # clockwise = negative (math convention, y up)
    for k in range(1, frames):
        px, py, vx, vy = x[k - 1]
        in_turn = TURN_ONSET_FRAME <= k < TURN_ONSET_FRAME + TURN_FRAMES and omega != 0.0
        if in_turn:
            s, c = math.sin(omega * period_s), math.cos(omega * period_s)
            x[k] = (px + (s * vx - (1.0 - c) * vy) / omega,
                    py + ((1.0 - c) * vx + s * vy) / omega,
                    c * vx - s * vy, s * vx + c * vy)
        elif k <= TURN_ONSET_FRAME:
            x[k] = (START_M[0] + VELOCITY_M_S[0] * k * period_s,
                    START_M[1] + VELOCITY_M_S[1] * k * period_s, vx, vy)
        else:
            x[k] = (px + vx * period_s, py + vy * period_s, vx, vy)
    return x


def _cells_of(xy: np.ndarray, x_min: float, y_min: float, cell_m: float) -> np.ndarray:
    """(row, col) of the cell containing each position: col = floor((x - x_min)
    / cell_m), row = floor((y - y_min) / cell_m)."""
    col = np.floor((xy[..., 0] - x_min) / cell_m).astype(np.int64)
    row = np.floor((xy[..., 1] - y_min) / cell_m).astype(np.int64)
    return np.stack([row, col], axis=-1)


def _fit_axis(pos: np.ndarray, lo_paper: float, span_paper: float, start: float,
              cells: int, cell_m: float) -> tuple[float, int]:
    """Grid origin on one axis, and the number of cells the track needs.

    The origin puts the start at the same fraction of the scene as in the
    paper, snapped to the paper's cell lattice, then shifted by whole cells
    so the track keeps EDGE_MARGIN_CELLS free cells to each edge.
    """
    frac = (start - lo_paper) / span_paper
    origin = start - frac * cells * cell_m
    origin = lo_paper + round((origin - lo_paper) / cell_m) * cell_m
    idx = np.floor((pos - origin) / cell_m).astype(np.int64)
    need = int(idx.max() - idx.min() + 1 + 2 * EDGE_MARGIN_CELLS)
    low, high = EDGE_MARGIN_CELLS, cells - 1 - EDGE_MARGIN_CELLS
    if idx.min() < low:
        origin -= (low - idx.min()) * cell_m
    elif idx.max() > high:
        origin += (idx.max() - high) * cell_m
    return origin, need


def scene_geometry(p) -> tuple[np.ndarray, dict, np.ndarray]:
    """(truth (K, 4), grid dict, target cells (K, 2)) for params ``p``.

    At the paper's size (500 cells of 100 m) the grid is exactly the paper's
    area, x 150-200 km and y 120-170 km. A smaller (or larger) grid keeps the
    cell size, the trajectory and hence the target's motion in cells per frame
    (the DP problem stays the paper's, only the number of noise cells
    changes): the scene is ``cells * cell_m`` wide, placed so the start sits
    at the same fraction of it as in the paper (0.6 across, 0.8 up), on the
    paper's cell lattice (so the true cell path, relative to its start cell,
    is the same at every grid size), then shifted by whole cells if needed so
    the whole track stays at least EDGE_MARGIN_CELLS cells inside.
    """
    truth = true_track(p.frames, p.frame_period_s, p.turn_rate_rad_s)
    x_min, need_x = _fit_axis(truth[:, 0], PAPER_X_RANGE_M[0], PAPER_X_RANGE_M[1] - PAPER_X_RANGE_M[0],
                              START_M[0], p.cells, p.cell_m)
    y_min, need_y = _fit_axis(truth[:, 1], PAPER_Y_RANGE_M[0], PAPER_Y_RANGE_M[1] - PAPER_Y_RANGE_M[0],
                              START_M[1], p.cells, p.cell_m)
    grid = {"rows": p.cells, "cols": p.cells, "cell_m": float(p.cell_m),
            "x_min_m": float(x_min), "y_min_m": float(y_min),
            "cells_needed": max(need_x, need_y)}
    cells = _cells_of(truth[:, :2], x_min, y_min, p.cell_m)
    return truth, grid, cells


# ------------------------------------------------------------------ scenario

@register_scenario
class TbdGrid(Scenario):
    r"""DP track-before-detect surveillance scene: one target on a grid of AR-correlated noise frames.

    **Scene** (Params ``cells``, ``frames``, ``cell_m``, ``frame_period_s``):
    see :func:`scene_geometry` and :func:`true_track`. At the defaults it is
    the paper's: 500 x 500 cells of 100 m over x 150-200 km, y 120-170 km,
    20 frames 1 s apart; the target starts at (180 km, 160 km) with
    v = (100, 100) m/s (1 cell per frame diagonally), turns clockwise at
    0.35 rad/s on the transitions into frames 11-15 (1-based; about
    1.41 cells per frame, two of those transitions jump 2 cells along one
    axis) and goes straight on for frames 16-20. With fewer than 15 frames the
    turn is truncated. Cell (row, col) covers
    $x \in [x_{\min} + \text{col}\, \Delta,\ x_{\min} + (\text{col} + 1) \Delta)$ ($\Delta$ = ``cell_m``)
    and the same in $y$ for rows; its centre is $x_{\min} + (\text{col} + 0.5) \Delta$. The target puts its whole amplitude in the
    cell that contains its true position (position error at most half a cell
    per axis from the cell centre; the paper's start lies on a cell corner and
    belongs to the cell above and to the right of it).

    **Noise** (``noise``, ``ar_coefficients``): independent across cells; per
    cell an AR($P$) process over frames,

    $$
    v_k + a_1 v_{k-1} + \dots + a_P v_{k-P} = w_k,
    $$

    scaled to stationary variance $\sigma^2 = 1$ and started from its
    stationary distribution (:func:`generate_noise`), or white $\mathcal{N}(0, 1)$. The
    coefficients must make the process stationary: all roots of
    $z^P + a_1 z^{P-1} + \dots + a_P$ strictly inside the unit circle. The paper's printed
    $a = (-2, 1.7, 0.64)$ has a pair of roots of modulus 1.525 (and in the
    opposite sign convention a root at -2.57): explosive either way, rejected
    at validation. The default $(-2, 1.7, -0.64)$ flips the sign of $a_3$: roots
    0.902 and $0.549 \pm 0.639i$ (modulus 0.842), stationary, lag-1..3
    correlations 0.903, 0.683, 0.471.

    **Target amplitude** (``amplitude``): ``constant`` $s$ in every frame
    (non-fluctuating), or ``swerling1``: independent from frame to frame
    (scan-to-scan fluctuation), $A_k = s \sqrt{E_k}$ with $E_k \sim \operatorname{Exp}(1)$, so the
    target power $A_k^2$ is exponential with mean $s^2$ (a Rayleigh amplitude).
    $\text{SNR} = 10 \log_{10}(s^2 / \sigma^2)$ (:data:`SNR_DEFINITION`); the realised SNR of
    a trial is $10 \log_{10}(\overline{A_k^2} / \sigma^2)$, the mean over frames (= ``snr_db`` for
    constant amplitude, NaN under the null).

    **Null** (``snr_db=None``): the same noise, no target; ``truth`` still
    holds the trajectory for reference, ``target_cells`` is None.

    **Randomness**: per trial, in this order whatever the SNR or hypothesis:
    the noise normals, numpy's ``standard_normal((K, H, W))`` of the trial's
    Generator (frame by frame, row by row; :func:`generate_noise`), then K exponentials
    for the Swerling draw (always drawn, used only by ``swerling1``). Trial i
    sees the same noise at every SNR and whatever the batch it is in.

    **Scene** (a :class:`~bench.tasks.tbd.TBDScene`; docs/architecture.md,
    'Scenes'): ``grid`` (a :class:`~bench.tasks.tbd.Grid`), ``target_cells``
    (n, K, 2) int (row, col) or None, ``frame_period_s``, ``noise_std``
    ($\sigma$), ``noise_autocovariance`` ($\gamma(0), \dots, \gamma(K-1)$ of the stationary noise
    for that $\sigma$: all lags that occur in a scene; white noise: $(\sigma^2, 0, \dots)$), ``ar_coefficients`` (None for white noise),
    ``hit_tolerance_cells``, ``snr_definition``, ``realised_snr_db`` (n,),
    ``amplitude`` (n, K) (the target amplitude per frame; zeros under the
    null), ``position_index`` (0, 1). ``truth`` is (n, K, 4) [x_m, y_m,
    vx_m_s, vy_m_s], the same trajectory in every trial; ``z`` is (n, K, H,
    W) float32.
    """

    name = "tbd-grid"
    tasks = (TBD,)
    #: the parameters its random streams were first keyed by (Scenario.stream_params)
    stream_params = ("cells", "frames", "noise", "ar_coefficients", "amplitude", "hit_tolerance_cells",
                     "frame_period_s", "cell_m", "turn_rate_rad_s")
    #: a small instance, for tests and quick looks
    small_params = {"cells": 32, "frames": 8}
    #: ``bench perf`` sizes: name -> (scenario params, trials)
    perf_sizes = {"small": ({"cells": 100}, 20), "paper": ({}, 4)}
    perf_snr_db = 6.0
    #: scene generation at the paper's size, one core
    perf_targets = {"paper": {"seconds_per_trial": 0.020}}

    def unit_memory_bytes(self, params, n: int) -> int:
        """The float32 frames n K H W, the float64 ring of the AR recursion (P H W)
        and a recorded trial's copy of its frames (K H W float32)."""
        K, H = params.frames, params.cells
        P = len(params.ar_coefficients) if params.noise == "ar" else 0
        return 4 * n * K * H * H + 8 * P * H * H + 4 * K * H * H

    @dataclass(frozen=True)
    class Params:
        cells: int = param(500, "grid side H = W (cells); the paper's scene is 500 (50 km at 100 m); "
                                "smaller grids keep the cell size and trajectory and move the scene "
                                "window so the whole track stays inside", ge=8, le=5000,
                           why="8 cells hold a short track with its margins; 5000 is 100 times the "
                               "paper's cells (a unit's memory, n K cells^2 x 4 bytes, is checked)")
        frames: int = param(20, "number of frames K", ge=2, le=1000,
                            why="two frames at least (more than the AR order, checked); 1000 is 50 "
                                "times the paper's (see cells for memory)")
        noise: str = param("ar", "per-cell noise over frames: 'ar' (AR(P), ar_coefficients) or "
                                 "'white'", choices=("ar", "white"))
        ar_coefficients: tuple[float, ...] = param(
            (-2.0, 1.7, -0.64), "AR coefficients (a1, ..., aP) of v_k + a1 v_(k-1) + ... + aP v_(k-P) "
            "= w_k (dimensionless); must be stationary. Default: the paper's (-2, 1.7, 0.64) with the "
            "sign of a3 flipped (the printed set is explosive)", gt=-70.0, lt=70.0, min_len=1, max_len=8,
            why="AR(1) to AR(8); a stationary AR(8) has coefficients of less than C(8, 4) = 70 in "
                "magnitude, and stationarity itself is checked")
        amplitude: str = param("constant", "target amplitude model: 'constant' (non-fluctuating) or "
                                           "'swerling1' (independent Rayleigh amplitude per frame, "
                                           "mean power s^2)", choices=("constant", "swerling1"))
        hit_tolerance_cells: int = param(1, "a backtracked cell is a hit within this Chebyshev "
                                            "distance of the true cell (cells)", ge=0, le=5000,
                                         why="0 is the exact cell; at most the grid side")
        frame_period_s: float = param(1.0, "frame period T (s)", ge=1e-3, le=100.0,
                                      why="1 ms to 100 s between frames: the target (141 m/s) moves "
                                          "from 0.14 m to 14 km a frame")
        cell_m: float = param(100.0, "cell size (m)", ge=1.0, le=1e5,
                              why="1 m to 100 km: the track spans between 1 and 1e-3 of the paper's "
                                  "cells (the grid must hold it, checked)")
        turn_rate_rad_s: float = param(0.35, "clockwise turn rate on the transitions into frames "
                                             "11-15 (rad/s); 0: straight line", ge=0.0, le=3.0,
                                       why="0 is a straight line; 3 rad/s nearly half a turn a frame")

        def validate(self) -> None:
            why = ar_coefficients_problem(self.ar_coefficients)
            if why is not None:
                raise ConfigError("ar_coefficients", why)
            if self.noise == "ar" and self.frames <= len(self.ar_coefficients):
                raise ConfigError("frames", f"AR({len(self.ar_coefficients)}) noise needs more frames than "
                                  f"its order (its autocovariance to lag {len(self.ar_coefficients)} sets the "
                                  f"noise power), got frames = {self.frames}")
            need = scene_geometry(self)[1]["cells_needed"]
            if need > self.cells:
                raise ConfigError("cells", f"the true track over {self.frames} frames spans "
                                  f"{need - 2 * EDGE_MARGIN_CELLS} cells (plus {EDGE_MARGIN_CELLS} "
                                  f"free cells each side); needs cells >= {need}, got {self.cells}")

    def generate(self, params, snr_db: float | None, n: int, rng) -> Batch:
        p = params
        K, H = p.frames, p.cells
        ar = tuple(p.ar_coefficients) if p.noise == "ar" else None
        # Draw first, in a fixed order, so every SNR and the null share the noise.
        z = generate_noise(rng, (H, H), K, ar, NOISE_STD)
        fluct = rng.exponential(K)                                   # (n, K), Swerling-1 powers

        truth1, grid, cells1 = scene_geometry(p)
        del grid["cells_needed"]
        n_rows = rng.n
        truth = np.broadcast_to(truth1, (n_rows, *truth1.shape)).copy()
        null = snr_db is None
        if null:
            amp = np.zeros((n_rows, K))
            target_cells = None
            realised = np.full(n_rows, np.nan)
        else:
            s = NOISE_STD * 10.0 ** (snr_db / 20.0)
            amp = s * (np.sqrt(fluct) if p.amplitude == "swerling1" else np.ones((n_rows, K)))
            target_cells = np.broadcast_to(cells1, (n_rows, K, 2)).copy()
            rows, cols = cells1[:, 0], cells1[:, 1]
            frames = np.arange(K)
            z[:, frames, rows, cols] += amp.astype(np.float32)
            realised = 10.0 * np.log10(np.mean(amp ** 2, axis=1) / NOISE_STD ** 2)

        if ar is None:
            gamma = np.zeros(K)
            gamma[0] = NOISE_STD ** 2
        else:
            gamma = np.array(ar_autocovariance(ar, K - 1, NOISE_STD ** 2))
        scene = TBDScene(
            grid=Grid(**grid), frame_period_s=float(p.frame_period_s), target_cells=target_cells,
            noise_std=NOISE_STD, noise_autocovariance=gamma, ar_coefficients=ar,
            hit_tolerance_cells=int(p.hit_tolerance_cells), amplitude=amp, snr_definition=SNR_DEFINITION,
            realised_snr_db=realised, position_index=(0, 1))
        return Batch(t=p.frame_period_s * np.arange(K), truth=truth, z=z, scene=scene,
                     trials=np.asarray(rng.trials))
