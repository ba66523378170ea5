"""The base of the maneuver detectors that test the innovation of the
scenario's reference linear Kalman filter (``innovation``, ``cumulant``,
``wavelet``).

Under a matched model the innovations nu_k of a linear-Gaussian filter are
white, N(0, S_k), and the whitened L_k^-1 nu_k (S_k = L_k L_k') i.i.d.
N(0, I); a maneuver shows as a departure from that (Bar-Shalom, Li &
Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001,
sec. 5.4 and 11.2). Each detector computes its statistic from
:func:`models.kalman.innovations` of the batch; what they share, written once
here, is their task and how ``bench perf`` measures them.
"""

from __future__ import annotations

import dataclasses

from bench.core import MANEUVER_DETECTION, Batch, DetectionOutput, Method


class InnovationDetector(Method):
    """A maneuver detector on the scenario's reference-filter innovations
    (``batch.meta["filter"]``, see :func:`models.kalman.innovations`).

    Reference implementation (``bench perf``): the same detector with the
    innovations computed by a per-trial, per-step filterpy ``KalmanFilter``
    loop instead of the batched filter: the speed-up is that of the batching.
    """

    task = MANEUVER_DETECTION
    reference_name = "same detector, per-trial filterpy KalmanFilter loop"
    #: the filterpy loop is a Python loop per trial and step: a hundred trials time it well enough
    reference_trials = 100
    #: the batched filter should beat the per-trial loop fifty-fold, at every size
    perf_targets = {"*": {"speedup": 50.0}}

    def reference_run(self, batch: Batch, params) -> DetectionOutput:
        """:meth:`run` on innovations from the filterpy loop
        (``meta["kalman_backend"] = "filterpy"``, honoured by
        :func:`models.kalman.innovations`); ``batch`` itself is not modified."""
        on_filterpy = dataclasses.replace(batch, meta={**batch.meta, "kalman_backend": "filterpy"})
        return self.run(on_filterpy, params)
