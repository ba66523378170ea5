"""Track management shared by the multi-target trackers (``jpda-ukf``,
``gnn-ekf``, ``stonesoup-jpda``; :mod:`methods.multitarget.trackers`,
:mod:`methods.multitarget.stonesoup_peer`): their common parameters (M/N initiation, the
termination rules, gates, the UKF's sigma points), the models read off the
multi-target scene, and the assembly of a :class:`MultiTargetOutput`.

The compiled scan loop is :mod:`methods.multitarget.kernels` (its docstring states
the chain step by step, after the HFSWR tracking chapter "目标检测与跟踪方法,
海洋遥感技术应用", section 2(2)); docs/architecture.md, 'Tasks' and 'Scenes'
describe the batch and the output.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.stats

from radarbench.bench.core import Batch
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.tasks.multitarget import MultiTargetOutput, MultiTargetScene
from radarbench.methods.multitarget import kernels as kern
from radarbench.models.hfswr import cv_process_noise, cv_transition
from radarbench.models.ukf import merwe_weights

#: the smallest clutter density used in logarithms (λ = 0: every gated plot is a target's)
LAMBDA_FLOOR = 1e-300


def gate_probability_param():
    """The ``gate_probability`` field every Stone Soup or own tracker here shares."""
    return param(0.99, "P_G: probability that a target's plot falls in the track's "
                       "validation gate (eq. 6.72; gamma = chi2(3) quantile)",
                 ge=0.5, le=0.999999, why="a gate that misses half the target's plots is "
                                          "useless; 1 - 1e-6 keeps the gate finite")


def alpha_param():
    """The UKF's ``alpha`` field (:mod:`models.ukf`), shared by every UKF tracker here."""
    return param(0.5, "UKF sigma-point spread alpha (Stone Soup's default)", ge=0.01, le=1.0,
                 why="the scaled unscented transform's range is (0, 1]; below 0.01 the central weight "
                     "passes -10^4 and the moment sums cancel in float64")


def beta_param():
    return param(2.0, "UKF prior-knowledge weight beta (2: optimal for a Gaussian)", ge=0.0, le=10.0,
                 why="non-negative; larger values only inflate the central covariance weight")


def kappa_param():
    return param(-1.0, "UKF secondary scale kappa (3 - n = -1 for the 4-state CV model, Stone "
                       "Soup's default)", ge=-3.0, le=10.0,
                 why="n + kappa > 0 for n = 4 keeps the sigma points real")


@dataclass(frozen=True)
class TrackerParams:
    """The parameters every multi-target tracker here shares."""

    confirm_m: int = param(2, "M of the M/N confirmation: plots needed in the N frames after the two "
                              "initial plots", ge=1, le=20, why="at least one plot; at most N (checked), N <= 20")
    confirm_n: int = param(3, "N of the M/N confirmation: frames 3 .. N + 2 of a tentative track", ge=1, le=20,
                           why="one frame at least; 20 frames keep a tentative track within a short scene")
    terminate_m: int = param(3, "termination rule 1: a confirmed track ends when M_t of its last N_t "
                                "frames had no plot", ge=1, le=60,
                             why="one missed frame at least; at most N_t (checked)")
    terminate_n: int = param(5, "termination rule 1: N_t, the frames looked back over", ge=1, le=60,
                             why="the miss history is a 62-bit word")
    max_position_std_m: float = param(20_000.0, "termination rule 2: a track ends when the std of its "
                                                "position along the covariance's major axis exceeds this (m)",
                                      gt=0.0, le=1e7, why="positive; 10 000 km is beyond any HF radar's reach")
    max_speed_m_s: float = param(40.0, "termination rule 3: a track ends when its speed exceeds this "
                                       "impossible v_max (m/s)", gt=0.0, le=1e4,
                                 why="positive; 10 km/s is beyond any surface target")
    gate_probability: float = gate_probability_param()
    init_gate_sigmas: float = param(3.0, "initiation gate: noise margin g in v_min T - g sigma_d <= d <= "
                                         "v_max T + g sigma_d (standard deviations)", ge=0.0, le=10.0,
                                    why="0: speed bounds alone; beyond 10 sigma the gate holds the whole scene")
    initial_velocity: str = param("two-point", "two-point: the velocity of the two initial plots by "
                                  "differencing (the chapter's initialisation); two-point+speed-prior: "
                                  "fused with a N(0, v_max^2) prior per axis (ours)",
                                  choices=("two-point", "two-point+speed-prior"))
    alpha: float = alpha_param()
    beta: float = beta_param()
    kappa: float = kappa_param()
    max_cluster_size: int = param(49, "exact JPDA up to clusters of tracks x plots this large; larger "
                                      "clusters use per-track PDA (counted in the trace)", ge=1, le=64,
                                  why="a fully connected 8 x 8 cluster has 1.4 million joint events")
    max_tracks: int = param(512, "track table capacity per trial (tentative and confirmed); a track "
                                 "started when it is full is dropped and counted", ge=8, le=8192,
                            why="8 slots at least; 8192 slots of (K, slots) outputs per trial stay in memory")

    def validate(self) -> None:
        if self.confirm_m > self.confirm_n:
            raise ConfigError("confirm_m", f"M = {self.confirm_m} is larger than N = {self.confirm_n}")
        if self.terminate_m > self.terminate_n:
            raise ConfigError("terminate_m", f"M_t = {self.terminate_m} is larger than N_t = {self.terminate_n}")


def check_speed_bound(params, scenario_params) -> str | None:
    """Termination rule 3 must not end true tracks: ``max_speed_m_s`` above the targets' top speed."""
    bounds = getattr(scenario_params, "speed_bounds_m_s", None)
    if bounds is not None and params.max_speed_m_s <= max(bounds):
        return (f"max_speed_m_s = {params.max_speed_m_s:g} (termination rule 3) is not above the "
                f"targets' top speed {max(bounds):g} m/s: every true track would end")
    return None


def _filter_param(default: str):
    return param(default, "the filter of every track: ukf (models/ukf.py, the chapter's) or ekf (H = dh/dx "
                          "at the prediction); the other one than the method's name is our ablation",
                 choices=tuple(FILTERS))


#: the ``filter`` parameter's kernel codes
FILTERS = {"ukf": kern.UKF, "ekf": kern.EKF}
#: the ``confirmation`` parameter's kernel codes
CONFIRMATIONS = {"frame-n+2": kern.CONFIRM_AT_FRAME_N_PLUS_2, "kth-plot": kern.CONFIRM_ON_KTH_PLOT}


@dataclass(frozen=True)
class OwnTrackerParams(TrackerParams):
    """:class:`TrackerParams` and the options of our compiled trackers alone
    (``jpda-ukf``, ``gnn-ekf``; the Stone Soup peer has its own initiator)."""

    confirmation: str = param("frame-n+2", "frame-n+2: M hits in frames 3 .. N + 2, confirmed at frame N + 2 "
                              "(the chapter's step 5); kth-plot: confirmed on the (M + 2)-th plot with no frame "
                              "deadline, dropped after N - M + 1 consecutive misses (ours, the rule of Stone "
                              "Soup's MultiMeasurementInitiator)", choices=tuple(CONFIRMATIONS))


@dataclass(frozen=True)
class UkfTrackerParams(OwnTrackerParams):
    filter: str = _filter_param("ukf")


@dataclass(frozen=True)
class EkfTrackerParams(OwnTrackerParams):
    filter: str = _filter_param("ekf")


def scene_of(batch: Batch) -> MultiTargetScene:
    scene = batch.scene
    if not isinstance(scene, MultiTargetScene):
        raise TypeError(f"expected a MultiTargetScene, got {type(scene).__name__}")
    return scene


@dataclass(frozen=True)
class TrackerModels:
    """What the trackers assume, read off the scene: F, Q (models/hfswr.py),
    R = diag(σ²) (ρ = 0, as the chapter assumes), the UKF weights, and the
    compiled loop's configuration vectors."""

    F: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    Wm: np.ndarray
    Wc: np.ndarray
    cfg: np.ndarray
    icfg: np.ndarray
    gamma: float


def tracker_models(scene: MultiTargetScene, params, filter_kind: int,
                   confirm_rule: int = kern.CONFIRM_AT_FRAME_N_PLUS_2) -> TrackerModels:
    T = float(scene.scan_period_s)
    sig = np.asarray(scene.measurement_std, float)
    Wm, Wc, zeta = merwe_weights(4, params.alpha, params.beta, params.kappa)
    gamma = float(scipy.stats.chi2.ppf(params.gate_probability, 3))
    pd_pg = scene.pd * params.gate_probability
    cfg = np.zeros(kern.N_CFG)
    cfg[kern.C_DT] = T
    cfg[kern.C_LOG_PD] = math.log(scene.pd) if scene.pd > 0 else -np.inf
    cfg[kern.C_LOG_MISS] = math.log(1.0 - pd_pg) if pd_pg < 1.0 else -np.inf
    cfg[kern.C_LOG_LAMBDA] = math.log(max(float(scene.clutter_density), LAMBDA_FLOOR))
    cfg[kern.C_GAMMA] = gamma
    cfg[kern.C_VMIN], cfg[kern.C_VMAX] = scene.speed_bounds_m_s
    cfg[kern.C_INIT_SIGMAS] = params.init_gate_sigmas
    cfg[kern.C_MAX_POS_STD] = params.max_position_std_m
    cfg[kern.C_MAX_SPEED] = params.max_speed_m_s
    cfg[kern.C_SX], cfg[kern.C_SY] = np.asarray(scene.sensor_xy, float)
    cfg[kern.C_SIG_R], cfg[kern.C_SIG_AZ] = sig[0], sig[1]
    cfg[kern.C_ZETA] = zeta
    icfg = np.zeros(kern.N_ICFG, np.int64)
    icfg[kern.I_CONFIRM_M], icfg[kern.I_CONFIRM_N] = params.confirm_m, params.confirm_n
    icfg[kern.I_TERM_M], icfg[kern.I_TERM_N] = params.terminate_m, params.terminate_n
    icfg[kern.I_MAX_CLUSTER] = params.max_cluster_size
    icfg[kern.I_FILTER] = filter_kind
    icfg[kern.I_SPEED_PRIOR] = params.initial_velocity == "two-point+speed-prior"
    icfg[kern.I_CONFIRM_RULE] = confirm_rule
    return TrackerModels(F=cv_transition(T), Q=cv_process_noise(T, scene.accel_std_m_s2), R=np.diag(sig ** 2),
                         Wm=Wm, Wc=Wc, cfg=cfg, icfg=icfg, gamma=gamma)


@dataclass
class TrialBuffers:
    """One trial's outputs over the whole track table (K scans × C slots)."""

    state: np.ndarray
    track_id: np.ndarray
    status: np.ndarray
    cov: np.ndarray

    @classmethod
    def empty(cls, K: int, C: int) -> "TrialBuffers":
        return cls(state=np.full((K, C, 4), np.nan), track_id=np.full((K, C), -1, np.int64),
                   status=np.zeros((K, C), np.int8), cov=np.full((K, C, 2, 2), np.nan))

    def take(self, used: int) -> "TrialBuffers":
        """A copy of the first ``used`` slots, and those slots emptied again here, so one
        working buffer serves every trial of a run and each trial keeps only the slots it
        used (not the table's capacity: ``max_tracks``)."""
        kept = TrialBuffers(state=self.state[:, :used].copy(), track_id=self.track_id[:, :used].copy(),
                            status=self.status[:, :used].copy(), cov=self.cov[:, :used].copy())
        self.state[:, :used], self.track_id[:, :used] = np.nan, -1
        self.status[:, :used], self.cov[:, :used] = 0, np.nan
        return kept


def assemble(trials: list[TrialBuffers], slots_used: list[int]) -> MultiTargetOutput:
    """Stack the trials' buffers, cut to J = the most slots any trial used (≥ 1)."""
    J = max(1, max(slots_used, default=0))
    n, K = len(trials), trials[0].state.shape[0] if trials else 0
    out = TrialBuffers.empty(K, J)
    state = np.repeat(out.state[None], n, axis=0)
    ids = np.repeat(out.track_id[None], n, axis=0)
    status = np.repeat(out.status[None], n, axis=0)
    cov = np.repeat(out.cov[None], n, axis=0)
    for i, buf in enumerate(trials):
        j = min(J, buf.state.shape[1])
        state[i, :, :j], ids[i, :, :j], status[i, :, :j], cov[i, :, :j] = (
            buf.state[:, :j], buf.track_id[:, :j], buf.status[:, :j], buf.cov[:, :j])
    return MultiTargetOutput(state=state, track_id=ids, status=status, position_covariance=cov)


def trace_of(counters: np.ndarray) -> dict[str, np.ndarray]:
    """Per-trial counters (n, N_COUNTERS) of the compiled loop by name."""
    return {name: counters[:, i] for i, name in enumerate(kern.COUNTER_NAMES)}
