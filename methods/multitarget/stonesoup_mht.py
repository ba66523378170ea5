"""Method ``stonesoup-mfa``: Stone Soup's multi-frame assignment (a track-oriented MHT
with N-scan pruning) as a peer of ``jpda-ukf``.

Needs the ``[peers]`` extra (``pip install -e ".[peers]"``: Stone Soup ≥ 1.4 and
OR-Tools, whose SCIP solver Stone Soup's MFA calls for its primal solutions);
without it ``bench list`` shows the method as unavailable with the reason
(bench/registry.py; docs/architecture.md, 'Plugins').
"""

from __future__ import annotations

from dataclasses import dataclass

from radarbench.bench.registry import PluginError

try:
    from stonesoup.dataassociator.mfa import MFADataAssociator   # imports OR-Tools
    from stonesoup.hypothesiser.mfa import MFAHypothesiser
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.types.mixture import GaussianMixture
    from stonesoup.types.numeric import Probability
    from stonesoup.types.state import TaggedWeightedGaussianState
    from stonesoup.types.update import GaussianMixtureUpdate
except ImportError as exc:     # the [peers] extra is missing: the method is unavailable, named, with the reason
    raise PluginError(f'needs the [peers] extra (pip install -e ".[peers]"): {exc}', name="stonesoup-mfa") from exc

from radarbench.bench.params import param  # noqa: E402 - after the guarded imports
from radarbench.bench.registry import register_method  # noqa: E402
from radarbench.methods.multitarget.track_management import LAMBDA_FLOOR, TrackerParams  # noqa: E402
from radarbench.methods.multitarget.stonesoup_peer import InitiatedPeer  # noqa: E402


@dataclass(frozen=True)
class MfaParams(TrackerParams):
    """``stonesoup-jpda``'s parameters (initiation, termination, gate, UKF, output
    slots) and the MHT's window and hypothesis limit."""

    slide_window: int = param(3, "W: scans in the multi-frame assignment's sliding window; a track's "
                                 "association W - 1 scans back is fixed to that of the best global "
                                 "hypothesis (N-scan pruning, Stone Soup's MFA example's 3); 1: the "
                                 "single-scan assignment", ge=1, le=8,
                              why="1 is the single-scan assignment; each scan of window multiplies a "
                                  "track's hypotheses by its gated plots, and Stone Soup builds the "
                                  "assignment's constraint matrix densely over all of them")
    max_hypotheses: int = param(100, "at most this many hypotheses (mixture components) per track after "
                                    "each scan's update, the heaviest kept (k-best pruning)", ge=1, le=1000,
                                why="1 keeps only each track's best branch; above 1000 one track's "
                                    "hypotheses cost Stone Soup seconds per scan")


@register_method
class StoneSoupMfa(InitiatedPeer):
    r"""Stone Soup's multi-frame assignment MHT (MFADataAssociator, MFAHypothesiser) with the UKF and MultiMeasurementInitiator (peer of jpda-ukf; extra [peers]).

    A track-oriented multiple hypothesis tracker: each confirmed track holds
    a tree of hypotheses (its Gaussian-mixture components, tagged with the
    plot index each one took at each scan, 0 for a miss), and the global
    hypothesis over the last $W$ scans (``slide_window``) is the assignment of
    one leaf per track, every plot used at most once per scan, of least
    total cost. It is Stone Soup's ``MFADataAssociator``, the multi-scan
    assignment of Xia, Granström, Svensson, García-Fernández & Williams,
    "Multiscan implementation of the trajectory Poisson multi-Bernoulli
    mixture filter" (J. Adv. Information Fusion 14(2), 2019): the
    $W$-dimensional assignment is relaxed by Lagrange multipliers into $W$
    single-scan assignments (``linear_sum_assignment``), the multipliers move
    by subgradient steps, and where the single-scan solutions disagree a
    primal solution is completed by an integer programme (SCIP through
    OR-Tools), until they agree, the duality gap is small or the primal cost
    stops falling (Stone Soup's limits, at most 10 iterations); then every
    hypothesis whose association $W - 1$ scans back differs from the
    best global hypothesis's is pruned (N-scan pruning). Stone Soup's other
    MHT-family tracker, ``PMHTTracker`` (Streit & Luginbuhl's probabilistic
    MHT), is not used: it keeps a fixed number of targets from given priors
    (no track birth) and assigns plots softly by EM over a batch, so it is
    neither track-oriented nor able to follow ships that appear and leave.
    At this preset's scale (6 ships, up to 30 clutter plots per scan, small
    gates) the hypotheses per track stay few with $W = 3$, bounded anyway by
    ``max_hypotheses``.

    The scan, in the order of the code (:class:`methods.multitarget.stonesoup_peer.InitiatedPeer`):

    1. each component of each confirmed track is predicted by the UKF and
       hypothesised against every plot by ``PDAHypothesiser`` with
       ``normalise=False``, so a hypothesis' weight is the track-score
       likelihood ratio of track-oriented MHT (Blackman, "Multiple hypothesis
       tracking for multiple target tracking", IEEE AESM 19(1), 2004):
       $1 - P_D P_G$ for a miss, $P_D\, \mathcal{N}(z; \hat{z}, S) / \lambda$ for a plot inside the gate
       ($\gamma$ the $\chi^2(3)$ quantile of $P_G$). ``MFAHypothesiser`` multiplies it by the
       component's weight and appends the plot's index to the tag;
    2. ``MFADataAssociator`` solves the window's assignment with cost
       $-\log(\text{weight})$ per leaf and a cost 0 for a plot being clutter, and
       returns each track's hypotheses that survive N-scan pruning;
    3. :meth:`_update`: the ``max_hypotheses`` heaviest survivors are updated by
       the UKF (a miss keeps its prediction) and form the track's new mixture;
    4. a track's estimate is its heaviest component (its most likely
       hypothesis); the termination rules of ``jpda-ukf`` (a miss: no plot in
       any component's gate; the position std; the speed) run on it;
    5. the plots no confirmed track's gate held go to ``MultiMeasurementInitiator``
       exactly as in ``stonesoup-jpda`` (:class:`methods.multitarget.stonesoup_peer.InitiatedPeer`);
       a holding track it confirms starts a one-component mixture at its
       last state (:meth:`_adopt`), so its hypothesis tree starts there.

    The same models, UKF ($\alpha$, $\beta$, $\kappa$), gate probability, initiator and
    termination as ``stonesoup-jpda``, so the two peers differ in the
    association alone (JPDA's soft single-scan update against the MHT's hard
    multi-scan decision). Parameters read by our own trackers alone
    (``init_gate_sigmas``, ``initial_velocity``, ``max_cluster_size``) are not
    read here, as in ``stonesoup-jpda``. Per trial and scan in Python objects.
    """

    name = "stonesoup-mfa"
    Params = MfaParams

    def _associator(self, scene, params, predictor, updater):
        likelihood_ratio = PDAHypothesiser(predictor, updater,
                                           clutter_spatial_density=max(scene.clutter_density, LAMBDA_FLOOR),
                                           prob_detect=scene.pd, prob_gate=params.gate_probability,
                                           normalise=False)
        return MFADataAssociator(MFAHypothesiser(likelihood_ratio), slide_window=params.slide_window)

    def _update(self, track, multi, when, updater, params) -> None:
        """Step 3: the heaviest ``max_hypotheses`` hypotheses, updated, are the track's mixture."""
        # weights compared as Stone Soup's log-domain Probability; a stable sort: ties stay in plot order
        kept = sorted(multi, key=lambda h: h.prediction.weight, reverse=True)[:params.max_hypotheses]
        components = [updater.update(h) if h else h.prediction for h in kept]
        track.append(GaussianMixtureUpdate(components=components, hypothesis=multi))

    def _adopt(self, track) -> None:
        """Step 5: a confirmed holding track's last state becomes the root of its hypothesis tree."""
        last = track.state
        track.append(GaussianMixture([TaggedWeightedGaussianState(last.state_vector, last.covar,
                                                                  timestamp=last.timestamp,
                                                                  weight=Probability(1.0), tag=[])]))

    def _estimate(self, track):
        """Step 4: the track's most likely hypothesis (its heaviest component)."""
        return max(track.state.components, key=lambda c: c.weight)
