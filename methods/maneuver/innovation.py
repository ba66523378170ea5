"""Method ``innovation``: the chi-square test on the normalised innovation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal
import scipy.stats

from radarbench.bench.core import Batch, DetectionOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.models.windows import sliding_sum
from radarbench.methods.maneuver.base import MAX_WINDOW_STEPS, InnovationDetector, steps_problem
from radarbench.models.kalman import InnovationSequence

#: the fading-memory statistic counts as formed once the weight of the
#: missing (pre-start) past is below this fraction of its steady total
FADING_SETTLE = 0.01
#: the largest fading-memory factor: the statistic settles after 4 603 steps
MAX_DELTA = 0.999


def fading_sum(x: np.ndarray, delta: float) -> np.ndarray:
    """e_k = delta e_{k-1} + x_k along axis 1, with e_{-1} = 0."""
    return scipy.signal.lfilter([1.0], [1.0, -delta], x, axis=1)


def fading_valid_from(delta: float) -> int:
    """First step k at which the missing tail weight delta^(k+1) of the
    fading sum (started at zero) is below :data:`FADING_SETTLE`, i.e. its
    mean is within 1% of the steady value n_z / (1 - delta)."""
    k = 0
    while delta ** (k + 1) >= FADING_SETTLE:
        k += 1
    return k


@register_method
class Innovation(InnovationDetector):
    r"""Normalised innovation squared (NIS) chi-square test, sliding-window or fading-memory.

    Bar-Shalom, Li & Kirubarajan (2001), sec. 11.2.2. For the scenario's
    reference filter (:func:`models.kalman.innovations`),
    $\epsilon_k = \nu_k' S_k^{-1} \nu_k \sim \chi^2(n_z)$ under a matched model, and the
    innovations are white, so:

    * sliding window (``delta = 0``): the sum of the last $s$ = ``window`` values,
      $\sim \chi^2(s\, n_z)$. Before the window fills the partial sum is reported;
      ``valid_from = window - 1``.
    * fading memory (``delta > 0``, ``window = 1``): $e_k = \delta e_{k-1} + \epsilon_k$,
      mean $n_z / (1 - \delta)$, variance $2 n_z / (1 - \delta^2)$. The nominal
      threshold uses the moment match $(1 + \delta)\, e \sim \chi^2\left(n_z \frac{1 + \delta}{1 - \delta}\right)$,
      which is approximate (its false-alarm rate runs above
      nominal; calibrate empirically). ``valid_from`` is the first step at
      which $\delta^{k+1} < 0.01$ (the start-up deficit of the mean is < 1%).

    Alarms of window statistics are correlated in time: the per-step Pfa is
    not the inverse of the mean run length.
    """

    name = "innovation"

    @dataclass(frozen=True)
    class Params:
        window: int = param(5, "sliding-window length s (steps); 1 with fading memory", ge=1,
                            le=MAX_WINDOW_STEPS, why="at most the longest scene (10 000 steps), and at "
                            "most the scenario's steps (checked per scenario config)")
        delta: float = param(
            0.0, "fading-memory factor (dimensionless); 0 selects the sliding "
            "window, > 0 the statistic e_k = delta e_(k-1) + eps_k (needs window = 1)",
            ge=0.0, le=MAX_DELTA, why="the statistic is formed once delta^(k+1) < 0.01: 4 603 steps "
                                      "at 0.999, beyond any scene above it (and the scenario's steps "
                                      "must exceed it, checked per scenario config)")

        def validate(self) -> None:
            if self.delta > 0.0 and self.window != 1:
                raise ConfigError("delta", "the fading-memory statistic (delta > 0) "
                                  f"needs window = 1, got window = {self.window}")

    def detect(self, batch: Batch, inn: InnovationSequence, params) -> DetectionOutput:
        nis = inn.nis
        statistic = fading_sum(nis, params.delta) if params.delta > 0.0 else sliding_sum(nis, params.window)
        return DetectionOutput(statistic=statistic, valid_from=self.valid_from(params, batch.steps),
                               traces={"nis": nis})

    def valid_from(self, params, steps: int) -> int:
        """Once the fading sum's start-up deficit is below 1%, or the sliding window is full."""
        return fading_valid_from(params.delta) if params.delta > 0.0 else params.window - 1

    def nominal_threshold(self, params, pfa: float, batch: Batch) -> float:
        """chi2 upper quantiles by the survival-function inverse, ``isf(pfa)``
        (``ppf(1 - pfa)`` loses pfa below 1e-16 to rounding and gives inf)."""
        n_z = self.measurement_dim(batch)
        if params.delta > 0.0:
            d = params.delta
            df = n_z * (1.0 + d) / (1.0 - d)          # moment match, approximate
            return float(scipy.stats.chi2.isf(pfa, df) / (1.0 + d))
        return float(scipy.stats.chi2.isf(pfa, params.window * n_z))

    def check_scenario(self, params, scenario_params) -> str | None:
        if params.delta > 0.0:
            return steps_problem(fading_valid_from(params.delta), f"the fading-memory statistic "
                                 f"(delta = {params.delta:g})", scenario_params)
        return steps_problem(params.window - 1, f"the window of {params.window} steps", scenario_params)
