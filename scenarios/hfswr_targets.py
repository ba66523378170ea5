"""Scenario ``hfswr-targets``: ship targets seen by an HF surface-wave radar in
range, azimuth and radial velocity, with missed detections and Poisson clutter."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from radarbench.bench.batched import matvec
from radarbench.bench.core import Batch, Scenario
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_scenario
from radarbench.bench.tasks.multitarget import CLUTTER, MULTI_TARGET, PADDING, MultiTargetScene
from radarbench.models.hfswr import POSITION_INDEX, cv_gain, cv_transition, measure, wrap_angle

#: the smallest noise stds a config may reach (reference or scaled by the SNR): below them the
#: trackers' innovation covariances lose definiteness in float64 at HFSWR ranges (100 km)
MIN_STD = {"range": 1.0, "azimuth": 1e-5, "radial_velocity": 1e-3}

SNR_DEFINITION = (
    "snr_db is the per-scan signal-to-noise ratio of a target's echo in its range-Doppler cell; with "
    "detection = 'swerling1' it sets the detection probability Pd = Pfa^(1/(1+SNR)) (a Swerling-1 target "
    "against a square-law CFAR at the per-cell false-alarm probability pfa_cell), and with "
    "noise_scales_with_snr it scales every measurement-noise std by 10^(-(snr_db - reference_snr_db)/20); "
    "with detection = 'fixed' Pd is the parameter pd whatever the SNR; snr_db = None: clutter only, no target."
)


def swerling1_pd(snr_db: float, pfa: float) -> float:
    """Pd = Pfa^(1/(1+SNR)) of a Swerling-1 target at linear SNR 10^(snr_db/10)
    in square-law detection at a per-cell false-alarm probability ``pfa``
    (the exponential echo power exceeds the threshold -ln Pfa of the noise)."""
    return float(pfa ** (1.0 / (1.0 + 10.0 ** (snr_db / 10.0))))


def _pair(lo_hi: tuple, name: str) -> None:
    if len(lo_hi) != 2 or not lo_hi[0] < lo_hi[1]:
        raise ConfigError(name, f"expected [min, max] with min < max, got {list(lo_hi)}")


@register_scenario
class HFSWRTargets(Scenario):
    r"""Several ships (CV, small random accelerations, appearing, disappearing, crossing) in range/azimuth/radial velocity with Pd < 1 and Poisson clutter.

    After the HFSWR tracking chapter, "目标检测与跟踪方法 (Target detection and
    tracking methods), 海洋遥感技术应用", section 2: a constant-velocity ship model
    in Cartesian coordinates (its eq. 6.69) measured in range, azimuth and
    radial velocity with independent Gaussian noise, $\rho = 0$ (eq. 6.71;
    :mod:`models.hfswr`), detections with probability $P_D$ and clutter Poisson
    with density $\lambda$, uniform over the surveillance region (ours: the
    chapter's JPDA step 4 takes the clutter in the gate as non-uniform,
    "非均匀分布"; the JPDA's clutter term here is the uniform density $\lambda$).
    The chapter prints no numbers for the scan period, the noise, Pd, lambda or the targets: every default
    below is ours, chosen like an HFSWR — a plot per minute, range sigma
    300 m (a 50 kHz sweep has 3 km range cells), azimuth sigma 1 deg (a
    beam-formed linear array), radial velocity sigma 0.2 m/s (a few-minute
    coherent integration at 5 MHz resolves about 0.1 m/s), ships at 1 to
    15 m/s, 50 to 150 km, +-30 deg.

    **Targets.** ``targets`` ships; target t is present from its appearance
    scan (uniform in the first third of the run) to its disappearance (uniform
    in the last third, exclusive; some stay to the end) *and* while its range,
    azimuth and radial velocity are inside the surveillance region;
    ``truth[i, k, t]`` is NaN while it is absent. Each target is anchored at
    the middle of its life, at a position uniform in the middle half of the
    range and azimuth spans, with a uniform heading and a speed uniform in
    ``speed_bounds_m_s``; from there the CV model with a white acceleration
    $\mathcal{N}(0, \sigma_a^2)$ ($\sigma_a$ = ``accel_std_m_s2``) per axis held over each scan (:func:`models.hfswr.cv_gain`)
    runs forward, and backward ($x_k = F^{-1} (x_{k+1} - G w_k)$), to the run's
    ends; the speed is clipped into ``speed_bounds_m_s`` after each scan (the
    trackers' initiation gates rely on it).
    **Crossing** (``crossing = true``): targets 0 .. ``crossing_targets`` - 1
    are all anchored at the middle scan of the run at one position with one
    speed, present from the first quarter to the end, with headings spread
    over ``crossing_angle_deg`` symmetrically about the line of sight (or its
    opposite): two crossing ships have the same range, azimuth *and* radial
    velocity at the crossing, the hard case for association.
    **Plots.** A present target gives a plot with probability Pd per scan:
    $h(x) + (\sigma_r, \sigma_{az}, \sigma_{v_r}) \odot \mathcal{N}(0, I)$, azimuth wrapped, dropped
    if it falls outside the region. Clutter: Poisson(``clutter_per_scan``)
    plots per scan, uniform over the region [range, azimuth, radial velocity]
    (density $\lambda$ = ``clutter_per_scan`` / region volume). The plots of a scan
    are in random order (targets are not first); ``scene.plot_origin`` says
    which is which.
    **SNR axis**: :data:`SNR_DEFINITION`. Pd from the SNR (``detection =
    'swerling1'``): at the default pfa_cell = 1e-3, 10 dB gives Pd = 0.53,
    15 dB 0.81, 20 dB 0.93; ``detection = 'fixed'`` sets Pd directly (the
    ``multi-target`` preset sweeps it). ``snr_db = None``: clutter only (no
    target plots, every truth NaN), the same clutter as every SNR level.
    **Random draws** per trial, in this order whatever the SNR, Pd, or
    crossing (common random numbers): appearance and disappearance (T,) each,
    anchor range, azimuth, heading and speed (T,) each, the crossing direction
    (1,), accelerations (K, T, 2) and measurement noise (K, T, 3) standard
    normals, detection uniforms (K, T) (detected when < Pd, so a higher Pd
    only adds plots), plot-order keys (K, T); then from the trial's generator
    the clutter counts (K,) Poisson, positions (C, 3) and order keys (C,).
    """

    name = "hfswr-targets"
    tasks = (MULTI_TARGET,)
    #: the parameters its random streams were first keyed by (Scenario.stream_params)
    stream_params = ("targets", "scans", "scan_period_s", "detection", "pd", "pfa_cell", "clutter_per_scan",
                     "range_bounds_m", "azimuth_bounds_deg", "radial_velocity_bounds_m_s", "sigma_range_m",
                     "sigma_azimuth_deg", "sigma_radial_velocity_m_s", "noise_scales_with_snr", "reference_snr_db",
                     "speed_bounds_m_s", "accel_std_m_s2", "crossing", "crossing_targets", "crossing_angle_deg",
                     "gospa_cutoff_m", "gospa_order")
    small_params: ClassVar[dict] = {"targets": 3, "scans": 20, "clutter_per_scan": 5.0}
    perf_sizes: ClassVar[dict] = {"default": ({}, 20)}
    perf_snr_db: ClassVar[float] = 15.0

    @dataclass(frozen=True)
    class Params:
        targets: int = param(6, "number of ship targets T", ge=1, le=100,
                             why="one target at least; at most 100, a crowded HFSWR scene")
        scans: int = param(60, "number of scans K (duration K times scan_period_s)", ge=6, le=2000,
                           why="the M/N logic needs a few scans; at most 2000 (a day and a half at 1 min)")
        scan_period_s: float = param(60.0, "time between scans T (s)", ge=1.0, le=600.0,
                                     why="HFSWR revisit times, a second to ten minutes")
        detection: str = param("swerling1", "'swerling1': Pd from snr_db (Pd = pfa_cell^(1/(1+SNR))); "
                               "'fixed': Pd = pd whatever the SNR", choices=("swerling1", "fixed"))
        pd: float = param(0.9, "detection probability when detection = 'fixed'", ge=0.0, le=1.0,
                          why="a probability")
        pfa_cell: float = param(1e-3, "per-cell false-alarm probability of the CFAR, for the Swerling-1 Pd",
                                ge=1e-12, le=0.5, why="a probability small enough for a threshold")
        clutter_per_scan: float = param(20.0, "expected clutter plots per scan over the surveillance region "
                                        "(lambda times the region's volume)", ge=0.0, le=2000.0,
                                        why="none to 2000, beyond which the tracker's tentative tracks "
                                            "dominate any unit")
        range_bounds_m: tuple[float, ...] = param((50e3, 150e3), "surveillance region: [min, max] range (m)",
                                                  ge=1e3, le=1e6, min_len=2, max_len=2,
                                                  why="1 km to 1000 km, HFSWR ranges")
        azimuth_bounds_deg: tuple[float, ...] = param((-30.0, 30.0), "surveillance region: [min, max] azimuth "
                                                      "(deg, clockwise from north)", ge=-90.0, le=90.0,
                                                      min_len=2, max_len=2,
                                                      why="the half-plane a shore array sees, away from the "
                                                          "wrap at south")
        radial_velocity_bounds_m_s: tuple[float, ...] = param(
            (-20.0, 20.0), "surveillance region: [min, max] radial velocity (m/s, positive receding)",
            ge=-200.0, le=200.0, min_len=2, max_len=2, why="ships and slow aircraft")
        sigma_range_m: float = param(300.0, "reference range noise std (m)", ge=MIN_STD["range"], le=1e4,
                                     why="a metre to 10 km (below a metre the trackers' innovation "
                                         "covariances lose definiteness at 100 km)")
        sigma_azimuth_deg: float = param(1.0, "reference azimuth noise std (deg)", ge=1e-3, le=10.0,
                                         why="a milli-degree to 10 deg, beyond which the banana-shaped "
                                             "gate breaks the trackers' linearisation")
        sigma_radial_velocity_m_s: float = param(0.2, "reference radial-velocity noise std (m/s)",
                                                 ge=MIN_STD["radial_velocity"], le=10.0,
                                                 why="a millimetre per second to 10 m/s")
        noise_scales_with_snr: bool = param(False, "scale every noise std by 10^(-(snr_db - reference_snr_db)/20) "
                                            "(else the noise is the reference whatever the SNR)")
        reference_snr_db: float = param(15.0, "the SNR (dB) at which the noise stds are the reference ones",
                                        ge=-50.0, le=100.0, why="any SNR an HFSWR plot is formed at")
        speed_bounds_m_s: tuple[float, ...] = param((1.0, 15.0), "[min, max] target speed (m/s)", ge=0.0,
                                                    le=300.0, min_len=2, max_len=2,
                                                    why="a drifting buoy to a slow aircraft")
        accel_std_m_s2: float = param(0.002, "std of the white acceleration per axis, held over a scan "
                                      "(m/s^2; the targets' process noise)", ge=0.0, le=1.0,
                                      why="0 is straight lines; 0.1 g is far beyond a ship")
        crossing: bool = param(True, "make crossing_targets targets cross at the middle scan")
        crossing_targets: int = param(2, "how many targets cross (the first ones)", ge=2, le=100,
                                      why="a crossing takes two; at most every target")
        crossing_angle_deg: float = param(20.0, "spread of the crossing targets' headings (deg)", ge=1.0,
                                          le=179.0, why="crossing, neither parallel nor head-on")
        gospa_cutoff_m: float = param(5000.0, "GOSPA / OSPA cut-off c (m): a larger error counts as a miss "
                                      "plus a false track", ge=1.0, le=1e6,
                                      why="a metre to 1000 km, beyond the region")
        gospa_order: float = param(2.0, "GOSPA / OSPA order p", ge=1.0, le=10.0,
                                   why="p >= 1 for a metric; beyond 10 it is the maximum error")

        def validate(self) -> None:
            for name in ("range_bounds_m", "azimuth_bounds_deg", "radial_velocity_bounds_m_s",
                         "speed_bounds_m_s"):
                _pair(getattr(self, name), name)
            if self.crossing and self.crossing_targets > self.targets:
                raise ConfigError("crossing_targets", f"{self.crossing_targets} crossing targets, but "
                                  f"targets = {self.targets}")

        def region(self) -> np.ndarray:
            """(3, 2) min/max of range (m), azimuth (rad), radial velocity (m/s)."""
            return np.array([self.range_bounds_m, np.radians(self.azimuth_bounds_deg),
                             self.radial_velocity_bounds_m_s], float)

        def noise_std(self, snr_db: float | None) -> np.ndarray:
            """(3,) sigma_r (m), sigma_az (rad), sigma_vr (m/s) at ``snr_db``."""
            ref = np.array([self.sigma_range_m, math.radians(self.sigma_azimuth_deg),
                            self.sigma_radial_velocity_m_s])
            if self.noise_scales_with_snr and snr_db is not None:
                return ref * 10.0 ** (-(snr_db - self.reference_snr_db) / 20.0)
            return ref

        def detection_probability(self, snr_db: float | None) -> float:
            """Pd at ``snr_db`` (0 under the null: there is no target)."""
            if snr_db is None:
                return 0.0
            return self.pd if self.detection == "fixed" else swerling1_pd(snr_db, self.pfa_cell)

    def check_snr(self, params, snr_db: float) -> str | None:
        """Scaled noise stds must stay above :data:`MIN_STD` (float64 definiteness of the
        trackers' innovation covariances)."""
        for label, std, floor in zip(MIN_STD, params.noise_std(snr_db), MIN_STD.values()):
            if std < floor:
                return (f"the {label} noise scaled to it, {std:.3g}, is below {floor:g}; raise "
                        f"reference_snr_db or turn noise_scales_with_snr off")
        return None

    def unit_memory_bytes(self, params, n: int) -> int:
        """The plots (n, K, P, 3) and their origins with P about T + clutter + 6 sqrt(clutter),
        the truth (n, K, T, 4), the draws (n, K, T, 7) and the packing scratch (four times the plots)."""
        c = params.clutter_per_scan
        plots = params.targets + c + 6.0 * math.sqrt(c) + 6
        return int(8 * n * params.scans * (plots * 4 * 5 + params.targets * 11))

    # ------------------------------------------------------------------ generation

    def generate(self, params, snr_db: float | None, n: int, rng) -> Batch:
        K, T, dt = params.scans, params.targets, params.scan_period_s
        region = params.region()
        draws = _draw_targets(params, rng, n)
        truth = _trajectories(params, draws, region)
        if snr_db is None:
            truth[:] = np.nan
        std = params.noise_std(snr_db)
        pd = params.detection_probability(snr_db)
        clutter = _draw_clutter(params, rng, region)
        z, origin = _pack_plots(truth, draws, clutter, std, pd, region)
        scene = MultiTargetScene(
            snr_definition=SNR_DEFINITION,
            realised_snr_db=np.full(n, np.nan if snr_db is None else float(snr_db)),
            position_index=POSITION_INDEX, n_plots=(origin != PADDING).sum(axis=2), plot_origin=origin,
            scan_period_s=float(dt), sensor_xy=np.zeros(2), measurement_std=std,
            clutter_density=float(params.clutter_per_scan / np.prod(np.diff(region, axis=1))),
            surveillance_region=region, pd=float(pd), speed_bounds_m_s=tuple(map(float, params.speed_bounds_m_s)),
            accel_std_m_s2=float(params.accel_std_m_s2), gospa_cutoff_m=float(params.gospa_cutoff_m),
            gospa_order=float(params.gospa_order))
        return Batch(t=np.arange(K) * dt, truth=truth, z=z, scene=scene, trials=np.asarray(rng.trials))


def _draw_targets(params, rng, n: int) -> dict[str, np.ndarray]:
    """Every fixed-shape draw of the targets, in the documented order."""
    K, T = params.scans, params.targets
    names = ("appear", "disappear", "range", "azimuth", "heading", "speed")
    d = {name: rng.uniform((T,)) for name in names}
    d["direction"] = rng.uniform((1,))
    d["accel"] = rng.standard_normal((K, T, 2))
    d["noise"] = rng.standard_normal((K, T, 3))
    d["detect"] = rng.uniform((K, T))
    d["order"] = rng.uniform((K, T))
    return d


def _lifetimes(params, d) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n, T) first scan, end scan (exclusive) and anchor scan of each target."""
    K = params.scans
    first = np.floor(d["appear"] * (K // 3 + 1)).astype(int)
    lo = (2 * K) // 3
    end = lo + np.floor(d["disappear"] * (K - lo + 1)).astype(int)      # K: to the end of the run
    if params.crossing:
        m = params.crossing_targets
        first[:, :m] = np.floor(d["appear"][:, :m] * (K // 4 + 1)).astype(int)
        end[:, :m] = K
    anchor = (first + end - 1) // 2
    if params.crossing:
        anchor[:, :params.crossing_targets] = K // 2
    return first, end, anchor


def _anchor_states(params, d, region) -> np.ndarray:
    """(n, T, 4) [x, vx, y, vy] of each target at its anchor scan."""
    (r0, r1), (a0, a1) = region[0], region[1]
    r = r0 + (r1 - r0) * (0.25 + 0.5 * d["range"])
    az = a0 + (a1 - a0) * (0.25 + 0.5 * d["azimuth"])
    v0, v1 = params.speed_bounds_m_s
    speed = v0 + (v1 - v0) * d["speed"]
    heading = 2.0 * np.pi * d["heading"]
    if params.crossing:
        m = params.crossing_targets
        r[:, :m], az[:, :m], speed[:, :m] = r[:, :1], az[:, :1], speed[:, :1]
        los = az[:, :1] + np.where(d["direction"] < 0.5, 0.0, np.pi)       # receding or approaching
        spread = np.radians(params.crossing_angle_deg) * (np.arange(m) / (m - 1) - 0.5)
        heading[:, :m] = los + spread
    # heading clockwise from north, like azimuth
    return np.stack([r * np.sin(az), speed * np.sin(heading), r * np.cos(az), speed * np.cos(heading)], axis=-1)


def _clip_speed(x: np.ndarray, bounds) -> None:
    """Speeds of states (..., 4) clipped into ``bounds`` (m/s), in place."""
    v = x[..., [1, 3]]
    speed = np.hypot(v[..., 0], v[..., 1])
    scale = np.clip(speed, *bounds) / np.maximum(speed, 1e-12)
    x[..., 1] *= scale
    x[..., 3] *= scale


def _trajectories(params, d, region) -> np.ndarray:
    """(n, K, T, 4) true states, NaN while a target is absent (before it appears, after it
    disappears, outside the surveillance region)."""
    K = params.scans
    F = cv_transition(params.scan_period_s)
    F_inv = cv_transition(-params.scan_period_s)
    G = cv_gain(params.scan_period_s)
    w = matvec(G, params.accel_std_m_s2 * d["accel"])                         # (n, K, T, 4): G w_k
    first, end, anchor = _lifetimes(params, d)
    x = np.empty((*anchor.shape[:1], K, anchor.shape[1], 4))
    start = _anchor_states(params, d, region)
    for k in range(K):                                                   # forward from each anchor
        prev = matvec(F, x[:, k - 1]) + w[:, k - 1] if k else start
        x[:, k] = np.where((k > anchor)[..., None], prev, start)
        _clip_speed(x[:, k], params.speed_bounds_m_s)
    for k in range(K - 2, -1, -1):                                       # backward before each anchor
        back = matvec(F_inv, x[:, k + 1] - w[:, k])
        _clip_speed(back, params.speed_bounds_m_s)
        x[:, k] = np.where((k < anchor)[..., None], back, x[:, k])
    scans = np.arange(K)[None, :, None]
    alive = (scans >= first[:, None]) & (scans < end[:, None])
    zt = measure(x, np.zeros(2))
    inside = np.all((zt >= region[:, 0]) & (zt <= region[:, 1]), axis=-1)
    x[~(alive & inside)] = np.nan
    return x


def _draw_clutter(params, rng, region) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per trial: clutter counts (K,), plots (C, 3) uniform over ``region``, order keys (C,),
    each from the trial's own generator (its count varies)."""
    lo, span = region[:, 0], region[:, 1] - region[:, 0]
    out = []
    for g in rng.generators:
        counts = g.poisson(params.clutter_per_scan, params.scans)
        plots = lo + span * g.random((int(counts.sum()), 3))
        out.append((counts, plots, g.random(int(counts.sum()))))
    return out


def _pack_plots(truth, d, clutter, std, pd, region) -> tuple[np.ndarray, np.ndarray]:
    """z (n, K, P, 3) and plot_origin (n, K, P): each scan's detected target plots and
    clutter, sorted by their order keys, NaN / -2 padded to P, the most plots of a scan."""
    n, K, T, _ = truth.shape
    present = np.isfinite(truth[..., 0])
    zt = measure(np.where(present[..., None], truth, 1.0), np.zeros(2)) + std * d["noise"]
    zt[..., 1] = wrap_angle(zt[..., 1])
    keep = present & (d["detect"] < pd) & np.all((zt >= region[:, 0]) & (zt <= region[:, 1]), axis=-1)
    C = max([int(c.max(initial=0)) for c, _, _ in clutter] + [0])
    cz = np.full((n, K, C, 3), np.nan)
    ckeep = np.zeros((n, K, C), bool)
    ckey = np.ones((n, K, C))
    for i, (counts, plots, keys) in enumerate(clutter):
        scan = np.repeat(np.arange(K), counts)
        slot = np.arange(len(scan)) - np.repeat(np.cumsum(counts) - counts, counts)
        cz[i, scan, slot], ckeep[i, scan, slot], ckey[i, scan, slot] = plots, True, keys
    allz = np.concatenate([zt, cz], axis=2)
    valid = np.concatenate([keep, ckeep], axis=2)
    origin = np.concatenate([np.broadcast_to(np.arange(T), (n, K, T)), np.full((n, K, C), CLUTTER)], axis=2)
    key = np.where(valid, np.concatenate([d["order"], ckey], axis=2), np.inf)
    order = np.argsort(key, axis=2, kind="stable")
    P = int(valid.sum(axis=2).max(initial=0))
    order = order[..., :P]
    valid = np.take_along_axis(valid, order, axis=2)
    z = np.where(valid[..., None], np.take_along_axis(allz, order[..., None], axis=2), np.nan)
    origin = np.where(valid, np.take_along_axis(origin, order, axis=2), PADDING)
    return z, origin.astype(np.int64)
