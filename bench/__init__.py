"""Benchmark harness for radar maneuver detection, tracking and track-before-detect.

The harness (this package) discovers methods and scenarios through
:mod:`bench.registry`, runs sweeps (:mod:`bench.run.runner`), stores results
(:mod:`bench.results.store`), calibrates thresholds (:mod:`bench.calibration`),
computes metrics (:mod:`bench.metrics`) and writes reports and Rerun
recordings (:mod:`bench.report`, :mod:`bench.recording`).
"""

if not __name__.startswith("radarbench."):   # imported by its old name from a checkout: the new package
    from radarbench import _compat           # instead, with a deprecation warning (radarbench/_compat.py)
    _compat.replace_old_package(__name__)


import os

__version__ = "0.1.0"

#: What keeps a number independent of the x86-64 machine (docs/architecture.md, 'Portable
#: numbers'). NumPy's AVX2 / AVX-512 loops of exp, log, log10, expm1, log1p, power, arctan2
#: and tanh round differently in the last bit from its baseline (x86-64-v2) loops: they are
#: disabled, read at numpy's import. Numba needs no pin: it compiles without fast-math, so
#: LLVM neither contracts multiply-adds nor reorders sums, whatever the host's vector width
#: (every method's output was bit-identical compiled for the host, AVX-512, and for
#: x86-64-v2), while pinning x86-64-v2 cost the TBD kernels 1.2-2.8x.
PORTABLE_ENVIRONMENT = {
    "NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR",
}


def _portable_target() -> None:
    """Set :data:`PORTABLE_ENVIRONMENT` for this process and its workers. It must precede
    numpy's import: ``models``, ``methods`` and ``scenarios`` import ``bench`` first, the
    command line and the workers start here; a host process that imported numpy before
    ``bench`` computes with numpy's host loops (``portable_numpy`` says whether it did).
    ``BENCH_PORTABLE=0`` leaves numpy's host loops on: only to measure what portability
    costs (numbers may then differ between machines in the last bits)."""
    if os.environ.get("BENCH_PORTABLE", "1") != "0":
        os.environ.update(PORTABLE_ENVIRONMENT)


def portable_numpy() -> bool:
    """True if numpy was imported under :data:`PORTABLE_ENVIRONMENT` (its dispatch is
    fixed at import)."""
    from numpy._core._multiarray_umath import __cpu_features__ as enabled

    return not any(enabled.get(name) for name in PORTABLE_ENVIRONMENT["NPY_DISABLE_CPU_FEATURES"].split())


_portable_target()
