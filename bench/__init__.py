"""Benchmark harness for radar maneuver detection, tracking and track-before-detect.

The harness (this package) discovers methods and scenarios through
:mod:`bench.registry`, runs sweeps (:mod:`bench.runner`), stores results
(:mod:`bench.store`), calibrates thresholds (:mod:`bench.calibration`),
computes metrics (:mod:`bench.metrics`) and writes reports and Rerun
recordings (:mod:`bench.report`, :mod:`bench.recording`).
"""

__version__ = "0.1.0"
