"""Method ``pf-tbd``: particle-filter track-before-detect with an existence variable.

Salmond & Birch, "A particle filter for track-before-detect", Proc. American
Control Conference, 2001 (a binary existence variable with birth and death
probabilities, particles over position, velocity and amplitude, weights from the
likelihood ratio of the cell values near each particle), with the birth and
existence computation of Rutten, Gordon & Maskell, "Recursive track-before-detect
with target amplitude fluctuations", IEE Proc. Radar, Sonar and Navigation
152(5), 2005 (separate birth and continuing particles, births proposed from the
current frame, the existence probability from the particles' likelihood sums).
The baseline the TBD benchmark's DP methods are set against: DP searches every
path exhaustively, the particle filter samples them (docs/architecture.md,
'Plugins').
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import TBD, Batch, Method, TBDOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.tbd import pf_kernels
from radarbench.methods.tbd.reference import reference_pf_tbd
from radarbench.methods.tbd.dp_tbd import (
    MAX_SPEED_M_S,
    ConditionalLLR,
    _frames32,
    conditional_llr_problem,
    noise_autocovariance,
    scene_shape,
)

#: the largest particle budget: 10^7 particles take 1.8 GB (:meth:`PfTbd.unit_memory_bytes`)
MAX_PARTICLES = 10_000_000
CHAIN_WHY = "a probability; 0 or 1 would make the existence chain deterministic"


def residual_predictors(batch: Batch) -> tuple[np.ndarray, np.ndarray]:
    """(betas (3, 2), variances (3,)): the one-step predictor of a cell's noise
    from its previous frames (:class:`methods.tbd.dp_tbd.ConditionalLLR`) for frame 0
    (none: beta = 0, var = gamma0), frame 1 (one: beta_first, var_first) and frames
    >= 2 (two: beta1, beta2, sigma_c^2)."""
    gamma = noise_autocovariance(batch)
    llr = ConditionalLLR.from_autocovariance(gamma, 1.0)
    betas = np.array([[0.0, 0.0], [llr.beta_first, 0.0], [llr.beta1, llr.beta2]])
    return betas, np.array([gamma[0], llr.var_first, llr.var])


@register_method
class PfTbd(Method):
    r"""Particle-filter TBD (Salmond-Birch existence model, Rutten-Gordon-Maskell births): posterior existence log-odds and mean track.

    **State.** $E_k \in \{0, 1\}$ (target absent / present) and, when present,
    $x_k = (p_x, p_y, v_x, v_y, A)$: position and velocity (m, m/s) in the plane of the
    scene's grid and the amplitude $A$ added to the cell holding $(p_x, p_y)$ (the
    ``tbd-grid`` cell model: the whole amplitude in one cell). $E$ is a Markov chain,
    $P(E_k = 1 \mid E_{k-1} = 0) = P_b$ (``birth_probability``),
    $P(E_k = 0 \mid E_{k-1} = 1) = P_d$ (``death_probability``); no target before frame 0.

    **Dynamics** (frame period $T$ from the scene). Nearly constant velocity with
    discrete white-noise acceleration of std $\sigma_a$ (``accel_std_m_s2``) per axis,

    $$
    p_k = p_{k-1} + T v_{k-1} + \tfrac{T^2}{2} \sigma_a w, \qquad v_k = v_{k-1} + T \sigma_a w,
    $$

    and a log-amplitude random walk $\log A_k = \log A_{k-1} + \sigma_l w_A$,
    $\sigma_l = D \ln(10) / 20$, $D$ = ``amplitude_walk_db`` ($w$, $w_A$ standard normal). A target
    whose cell leaves the grid is not in the scene: its particles get weight 0. Birth
    prior: position uniform over the grid, velocity uniform in the box
    $|v_x|, |v_y| \le$ ``max_speed_m_s``, SNR $20 \log_{10}(A / \sigma)$ uniform on
    [``snr_min_db``, ``snr_max_db``].

    **Likelihood.** The frames are the scene's: independent across cells, each
    cell's noise stationary Gaussian over frames with autocovariance $\gamma(h)$
    (``scene.noise_autocovariance``; white: $\gamma(h > 0) = 0$). As in ``dp-tbd-mf``
    (:class:`methods.tbd.dp_tbd.DpTbdMf`), a cell's value is predicted from the same
    cell's two previous frames, $r_k(c) = z_k(c) - \beta_1 z_{k-1}(c) - \beta_2 z_{k-2}(c)$,
    which is $\mathcal{N}(0, \sigma_c^2)$ under H0 (Markov-2 approximation of the
    noise; frames 1 and 0 use one and no previous frame). Under a particle's
    history (cells $c_0, c_1, c_2$ at frames $k, k-1, k-2$ and amplitudes $a_0, a_1, a_2$; a
    frame before its birth has none) the residual of cell $c$ has mean

    $$
    m(c) = a_0 [c_0 = c] - \beta_1 a_1 [c_1 = c] - \beta_2 a_2 [c_2 = c],
    $$

    so the frame's log-likelihood ratio against H0, given the past frames, is the
    sum over the distinct cells of the particle's history of

    $$
    \lambda_k(c) = \frac{m(c)\, r_k(c) - m(c)^2 / 2}{\sigma_c^2}
    $$

    (the cells the target left carry its echo through the predictor; every other
    cell's ratio is 1). White noise: $\beta = 0$ and
    $\lambda = (A z_k(c_0) - A^2 / 2) / \sigma^2$, Salmond & Birch's point target in
    Gaussian noise. The likelihood ratio $l = e^{\lambda}$ is the particle weight.

    **Birth and existence** (Rutten et al.). Each frame $N_b$ birth particles (a
    ``birth_fraction`` of the ``particles``) are drawn from a proposal $q_b$ and $N_c$
    continuing ones are predicted from the $N_c$ resampled at the previous frame.
    With $P_{k-1}$ the existence probability and $o = P / (1 - P)$ its odds,

    $$
    \begin{aligned}
    S_b &= \frac{1}{N_b} \sum_i \frac{l(x_b^i)\, p_b(x_b^i)}{q_b(x_b^i)}, \qquad
    S_c = \frac{1}{N_c} \sum_j l(x_c^j), \\
    o_k &= \frac{P_b S_b + (1 - P_d)\, o_{k-1} S_c}{(1 - P_b) + P_d\, o_{k-1}}
    \end{aligned}
    $$

    (the existence posterior: the numerator is present-at-$k$ by birth or by
    survival, the denominator absent-at-$k$, whose likelihood ratio is 1). Birth
    particle $i$ has weight proportional to $P_b l p_b / (q_b N_b)$, continuing
    particle $j$ to $(1 - P_d)\, o_{k-1} l / N_c$; $N_c$ of the $N_b + N_c$ are resampled
    (``resampling``: systematic, or stratified) for the next frame. Proposal
    (``birth_proposal``): ``measurement`` draws the birth cell uniformly among the
    cells whose residual reaches ``birth_threshold`` $\times\, \sigma_c$ at frame $k$
    ($p_b / q_b = M / (H W)$ for $M$ such cells; uniform over the grid when none
    does), position uniform in the cell, velocity and SNR from the prior; this
    ignores the prior mass of the cells below the threshold (Rutten et al.'s
    approximation: their likelihood ratio is small). ``uniform`` draws from the
    prior itself (Salmond & Birch; $p_b / q_b = 1$). All in the log domain.
    Defaults (``birth_threshold``, ``birth_fraction``, ``accel_std_m_s2``): from
    a small study on 128 x 128 ``tbd-grid`` scenes near Pd = 0.5 (the threshold
    trades births on noise cells against missing the target's cell; an
    acceleration std below the turn's own lets the particles lose the target
    in the turn, which collapses the existence probability).

    **Outputs.** Score $= \log o_{K-1}$, the log-odds of existence at the last frame
    (monotone in the posterior existence probability, without its saturation at 1);
    there is no analytic null law, so it is calibrated on null scenes. Track: per
    frame the existence-conditioned posterior mean of $(p_x, p_y)$ over the weighted
    particles (before resampling), the cell holding it (clipped to the grid). No
    value map.

    **Random numbers and cost.** Counter-based draws per trial from ``seed`` and
    the trial number (:mod:`methods.tbd.pf_kernels`): a trial's output does not
    depend on its batch. One numba kernel over trials (one at a time), particles
    and frames: $O(K (N + H W))$ per trial (the $H W$ term: the measurement proposal's
    scan of each frame). Reference for ``bench perf`` and the tests: the same
    filter in plain NumPy over the particle axis, one trial at a time
    (:func:`methods.tbd.reference.reference_pf_tbd`), on the same draws.
    """

    name = "pf-tbd"
    task = TBD
    reference_name = "NumPy particle filter vectorised over particles, a Python loop over trials and frames"
    reference_trials = 4

    @dataclass(frozen=True)
    class Params:
        particles: int = param(20_000, "particle budget N per trial and frame: N_b births plus N_c "
                                       "continuing particles", ge=10, le=MAX_PARTICLES,
                               why="at least a few births and survivors; 10^7 particles (about 1.8 GB of "
                                   "particle state and weights, checked against the unit memory limit) is "
                                   "beyond any scene here")
        birth_fraction: float = param(0.25, "share of the particles that are births each frame: "
                                           "N_b = round(N birth_fraction), at least 1 of each kind",
                                      gt=0.0, lt=1.0, why="both kinds must exist")
        birth_probability: float = param(0.05, "P_b: probability that an absent target appears at the "
                                               "next frame", gt=0.0, lt=1.0, why=CHAIN_WHY)
        death_probability: float = param(0.05, "P_d: probability that a present target disappears at "
                                               "the next frame", gt=0.0, lt=1.0, why=CHAIN_WHY)
        birth_proposal: str = param("measurement", "birth cells drawn among the cells whose residual "
                                                   "reaches birth_threshold ('measurement', Rutten et al.) "
                                                   "or uniformly over the grid ('uniform', Salmond & Birch)",
                                    choices=pf_kernels.PROPOSALS)
        birth_threshold: float = param(2.5, "residual threshold of the measurement proposal, in units of "
                                            "the residual's std sigma_c", ge=0.0, le=10.0,
                                       why="0 keeps half the cells; beyond 10 no noise cell ever reaches "
                                           "it (the proposal falls back to uniform)")
        resampling: str = param("systematic", "resampling scheme of the N_c survivors",
                                choices=pf_kernels.RESAMPLERS)
        max_speed_m_s: float = param(150.0, "birth velocity prior: uniform in |vx|, |vy| <= this (m/s)",
                                     gt=0.0, le=MAX_SPEED_M_S,
                                     why="a speed (> 0) up to Mach 30, as the DP methods' window")
        accel_std_m_s2: float = param(50.0, "sigma_a of the white-noise acceleration per axis (m/s^2); "
                                            "the default matches the tbd-grid turn's centripetal "
                                            "acceleration, 0.35 rad/s x 141 m/s = 49.5 m/s^2",
                                      ge=0.0, le=1000.0, why="0 is constant velocity; 1000 m/s^2 is 100 g")
        snr_min_db: float = param(-10.0, "lower end of the birth SNR prior 20 log10(A / sigma) (dB)",
                                  ge=-30.0, lt=40.0, why="the DP methods' design-SNR range, below snr_max_db")
        snr_max_db: float = param(20.0, "upper end of the birth SNR prior (dB); > snr_min_db",
                                  gt=-30.0, le=40.0, why="the DP methods' design-SNR range, above snr_min_db")
        amplitude_walk_db: float = param(0.5, "std of the amplitude's random walk per frame (dB)",
                                         ge=0.0, le=10.0, why="0 is a constant amplitude; 10 dB a frame "
                                                              "is a fully fluctuating one")
        seed: int = param(0, "seed of the filter's own draws (with the trial number)", ge=0, le=2**32 - 1,
                          why="a 32-bit seed; the trial number fills the other 32 bits of the key")

        def validate(self) -> None:
            if not self.snr_max_db > self.snr_min_db:
                raise ConfigError("snr_max_db", f"must exceed snr_min_db = {self.snr_min_db}, "
                                  f"got {self.snr_max_db}")

    def run(self, batch: Batch, params) -> TBDOutput:
        score, track = np.empty(batch.n), np.empty((batch.n, batch.steps, 2), np.int64)
        pf_kernels.pf_tbd(_frames32(batch), *self._kernel_arguments(batch, params), score, track)
        return TBDOutput(score=score, track=track)

    def reference_run(self, batch: Batch, params) -> TBDOutput:
        """The straightforward implementation ``bench perf`` compares against."""
        score, track = reference_pf_tbd(_frames32(batch), *self._kernel_arguments(batch, params))
        return TBDOutput(score=score, track=track)

    @staticmethod
    def _kernel_arguments(batch: Batch, params) -> tuple:
        """(keys, geometry, model, betas, variances, flags) of :func:`methods.tbd.pf_kernels.pf_tbd`."""
        grid = batch.scene.grid
        betas, variances = residual_predictors(batch)
        nb, nc = particle_split(params)
        geometry = np.array([grid.x_min_m, grid.y_min_m, grid.cell_m, batch.scene.frame_period_s], float)
        pb, pd = params.birth_probability, params.death_probability
        model = np.array([nb, nc, math.log(pb), math.log1p(-pb), math.log(pd), math.log1p(-pd),
                          params.max_speed_m_s, params.accel_std_m_s2, params.snr_min_db, params.snr_max_db,
                          params.amplitude_walk_db * math.log(10.0) / 20.0, math.sqrt(variances[0]),
                          params.birth_threshold])
        flags = np.array([pf_kernels.PROPOSALS.index(params.birth_proposal),
                          pf_kernels.RESAMPLERS.index(params.resampling)], np.int64)
        return pf_kernels.trial_keys(params.seed, batch.trials), geometry, model, betas, variances, flags

    def work(self, batch: Batch, params) -> tuple[str, float]:
        """Particle updates: particles x frames per trial."""
        return "particle_updates", float(batch.n * batch.steps * params.particles)

    def check_scenario(self, params, scenario_params) -> str | None:
        """The conditional LLR's covariance (:func:`methods.tbd.dp_tbd.conditional_llr_problem`)."""
        return conditional_llr_problem(scenario_params)

    def unit_memory_bytes(self, params, scenario_params, n: int) -> int | None:
        """The kernel's particle arrays (state, cells, log-weight and weight of the N
        particles, state and cells of the N_c survivors: at most 22 8-byte values per
        particle) and its candidate cells (H W int64), for one trial at a time."""
        shape = scene_shape(scenario_params)
        if shape is None:
            return None
        _, H, W = shape
        return 176 * params.particles + 8 * H * W

    # No nominal_threshold (bench.core.Method: NaN, none): the null law of the existence
    # log-odds has no closed form; calibrate on null scenes (``empirical``, ``gumbel`` or ``pot``).


def particle_split(params) -> tuple[int, int]:
    """(N_b, N_c): N_b = round(N birth_fraction), kept within [1, N - 1]."""
    nb = min(max(round(params.particles * params.birth_fraction), 1), params.particles - 1)
    return nb, params.particles - nb
