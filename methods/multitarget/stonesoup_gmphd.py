"""Method ``stonesoup-gmphd``: Stone Soup's Gaussian-mixture PHD (or LCC) filter
as a tracker, a peer of ``jpda-ukf`` from the random-finite-set family.

Needs the ``[peers]`` extra (``pip install -e ".[peers]"``, Stone Soup ≥ 1.4);
without it ``bench list`` shows the method as unavailable with the reason
(bench/registry.py; docs/architecture.md, 'Plugins').
"""

from __future__ import annotations

import datetime
import math
from dataclasses import dataclass

import numpy as np
import scipy.stats

from radarbench.bench.registry import PluginError

try:
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.gaussianmixture import GaussianMixtureHypothesiser
    from stonesoup.measures import Mahalanobis
    from stonesoup.mixturereducer.gaussianmixture import GaussianMixtureReducer
    from stonesoup.types.array import StateVector
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import TaggedWeightedGaussianState
    from stonesoup.updater.pointprocess import LCCUpdater, PHDUpdater
except ImportError as exc:     # the [peers] extra is missing: the method is unavailable, named, with the reason
    raise PluginError(f'needs the [peers] extra (pip install -e ".[peers]"): {exc}', name="stonesoup-gmphd") from exc

from radarbench.bench.params import param  # noqa: E402 - after the guarded imports
from radarbench.bench.registry import register_method  # noqa: E402
from radarbench.methods.multitarget import kernels as kern  # noqa: E402
from radarbench.methods.multitarget.track_management import (  # noqa: E402
    LAMBDA_FLOOR,
    TrialBuffers,
    alpha_param,
    beta_param,
    gate_probability_param,
    kappa_param,
)
from radarbench.methods.multitarget.stonesoup_peer import StoneSoupPeer, _Slots, ukf_parts  # noqa: E402
from radarbench.models.hfswr import cv_process_noise, cv_transition  # noqa: E402

#: the ``cardinality`` parameter: Stone Soup's point-process updaters
UPDATERS = {"phd": PHDUpdater, "lcc": LCCUpdater}
#: the ``births`` parameter: how the birth rate is spread over the last scan's plots
BIRTHS = ("adaptive", "unheld")


@dataclass(frozen=True)
class GmPhdParams:
    """The GM-PHD tracker's parameters (Vo & Ma 2006's defaults where they give one)."""

    cardinality: str = param("phd", "phd: the GM-PHD update (Vo & Ma 2006, Stone Soup's PHDUpdater); lcc: the "
                             "second-order GM-LCC update (Clark & De Melo 2018, Stone Soup's LCCUpdater), the "
                             "clutter count Poisson with the scene's mean (variance = mean)",
                             choices=tuple(UPDATERS))
    birth_rate: float = param(0.2, "expected new targets per scan, the same at every scan and set without "
                                   "the scene's arrivals: Vo & Ma 2006's birth intensity (two components of "
                                   "weight 0.1); spread over the last scan's plots as ``births`` says",
                              gt=0.0, le=10.0, why="positive; more than 10 ships appearing per scan is no "
                                                   "HFSWR scene")
    births: str = param("adaptive", "adaptive: every plot of the last scan is a birth, weighted by the "
                                     "probability that no component of the mixture produced it (Ristic, Clark, "
                                     "Vo & Vo 2012: birth_rate (1 - rho(z)) / sum (1 - rho)); unheld: the plots "
                                     "no extracted component's gate held, birth_rate split evenly (the earlier "
                                     "rule)", choices=BIRTHS)
    survival_probability: float = param(0.99, "P_S: probability that a target present at one scan is present "
                                              "at the next (Vo & Ma's 0.99)", ge=0.5, le=1.0,
                                        why="a target lasting two scans on average is no track; 1: no deaths")
    extraction_threshold: float = param(0.5, "a component with weight above this is a confirmed track "
                                             "(Vo & Ma's state extraction at 0.5)", gt=0.0, lt=1.0,
                                        why="a weight is an expected target count in (0, 1] once merged")
    prune_threshold: float = param(1e-5, "components with weight below this are pruned (Vo & Ma's T)",
                                   gt=0.0, le=0.1, why="positive; above 0.1 a new component dies before its "
                                                       "second plot")
    merge_threshold: float = param(4.0, "components closer than this squared Mahalanobis distance are merged "
                                        "(Vo & Ma's U)", gt=0.0, le=1000.0,
                                   why="positive; beyond 1000 two ships kilometres apart merge")
    max_components: int = param(100, "at most this many components after pruning and merging (Vo & Ma's "
                                     "J_max)", ge=10, le=10_000,
                                why="10 holds a few targets and their births; 10 000 stalls Stone Soup")
    gate_probability: float = gate_probability_param()
    alpha: float = alpha_param()
    beta: float = beta_param()
    kappa: float = kappa_param()
    max_tracks: int = param(512, "output slots per trial (extracted components with their own identity at "
                                 "one scan); one more extracted at once is dropped", ge=8, le=8192,
                            why="8 slots at least; 8192 slots of (K, slots) outputs per trial stay in memory")


@register_method
class StoneSoupGmPhd(StoneSoupPeer):
    r"""Stone Soup's GM-PHD filter (PHDUpdater, GaussianMixtureReducer) with the UKF and labelled components, as a tracker (peer of jpda-ukf; extra [peers]).

    The Gaussian-mixture PHD filter of Vo & Ma, "The Gaussian mixture
    probability hypothesis density filter" (IEEE Trans. Signal Processing 54(11),
    2006), with the component labels of Clark, Panta & Vo, "The GM-PHD filter
    multiple target tracker" (FUSION 2006) as identities, all from Stone Soup:
    the scene's CV transition and range / azimuth / radial velocity
    measurement (:class:`methods.multitarget.stonesoup_peer.HFSWRMeasurement`) under
    ``UnscentedKalmanPredictor`` / ``UnscentedKalmanUpdater`` (the same $\alpha$, $\beta$, $\kappa$
    as ``jpda-ukf``), ``GaussianMixtureHypothesiser`` over a
    ``DistanceHypothesiser`` (Mahalanobis gate $\sqrt{\gamma}$, $\gamma$ the $\chi^2(3)$ quantile of
    $P_G$), ``PHDUpdater`` (or ``LCCUpdater``) with the scene's $P_D$ and clutter
    density $\lambda$ and the parameter $P_S$, and ``GaussianMixtureReducer`` (prune,
    merge, cap). The scan loop is that of Stone Soup's
    ``PointProcessMultiTargetTracker.__next__`` with one change: its single
    static birth component cannot cover a 100 km sector in polar coordinates
    with a UKF, so the birth intensity is measurement-driven (after Ristic,
    Clark, Vo & Vo, "Adaptive target birth intensity for PHD and CPHD filters",
    IEEE Trans. AES 48(2), 2012): one component per plot of the last scan that
    no extracted component's gate held, its position the plot's and velocity
    the radial velocity along the line of sight with a $\mathcal{N}(0, v_{\max}^2)$ prior per
    axis — Stone Soup's ``MultiMeasurementInitiator`` prior of the JPDA peer —
    each weighted ``birth_rate`` / (number of such plots).
    With ``births = "adaptive"`` (the default) every plot $z$ of the last scan
    is a birth, weighted ``birth_rate`` $\times\, (1 - \rho(z)) / \sum (1 - \rho)$, $\rho(z)$ the
    updated weight of the mixture's own components on $z$, the probability that
    $z$ came from a target already in the mixture (Ristic et al. 2012's
    measurement-driven birth): a plot a tentative component explains gives
    little birth mass, an unexplained one most of it. The birth rate is the
    same at every scan and set without the scene's arrivals, so targets may
    appear anywhere and at any scan.

    Outputs: at each scan, every component whose weight exceeds
    ``extraction_threshold`` is a confirmed track (2) identified by its label
    (two components sharing a label after an update: the heavier one); a
    label that stops being extracted frees its slot and keeps its identity
    should it return. Per trial and scan in Python objects, like
    ``stonesoup-jpda``.
    """

    name = "stonesoup-gmphd"
    Params = GmPhdParams

    def check_scenario(self, params, scenario_params) -> str | None:
        if params.cardinality == "lcc" and getattr(scenario_params, "clutter_per_scan", None) == 0:
            return ("cardinality = 'lcc' needs clutter: Stone Soup's LCCUpdater divides by the clutter "
                    "count's mean and variance, 0 without clutter")
        return None

    def _components(self, scene, params):
        T = float(scene.scan_period_s)
        R = np.diag(np.asarray(scene.measurement_std, float) ** 2)
        measurement, predictor, ukf = ukf_parts(scene, cv_transition(T), cv_process_noise(T, scene.accel_std_m_s2),
                                                R, params)
        gate = math.sqrt(float(scipy.stats.chi2.ppf(params.gate_probability, 3)))
        hypothesiser = GaussianMixtureHypothesiser(DistanceHypothesiser(predictor, ukf, Mahalanobis(),
                                                                        missed_distance=gate),
                                                   order_by_detection=True)
        density = max(float(scene.clutter_density), LAMBDA_FLOOR)
        common = dict(updater=ukf, clutter_spatial_density=density, prob_detection=scene.pd,
                      prob_survival=params.survival_probability)
        if params.cardinality == "lcc":
            common.update(mean_number_of_false_alarms=scene.clutter_per_scan,
                          variance_of_false_alarms=scene.clutter_per_scan)
        updater = UPDATERS[params.cardinality](**common)
        reducer = GaussianMixtureReducer(prune_threshold=params.prune_threshold,
                                         merge_threshold=params.merge_threshold,
                                         max_number_components=params.max_components)
        return measurement, hypothesiser, updater, reducer

    def _trial(self, z, n_plots, scene, params, K):
        measurement, hypothesiser, updater, reducer = self._components(scene, params)
        start = datetime.datetime(2000, 1, 1)
        buf = TrialBuffers.empty(K, params.max_tracks)
        slots = _Slots(params.max_tracks)
        vmax = float(scene.speed_bounds_m_s[1])
        mixture, births = [], []
        for k in range(K):
            when = start + datetime.timedelta(seconds=k * float(scene.scan_period_s))
            plots = [Detection(StateVector(p), timestamp=when, measurement_model=measurement)
                     for p in z[k, :int(n_plots[k])]]
            hypotheses = hypothesiser.hypothesise(mixture + births, plots, when)
            updated = list(updater.update(hypotheses).components)
            spread = _birth_weights(params, plots, hypotheses, updated)     # before the reducer merges
            mixture = sorted(reducer.reduce(updated), key=_component_key)
            extracted = _heaviest_per_label(mixture, params.extraction_threshold)
            for label, component in extracted.items():
                slots.record(buf, k, label, kern.CONFIRMED, component)
            slots.release_missing(set(extracted))
            births = [_birth(measurement, p, w, vmax) for p, w in spread if w > params.prune_threshold]
        return buf, slots.used


def _birth_weights(params, plots, hypotheses, updated) -> list:
    """(plot, birth weight) for the next scan, as ``params.births`` says."""
    if params.births == "unheld":
        unheld = _plots_no_extracted_gate_held(hypotheses[:-1], plots, params.extraction_threshold)
        return [(p, params.birth_rate / len(unheld)) for p in unheld]
    free = 1.0 - np.clip(_persistent_share(hypotheses[:-1], updated), 0.0, 1.0)
    total = float(free.sum())
    return [(p, params.birth_rate * f / total) for p, f in zip(plots, free)] if total > 0 else []


def _persistent_share(per_plot, updated) -> np.ndarray:
    """ρ(z) per plot: the summed updated weight of the mixture's own components (not this
    scan's births) on each plot. Stone Soup's point-process updater appends, plot by plot in
    hypothesis order, one component per single hypothesis (its missed-detection terms after);
    an updated component keeps its prediction's tag, which checks the alignment."""
    rho, offset = np.zeros(len(per_plot)), 0
    for i, multi in enumerate(per_plot):
        for h in multi:
            tag = h.prediction.tag
            if tag not in (None, TaggedWeightedGaussianState.BIRTH):
                if updated[offset].tag != tag:
                    raise RuntimeError("Stone Soup's updater no longer lists components plot by plot")
                rho[i] += float(updated[offset].weight)
            offset += 1
    return rho


def _component_key(c):
    """A deterministic order for the mixture (Stone Soup's reducer orders duplicate
    labels through a set): heavier first, then by state."""
    return -float(c.weight), tuple(np.asarray(c.state_vector, float).ravel())


def _heaviest_per_label(mixture, threshold: float) -> dict:
    """label -> the heaviest component of that label whose weight exceeds ``threshold``, in mixture order."""
    out: dict = {}
    for c in mixture:                    # heaviest first (:func:`_component_key`)
        if float(c.weight) > threshold and c.tag not in out:
            out[c.tag] = c
    return out


def _plots_no_extracted_gate_held(per_plot, plots, threshold: float) -> list:
    """The plots whose hypotheses (one ``MultipleHypothesis`` per plot, in plot order)
    include no component that was extracted at the last scan (prior weight above ``threshold``)."""
    return [p for p, multi in zip(plots, per_plot)
            if not any(h.prediction.tag != TaggedWeightedGaussianState.BIRTH and float(h.prediction.weight) > threshold
                       for h in multi)]


def _birth(measurement, plot, weight: float, vmax: float):
    """A birth component at ``plot``: position and line-of-sight velocity from the
    plot (``HFSWRMeasurement.inverse_function``), position covariance J R J' of the
    polar-to-Cartesian map, a N(0, v_max²) velocity prior per axis."""
    x = measurement.inverse_function(plot)
    r, az = float(plot.state_vector[0, 0]), float(plot.state_vector[1, 0])
    J = np.array([[math.sin(az), r * math.cos(az)], [math.cos(az), -r * math.sin(az)]])   # d(x, y)/d(r, az)
    P = np.zeros((4, 4))
    P[np.ix_((0, 2), (0, 2))] = J @ measurement.noise_covar[:2, :2] @ J.T
    P[1, 1] = P[3, 3] = vmax ** 2
    return TaggedWeightedGaussianState(x, P, weight=weight, tag=TaggedWeightedGaussianState.BIRTH,
                                       timestamp=plot.timestamp)
