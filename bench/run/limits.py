"""The machine's limits, measured by ``bench perf`` at the start of its run, and a kernel's fraction of them.

Two limits of one core (docs/architecture.md, 'Performance'), each the best of
:data:`ROUNDS` rounds of the CPU time of the measuring thread, like every perf time:

* ``bytes_per_second``: memory bandwidth, the bytes read plus the bytes written
  per second by a streaming copy (``np.copyto``) of an array at least as large
  as the last-level cache into another, so a pass cannot find its data in the
  cache the previous one left;
* ``float32_operations_per_second`` and ``float64_operations_per_second``: the
  SIMD add and max rate of a tight compiled loop ``acc[i] = max(acc[i], x[i] + c)``
  (one add and one max per element) over arrays that stay in the first-level cache.

A method declares what :meth:`bench.core.Method.least_cost` its run must at least
move and compute; the time that takes at these limits (the larger of the bytes'
and the operations': a roofline) over the time measured is its fraction.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

#: rounds of each limit's measurement (each keeps its minimum time)
ROUNDS = 5
#: the streaming copy's array when the last-level cache's size cannot be read
FALLBACK_STREAM_BYTES = 64 << 20
#: bytes of each in-cache array of the add/max loop (two of them fit a first-level cache of 48 KiB)
IN_CACHE_BYTES = 16 << 10
#: add and max operations per round of the compute loop
OPERATIONS_PER_ROUND = 1 << 29
#: the kinds of work a method's least cost counts, and the limit each is timed against
RESOURCES = {"bytes": "bytes_per_second", "float32_operations": "float32_operations_per_second",
             "float64_operations": "float64_operations_per_second"}
#: what each limit is called in the report
LIMIT_NAMES = {"bytes_per_second": "memory bandwidth", "float32_operations_per_second": "float32 add/max rate",
               "float64_operations_per_second": "float64 add/max rate"}


def last_level_cache_bytes(root: Path = Path("/sys/devices/system/cpu/cpu0/cache")) -> int | None:
    """The largest cache of the first CPU (Linux sysfs ``index*/size``, e.g. "300M"), or None unreadable."""
    units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}
    sizes = []
    for entry in root.glob("index*/size"):
        try:
            text = entry.read_text().strip()
        except OSError:
            continue
        if text[:-1].isdigit() and text[-1] in units:
            sizes.append(int(text[:-1]) * units[text[-1]])
        elif text.isdigit():
            sizes.append(int(text))
    return max(sizes, default=None)


def _best_cpu_seconds(fn) -> float:
    """The least CPU time of the calling thread over :data:`ROUNDS` calls of ``fn``."""
    best = np.inf
    for _ in range(ROUNDS):
        t0 = time.thread_time()
        fn()
        best = min(best, time.thread_time() - t0)
    return best


def stream_bandwidth(nbytes: int) -> float:
    """Bytes read plus written per second by a copy of ``nbytes`` into another array (both touched first)."""
    source = np.ones(nbytes // 8)
    target = np.zeros_like(source)
    np.copyto(target, source)
    return 2.0 * source.nbytes / _best_cpu_seconds(lambda: np.copyto(target, source))


def _add_max_kernel():
    import numba

    @numba.njit(fastmath=True)
    def add_max(acc, x, addends):  # pragma: no cover - compiled
        for c in addends:                   # a new addend each pass, so no pass repeats the last
            for i in range(acc.size):
                y = x[i] + c
                acc[i] = acc[i] if acc[i] > y else y
    return add_max


def add_max_rate(dtype) -> float:
    """Add and max operations per second of :func:`_add_max_kernel` on in-cache ``dtype`` arrays."""
    kernel = _add_max_kernel()
    n = IN_CACHE_BYTES // np.dtype(dtype).itemsize
    acc, x = np.zeros(n, dtype), np.linspace(0.0, 1.0, n).astype(dtype)
    addends = np.arange(max(1, OPERATIONS_PER_ROUND // (2 * n)), dtype=dtype)
    kernel(acc, x, addends[:1])               # compiled before it is timed
    return 2.0 * n * addends.size / _best_cpu_seconds(lambda: kernel(acc, x, addends))


def measure_limits() -> dict:
    """The limits of one core (run in a fresh process held to one thread), with the
    streaming copy's array size (``stream_bytes``) and the cache size it was chosen from."""
    cache = last_level_cache_bytes()
    stream = max(cache or 0, FALLBACK_STREAM_BYTES)
    return {"bytes_per_second": stream_bandwidth(stream),
            "float32_operations_per_second": add_max_rate(np.float32),
            "float64_operations_per_second": add_max_rate(np.float64),
            "stream_bytes": stream, "last_level_cache_bytes": cache}


def limit_fraction(cost: dict[str, float], seconds: float, limits: dict) -> tuple[float, str]:
    """(fraction, binding limit): the least time of ``cost`` at ``limits`` (the largest over its
    kinds of work: they may overlap, none can be skipped) over the ``seconds`` measured, and the
    limit that sets that time."""
    times = {RESOURCES[kind]: amount / limits[RESOURCES[kind]] for kind, amount in cost.items()}
    binding = max(times, key=times.get)
    return times[binding] / seconds, binding
