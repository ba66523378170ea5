"""Methods ``jpda-ukf`` and ``gnn-ekf``: multi-target trackers in range, azimuth and radial velocity."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import scipy.optimize

from radarbench.bench.core import Batch, Method
from radarbench.bench.registry import register_method
from radarbench.bench.tasks.multitarget import MULTI_TARGET, MultiTargetOutput
from radarbench.methods.multitarget import kernels as kern
from radarbench.methods.multitarget.track_management import (
    CONFIRMATIONS,
    FILTERS,
    EkfTrackerParams,
    TrialBuffers,
    UkfTrackerParams,
    assemble,
    check_speed_bound,
    scene_of,
    trace_of,
    tracker_models,
)

#: GNN's cost of leaving a track unassigned: above any gated statistical distance (γ < 50 for P_G <= 1 - 1e-6)
_UNGATED_COST = 1e6


class _MultiTargetTracker(Method):
    """What the trackers share: the parameters, the scenario checks, the trace."""

    task = MULTI_TARGET

    #: per-trial counters of the last :meth:`run` (``methods.multitarget.kernels.COUNTER_NAMES``)
    last_trace: dict[str, np.ndarray] | None = None

    def check_scenario(self, params, scenario_params) -> str | None:
        return check_speed_bound(params, scenario_params)

    def least_cost(self, batch: Batch, params, output) -> str:
        return ("gating, clusters and joint events follow the scene's plots and tracks: no floor of bytes or "
                "add/max operations holds apart from the algorithm's own branching")

    def run(self, batch: Batch, params) -> MultiTargetOutput:
        scene = scene_of(batch)
        models = tracker_models(scene, params, FILTERS[params.filter], CONFIRMATIONS[params.confirmation])
        n, K, P = batch.z.shape[:3]
        trials, slots = [], []
        counters = np.zeros((n, kern.N_COUNTERS), np.int64)
        z = np.ascontiguousarray(batch.z, dtype=np.float64)
        n_plots = np.ascontiguousarray(scene.n_plots, dtype=np.int64)
        buf = TrialBuffers.empty(K, params.max_tracks)     # the working buffer, emptied after each trial
        for i in range(n):                          # one compiled trial each (docs/architecture.md, 'Performance')
            tab = kern.new_table(params.max_tracks, P)
            self.track_trial(z[i], n_plots[i], models, tab, buf)
            counters[i] = tab.counters
            slots.append(int(tab.counters[kern.K_SLOTS]))
            trials.append(buf.take(slots[-1]))
        self.last_trace = trace_of(counters)
        return assemble(trials, slots)

    def track_trial(self, z, n_plots, models, tab, buf) -> None:
        raise NotImplementedError


@register_method
class JpdaUkf(_MultiTargetTracker):
    r"""JPDA with a UKF, M/N initiation and three termination rules (the HFSWR tracking chapter's chain).

    After "目标检测与跟踪方法 (Target detection and tracking methods),
    海洋遥感技术应用", section 2(2): M/N track initiation (every unassociated plot
    a track head, a speed-and-noise gate, two plots initialise a UKF, M/N
    confirmation at frame N + 2), maintenance by JPDA (validation matrix,
    feasible joint events, Poisson clutter of density $\lambda$, marginal association
    probabilities weighting the UKF updates, eqs. 6.72–6.74) and a UKF
    (eqs. 6.75 onwards; :mod:`models.ukf`), termination when $M_t$ of the last
    $N_t$ frames have no plot, when the position covariance exceeds a bound, or
    when the speed is impossible. The scan loop, step by step:
    :mod:`methods.multitarget.kernels`; the joint events: :mod:`methods.multitarget.jpda`
    (exact up to ``max_cluster_size`` tracks × plots, per-track PDA beyond,
    counted in ``last_trace["pda_fallback_clusters"]``).

    The tracker is told what a scenario's scene states: $P_D$, $\lambda$, the noise
    stds, the scan period, the sensor, the targets' speed bounds and process
    noise (docs/architecture.md, 'Scenes'). Every trial runs as one compiled
    call; the outputs hold tentative (1), confirmed (2) and terminated (3)
    tracks, $J$ = the most table slots a trial of the batch used.

    Our ablations, not the chapter's: ``filter = "ekf"`` is JPDA with the EKF
    of ``gnn-ekf`` (association and filter then separate against
    ``gnn-ekf`` with ``filter = "ukf"``); ``confirmation = "kth-plot"``
    confirms on the $(M + 2)$-th plot with no frame deadline, the rule of
    Stone Soup's ``MultiMeasurementInitiator``.
    """

    name = "jpda-ukf"
    Params = UkfTrackerParams
    reference_name = "Stone Soup JPDA + UnscentedKalmanUpdater + MultiMeasurementInitiator (stonesoup-jpda)"
    reference_trials = 2
    #: the peer's initiator timed apart: a second ``bench perf`` row of its JPDA + UKF alone
    #: against our whole tracker (initiation included), so the speed-up is not an initiator's
    reference_parts: ClassVar[dict] = {"initiation": "MultiMeasurementInitiator"}
    #: the issue's goal: at least 20 times the Stone Soup peer's throughput
    perf_targets: ClassVar[dict] = {"*": {"speedup": 20.0}}

    def track_trial(self, z, n_plots, models, tab, buf) -> None:
        kern.jpda_trial(z, n_plots, models.F, models.Q, models.R, models.Wm, models.Wc, models.cfg, models.icfg,
                        tab, buf.state, buf.track_id, buf.status, buf.cov)

    def reference_run(self, batch: Batch, params) -> MultiTargetOutput:
        """The Stone Soup peer on the same batch with the same parameters
        (``bench perf``'s baseline; :mod:`methods.multitarget.stonesoup_peer`), the CPU
        seconds of its initiator in :attr:`reference_part_seconds`."""
        from radarbench.methods.multitarget.stonesoup_peer import StoneSoupJpda

        peer = StoneSoupJpda()
        out = peer.run(batch, params)
        self.reference_part_seconds = {"initiation": peer.initiation_seconds}
        return out


@register_method
class GnnEkf(_MultiTargetTracker):
    r"""Global nearest neighbour (linear_sum_assignment on the gated statistical distance) with an EKF; the same initiation and termination.

    The baseline of ``jpda-ukf``: the same scan loop (:mod:`methods.multitarget.kernels`)
    with an EKF ($H = \partial h / \partial x$ of :func:`models.hfswr.measure_jacobian` at the
    prediction) and, at each association stage (confirmed tracks, then
    tentative ones on the plots left), the assignment of plots to tracks that
    minimises the sum of squared statistical distances $\nu' S^{-1} \nu$ over the gated
    pairs (``scipy.optimize.linear_sum_assignment``; an ungated pair costs more
    than leaving the track without a plot). The assignment runs in Python
    between two compiled calls per stage and scan. ``filter = "ukf"`` (our
    ablation) is GNN with the UKF of ``jpda-ukf``; ``confirmation`` as there.
    """

    name = "gnn-ekf"
    Params = EkfTrackerParams

    def track_trial(self, z, n_plots, models, tab, buf) -> None:
        kern.reset_table(tab)
        cfg, icfg = models.cfg, models.icfg
        for k in range(z.shape[0]):
            m = int(n_plots[k])
            zk = z[k]
            free = np.ones(m, np.bool_)
            kern.predict_all(tab, models.F, models.Q, models.R, models.Wm, models.Wc, cfg, icfg)
            for stage in (kern.CONFIRMED, kern.TENTATIVE):
                slots, plots, d2 = kern.stage_gate(tab, stage, zk, m, free, models.gamma)
                kern.apply_assignment(tab, slots, plots, gnn_assignment(d2), zk, free)
            kern.manage(tab, cfg, icfg)
            kern.initiate(tab, zk, m, free, cfg, icfg)
            kern.record(tab, k, buf.state, buf.track_id, buf.status, buf.cov)


def gnn_assignment(d2: np.ndarray) -> np.ndarray:
    """Per track (row of ``d2`` (t, m), +inf outside the gate): the plot column
    assigned by ``linear_sum_assignment`` on the gated distances, −1 for none."""
    assigned = np.full(d2.shape[0], -1, np.int64)
    if d2.size == 0:
        return assigned
    cost = np.where(np.isfinite(d2), d2, _UNGATED_COST)
    rows, cols = scipy.optimize.linear_sum_assignment(cost)
    ok = np.isfinite(d2[rows, cols])
    assigned[rows[ok]] = cols[ok]
    return assigned
