"""Preloaded by the forkserver of :class:`bench.executors.LocalExecutor`:
the runner, numpy, scipy and the plugins are imported once in the server, so
every worker it forks starts warm."""

import bench.runner  # noqa: F401
