"""An oracle cell detector for the detect-and-track chain's tests: it declares exactly the
cells of the targets present (the map scene's ``target_cells`` whose SNR is finite) and
nothing else, so the chain's plots are the targets' alone."""

from dataclasses import dataclass

import numpy as np

from radarbench.bench.core import Method
from radarbench.bench.params import param
from radarbench.bench.tasks.cells import CELL_DETECTION, CellDetectionOutput

#: the significance of a truth cell: above any nominal threshold a chain may ask (Pfa >= 1e-12)
SURE = 50.0


class TruthCells(Method):
    """Declares the true target cells only."""

    name = "truth-cells"
    task = CELL_DETECTION

    @dataclass(frozen=True)
    class Params:
        unused: float = param(1.0, "no effect (a Params needs a field)", ge=0.0, le=1.0, why="none")

    def run(self, batch, params):
        scene = batch.scene
        statistic = np.zeros(batch.z.shape[:1] + batch.z.shape[2:], np.float32)
        i, t = np.nonzero(np.isfinite(scene.target_snr_db))
        statistic[i, scene.target_cells[i, t, 0], scene.target_cells[i, t, 1]] = SURE
        return CellDetectionOutput(statistic=statistic)

    def nominal_threshold(self, params, pfa: float, batch) -> float:
        return float(-np.log10(pfa))
