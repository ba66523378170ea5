"""Benchmark harness for radar maneuver detection, tracking and track-before-detect.

The harness (this package) discovers methods and scenarios through
:mod:`bench.registry`, runs sweeps (:mod:`bench.runner`), stores results
(:mod:`bench.store`), calibrates thresholds (:mod:`bench.calibration`),
computes metrics (:mod:`bench.metrics`) and writes reports and Rerun
recordings (:mod:`bench.report`, :mod:`bench.recording`).
"""

import os

__version__ = "0.1.0"

#: The one instruction set every number is computed for (docs/architecture.md, 'Portable
#: numbers'): x86-64-v2 (SSE4.2, no AVX/FMA), NumPy 2's own baseline. Numba compiles every
#: kernel for it, whatever the host (numba re-reads these variables at each compilation, and
#: its cache is keyed on the target, so a kernel cached for another target is recompiled).
PORTABLE_CPU = "x86-64-v2"
PORTABLE_ENVIRONMENT = {
    "NUMBA_CPU_NAME": PORTABLE_CPU,
    "NUMBA_CPU_FEATURES": "",                   # the CPU name's own features, not the host's
    # NumPy's AVX2 / AVX-512 loops of exp, log, log10, expm1, log1p, power, arctan2 and tanh
    # round differently in the last bit from its baseline loops; read at numpy's import.
    "NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR",
}


def _portable_target() -> None:
    """Set :data:`PORTABLE_ENVIRONMENT` for this process and its workers. It must precede
    numpy's import: ``models``, ``methods`` and ``scenarios`` import ``bench`` first, the
    command line and the workers start here; a host process that imported numpy before
    ``bench`` computes with numpy's host loops (``portable_numpy`` says whether it did)."""
    os.environ.update(PORTABLE_ENVIRONMENT)


def portable_numpy() -> bool:
    """True if numpy was imported under :data:`PORTABLE_ENVIRONMENT` (its dispatch is
    fixed at import)."""
    from numpy._core._multiarray_umath import __cpu_features__ as enabled

    return not any(enabled.get(name) for name in PORTABLE_ENVIRONMENT["NPY_DISABLE_CPU_FEATURES"].split())


_portable_target()
