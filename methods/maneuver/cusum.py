"""Method ``cusum``: Page's cumulative sum on the NIS or on the GLR statistic."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import Batch, DetectionOutput
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.maneuver.base import InnovationDetector
from radarbench.methods.maneuver.glr import JUMPS, MAX_GLR_WINDOW, Glr
from radarbench.models.kalman import InnovationSequence

#: the per-step scores the sum accumulates
SCORES = ("nis", "glr")
#: the largest drift: far above any score of a plausible scene, where g stays at zero
MAX_DRIFT = 1e4


def page_cusum(score: np.ndarray, drift: float) -> np.ndarray:
    """Page (1954), "Continuous inspection schemes", Biometrika 41:
    g_t = max(0, g_(t-1) + s_t - drift), g_(-1) = 0, along axis 1 of ``score`` (n, K).
    Sequential in time: a loop over steps, every trial at once."""
    g = np.zeros_like(score, dtype=float)
    previous = np.zeros(score.shape[0])
    for k in range(score.shape[1]):
        previous = g[:, k] = np.maximum(0.0, previous + score[:, k] - drift)
    return g


def reference_cusum(score: np.ndarray, drift: float) -> np.ndarray:
    """The same recursion one trial and one step at a time, in plain Python floats
    (the oracle of the tests; ``bench perf``'s reference runs :func:`page_cusum`, the
    recursion as a NumPy user writes it, on the filterpy loop's score)."""
    g = np.zeros(score.shape)
    for i, row in enumerate(score.tolist()):
        value = 0.0
        for k, s in enumerate(row):
            value = max(0.0, value + s - drift)
            g[i, k] = value
    return g


@register_method
class Cusum(InnovationDetector):
    r"""Page's CUSUM on the normalised innovation squared (NIS) or on the GLR statistic, drift a parameter.

    Page (1954), "Continuous inspection schemes", Biometrika 41; for maneuvers,
    Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
    Navigation* (2001), sec. 11.2. The score $s_t$ is the NIS
    $\nu_t' S_t^{-1} \nu_t$ of the scenario's reference filter (``score = "nis"``,
    $\chi^2(n_z)$ under a matched model, mean $n_z$) or the GLR statistic $l(t)$ of
    :class:`methods.maneuver.glr.Glr` (``score = "glr"``, with its ``window`` and
    ``jump``), and, with the drift $\delta$ (``drift``),

    $$
    g_t = \max(0,\ g_{t-1} + s_t - \delta), \qquad g_{-1} = 0
    $$

    accumulates the excess of the score over the drift (:func:`page_cusum`). The
    drift must exceed the score's mean under no maneuver ($n_z$ for the NIS; the
    GLR's depends on its window), else $g$ grows without a maneuver; between that
    mean and the score's mean under the maneuver one wants to see, it trades
    delay against false alarms. $g$ has no closed-form null law, so there is no
    nominal threshold: calibrate empirically (on null trials). ``valid_from`` is
    the score's (0 for the NIS, $M - 1$ for the GLR). $g$ starts at zero and reaches its
    stationary law only after a few times $(\text{score spread} / (\delta - \text{null mean}))^2$
    steps, so with a drift close to the null mean its early steps alarm less often
    than later ones (calibration pools them all); its alarms cluster in few trials.
    """

    name = "cusum"

    @dataclass(frozen=True)
    class Params:
        drift: float = param(3.0, "drift subtracted from the score each step (units of the score); "
                             "above the score's null mean (n_z for the NIS)", ge=0.0, le=MAX_DRIFT,
                             why="non-negative by definition; beyond 10 000 (thousands of times the NIS's "
                                 "null mean) g stays at zero on any plausible scene")
        score: str = param("nis", "the score summed: the NIS, or the GLR statistic", choices=SCORES)
        window: int = param(20, "the GLR's window M of candidate onsets (steps); score = glr only",
                            ge=1, le=MAX_GLR_WINDOW, why="as the glr method's window")
        jump: str = param("acceleration", "the GLR's jump; score = glr only", choices=JUMPS)

        def validate(self) -> None:
            if self.score == "nis":
                defaults = type(self)()
                for name in ("window", "jump"):
                    if getattr(self, name) != getattr(defaults, name):
                        raise ConfigError(name, f"sets the GLR score, unused with score = \"nis\"; "
                                                f"got {getattr(self, name)!r}")

    def detect(self, batch: Batch, inn: InnovationSequence, params) -> DetectionOutput:
        if params.score == "nis":
            score, valid_from = inn.nis, 0
        else:
            glr = Glr().detect(batch, inn, params)
            score, valid_from = glr.statistic, glr.valid_from
        return DetectionOutput(statistic=page_cusum(score, params.drift), valid_from=valid_from,
                               traces={params.score: score})

    def valid_from(self, params, steps: int) -> int:
        """The score's: 0 for the NIS, the GLR's once its window is whole."""
        return Glr().valid_from(params, steps) if params.score == "glr" else 0

    def check_scenario(self, params, scenario_params) -> str | None:
        return Glr().check_scenario(params, scenario_params) if params.score == "glr" else None
