"""Field checks for the models' frozen dataclasses: a bad field is a
ValueError whose message names it (``GlintModel.sigma: expected ...``), raised
where the model is built (a scenario's ``generate``), not where it is used."""

from __future__ import annotations

import numpy as np


def describe(value) -> str:
    """A short description of a value for an error message."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} ({value.dtype})"
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 60 else text[:57] + '...'}"


def require(owner, field: str, ok: bool, expected: str) -> None:
    """ValueError naming ``Owner.field`` unless ``ok``."""
    if not ok:
        raise ValueError(f"{type(owner).__name__}.{field}: expected {expected}, "
                         f"got {describe(getattr(owner, field))}")


def is_array(value, shape: tuple) -> bool:
    """Whether ``value`` is a real-valued array of ``shape`` (None: any length)."""
    return (isinstance(value, np.ndarray) and value.dtype.kind in "fiu" and value.ndim == len(shape)
            and all(s is None or s == d for s, d in zip(shape, value.shape)))


def require_arrays(owner, shapes: dict[str, tuple]) -> None:
    """:func:`require` that each named field is a real array of its shape."""
    for field, shape in shapes.items():
        require(owner, field, is_array(getattr(owner, field), shape),
                "an array of shape (" + ", ".join("?" if s is None else str(s) for s in shape)
                + (",)" if len(shape) == 1 else ")"))
