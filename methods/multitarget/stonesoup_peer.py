"""Method ``stonesoup-jpda``: Stone Soup's JPDA with its UKF, as a peer of ``jpda-ukf``.

Needs the ``[peers]`` extra (``pip install -e ".[peers]"``, Stone Soup ≥ 1.4).
Stone Soup is imported when this module is, so without it ``bench list``
shows the method as unavailable with the import error (bench/registry.py;
docs/architecture.md, 'Plugins').
"""

from __future__ import annotations

import datetime
import time

import numpy as np

from radarbench.bench.registry import PluginError

try:
    from stonesoup.base import Property
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.dataassociator.probability import JPDA
    from stonesoup.deleter.time import UpdateTimeStepsDeleter
    from stonesoup.functions import gm_reduce_single
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.initiator.simple import MultiMeasurementInitiator
    from stonesoup.measures import Mahalanobis
    from stonesoup.models.base import ReversibleModel
    from stonesoup.models.measurement.nonlinear import NonLinearGaussianMeasurement
    from stonesoup.models.transition.linear import LinearGaussianTransitionModel
    from stonesoup.predictor.kalman import UnscentedKalmanPredictor
    from stonesoup.types.array import StateVector, StateVectors
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.update import GaussianStateUpdate, Update
    from stonesoup.updater.kalman import UnscentedKalmanUpdater
except ImportError as exc:     # the [peers] extra is missing: the method is unavailable, named, with the reason
    raise PluginError(f'needs the [peers] extra (pip install -e ".[peers]"): {exc}', name="stonesoup-jpda") from exc

from radarbench.bench.core import Batch, Method  # noqa: E402 - after the guarded imports
from radarbench.bench.registry import register_method  # noqa: E402
from radarbench.bench.tasks.multitarget import MULTI_TARGET, MultiTargetOutput
from radarbench.methods.multitarget import kernels as kern
from radarbench.methods.multitarget.track_management import (
    LAMBDA_FLOOR,
    TrackerParams,
    TrialBuffers,
    assemble,
    check_speed_bound,
    scene_of,
    tracker_models,
)
from radarbench.models.hfswr import measure, plot_to_cartesian


class HFSWRTransition(LinearGaussianTransitionModel):
    """The CV model of :mod:`models.hfswr` (F, discrete white-noise Q) for Stone Soup."""

    F: np.ndarray = Property(doc="(4, 4) transition over one scan")
    Q: np.ndarray = Property(doc="(4, 4) process noise over one scan")

    @property
    def ndim_state(self):
        return 4

    def matrix(self, **kwargs):
        return self.F

    def covar(self, **kwargs):
        return self.Q


class HFSWRMeasurement(NonLinearGaussianMeasurement, ReversibleModel):
    """Range, azimuth (clockwise from north) and radial velocity of
    :func:`models.hfswr.measure` for Stone Soup. The azimuth is a plain float,
    not a Stone Soup ``Bearing``: the scenario's region stays within ±90°, away
    from the ±π cut. ``inverse_function`` gives the position of the plot and
    its radial velocity along the line of sight (Stone Soup's initiator adds
    the prior's velocity uncertainty)."""

    sensor_xy: np.ndarray = Property(doc="(2,) sensor position (m)")

    @property
    def ndim_meas(self):
        return 3

    def function(self, state, noise=False, **kwargs):
        x = np.asarray(state.state_vector, dtype=float)            # (4, N)
        z = measure(x.T, self.sensor_xy).T
        if isinstance(noise, bool) and noise:
            z = z + self.rvs(num_samples=x.shape[1], **kwargs)
        elif not isinstance(noise, bool):
            z = z + noise
        return StateVectors(z) if z.shape[1] > 1 else StateVector(z[:, 0])

    def inverse_function(self, detection, **kwargs):
        r, az, vr = np.asarray(detection.state_vector, float)[:, 0]
        px, py = plot_to_cartesian(np.array([r, az]), self.sensor_xy)
        return StateVector([px, vr * np.sin(az), py, vr * np.cos(az)])


def ukf_parts(scene, F, Q, R, params):
    """Stone Soup's measurement model, UKF predictor and updater for the scene's
    models (F, Q, R of :mod:`models.hfswr`) and the parameters' α, β, κ."""
    transition = HFSWRTransition(F=F, Q=Q)
    measurement = HFSWRMeasurement(ndim_state=4, mapping=(0, 2), noise_covar=R,
                                   sensor_xy=np.asarray(scene.sensor_xy, float))
    ukf = dict(alpha=params.alpha, beta=params.beta, kappa=params.kappa)
    return measurement, UnscentedKalmanPredictor(transition, **ukf), UnscentedKalmanUpdater(measurement, **ukf)


class StoneSoupPeer(Method):
    """What the Stone Soup peers share: one trial at a time in Python objects
    (:meth:`_trial`), the trials' buffers assembled as ``jpda-ukf``'s are."""

    task = MULTI_TARGET

    def run(self, batch: Batch, params) -> MultiTargetOutput:
        scene = scene_of(batch)
        n, K = batch.z.shape[:2]
        trials, slots = [], []
        for i in range(n):
            buf, used = self._trial(batch.z[i], scene.n_plots[i], scene, params, K)
            trials.append(buf)
            slots.append(used)
        return assemble(trials, slots)

    def _trial(self, z, n_plots, scene, params, K) -> tuple[TrialBuffers, int]:
        """One trial through the peer's Stone Soup tracker: its output buffers and the track
        slots used. Each peer overrides it; Stone Soup runs one scene at a time, so this loop
        over trials is the peer's own cost, timed as such by ``bench perf``."""
        raise NotImplementedError(f"{type(self).__name__} must define _trial")


class InitiatedPeer(StoneSoupPeer):
    r"""The peers that start tracks as ``stonesoup-jpda`` does and end them by ``jpda-ukf``'s rules.

    The scan loop of the track-based Stone Soup peers at equal footing with
    ``jpda-ukf`` (:mod:`methods.multitarget.trackers`): the same models and UKF
    (:func:`ukf_parts`), the peer's data associator over the confirmed tracks
    (:meth:`_associator`) and its update of a track from the hypotheses kept
    (:meth:`_update`), then ``MultiMeasurementInitiator`` on the plots no
    confirmed track's gate held (:meth:`_initiator`), the three termination
    rules on the track's estimate (:meth:`_estimate`).

    **Initiation**: Stone Soup's closest to M/N is ``MultiMeasurementInitiator``:
    every plot no confirmed track's gate holds starts a holding track
    (position from the plot, velocity from the plot's radial velocity along the
    line of sight plus a prior std of $v_{\max}$ per axis); holding tracks are
    associated by ``GNNWith2DAssignment`` on the Mahalanobis distance (gate
    $\sqrt{\gamma}$) and updated by the UKF; a holding track with $M + 2$ plots (the two
    initial plots and M more) is confirmed; one without a plot for $N - M + 1$
    consecutive scans (``UpdateTimeStepsDeleter``) is dropped. So it is
    "$M + 2$ plots before $N - M + 1$ consecutive misses", not "$M$ of the $N$ frames
    after the second plot": close, not identical (no N-frame deadline, no
    speed gate on the second plot beyond the prior's $v_{\max}$).
    **Termination**: the same three rules as ``jpda-ukf`` ($M_t$ of the last
    $N_t$ scans without a plot in the gate, the position std bound, the speed
    bound), evaluated here on Stone Soup's tracks (Stone Soup has no
    "M of N" deleter). Outputs: confirmed tracks (2), terminated at their last
    scan (3), holding tracks with at least two plots as tentative (1).
    """

    #: CPU seconds (this thread) spent in ``MultiMeasurementInitiator.initiate`` since the instance was made
    initiation_seconds: float = 0.0

    def check_scenario(self, params, scenario_params) -> str | None:
        return check_speed_bound(params, scenario_params)

    def _associator(self, scene, params, predictor, updater):
        """The peer's data associator of the confirmed tracks (``associate(tracks, plots, when)``)."""
        raise NotImplementedError(f"{type(self).__name__} must define _associator")

    def _update(self, track, multi, when, updater, params) -> None:
        """Append to ``track`` its posterior at ``when`` from the hypotheses ``multi`` the associator kept."""
        raise NotImplementedError(f"{type(self).__name__} must define _update")

    def _adopt(self, track) -> None:
        """A holding track just confirmed becomes one of the associator's (nothing to do by default)."""

    def _estimate(self, track):
        """The track's state estimate (a Gaussian state) for the termination rules and the outputs."""
        return track.state

    def _initiator(self, scene, params, models, measurement, predictor, updater):
        vmax = float(scene.speed_bounds_m_s[1])
        return MultiMeasurementInitiator(
            prior_state=GaussianState(StateVector([0.0, 0.0, 0.0, 0.0]), np.diag([0.0, vmax ** 2, 0.0, vmax ** 2])),
            deleter=UpdateTimeStepsDeleter(time_steps_since_update=params.confirm_n - params.confirm_m + 1),
            data_associator=GNNWith2DAssignment(DistanceHypothesiser(
                predictor, updater, Mahalanobis(), missed_distance=float(np.sqrt(models.gamma)))),
            updater=updater, measurement_model=measurement, min_points=params.confirm_m + 2)

    def _components(self, scene, params):
        models = tracker_models(scene, params, kern.UKF)
        measurement, predictor, updater = ukf_parts(scene, models.F, models.Q, models.R, params)
        associator = self._associator(scene, params, predictor, updater)
        return measurement, updater, associator, self._initiator(scene, params, models, measurement, predictor,
                                                                 updater)

    def _ends(self, track, misses: int, params) -> bool:
        """The three termination rules on the track's miss history and estimate."""
        estimate = self._estimate(track)
        speed = float(np.hypot(estimate.state_vector[1, 0], estimate.state_vector[3, 0]))
        return (bin(misses).count("1") >= params.terminate_m
                or kern.position_std(np.asarray(estimate.covar, float)) > params.max_position_std_m
                or speed > params.max_speed_m_s)

    def _trial(self, z, n_plots, scene, params, K):
        measurement, updater, associator, initiator = self._components(scene, params)
        start = datetime.datetime(2000, 1, 1)
        buf = TrialBuffers.empty(K, params.max_tracks)
        tracks: dict = {}                 # Stone Soup track -> its miss history (bit 0 = this scan)
        slots = _Slots(params.max_tracks)
        term_mask = (1 << params.terminate_n) - 1
        for k in range(K):
            when = start + datetime.timedelta(seconds=k * float(scene.scan_period_s))
            ordered = [Detection(StateVector(p), timestamp=when, measurement_model=measurement)
                       for p in z[k, :int(n_plots[k])]]
            detections = set(ordered)
            # lists, not sets: Stone Soup sums the joint events in iteration order (determinism to the last bit)
            hypotheses = associator.associate(list(tracks), ordered, when)
            gated = set()
            ended = []
            for track, multi in hypotheses.items():
                hit = any(h for h in multi)
                gated |= {h.measurement for h in multi if h}
                self._update(track, multi, when, updater, params)
                tracks[track] = ((tracks[track] << 1) | (0 if hit else 1)) & term_mask
                if self._ends(track, tracks[track], params):
                    ended.append(track)
            t0 = time.thread_time()
            started = initiator.initiate(detections - gated, when)
            self.initiation_seconds += time.thread_time() - t0
            for track in sorted(started, key=_track_key):
                self._adopt(track)
                tracks[track] = 0
            for track in ended:
                del tracks[track]
                slots.record(buf, k, track, kern.TERMINATED, self._estimate(track))
            for track in tracks:
                slots.record(buf, k, track, kern.CONFIRMED, self._estimate(track))
            for track in sorted(initiator.holding_tracks, key=_track_key):
                if sum(1 for s in track if isinstance(s, Update) and s.hypothesis) >= 2:
                    slots.record(buf, k, track, kern.TENTATIVE)
            slots.release_missing(set(tracks) | set(initiator.holding_tracks))
        return buf, slots.used


@register_method
class StoneSoupJpda(InitiatedPeer):
    r"""Stone Soup's JPDA with UnscentedKalmanUpdater and MultiMeasurementInitiator (peer of jpda-ukf; extra [peers]).

    The same models and parameters as ``jpda-ukf`` (:mod:`methods.multitarget.trackers`):
    the CV transition and discrete white-noise Q of :mod:`models.hfswr`
    (:class:`HFSWRTransition`), the range / azimuth / radial velocity
    measurement with $R = \operatorname{diag}(\sigma^2)$ (:class:`HFSWRMeasurement`),
    ``UnscentedKalmanPredictor`` / ``UnscentedKalmanUpdater`` with the same
    $\alpha$, $\beta$, $\kappa$, ``PDAHypothesiser`` (clutter density $\lambda$, $P_D$, gate probability
    $P_G$) under ``JPDA`` (which enumerates the joint events of *all* tracks of
    a scan at once: no clustering, so its cost grows exponentially with the
    number of tracks), the JPDA mixture reduced by ``gm_reduce_single`` (eqs.
    6.73–6.74). Initiation and termination: :class:`InitiatedPeer`.
    Per trial and scan in Python objects: slow by nature, the baseline of
    ``bench perf`` for ``jpda-ukf``.
    """

    name = "stonesoup-jpda"
    Params = TrackerParams

    def _associator(self, scene, params, predictor, updater):
        return JPDA(PDAHypothesiser(predictor, updater, clutter_spatial_density=max(scene.clutter_density,
                                                                                     LAMBDA_FLOOR),
                                    prob_detect=scene.pd, prob_gate=params.gate_probability))

    def _update(self, track, multi, when, updater, params) -> None:
        _append_mixture(track, multi, when, updater)


def _track_key(track):
    """A deterministic order for Stone Soup's tracks (sets of objects hashed by
    address): first timestamp, then first state."""
    return track[0].timestamp, tuple(np.asarray(track[0].state_vector, float).ravel())


def _append_mixture(track, multi, when, updater) -> None:
    """The JPDA update of Stone Soup's tutorial: each hypothesis' posterior
    (the prediction for the missed detection) weighted by its probability,
    reduced to one Gaussian."""
    states, weights = [], []
    for h in multi:
        states.append(updater.update(h) if h else h.prediction)
        weights.append(float(h.probability))
    means = StateVectors([s.state_vector for s in states])
    covars = np.stack([s.covar for s in states], axis=2)
    mean, covar = gm_reduce_single(means, covars, np.asarray(weights))
    track.append(GaussianStateUpdate(mean, covar, multi, when))


class _Slots:
    """Output slots for Stone Soup's tracks: identities in first-seen order, the lowest free slot."""

    def __init__(self, capacity: int):
        self.capacity = capacity
        self.slot_of: dict = {}
        self.id_of: dict = {}
        self.used = 0

    def record(self, buf: TrialBuffers, k: int, track, status: int, state=None) -> None:
        """Write ``state`` (default: the track's last) of the track keyed ``track`` at scan k."""
        state = track if state is None else state
        if track not in self.slot_of:
            taken = set(self.slot_of.values())
            free = next((s for s in range(self.capacity) if s not in taken), None)
            if free is None:
                return
            self.slot_of[track] = free
            self.id_of.setdefault(track, len(self.id_of))
            self.used = max(self.used, free + 1)
        s = self.slot_of[track]
        sv, P = np.asarray(state.state_vector, float)[:, 0], np.asarray(state.covar, float)
        buf.state[k, s] = sv
        buf.track_id[k, s] = self.id_of[track]
        buf.status[k, s] = status
        buf.cov[k, s] = P[np.ix_((0, 2), (0, 2))]

    def release_missing(self, alive: set) -> None:
        for track in [t for t in self.slot_of if t not in alive]:
            del self.slot_of[track]
