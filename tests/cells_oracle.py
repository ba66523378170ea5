"""The ideal (known-noise) cell detector, as a test oracle of the cell-detection
task: it thresholds z / N with N the scene's true noise-plus-clutter power of
each cell (bench/tasks/cells/metrics.py, 'the ideal detector'). For exponential
noise P(z / N >= x) = exp(-x), so its statistic -log10 of that, x log10(e),
is exactly the nominal significance and its nominal threshold -log10(pfa) has
per-cell Pfa exactly pfa in every clutter region. Registered through an entry
point by tests/test_cells_task.py (a plugin from outside the repository)."""

from dataclasses import dataclass

import numpy as np

from radarbench.bench.params import param
from radarbench.bench.core import Method
from radarbench.bench.tasks.cells import CELL_DETECTION, CellDetectionOutput

LOG10_E = float(np.log10(np.e))


class KnownNoise(Method):
    """Ideal cell detector: z over the true noise power of the cell."""

    name = "known-noise"
    task = CELL_DETECTION

    @dataclass(frozen=True)
    class Params:
        scale: float = param(1.0, "multiplies the noise power the detector assumes (1: the truth)",
                             ge=0.1, le=10.0, why="a mis-scaled oracle for tests")

    @staticmethod
    def threshold_factor(params, pfa: float) -> float:
        return float(-np.log(pfa))

    def run(self, batch, params):
        noise = np.asarray(batch.scene.noise_power, np.float32) * np.float32(params.scale)
        ratio = batch.z[:, 0] / noise
        return CellDetectionOutput(statistic=(ratio * LOG10_E).astype(np.float32), noise_estimate=noise,
                                   threshold_factor=lambda pfa: self.threshold_factor(params, pfa) * params.scale)

    def nominal_threshold(self, params, pfa: float, batch) -> float:
        return float(-np.log10(pfa))
