"""Preloaded by the forkserver of :class:`bench.run.executors.LocalExecutor`:
the runner, numpy, scipy and the plugins are imported once in the server, so
every worker it forks starts warm.

Imported in the forkserver, it also makes the server exit with the driver that
started it (named by ``BENCH_FORKSERVER_DRIVER``): on Linux the kernel kills it
when the driver dies (``prctl(PR_SET_PDEATHSIG)``); everywhere, the server
exits once the driver and every worker have closed its "alive" pipe, and the
workers exit with the driver (:func:`bench.run.processes._exit_with_driver`).
"""

import os
import signal
import sys

import radarbench.bench.run.runner  # noqa: F401
from radarbench.bench import registry

PR_SET_PDEATHSIG = 1


def _die_with(driver: int) -> None:
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):      # no libc or no prctl: the alive pipe still ends the server
            pass
    if os.getppid() != driver:                 # the driver died before the line above
        os._exit(0)


_driver = os.environ.pop("BENCH_FORKSERVER_DRIVER", "")   # set only while the driver starts this server
if _driver.isdigit():
    _die_with(int(_driver))
    try:
        registry.discover()        # the plugins, once for every worker (one that fails is kept as unavailable)
    except Exception:  # noqa: BLE001 - a worker finds out again, unit by unit
        pass
