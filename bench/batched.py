"""Small products over a leading trial axis whose every trial's result is the same
whatever the batch (docs/architecture.md, 'Portable numbers').

``x @ A.T`` on an (n, d) batch is one BLAS product whose kernel, blocking and
summation order change with n (and with the CPU); ``einsum`` and stacked ``matmul``
pick their loops from the operands' sizes and strides. A per-trial number must not
depend on which other trials share its batch, so the products of a trial's small
vectors and matrices are written here as elementwise multiplies and adds, summed in
index order: IEEE-exact per element, the same for one trial or a million, on any
x86-64 machine. The contracted dimension is a handful of states or measurements, so
the Python loop over it costs a few array operations per product.
"""

from __future__ import annotations

import numpy as np

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

__all__ = ["inner", "matmul", "matvec"]


def matmul(a, b) -> np.ndarray:
    """``a @ b`` over the last two axes, leading axes broadcast (as ``np.matmul``)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    out = a[..., :, 0, None] * b[..., None, 0, :]
    for c in range(1, a.shape[-1]):
        out += a[..., :, c, None] * b[..., None, c, :]
    return out


def matvec(A, x) -> np.ndarray:
    """``A @ x`` for vectors ``x`` (..., d): ``x @ A.T`` with A (..., m, d), leading axes broadcast."""
    A, x = np.asarray(A, dtype=float), np.asarray(x, dtype=float)
    out = A[..., :, 0] * x[..., 0, None]
    for c in range(1, A.shape[-1]):
        out += A[..., :, c] * x[..., c, None]
    return out


def inner(a, b) -> np.ndarray:
    """Sum over the last axis of ``a * b`` (``einsum('...i,...i->...')``), in index order."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    out = a[..., 0] * b[..., 0]
    for c in range(1, a.shape[-1]):
        out = out + a[..., c] * b[..., c]
    return out
