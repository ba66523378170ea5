"""The base of the maneuver detectors that test the innovation of the
scenario's reference linear Kalman filter (``innovation``, ``cumulant``,
``wavelet``).

Under a matched model the innovations nu_k of a linear-Gaussian filter are
white, N(0, S_k), and the whitened L_k^-1 nu_k (S_k = L_k L_k') i.i.d.
N(0, I); a maneuver shows as a departure from that (Bar-Shalom, Li &
Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001,
sec. 5.4 and 11.2). Each detector computes its statistic from the innovations
of the detection scene's ``reference_filter`` (docs/architecture.md,
'Scenes'); what they share, written once here, is their task, where the
innovations come from and how ``bench perf`` measures them.
"""

from __future__ import annotations

import dataclasses
import math

from radarbench.bench.core import MANEUVER_DETECTION, Batch, DetectionOutput, Method
from radarbench.models.kalman import InnovationSequence, LinearGaussianFilter, innovations, reference_innovations

#: why a Kalman filter's run has no model of its least cost (``Method.least_cost``, ``bench perf``)
KALMAN_RECURSION = ("a Kalman recursion: its least work is multiply-adds of small matrices step after step, "
                    "which neither the streaming copy nor the add/max loop measures")


def reference_filter(batch: Batch) -> LinearGaussianFilter:
    """The scene's reference filter; TypeError, naming the field, when the
    scenario gave none (or something else)."""
    filt = getattr(batch.scene, "reference_filter", None)
    if not isinstance(filt, LinearGaussianFilter):
        raise TypeError(f"{type(batch.scene).__name__}.reference_filter: the innovation detectors need a "
                        f"models.kalman.LinearGaussianFilter, got {type(filt).__name__}")
    return filt

#: the longest detector window (steps): the longest scene a built-in detection scenario
#: generates (``cv-turn-cv`` ``steps`` <= 10 000)
MAX_WINDOW_STEPS = 10_000


def sidak_level(pfa: float, k: int) -> float:
    """1 - (1 - pfa)^(1/k): the level of each of k independent tests whose
    maximum has level ``pfa`` (Sidak), as -expm1(log1p(-pfa) / k), which does
    not cancel for small pfa; pfa / k (its first-order value) where that
    underflows to 0, so a threshold from it is always finite."""
    level = -math.expm1(math.log1p(-pfa) / k)
    return level if level > 0.0 else pfa / k


def steps_problem(first_valid: int, what: str, scenario_params) -> str | None:
    """None if a statistic first formed at step ``first_valid`` leaves null steps in a scene
    of the scenario's ``steps`` (read by name; unknown: not checked), else the reason: with
    none, calibration has no null value and every unit fails."""
    steps = getattr(scenario_params, "steps", None)
    if isinstance(steps, int) and first_valid >= steps:
        return f"{what} first forms at step {first_valid}, but the scenario has {steps} steps"
    return None


class InnovationDetector(Method):
    """A maneuver detector on the scenario's reference-filter innovations
    (the scene's ``reference_filter``, see :func:`models.kalman.innovations`).
    Subclasses implement :meth:`detect`.

    Reference implementation (``bench perf``): the same detector with the
    innovations computed by a per-trial, per-step filterpy ``KalmanFilter``
    loop (:func:`models.kalman.reference_innovations`) instead of the batched
    filter: the speed-up is that of the batching.
    """

    task = MANEUVER_DETECTION
    #: the scene's reference filter; a ragged batch (``valid-step-masks``) is not handled: the
    #: detectors' windows and statistics assume every step of every trial
    needs = frozenset({"reference-filter"})
    reference_name = "same detector, per-trial filterpy KalmanFilter loop"
    #: the filterpy loop is a Python loop per trial and step: a hundred trials time it well enough
    reference_trials = 100
    #: the batched filter should beat the per-trial loop fifty-fold, at every size
    perf_targets = {"*": {"speedup": 50.0}}

    def least_cost(self, batch: Batch, params, output) -> str:
        return KALMAN_RECURSION

    def run(self, batch: Batch, params) -> DetectionOutput:
        return self.detect(batch, innovations(reference_filter(batch), batch.z), params)

    def reference_run(self, batch: Batch, params) -> DetectionOutput:
        """:meth:`detect` on innovations from the filterpy loop."""
        return self.detect(batch, reference_innovations(reference_filter(batch), batch.z), params)

    def detect(self, batch: Batch, inn: InnovationSequence, params) -> DetectionOutput:
        """The detector's output from the innovations ``inn`` of ``batch``."""
        raise NotImplementedError

    @staticmethod
    def measurement_dim(batch: Batch) -> int:
        """n_z, the size of the reference filter's measurement (and innovation)."""
        return reference_filter(batch).dim_z
