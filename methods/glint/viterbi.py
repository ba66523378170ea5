"""Method ``viterbi``: block Viterbi state estimation on a quantised trellis (Demirbas; Song & Sun)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import TRACKING, Batch, Method, TrackingOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.glint.trellis import backtrack, trellis_step
from radarbench.methods.glint.viterbi_paper1d import paper_1d_track
from radarbench.models.glint import GlintModel, glint_logpdf, glint_model_of
from radarbench.models.kalman import LinearGaussianModel, covariance_sequence
from radarbench.models.spherical import measure, measurement_residual


# --------------------------------------------------------------------------- the tracker

def disturbance_levels(count: int, std: float, span: float) -> tuple[np.ndarray, np.ndarray]:
    """``count`` levels of a N(0, std^2) disturbance and their log probabilities.

    Levels equally spaced on [-span std, span std], probabilities proportional
    to the normal density at each level (normalised to sum to 1), so the cost
    -log pi of a level grows as w^2 / (2 std^2) like the Gaussian's and small
    corrections stay cheap. (Gauss-Hermite nodes, which match more moments,
    put the smallest non-zero level at 1.36 std for 5 levels; every small
    correction then costs 0.9 nat and the best path keeps metre-size offsets
    rather than pay it.) ``count = 1`` or ``std = 0``: the single level 0.
    """
    if count == 1 or std == 0.0:
        return np.zeros(1), np.zeros(1)
    t = np.linspace(-span, span, count)
    logpi = -0.5 * t ** 2
    logpi -= np.log(np.sum(np.exp(logpi)))
    return std * t, logpi


@dataclass(frozen=True)
class _Axis:
    """One line-of-sight axis: its prior, control and gate at each step."""

    j: int
    u: float                 # control along the axis (m/s^2)
    x0: np.ndarray           # (2,) prior mean (p, v)
    P0: np.ndarray           # (2, 2) prior covariance
    step: np.ndarray         # (K, 2) quantisation step (dp, dv) at each step
    w: np.ndarray            # (J,) disturbance levels of the axis (m/s^2)
    logpi: np.ndarray        # (J,) their log probabilities


@dataclass(frozen=True)
class _Context:
    z: np.ndarray
    R: np.ndarray
    F2: np.ndarray
    g2: np.ndarray
    sensor: str
    density: dict
    Lp: int
    Lv: int
    snap: bool


@register_method
class Viterbi(Method):
    r"""Block Viterbi estimation on a quantised state trellis, with the true glint density.

    After Demirbas, "Manoeuvring-target tracking with the Viterbi algorithm in
    the presence of interference", IEE Proc. F 136(6), 1989 (component-by-
    component Viterbi estimation in blocks), and Song & Sun, "Filtering method
    with non-Gaussian noise" (glint noise; the next block seeded with the
    ``n`` best survivors rather than the single best node). Viterbi
    algorithm: Forney, "The Viterbi algorithm", Proc. IEEE 61(3), 1973.

    **Axes.** The ``glint`` dynamics are the same on every Cartesian axis,
    with isotropic process noise, so they are the same on the axes of any
    rotated frame. The trellis runs in the line-of-sight frame of the prior
    mean (the model's ``los_rotation``: radial, bearing and elevation
    directions), where the spherical measurement nearly decouples: range
    depends on the radial coordinate, bearing on the bearing-direction one,
    elevation on the elevation-direction one (up to terms of the order of
    the target's cross-range excursion over its range). Each axis has the
    2-state (position, velocity) model $s' = F_2 s + g (u_{\text{axis}} + w)$,
    $F_2 = \begin{bmatrix} 1 & P_1 \\ 0 & a \end{bmatrix}$, $g = [P_2, P_1]'$, and its own trellis — the paper's
    component-by-component estimation — with the other axes held at their
    current estimates when the likelihood is evaluated; ``sweeps`` > 1
    repeats the pass over the axes within each block (block coordinate ascent
    on the joint path score). A passive sensor sees nothing along the line
    of sight: the radial axis's likelihood is flat, its best path is the
    zero-disturbance prediction, and it is returned without a trellis.

    **Trellis of one axis** (derivation). The MAP path maximises

    $$
    \log p(s_0) + \sum_k \left[ \log p(s_k \mid s_{k-1}) + \log p(z_k \mid s_k) \right].
    $$

    The disturbance $w$ is represented by ``disturbance_levels`` values $w_m$ equally
    spaced on $\pm$ ``disturbance_span`` $\times\, \sigma_w$ with probabilities $\pi_m$ from the
    normal density (:func:`disturbance_levels`), so a node has that many
    successors $F_2 s + g (u + w_m)$, with log transition probability $\log \pi_m$.
    The state is quantised on a grid of ``position_levels`` x
    ``velocity_levels`` nodes centred on the prediction $F_2 s^* + g u$ of the
    best node $s^*$ of the previous step, spanning $\pm$ ``gate_sigmas`` standard
    deviations of the predicted $(p, v)$ of a linear filter for the axis (the
    gate; :func:`models.kalman.covariance_sequence` with the measurement
    variance mapped to metres at the prior range); the quantisation step is
    the gate over the levels. Successors entering the same node merge (the
    Viterbi recursion keeps the best score), those outside the gate are
    dropped. The branch metric is $\log \pi_m + \log p(z_k \mid \text{state})$, the second
    the *true* glint log density (:func:`models.glint.glint_logpdf`:
    the scenario's mixture or additive model with its $\sigma$, $\eta$ and $\epsilon$) of
    the measurement residuals, evaluated on the position levels and
    interpolated linearly at the successor's position.

    * ``node_value = "survivor"`` (default) keeps in each node the exact state
      of its surviving path, so increments smaller than a quantisation step
      ($P_2 w$ is millimetres here) are not rounded away; ``"centre"`` replaces
      it by the node's grid value, the textbook quantised trellis.
    * ``gate_noise = "glint"`` (default) sizes the gate as if every
      measurement had the glint part's variance $2 \eta^2$ (at least the total
      variance; the total variance when $\epsilon = 0$). A gate from the total
      variance (``"total"``) is ~3x narrower here and, when a glint spike
      falls on the first measurements, can settle on a wrong track that
      never re-enters the gate (about 1 trial in 30 at $\epsilon = 0.05$).
    * Step 0 is built in stages: the prior's gate on a coarse grid (metric
      $\log \mathcal{N}(\text{node}; x_0, P_0) + \log p(z_0 \mid \text{node})$) locates the best position
      level, then grids each spanning at least $\pm 2$ steps of the previous one
      around the best level (with 3 or 5 position levels, halving the step:
      :func:`refined_step`) refine it down to the step of step 1. The
      prior's gate is ~10-100x wider than later ones, and a coarse start
      would leave offsets that the exact dynamics correct only slowly.

    **Blocks.** Steps are processed in blocks of ``Lb`` (the paper: 4). At
    the end of a block the best node is backtracked through the block and
    that path is the estimate of the block's steps, so an estimate uses the
    measurements up to the end of its block (a smoothing lag of up to
    ``Lb`` - 1 steps). The ``survivors`` best nodes of the block's last step,
    with their scores, seed the next block (the paper's ``n``, renamed
    because ``n`` is the trial count here; ``survivors = 1`` is Demirbas's
    original). With few survivors the velocity diversity collapses at every
    block boundary and the paths stop correcting their offsets (the default
    keeps about a tenth of the nodes).

    **The paper's trellis** (``trellis = "paper-1d"``; the default
    ``"pv-grid"`` is the trellis above, ours). Song & Sun (section 2) quantise
    each spherical component $s_i$ (range, bearing, elevation) on its own 1-D
    trellis of values $q \delta_i$ (gates ``quantisation_steps``, printed:
    0.005, 0.001, 0.001), with successors (eq. 6, the derivative $\dot{s}$ from
    differences of the estimates)

    $$
    s_{q_i}(k+1) = Q\big(f_i(s_{q_i}(k), \dot{s}_i(k), \dots, w_{d_i}(k), \dots)\big) \qquad (6)
    $$

    transition probabilities from the discrete disturbance levels (three
    values, section 3), the branch metric with the true glint density

    $$
    M = \log \Pr(s_q(k) \mid s_q(k-1)) + \log p(z_i(k) \mid s_q(k)) \qquad (8\text{-}2)
    $$

    and blocks of ``Lb`` and
    ``start_nodes`` candidate start nodes per block (the paper's $n$, not
    printed; 1 is Demirbas's single node). See :func:`paper_1d_component`
    and :func:`paper_1d_track` for our readings (constant-rate prediction,
    Gauss-Hermite levels, $n_{i0}$, passive range).

    **Cost** per trial and step: for each observed axis and sweep, up to
    ``survivors`` (at a block start) or ``position_levels`` x
    ``velocity_levels`` nodes times ``disturbance_levels`` successors, and
    ``position_levels`` density evaluations per measured component.
    :func:`trellis_step` is compiled with numba when it is installed
    (NumPy otherwise); trials are batched, the loop runs over steps. Returns
    the estimate only (the method has no covariance).
    """

    name = "viterbi"
    task = TRACKING
    needs = frozenset({"glint-model"})

    @dataclass(frozen=True)
    class Params:
        Lb: int = param(4, "block length Lb (steps): the best path is backtracked and the trellis "
                        "re-seeded every Lb steps (the paper: 4)", ge=1, le=1000,
                        why="one step at least; a block's nodes are all kept until it ends, so at most "
                            "1000 steps (and the unit's memory is checked)")
        survivors: int = param(256, "best end nodes of a block that seed the next block (the paper's "
                               "n; 1 = Demirbas's original)", ge=1, le=100_000,
                               why="one node at least; more than a trellis step's nodes are never kept")
        position_levels: int = param(41, "quantisation levels of an axis's position within its gate "
                                     "(odd)", ge=3, le=1001,
                                     why="a level on the prediction and one each side; at most 1001 (the "
                                         "trellis has position x velocity levels nodes per step and the "
                                         "unit's memory is checked)")
        velocity_levels: int = param(61, "quantisation levels of an axis's velocity within its gate "
                                     "(odd)", ge=1, le=1001,
                                     why="1 holds the velocity at the prediction; at most 1001 (see "
                                         "position_levels)")
        gate_sigmas: float = param(4.0, "gate half-width, in standard deviations of a linear filter's "
                                   "predicted position and velocity for the axis", ge=0.1, le=100.0,
                                   why="below 0.1 sigma the gate misses the target; above 100 sigma a "
                                       "quantisation step is coarser than the errors it estimates")
        gate_noise: str = param("glint", "measurement variance the gate is sized with: 'glint' = "
                                "max(2 eta^2, total variance) (total if eps = 0), 'total' = the glint "
                                "noise's total variance", choices=("glint", "total"))
        disturbance_levels: int = param(9, "discrete levels of the disturbance w per axis, equally "
                                        "spaced, probabilities from the normal density", ge=1, le=31,
                                        why="1 is the zero disturbance; each level multiplies a node's "
                                            "successors, 31 resolve the normal law finely")
        disturbance_span: float = param(2.0, "the disturbance levels span +- this many sigma_w", ge=0.01,
                                        le=10.0, why="levels beyond +-10 sigma have probabilities below "
                                                     "e^-50; below 0.01 sigma they all coincide")
        sweeps: int = param(1, "passes over the axes within a block (block coordinate ascent)", ge=1,
                            le=16, why="one pass at least; each pass repeats the whole block's work and "
                                       "the ascent over three axes settles in a few")
        node_value: str = param("survivor", "state a node carries: 'survivor' = the exact state of "
                                "its best path, 'centre' = the node's grid value",
                                choices=("survivor", "centre"))

        trellis: str = param("pv-grid", "trellis: 'pv-grid' = a (position, velocity) grid per line-of-"
                             "sight axis (ours); 'paper-1d' = a 1-D trellis of quantised values per "
                             "measured spherical component, derivative from differences of the "
                             "estimates (Song & Sun, section 2)", choices=("pv-grid", "paper-1d"))
        start_nodes: int = param(1, "paper-1d: best end nodes of a block that start the next (the "
                                 "paper's n, not printed; 1 = Demirbas's single node)", ge=1, le=10_000,
                                 why="one node at least; more than a window's nodes are never kept")
        quantisation_steps: tuple[float, ...] = param(
            (0.005, 0.001, 0.001), "paper-1d: quantisation gates of range (m), bearing and elevation "
            "(rad) (the paper's printed values)", ge=1e-6, le=1000.0, min_len=3, max_len=3,
            why="a node per micrometre or microradian at the finest (a component's window spans "
                "+-3 prior stds in nodes, and the unit's memory is checked); above 1000 every value "
                "falls in one node")
        component_disturbance_variance: tuple[float, ...] = param(
            (7.0, 0.07, 0.07), "paper-1d: variances of the disturbance of range (m^2/s^4), bearing and "
            "elevation (rad^2/s^4), entering a component as P2 w per step (the paper's printed "
            "values)", ge=0.0, le=1e4, min_len=3, max_len=3,
            why="0 is no disturbance; 1e4 (a std of 100 units/s^2, 10 g in range) is beyond any target")
        initial_nodes: int = param(3, "paper-1d: values of a component at step 0 (the paper's n_i0, not "
                                   "printed): 3 = Gauss-Hermite levels of the prior, 1 = its mean, "
                                   "else equally spaced on +-3 prior stds", ge=1, le=100_001,
                                   why="one value at least; more values than nodes of the prior's window "
                                       "merge")

        def validate(self) -> None:
            for name in ("position_levels", "velocity_levels"):
                if getattr(self, name) % 2 == 0:
                    raise ConfigError(name, f"must be odd (a level on the prediction), got "
                                      f"{getattr(self, name)}")

    def unit_memory_bytes(self, params, scenario_params, n: int) -> int | None:
        """The trellis kept over a block, per trial: ``pv-grid``: every node's state,
        back-pointer and score (32 bytes) for each of the block's steps, per axis in
        turn; ``paper-1d``: the widest node window of a component (+-3 prior stds
        in nodes, widened by the disturbance levels at every step), with scores and
        back-pointers (16 bytes a node) for the block's steps and a few temporaries.
        Read from the ``glint`` scenario's parameters by name (None if absent)."""
        steps = getattr(scenario_params, "steps", None)
        if not isinstance(steps, int):
            return None
        block = min(params.Lb, steps)
        if params.trellis == "pv-grid":
            nodes = params.position_levels * params.velocity_levels
            return int(n * nodes * (32 * (block + 1) + 8 * params.disturbance_levels))
        return int(n * paper_1d_window(params, scenario_params, steps) * 16 * (block + 6))

    def run(self, batch: Batch, params) -> TrackingOutput:
        track = paper_1d_track if params.trellis == "paper-1d" else viterbi_track
        return TrackingOutput(estimate=track(batch.z, glint_model_of(batch.scene), params))


def paper_1d_window(params, scenario_params, steps: int) -> int:
    """An upper estimate of the widest node window of the ``paper-1d`` trellis over a
    scene of ``steps`` steps (:func:`methods.glint.viterbi_paper1d.paper_1d_component`):
    the prior's +-3 stds (Gauss-Hermite +-sqrt(3) for ``initial_nodes`` = 3, one
    node for 1) in nodes, plus per step the spread of the three disturbance levels,
    2 sqrt(3) std_w P2 / delta nodes (P2 <= T^2 / 2), for each measured component;
    prior stds from the ``glint`` parameters (range: along the line of sight;
    bearing and elevation: the cross-range std over the range, or the angle stds)."""
    get = functools.partial(getattr, scenario_params)
    r0 = float(get("initial_range_m", 5000.0))
    cos_e0 = max(math.cos(math.radians(float(get("initial_elevation_deg", 0.0)))), 1e-3)
    cross = float(get("initial_cross_range_std_m", 20.0))
    angles = tuple(get("initial_angle_std_rad", ()) or ())
    std0 = (float(get("initial_range_std_m", 100.0)),
            angles[0] if angles else cross / (r0 * cos_e0), angles[1] if angles else cross / r0)
    span = {1: 0.0, 3: 2.0 * math.sqrt(3.0)}.get(params.initial_nodes, 6.0)
    P2 = 0.5 * float(get("dt_s", 0.1)) ** 2
    widest = 0.0
    for delta, sd, var in zip(params.quantisation_steps, std0, params.component_disturbance_variance):
        grow = 2.0 * math.sqrt(3.0) * math.sqrt(var) * P2 / delta + 1.0
        widest = max(widest, span * sd / delta + 1.0 + steps * grow)
    return int(min(widest, 2.0 ** 62))


def process_noise_los(model: GlintModel) -> np.ndarray:
    """(3,) disturbance std (m/s^2) along the radial, bearing and elevation
    directions of the prior mean (isotropic: sigma_w three times)."""
    return np.asarray(model.process_noise_los, float)


def axis_model(model: GlintModel) -> tuple[np.ndarray, np.ndarray]:
    """(F2, g2): the per-axis 2-state transition and input gain of the model."""
    F, G = model.F, model.G
    return np.array([[1.0, F[0, 3]], [0.0, F[3, 3]]]), np.array([G[0, 0], G[3, 0]])


def _axes(model: GlintModel, K: int, params) -> tuple[list[_Axis], list[int]]:
    """Per line-of-sight axis: prior, control and quantisation steps; and the
    observed axes (a passive sensor does not observe the radial axis)."""
    R = model.los_rotation
    F2, g2 = axis_model(model)
    sigma_w = process_noise_los(model)
    x0, P0 = np.asarray(model.x0, float), np.asarray(model.P0, float)
    T = np.zeros((6, 6))
    T[:3, :3] = T[3:, 3:] = R
    x0los, P0los = T @ x0, T @ P0 @ T.T
    r0 = float(np.linalg.norm(x0[:3]))
    cos_e0 = math.sqrt(max(1.0 - (x0[2] / r0) ** 2, 0.0))
    variance = np.asarray(model.noise_variance, float)
    if params.gate_noise == "glint" and float(model.epsilon) > 0.0:
        variance = np.maximum(variance, 2.0 * np.asarray(model.eta, float) ** 2)
    var = dict(zip(model.measurement_labels, variance))
    in_metres = {0: var.get("range"), 1: var["bearing"] * (r0 * cos_e0) ** 2, 2: var["elevation"] * r0 ** 2}
    half = np.array([(params.position_levels - 1) / 2, max((params.velocity_levels - 1) / 2, 1.0)])
    axes, observed = [], []
    for j in range(3):
        P0j = P0los[np.ix_([j, j + 3], [j, j + 3])]
        if in_metres[j] is not None:
            observed.append(j)
            Q2 = float(sigma_w[j]) ** 2 * np.outer(g2, g2)
            lin = LinearGaussianModel(F=F2, H=np.array([[1.0, 0.0]]), Q=Q2, R=np.array([[in_metres[j]]]))
            P_prior = covariance_sequence(lin, P0j, K)[0]
        else:
            P_prior = np.broadcast_to(P0j, (K, 2, 2))
        std = np.sqrt(np.stack([P_prior[:, 0, 0], P_prior[:, 1, 1]], axis=-1))
        w, logpi = disturbance_levels(params.disturbance_levels, float(sigma_w[j]), params.disturbance_span)
        axes.append(_Axis(j=j, u=float(R[j] @ model.u), x0=x0los[[j, j + 3]], P0=P0j,
                          step=params.gate_sigmas * std / half, w=w, logpi=logpi))
    return axes, observed


def viterbi_track(z: np.ndarray, model: GlintModel, params) -> np.ndarray:
    """Estimates (n, K, 6) in the world frame; see :class:`Viterbi`."""
    z = np.asarray(z, float)
    n, K, _ = z.shape
    R = model.los_rotation
    F2, g2 = axis_model(model)
    axes, observed = _axes(model, K, params)
    density = {"sigma": np.asarray(model.sigma, float), "eta": np.asarray(model.eta, float),
               "epsilon": float(model.epsilon), "model": model.glint_model}
    ctx = _Context(z=z, R=R, F2=F2, g2=g2, sensor=model.sensor, density=density,
                   Lp=params.position_levels, Lv=params.velocity_levels, snap=params.node_value == "centre")

    est = np.empty((n, K, 3, 2))                       # line-of-sight (p, v) per axis
    seeds: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for b0 in range(0, K, params.Lb):
        b1 = min(b0 + params.Lb, K)
        if b0 == 0:
            start = np.broadcast_to(np.stack([a.x0 for a in axes]), (n, 3, 2))
            cur = _predict(start, axes, ctx, b1 - b0, include_start=True)
        else:
            cur = _predict(est[:, b0 - 1], axes, ctx, b1 - b0, include_start=False)
        new_seeds = {}
        for _ in range(params.sweeps):
            for j in observed:
                cur[:, :, j], new_seeds[j] = _axis_block(axes[j], b0, b1, seeds.get(j), cur, ctx,
                                                         params.survivors)
        seeds = new_seeds
        est[:, b0:b1] = cur
    return np.concatenate([est[..., 0] @ R, est[..., 1] @ R], axis=-1)     # world = R' q (rows: q R)


def _predict(start: np.ndarray, axes, ctx: _Context, length: int, include_start: bool) -> np.ndarray:
    """(n, length, 3, 2) zero-disturbance prediction of every axis from
    ``start`` (n, 3, 2): starting at ``start`` itself (``include_start``) or
    at the step after it."""
    u = np.array([a.u for a in axes])
    out = np.empty((start.shape[0], length, 3, 2))
    s = np.array(start, float)
    for k in range(length):
        if k > 0 or not include_start:
            s = s @ ctx.F2.T + u[:, None] * ctx.g2
        out[:, k] = s
    return out


def _node_metric(ctx: _Context, k: int, j: int, levels: np.ndarray, others: np.ndarray) -> np.ndarray:
    """log p(z_k | axis j at the positions ``levels`` (n, Lp), the other axes
    at ``others`` (n, 3)), summed over the measured components: (n, Lp)."""
    q = np.repeat(others[:, None, :], levels.shape[1], axis=1)
    q[..., j] = levels
    res = measurement_residual(ctx.z[:, k, None, :], measure(q @ ctx.R, ctx.sensor))
    return glint_logpdf(res, **ctx.density).sum(axis=-1)


def _gaussian2_logpdf(s: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    d = s - mean
    sol = np.linalg.solve(cov, d.reshape(-1, 2).T).T.reshape(d.shape)
    return -0.5 * np.sum(d * sol, axis=-1) - 0.5 * math.log(np.linalg.det(cov)) - math.log(2 * math.pi)


def _grid(centre: np.ndarray, step: np.ndarray, Lp: int, Lv: int):
    """Position levels (n, Lp) and node states (n, Lp Lv, 2) around ``centre``
    (n, 2); node index ip Lv + iv."""
    levels = centre[:, 0, None] + (np.arange(Lp) - (Lp - 1) // 2) * step[0]
    nodes = np.empty((centre.shape[0], Lp, Lv, 2))
    nodes[..., 0] = levels[:, :, None]
    nodes[..., 1] = centre[:, 1, None, None] + (np.arange(Lv) - (Lv - 1) // 2) * step[1]
    return levels, nodes.reshape(centre.shape[0], Lp * Lv, 2)


#: the most grids step 0 is refined through (a safety net: the shrink factor is at most
#: 2/3, so a prior gate 10^100 times the target step takes 568 stages)
MAX_REFINEMENT_STAGES = 1000


def refined_step(step: float, Lp: int) -> float:
    """The position step of the next refinement grid of step 0: 4 step / (Lp - 1),
    so the new grid of Lp levels spans +-2 steps of the previous one, when that
    shrinks (Lp >= 7); with 3 or 5 levels such a grid would not shrink (5 levels:
    the same step, 3: twice it, and refining never ended), so the step is halved
    instead: the new grid spans +-1/2 (Lp = 3) or +-1 (Lp = 5) previous step
    around the best level, a bisection."""
    return 4.0 * step / (Lp - 1) if Lp - 1 > 4 else 0.5 * step


def refinement_steps(step0: np.ndarray, target: float, Lp: int) -> list[np.ndarray]:
    """The (position, velocity) steps of the grids step 0 is built on: the prior's
    ``step0``, then position steps shrunk by :func:`refined_step` down to
    ``target`` (never below it), the velocity step unchanged. Ends for every Lp >= 3
    (each step at most 2/3 of the previous) and every target (at most
    :data:`MAX_REFINEMENT_STAGES` grids)."""
    steps = [np.array(step0, dtype=float)]
    while steps[-1][0] > target and len(steps) < MAX_REFINEMENT_STAGES:
        steps.append(np.array([max(target, refined_step(steps[-1][0], Lp)), step0[1]]))
    return steps


def _initial_nodes(axis: _Axis, ctx: _Context, others0: np.ndarray):
    """Step 0: states (n, Lp Lv, 2) and scores (n, Lp Lv), refined in stages
    (see :class:`Viterbi`)."""
    n, Lp, Lv = others0.shape[0], ctx.Lp, ctx.Lv
    centre = np.broadcast_to(axis.x0, (n, 2)).copy()
    target = min(axis.step[min(1, len(axis.step) - 1), 0], axis.step[0, 0])
    for step in refinement_steps(axis.step[0], target, Lp):
        levels, nodes = _grid(centre, step, Lp, Lv)
        metric = _node_metric(ctx, 0, axis.j, levels, others0)
        score = _gaussian2_logpdf(nodes, axis.x0, axis.P0) + np.repeat(metric, Lv, axis=1)
        centre[:, 0] = nodes[np.arange(n), np.argmax(score, axis=1), 0]
    return nodes, score


def _axis_block(axis: _Axis, b0: int, b1: int, seeds, cur: np.ndarray, ctx: _Context, survivors: int):
    """Axis ``axis.j``'s trellis over steps [b0, b1). ``seeds`` = (states
    (n, S, 2), scores (n, S)) from the previous block (None when b0 = 0);
    ``cur`` (n, L, 3, 2) holds the current estimates of all axes. Returns the
    block's best path (n, L, 2) and the seeds of the next block."""
    n = cur.shape[0]
    rows = np.arange(n)
    Lp, Lv, J = ctx.Lp, ctx.Lv, len(axis.w)
    others = cur[..., 0]                                          # (n, L, 3) positions
    states, backs = [], []
    if b0 == 0:
        parent_state, parent_score = _initial_nodes(axis, ctx, others[:, 0])
        states.append(parent_state)
        backs.append(np.full((n, Lp * Lv), -1, dtype=np.int64))
    else:
        parent_state, parent_score = seeds
    for k in range(b0 + len(states), b1):
        best = parent_state[rows, np.argmax(parent_score, axis=1)]
        centre = best @ ctx.F2.T + axis.u * ctx.g2                # prediction of the best node
        step = axis.step[k]
        levels = centre[:, 0, None] + (np.arange(Lp) - (Lp - 1) // 2) * step[0]
        metric = _node_metric(ctx, k, axis.j, levels, others[:, k - b0])
        score, back, state = trellis_step(parent_state, parent_score, ctx.F2, ctx.g2, axis.u, axis.w,
                                          axis.logpi, centre, step, Lp, Lv, metric, ctx.snap)
        states.append(state)
        backs.append(back)
        parent_state, parent_score = state, score

    last = np.argmax(parent_score, axis=1)
    nodes = backtrack(backs, J, last)
    path = np.stack([states[i][rows, nodes[:, i]] for i in range(len(states))], axis=1)
    top = np.argsort(-parent_score, axis=1, kind="stable")[:, :survivors]
    seed_score = np.take_along_axis(parent_score, top, axis=1)
    seed_score = seed_score - seed_score[:, :1]                   # the best seed at 0
    return path, (parent_state[rows[:, None], top], seed_score)
