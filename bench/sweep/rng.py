"""Random streams that make results independent of chunking and workers.

Every trial owns a stream derived from the sweep seed and the trial's identity
only: ``SeedSequence(seed, spawn_key=(domain, scenario_key, trial))``. A unit
of work (a chunk of trials) draws each trial's numbers from that trial's
stream, so a trial sees the same noise whatever chunk, worker or executor it
runs in. The ``domain`` separates the evaluation trials (0) from the null
trials used for calibration (1), so a threshold is never measured on the noise
it was fitted to. The stream does not depend on SNR: trial ``i`` sees the same
noise at every SNR level (common random numbers along the SNR axis too), which
makes Pd curves smooth and their differences meaningful.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any, Sequence

import numpy as np

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

EVALUATION = 0
CALIBRATION = 1


def stable_key(obj: Any) -> int:
    """A 64-bit integer from canonical JSON of ``obj`` (stable across runs)."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "little")


def trial_seed(seed: int, domain: int, scenario_key: int, trial: int) -> np.random.SeedSequence:
    return np.random.SeedSequence(seed, spawn_key=(domain, scenario_key, int(trial)))


class TrialRNG:
    """A batch of per-trial generators with a NumPy-like, batched interface.

    Each call draws ``shape`` numbers from every trial's own stream and returns
    an array of shape ``(n, *shape)``. This loop over trials is the one place
    the harness pays per trial in Python, and it is what buys results that do
    not depend on chunk size.
    """

    def __init__(self, seed: int, domain: int, scenario_key: int, trials: Sequence[int]):
        self.trials = np.asarray(trials, dtype=np.int64)
        self.seeds = [trial_seed(seed, domain, scenario_key, t) for t in self.trials]
        self._gens = [np.random.Generator(np.random.PCG64(s)) for s in self.seeds]

    @property
    def n(self) -> int:
        return len(self._gens)

    @property
    def generators(self) -> list[np.random.Generator]:
        """Each trial's own Generator, in trial order, for code that draws a
        trial's numbers itself (e.g. compiled code: numba accepts a numpy
        Generator and runs numpy's algorithms on its bits)."""
        return self._gens

    def seed_values(self) -> np.ndarray:
        """One 32-bit integer per trial identifying its stream (for the CSV)."""
        return np.array([s.generate_state(1)[0] for s in self.seeds], dtype=np.int64)

    def _draw(self, name: str, shape, **kwargs) -> np.ndarray:
        shape = (shape,) if isinstance(shape, int) else tuple(shape)
        return np.stack([getattr(g, name)(size=shape, **kwargs) for g in self._gens]) \
            if self._gens else np.empty((0, *shape))

    def standard_normal(self, shape) -> np.ndarray:
        return self._draw("standard_normal", shape)

    def uniform(self, shape, low: float = 0.0, high: float = 1.0) -> np.ndarray:
        return self._draw("uniform", shape, low=low, high=high)

    def laplace(self, shape, scale: float = 1.0) -> np.ndarray:
        return self._draw("laplace", shape, scale=scale)

    def exponential(self, shape, scale: float = 1.0) -> np.ndarray:
        return self._draw("exponential", shape, scale=scale)

    def random(self, shape) -> np.ndarray:
        return self._draw("random", shape)
