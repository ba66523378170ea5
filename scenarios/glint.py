"""Scenario ``glint``: spherical measurements of a damped target under glint noise."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from radarbench.bench.batched import matvec
from radarbench.bench.core import TRACKING, Batch, Scenario
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_scenario
from radarbench.bench.tasks.tracking import TrackingScene
from radarbench.models.glint import GLINT_MODELS, GlintModel, glint_fisher_information, glint_variance
from radarbench.models.pcrb import linear_dynamics_pcrb, measurement_information, position_mse_bound
from radarbench.models.spherical import (MEASURED, MEASUREMENT_LABELS, los_basis, measurement_jacobian, spherical,
                                         wrap_angle)

#: state components, in order (metres, m/s; x east, y north, z up)
STATE_LABELS = ("x", "y", "z", "vx", "vy", "vz")
#: the longest scene (steps) and the smallest noise stds (reference, and scaled by the SNR)
MAX_STEPS = 10_000
MIN_RANGE_NOISE_M = 1e-3
MIN_ANGLE_NOISE_RAD = 1e-6
RANGE_NOISE_WHY = ("a millimetre to 10 km: below it the trackers' covariances lose definiteness in "
                   "float64 (the scaled noise at each SNR level is held to the same floor)")
ANGLE_NOISE_WHY = ("a microradian to 0.1 rad: below it the trackers' covariances lose definiteness in "
                   "float64 (the scaled noise at each SNR level is held to the same floor); above it "
                   "the small-angle linearisation of the trackers fails")
SPREAD_WHY = ("a millimetre to 100 km: the prior covariance stays positive definite in float64 "
              "beside the velocity spread")
#: indices of the position components in the state
POSITION_INDEX = (0, 1, 2)

SNR_DEFINITION = (
    "snr_db is a measurement-noise level relative to the scenario's reference noise: "
    "every noise scale (the Gaussian core's sigma and the Laplace glint scale eta of each "
    "measured component) is the reference value times 10^(-snr_db/20), so 0 dB is the "
    "reference and +6 dB halves all noise; the glint shape (epsilon, eta/sigma) does not "
    "change along the axis; snr_db=None is the 0 dB reference (tracking has no null)."
)


def discretisation(mu: float, dt: float) -> tuple[float, float, float]:
    """(a, P1, P2) of the per-axis model dv/dt = -mu v + u + w, dp/dt = v with
    u + w held constant over each interval (zero-order hold):
    a = exp(-mu T), P1 = (1 - exp(-mu T))/mu, P2 = (mu T - 1 + exp(-mu T))/mu^2;
    mu = 0 gives the limits (1, T, T^2/2)."""
    if mu == 0.0:
        return 1.0, dt, 0.5 * dt * dt
    x = mu * dt
    em1 = math.expm1(-x)                                 # exp(-mu T) - 1, accurate for small mu T
    if x < 1e-3:                                         # mu T - 1 + exp(-mu T) cancels: series
        P2 = dt * dt * (0.5 - x / 6.0 + x * x / 24.0 - x ** 3 / 120.0)
    else:
        P2 = (x + em1) / mu ** 2
    return 1.0 + em1, -em1 / mu, P2


def transition_matrices(mu: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """F (6, 6) and the input gain G (6, 3) for the state [x, y, z, vx, vy, vz]:
    x_{k+1} = F x_k + G (u + w_k), the same per-axis model on each axis."""
    a, P1, P2 = discretisation(mu, dt)
    eye = np.eye(3)
    F = np.block([[eye, P1 * eye], [np.zeros((3, 3)), a * eye]])
    G = np.vstack([P2 * eye, P1 * eye])
    return F, G


def spherical_components(states) -> dict[str, np.ndarray]:
    """Range (m), bearing and elevation (rad) of states (..., 6) seen from the
    sensor: the components the paper's Fig. 4 plots (``derived_components``)."""
    s = spherical(np.asarray(states, float)[..., :3])
    return {"range_m": s[..., 0], "bearing_rad": s[..., 1], "elevation_rad": s[..., 2]}


@register_scenario
class Glint(Scenario):
    r"""Damped target with known control, spherical measurements under Gaussian + Laplace glint noise.

    After Song & Sun, "Filtering method with non-Gaussian noise" (the estimator after Demirbas, "Manoeuvring-target tracking with the
    Viterbi algorithm in the presence of interference", IEE Proc. F 136(6),
    1989). A sensor at the origin (ENU frame: x east, y north, z up, metres)
    tracks one target.

    **State** $[x, y, z, v_x, v_y, v_z]'$ (:data:`STATE_LABELS`), positions
    ``POSITION_INDEX = (0, 1, 2)``.

    **Motion** per Cartesian axis: $\dot{v} = -\mu v + u + w$, $\dot{p} = v$ (the
    paper's eq. (1) $\dot{x} = -\mu x + u + w$ acts on the velocity; its $P_1$, $P_2$ of
    eq. (2) are the zero-order-hold gains of this second-order model), with $u + w$ held
    over each interval $T$:

    $$
    \begin{aligned}
    x_{k+1} &= F x_k + G (u + w_k), &
    F &= \begin{bmatrix} I & P_1 I \\ 0 & a I \end{bmatrix}, \quad
    G = \begin{bmatrix} P_2 I \\ P_1 I \end{bmatrix}, \\
    a &= e^{-\mu T}, &
    P_1 &= \frac{1 - a}{\mu}, \quad P_2 = \frac{\mu T - 1 + a}{\mu^2} \qquad (2)
    \end{aligned}
    $$

    $w_k \sim \mathcal{N}(0, \sigma_w^2 I)$ white, $\sigma_w$ = ``process_noise_m_s2`` (so
    $Q = \sigma_w^2 G G'$). Defaults $T = 0.1$ s, $\mu = 0.4$ /s (the paper's).

    **Control.** The paper's state is spherical (Demirbas estimates range,
    bearing and elevation component by component) and its control is given in
    the radial, bearing and elevation directions: $u_r = 1.5$, $u_b = 0.07$,
    $u_e = 0.06$. With a Cartesian state we read them as accelerations in m/s^2
    along the unit vectors of increasing range, bearing and elevation at the
    *prior mean* initial position (:func:`models.spherical.los_basis`), a constant Cartesian
    vector ``u`` (so the model stays linear and the control is exactly
    known). Reading $u_b$, $u_e$ as angular accelerations (rad/s^2) times range
    would mean 350 m/s^2 at 5 km, not a plausible target. The model's
    ``los_rotation`` (:class:`models.glint.GlintModel`) is that basis; with the default geometry (bearing 0,
    elevation 0) it is the world frame up to axis order: y is the radial
    (range) direction, x the bearing and z the elevation direction, so the
    per-component errors read as range / cross-range errors.

    **Initial state**: the prior mean (the model's ``x0``) is at
    ``initial_range_m``, ``initial_bearing_deg``, ``initial_elevation_deg``
    with velocity ``initial_velocity_m_s`` in line-of-sight coordinates; the
    prior covariance $P_0$ is diagonal in line-of-sight coordinates (range,
    cross-range, velocity stds). Each trial's true initial state is drawn from
    $\mathcal{N}(x_0, P_0)$; trackers start from $(x_0, P_0)$.

    **Measurements** (``sensor``): ``"passive"`` (the paper's case) measures
    [bearing, elevation], ``"active"`` [range, bearing, elevation]; bearing
    $b = \operatorname{atan2}(x, y)$ (clockwise from north) wrapped to $(-\pi, \pi]$, elevation
    $e = \operatorname{atan2}(z, \sqrt{x^2 + y^2})$, range in m (:mod:`models.spherical`). Noise per
    component, independent:
    ``glint_model = "mixture"`` (Song & Sun, eq. 5, $f = (1 - \epsilon) f_g + \epsilon f_l$):

    $$
    (1 - \epsilon)\, \mathcal{N}(0, \sigma^2) + \epsilon\, \operatorname{Laplace}(0, \eta) \qquad (5)
    $$

    $\eta$ the Laplace *scale* (variance $2 \eta^2$);
    ``"additive"``: $\mathcal{N}(0, \sigma^2)$ always plus, with probability $\epsilon$, a
    $\operatorname{Laplace}(0, \eta)$ spike (the outlier part is the Gaussian-Laplace
    convolution). See :mod:`models.glint`. $\epsilon = 0$ is the Gaussian case.

    **Noise defaults** (ours, not the paper's): $\sigma$ = 1 mrad for the angles
    and 5 m for range (about 5 m cross-range at the default 5 km), glint
    scale $\eta = 5 \sigma$, a typical glint setting giving with $\epsilon = 0.05$ a
    total variance of $3.45 \sigma^2$ of which 72 % comes from the glint. Song &
    Sun's section 3 prints $\epsilon = 0.05$, $\eta = (0.5, 0.03, 0.03)$ and
    $\sigma^2 = (5 \times 10^{-3}, 4 \times 10^{-4}, 4 \times 10^{-4})$ (range, bearing, elevation) for the simulated noise,
    and, in its first paragraph, a different set of "observation-noise
    variances (5.0, 0.03, 0.03)"; the ``glint-tracking`` preset's
    ``paper-passive`` config sets the former (with the paper's initial
    angles, rates and disturbance variances, :attr:`Params`), the defaults
    stay as they were.

    **Disturbance.** ``process_noise_los_m_s2`` (3 stds) makes w diagonal in
    the line-of-sight frame of the prior mean, $w = R' \operatorname{diag}(\sigma_{los})\, g$,
    $Q = G R' \operatorname{diag}(\sigma_{los}^2) R G'$ (the paper's disturbance variances (7.0,
    0.07, 0.07) along range, bearing and elevation); empty (default): the
    isotropic ``process_noise_m_s2``. The model's ``process_noise_los`` is
    the per-direction std either way. The paper's spherical control and
    disturbance rotate with the line of sight (its appendix, A-4 to A-6); ours
    are fixed at the prior mean's (the target stays within a few degrees of
    it at the paper's rates).

    **Initial angles** (the paper's state is spherical): ``initial_angle_rate_rad_s``
    adds $r_0 \cos(e_0)\, \dot{b}$ and $r_0 \dot{e}$ to the prior mean velocity along the
    bearing and elevation directions, and ``initial_angle_std_rad`` replaces
    the cross-range stds by $r_0 \cos(e_0)\, \sigma_b$ and $r_0 \sigma_e$.

    **SNR axis**: :data:`SNR_DEFINITION`; all $\sigma$ and $\eta$ scale together, so
    the axis is a pure noise-level axis and the realised SNR of each trial is
    ``snr_db`` itself. ``snr_db = None`` is the 0 dB reference.

    **Random draws**, in this order whatever the SNR, epsilon or sensor (common
    random numbers along all three): initial state (6,) standard normals,
    process noise (K, 3) standard normals, and for all three spherical
    components whatever the sensor: Gaussian core (K, 3) standard normals,
    glint (K, 3) standard Laplace, outlier selectors (K, 3) uniforms. A
    component is a glint outlier when its uniform is $< \epsilon$, so raising $\epsilon$
    only adds outliers; noise $= \sigma g$ (core) or $\eta l$ (outlier) for the
    mixture, $\sigma g + [\text{outlier}]\, \eta l$ for the additive model.

    **Scene** (a :class:`~bench.tasks.tracking.TrackingScene`; docs/architecture.md,
    'Scenes'): ``model`` the :class:`models.glint.GlintModel` at the SNR
    (:meth:`model`), ``position_index``, ``state_labels``,
    ``measurement_labels``, ``derived_components`` (range, bearing,
    elevation), ``measurements_xy`` (n, K, 2) measurements in the horizontal
    plane (active: the measured range; passive: the *true* range, there being
    no measured one — for plotting only), ``outlier_flags`` (n, K, m) the
    glint outliers, ``divergence_bound_m``, ``snr_definition``,
    ``realised_snr_db`` (n,), ``position_bound`` (n, K) the posterior Cramér-Rao bound
    along each trial's truth (:meth:`position_bound`).
    """

    name = "glint"
    tasks = (TRACKING,)
    #: the parameters its random streams were first keyed by (Scenario.stream_params)
    stream_params = ("steps", "dt_s", "damping_per_s", "control_m_s2", "process_noise_m_s2",
                     "process_noise_los_m_s2", "sensor", "epsilon", "glint_model", "sigma_range_m",
                     "sigma_bearing_rad", "sigma_elevation_rad", "eta_range_m", "eta_bearing_rad",
                     "eta_elevation_rad", "initial_range_m", "initial_bearing_deg", "initial_elevation_deg",
                     "initial_velocity_m_s", "initial_angle_rate_rad_s", "initial_angle_std_rad",
                     "initial_range_std_m", "initial_cross_range_std_m", "initial_velocity_std_m_s",
                     "divergence_bound_m")
    provides = frozenset({"glint-model"})
    #: a small instance for quick conformance tests
    small_params: ClassVar[dict] = {"steps": 60}
    perf_sizes: ClassVar[dict] = {"paper": ({"sensor": "active"}, 50)}
    perf_snr_db: ClassVar[float] = 0.0

    def check_snr(self, params, snr_db: float) -> str | None:
        """The SNR axis scales every noise std by 10^(-snr_db/20): the scaled stds
        must stay at or above the lower bounds of the reference ones (1 mm, 1 urad),
        below which the trackers' covariances lose definiteness in float64 (the EKF's
        innovation covariance turns singular near 1e-13 rad)."""
        scale = 10.0 ** (-snr_db / 20.0)
        floor = {"range": MIN_RANGE_NOISE_M, "bearing": MIN_ANGLE_NOISE_RAD, "elevation": MIN_ANGLE_NOISE_RAD}
        for label, sigma, eta in zip(("range", "bearing", "elevation"), params.sigma_ref(), params.eta_ref()):
            if label == "range" and params.sensor != "active":
                continue
            low = min(sigma, eta) * scale
            if low < floor[label]:
                unit = "m" if label == "range" else "rad"
                return (f"the {label} noise scaled to it, {low:.3g} {unit}, is below {floor[label]:g} {unit}; "
                        f"at most {20.0 * math.log10(min(sigma, eta) / floor[label]):.4g} dB for this config")
        return None

    def unit_memory_bytes(self, params, n: int) -> int:
        """About 120 float64 values per trial and step: the truth (6), the draws (12),
        the noise and measurements (9), their planar projection (2), and a tracker's
        estimate with its covariance (6 + 36) and per-step scratch."""
        return 8 * 120 * n * params.steps

    @dataclass(frozen=True)
    class Params:
        steps: int = param(300, "number of measurement steps K (duration K T)", ge=2, le=MAX_STEPS,
                           why="two steps at least; the simulation and the trackers loop over steps in "
                               "Python, so at most 10 000 (33 times the paper's 300)")
        dt_s: float = param(0.1, "sampling interval T (s)", ge=1e-3, le=10.0,
                            why="sensor revisit times, 1 ms to 10 s")
        damping_per_s: float = param(0.4, "velocity damping mu (1/s) of dv/dt = -mu v + u + w", ge=0.0,
                                     le=100.0, why="0 is no damping; at 100 /s the velocity forgets "
                                                   "itself within 10 ms")
        control_m_s2: tuple[float, ...] = param(
            (1.5, 0.07, 0.06), "known control u (m/s^2) along the radial, bearing and elevation "
            "directions at the prior mean initial position (the paper's u_r, u_b, u_e)",
            ge=-100.0, le=100.0, min_len=3, max_len=3, why="at most 10 g along each direction")
        process_noise_m_s2: float = param(
            1.0, "std sigma_w (m/s^2) of the white Gaussian disturbance w, per axis, held over each "
            "interval", ge=0.0, le=100.0, why="0 is a deterministic target; at most 10 g")
        process_noise_los_m_s2: tuple[float, ...] = param(
            (), "stds (m/s^2) of the disturbance along the radial, bearing and elevation directions "
            "at the prior mean initial position (3 values; empty: isotropic process_noise_m_s2)",
            ge=0.0, le=100.0, min_len=0, max_len=3, why="0 is no disturbance; at most 10 g")
        sensor: str = param("passive", "'passive': bearing and elevation (the paper's case); "
                            "'active': range, bearing and elevation", choices=("passive", "active"))
        epsilon: float = param(0.05, "glint probability eps per measured component (0: Gaussian)",
                               ge=0.0, le=1.0, why="a probability")
        glint_model: str = param(
            "mixture", "'mixture': (1-eps) N(0,sigma^2) + eps Laplace(0,eta); 'additive': "
            "N(0,sigma^2) plus a Laplace(0,eta) spike with probability eps", choices=GLINT_MODELS)
        sigma_range_m: float = param(5.0, "reference std of the Gaussian core, range (m)",
                                     ge=MIN_RANGE_NOISE_M, le=1e4, why=RANGE_NOISE_WHY)
        sigma_bearing_rad: float = param(1e-3, "reference std of the Gaussian core, bearing (rad)",
                                         ge=MIN_ANGLE_NOISE_RAD, le=0.1, why=ANGLE_NOISE_WHY)
        sigma_elevation_rad: float = param(1e-3, "reference std of the Gaussian core, elevation (rad)",
                                           ge=MIN_ANGLE_NOISE_RAD, le=0.1, why=ANGLE_NOISE_WHY)
        eta_range_m: float = param(25.0, "reference Laplace glint scale eta, range (m); variance "
                                   "2 eta^2", ge=MIN_RANGE_NOISE_M, le=1e4, why=RANGE_NOISE_WHY)
        eta_bearing_rad: float = param(5e-3, "reference Laplace glint scale eta, bearing (rad)",
                                       ge=MIN_ANGLE_NOISE_RAD, le=0.1, why=ANGLE_NOISE_WHY)
        eta_elevation_rad: float = param(5e-3, "reference Laplace glint scale eta, elevation (rad)",
                                         ge=MIN_ANGLE_NOISE_RAD, le=0.1, why=ANGLE_NOISE_WHY)
        initial_range_m: float = param(5000.0, "prior mean initial range (m)", ge=10.0, le=1e6,
                                       why="10 m to 1000 km; at least 5 prior range stds from the sensor "
                                           "(checked against initial_range_std_m)")
        initial_bearing_deg: float = param(0.0, "prior mean initial bearing (deg, clockwise from north)",
                                           ge=-180.0, le=180.0, why="a bearing")
        initial_elevation_deg: float = param(0.0, "prior mean initial elevation (deg)", gt=-80.0, lt=80.0,
                                             why="away from the zenith, where bearing is singular")
        initial_velocity_m_s: tuple[float, ...] = param(
            (0.0, 0.0, 0.0), "prior mean initial velocity (m/s) along the radial, bearing and "
            "elevation directions", ge=-1000.0, le=1000.0, min_len=3, max_len=3,
            why="at most Mach 3 along each direction")
        initial_angle_rate_rad_s: tuple[float, ...] = param(
            (0.0, 0.0), "prior mean initial bearing and elevation rates (rad/s), added to "
            "initial_velocity_m_s as r0 cos(e0) db/dt and r0 de/dt along the bearing and elevation "
            "directions", ge=-0.1, le=0.1, min_len=2, max_len=2,
            why="at most 0.1 rad/s (6 deg/s) of line-of-sight rate")
        initial_angle_std_rad: tuple[float, ...] = param(
            (), "prior stds of the initial bearing and elevation (rad; 2 values): the cross-range "
            "stds become r0 cos(e0) std_b and r0 std_e (empty: initial_cross_range_std_m)",
            ge=1e-6, le=0.1, min_len=0, max_len=2,
            why="a microradian to 0.1 rad: the prior covariance stays positive definite in float64")
        initial_range_std_m: float = param(100.0, "initial-state spread: prior std along the line of "
                                           "sight (m)", ge=1e-3, le=1e5, why=SPREAD_WHY)
        initial_cross_range_std_m: float = param(20.0, "initial-state spread: prior std across the "
                                                 "line of sight, each direction (m)", ge=1e-3, le=1e5,
                                                 why=SPREAD_WHY)
        initial_velocity_std_m_s: float = param(2.0, "initial-state spread: prior velocity std per "
                                                "axis (m/s)", ge=1e-3, le=1e3,
                                                why="a millimetre per second to Mach 3: the prior "
                                                    "covariance stays positive definite in float64")
        divergence_bound_m: float = param(
            500.0, "a trial has diverged when its position error exceeds this bound (m) at some step",
            ge=1e-3, le=1e9, why="any distance from a millimetre to beyond any scene")

        def validate(self) -> None:
            for name, size in (("process_noise_los_m_s2", 3), ("initial_angle_std_rad", 2)):
                if len(getattr(self, name)) not in (0, size):
                    raise ConfigError(name, f"expected {size} values or none, got {len(getattr(self, name))}")
            spread = 5.0 * self.initial_range_std_m
            if spread >= self.initial_range_m:
                raise ConfigError("initial_range_std_m", f"5 x {self.initial_range_std_m} m reaches the "
                                  f"sensor at initial_range_m = {self.initial_range_m} m; the spherical "
                                  "measurement is singular there")

        def sigma_ref(self) -> np.ndarray:
            """Reference core std of (range, bearing, elevation)."""
            return np.array([self.sigma_range_m, self.sigma_bearing_rad, self.sigma_elevation_rad])

        def eta_ref(self) -> np.ndarray:
            """Reference glint scale of (range, bearing, elevation)."""
            return np.array([self.eta_range_m, self.eta_bearing_rad, self.eta_elevation_rad])

    def generate(self, params, snr_db: float | None, n: int, rng) -> Batch:
        p = params
        K = p.steps
        # Draw first, in a fixed order: every SNR, eps and sensor share the draws.
        e0 = rng.standard_normal(6)
        w = rng.standard_normal((K, 3))
        g = rng.standard_normal((K, 3))
        lap = rng.laplace((K, 3))
        sel = rng.uniform((K, 3))

        model = self.model(p, snr_db)
        F, G, u = model.F, model.G, model.u
        idx = list(MEASURED[p.sensor])
        sigma_all = p.sigma_ref() * model.noise_scale
        eta_all = p.eta_ref() * model.noise_scale

        truth = np.empty((n, K, 6))
        x = model.x0 + matvec(np.linalg.cholesky(model.P0), e0)
        if p.process_noise_los_m_s2:                            # (n, K, 3)
            drive = u + matvec(model.noise_factor, w)
        else:
            drive = u + p.process_noise_m_s2 * w
        for k in range(K):
            truth[:, k] = x
            x = matvec(F, x) + matvec(G, drive[:, k])

        outlier = sel < p.epsilon                               # (n, K, 3)
        if p.glint_model == "mixture":
            noise = np.where(outlier, eta_all * lap, sigma_all * g)
        else:
            noise = sigma_all * g + np.where(outlier, eta_all * lap, 0.0)
        sph = spherical(truth[..., :3])
        z_all = sph + noise
        z_all[..., 1] = wrap_angle(z_all[..., 1])
        z = z_all[..., idx]

        rng_xy = z_all[..., 0] if p.sensor == "active" else sph[..., 0]
        ce = np.cos(z_all[..., 2])
        z_xy = np.stack([rng_xy * ce * np.sin(z_all[..., 1]), rng_xy * ce * np.cos(z_all[..., 1])], axis=-1)

        snr = 0.0 if snr_db is None else float(snr_db)
        scene = TrackingScene(
            snr_definition=SNR_DEFINITION, realised_snr_db=np.full(n, snr), position_index=POSITION_INDEX,
            measurements_xy=z_xy, model=model, state_labels=STATE_LABELS,
            measurement_labels=MEASUREMENT_LABELS[p.sensor], divergence_bound_m=p.divergence_bound_m,
            derived_components=spherical_components, outlier_flags=outlier[..., idx],
            position_bound=self.position_bound(model, truth))
        return Batch(t=p.dt_s * np.arange(K), truth=truth, z=z, scene=scene, trials=np.asarray(rng.trials))

    @staticmethod
    def position_bound(model: GlintModel, truth: np.ndarray) -> np.ndarray:
        """(n, K) the posterior Cramér-Rao bound on the position MSE (m^2) along each trial's
        truth (:mod:`models.pcrb`): the linear dynamics F, Q and prior P0 the truth is drawn
        from, and the measurement information H' diag(I) H with H the spherical Jacobian at
        the true position and I the glint density's Fisher information per component
        (:func:`models.glint.glint_fisher_information`; 1/sigma^2 at eps = 0)."""
        H = np.zeros((*truth.shape[:2], model.dim_z, truth.shape[-1]))
        H[..., :3] = measurement_jacobian(truth[..., :3], model.sensor)
        fisher = glint_fisher_information(model.sigma, model.eta, model.epsilon, model.glint_model)
        bound = linear_dynamics_pcrb(model.P0, model.F, model.Q, measurement_information(H, fisher))
        return position_mse_bound(bound, POSITION_INDEX)

    @staticmethod
    def model(p, snr_db: float | None = None) -> GlintModel:
        """Everything a tracker needs (the scene's ``model``), at ``snr_db``."""
        F, G = transition_matrices(p.damping_per_s, p.dt_s)
        R_los = los_basis(math.radians(p.initial_bearing_deg), math.radians(p.initial_elevation_deg))
        control_los = np.asarray(p.control_m_s2, float)
        u = R_los.T @ control_los
        pos0 = p.initial_range_m * R_los[0]
        cos_e0 = math.cos(math.radians(p.initial_elevation_deg))
        rate_b, rate_e = p.initial_angle_rate_rad_s
        vel_los = np.asarray(p.initial_velocity_m_s, float) + np.array(
            [0.0, p.initial_range_m * cos_e0 * rate_b, p.initial_range_m * rate_e])
        vel0 = R_los.T @ vel_los
        cross = ((p.initial_cross_range_std_m,) * 2 if not p.initial_angle_std_rad else
                 (p.initial_range_m * cos_e0 * p.initial_angle_std_rad[0],
                  p.initial_range_m * p.initial_angle_std_rad[1]))
        P_pos = R_los.T @ np.diag([p.initial_range_std_m, *cross]) ** 2 @ R_los
        # w_k = noise_factor @ (standard normals): isotropic sigma_w I, or diagonal in the
        # line-of-sight frame (world = R' q)
        if p.process_noise_los_m_s2:
            process_los = np.asarray(p.process_noise_los_m_s2, float)
            noise_factor = R_los.T @ np.diag(process_los)
            Q = G @ (noise_factor @ noise_factor.T) @ G.T
        else:
            process_los = np.full(3, p.process_noise_m_s2)
            noise_factor = p.process_noise_m_s2 * np.eye(3)
            Q = p.process_noise_m_s2 ** 2 * G @ G.T
        P0 = np.zeros((6, 6))
        P0[:3, :3] = 0.5 * (P_pos + P_pos.T)
        P0[3:, 3:] = p.initial_velocity_std_m_s ** 2 * np.eye(3)
        scale = 10.0 ** (-(0.0 if snr_db is None else float(snr_db)) / 20.0)
        idx = list(MEASURED[p.sensor])
        sigma = p.sigma_ref()[idx] * scale
        eta = p.eta_ref()[idx] * scale
        return GlintModel(
            F=F, G=G, u=u, Bu=G @ u, Q=Q, noise_factor=noise_factor, process_noise_los=process_los,
            process_noise_m_s2=p.process_noise_m_s2, x0=np.concatenate([pos0, vel0]), P0=P0,
            sensor=p.sensor, measurement_labels=MEASUREMENT_LABELS[p.sensor], sigma=sigma, eta=eta,
            epsilon=p.epsilon, glint_model=p.glint_model,
            noise_variance=glint_variance(sigma, eta, p.epsilon, p.glint_model),
            dt_s=p.dt_s, los_rotation=R_los, control_los=control_los, noise_scale=scale)
