"""Sliding-window sums along the time axis, shared by the window detectors."""

from __future__ import annotations

import numpy as np

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True


def sliding_sum(x: np.ndarray, window: int) -> np.ndarray:
    """Sum of the last ``window`` values along axis 1, for every step at once.

    Partial sums before the window fills. One cumulative sum and one
    subtraction: O(n K) whatever the window length.
    """
    c = np.cumsum(x, axis=1)
    out = c.copy()
    out[:, window:] -= c[:, :-window]
    return out
