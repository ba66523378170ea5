"""Executors map units of work to results; results never depend on them.

An executor has one job: ``imap_unordered(fn, tasks)`` yields ``fn(task)`` for
every task, in any order, as they finish. The driver stores each result as it
arrives, so the store, the recording and the progress bar stay in one process.

* :class:`SerialExecutor` — in the driver process (``--workers 1``).
* :class:`LocalExecutor` — a process pool (default: one worker per CPU). Workers
  ignore SIGINT: Ctrl-C reaches the driver, which drops the units not yet
  started, lets the ones in flight end (a second Ctrl-C kills them) and keeps
  what is stored.

* :class:`DaskExecutor` — a dask.distributed cluster (``--executor dask``):
  an existing one (``--scheduler tcp://HOST:8786``) or a ``LocalCluster`` of
  ``--workers`` processes. Optional: ``pip install "radar-maneuver-bench[dask]"``.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import multiprocessing
import os
import signal
import threading
import time
from multiprocessing import forkserver
from typing import Callable, Iterable, Iterator

from bench.errors import ConfigError


class SerialExecutor:
    workers = 1

    def imap_unordered(self, fn: Callable, tasks: Iterable) -> Iterator:
        for task in tasks:
            yield fn(task)

    def shutdown(self, cancel: bool = False) -> None:
        pass

    def kill(self) -> None:
        pass


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def _sigint_deferred():
    """Hold Ctrl-C until the block ends, then raise KeyboardInterrupt as usual.

    A Python-level handler (it always runs in the main thread), not a signal
    mask: the pool's helper threads would take a masked signal instead.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        raise KeyboardInterrupt


def _start_forkserver(preload: list[str]) -> None:
    """Start the forkserver (if not running) with SIGINT ignored, a disposition
    that survives exec: the server and every worker it forks ignore Ctrl-C (a
    terminal sends it to the whole process group) and the driver alone handles it."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(preload)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        forkserver.ensure_running()
    finally:
        signal.signal(signal.SIGINT, previous)


class LocalExecutor:
    """A process pool with a bounded number of units in flight."""

    def __init__(self, workers: int):
        self.workers = workers
        # forkserver: no fork of a driver that may hold threads (rerun, BLAS).
        _start_forkserver(["bench._forkserver"])
        ctx = multiprocessing.get_context("forkserver")
        self.pool = cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                           initializer=_ignore_sigint)
        # Start every worker now, with Ctrl-C held back: an interrupt that
        # lands while a worker is being spawned would leave it half-born.
        with _sigint_deferred():
            cf.wait([self.pool.submit(os.getpid) for _ in range(workers)])

    def imap_unordered(self, fn: Callable, tasks: Iterable) -> Iterator:
        pending: set[cf.Future] = set()
        todo = iter(tasks)
        limit = 2 * self.workers
        while True:
            while len(pending) < limit:
                task = next(todo, None)
                if task is None:
                    break
                pending.add(self.pool.submit(fn, task))
            if not pending:
                return
            done, pending = cf.wait(pending, return_when=cf.FIRST_COMPLETED)
            for fut in done:
                yield fut.result()

    def shutdown(self, cancel: bool = False) -> None:
        """Wait for the units in flight; with ``cancel``, drop those not started."""
        self.pool.shutdown(wait=True, cancel_futures=cancel)

    def kill(self) -> None:
        """Stop at once: terminate the workers (their units are lost, never half-stored)."""
        for proc in list((getattr(self.pool, "_processes", None) or {}).values()):
            proc.terminate()
        self.pool.shutdown(wait=False, cancel_futures=True)


DASK_INSTALL_HINT = 'pip install "radar-maneuver-bench[dask]"'


def require_dask() -> None:
    """Raise a one-line ConfigError saying how to install dask when it is missing."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise ConfigError("--executor", f"dask is not installed; install it with: {DASK_INSTALL_HINT}") from None


class DaskExecutor:
    """Units on a dask.distributed cluster; results come back to the driver as they finish.

    With ``scheduler`` (``tcp://HOST:PORT``) the units go to an existing cluster
    whose workers have this package (and the plugins the sweep uses) installed;
    without it a ``LocalCluster`` of ``workers`` single-threaded processes is
    started (no dashboard, quiet logs) and closed at the end.

    At most two units per worker thread are in flight (the window follows the
    cluster as workers join or leave), so a huge sweep never floods the
    scheduler. A unit whose worker dies is rescheduled by dask on another worker
    (``distributed.scheduler.allowed-failures`` times); a unit that raises is
    retried ``retries`` times. Each submitted unit yields exactly one result, and
    the store ignores a second result of a unit it already holds, so a unit is
    never counted twice. Results never depend on the cluster: a unit's random
    streams come from the sweep seed and the unit's trials only.
    """

    retries = 2
    connect_timeout = "15s"     # to reach an existing scheduler
    worker_timeout = 60         # seconds to wait for its first worker

    def __init__(self, workers: int, scheduler: str | None = None):
        require_dask()
        import logging

        from distributed import Client, LocalCluster

        self.cluster = None
        self._futures: set = set()
        self._limit_checked = 0.0
        self.client = None
        self._config = None
        if scheduler is None:
            # The workers are forked by the forkserver LocalExecutor uses, started
            # with SIGINT ignored and the harness preloaded: they start warm and
            # ignore Ctrl-C (a terminal sends it to the whole process group) now
            # and when the nanny restarts one; the driver alone handles it.
            import dask

            _start_forkserver(["bench._forkserver", "distributed"])
            self._config = dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"})
            try:
                self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                            dashboard_address=None, silence_logs=logging.ERROR)
                self.client = Client(self.cluster, set_as_default=False)
            except BaseException:
                self.shutdown(cancel=True)
                raise
        else:
            try:
                self.client = Client(scheduler, timeout=self.connect_timeout, set_as_default=False)
            except (OSError, TimeoutError, ValueError) as exc:
                raise ConfigError("--scheduler", f"cannot connect to {scheduler}: "
                                                 f"{type(exc).__name__}: {exc}"[:300]) from None
        try:
            self._check_workers(scheduler or "the local cluster")
        except BaseException:
            self.shutdown(cancel=True)
            raise
        self.workers = self._threads() or workers
        self._limit_checked = time.monotonic()

    def _check_workers(self, scheduler: str) -> None:
        """Every worker imports the harness and its plugins now (warm; on an existing cluster,
        a clear error instead of failed units) and runs the driver's version of them."""
        here = worker_environment()
        try:
            self.client.wait_for_workers(1, timeout=self.worker_timeout)
        except TimeoutError:
            raise ConfigError("--scheduler", f"{scheduler} has no workers; start some with "
                                             f"`dask worker {scheduler} --nthreads 1`") from None
        try:
            there = self.client.run(worker_environment)
        except Exception as exc:  # noqa: BLE001 - e.g. the package is not installed on a worker
            raise ConfigError("--scheduler", f"the workers of {scheduler} cannot run bench units "
                                             f"({type(exc).__name__}: {exc}); install this package "
                                             "(and its plugins) on every worker"[:300]) from None
        for address, env in sorted(there.items()):
            if env != here:
                diff = ", ".join(f"{k} {env.get(k)!r} (here {v!r})" for k, v in here.items() if env.get(k) != v)
                raise ConfigError("--scheduler", f"worker {address} differs from this machine: {diff}"[:300])

    def _threads(self) -> int:
        return sum(self.client.nthreads().values())

    def _limit(self) -> int:
        now = time.monotonic()
        if now - self._limit_checked > 2.0:          # follow workers that join or leave
            self._limit_checked = now
            self.workers = self._threads() or self.workers
        return max(2, 2 * self.workers)

    def imap_unordered(self, fn: Callable, tasks: Iterable) -> Iterator:
        from distributed import as_completed

        todo = iter(tasks)
        running = as_completed(loop=self.client.loop)
        end = object()

        def refill() -> None:
            while len(self._futures) < self._limit():
                task = next(todo, end)
                if task is end:
                    return
                fut = self.client.submit(fn, task, pure=False, retries=self.retries)
                self._futures.add(fut)
                running.add(fut)

        refill()
        for fut in running:
            self._futures.discard(fut)
            result = fut.result()         # the unit's own exception, after its retries
            fut.release()
            refill()
            yield result

    def shutdown(self, cancel: bool = False) -> None:
        """Close the client (and the LocalCluster); with ``cancel``, drop the units in flight.

        Dropped units were never stored: a re-run computes them again.
        """
        if cancel and self._futures:
            with contextlib.suppress(Exception):
                self.client.cancel(list(self._futures))
        self._futures.clear()
        if self.client is not None:
            with contextlib.suppress(Exception):
                self.client.close(timeout=10)
        if self.cluster is not None:
            with contextlib.suppress(Exception):
                self.cluster.close(timeout=10)
            self.cluster = None
        if self._config is not None:
            self._config.__exit__(None, None, None)
            self._config = None

    def kill(self) -> None:
        """Stop at once (a second Ctrl-C)."""
        self.shutdown(cancel=True)


def worker_environment() -> dict[str, str]:
    """What must match between the driver and a worker for results to be the same: the
    harness version and the registered plugins (importing them warms the worker up)."""
    import bench
    from bench import registry

    missing = ", ".join(u.source for u in registry.unavailable()) or "-"
    return {"bench": bench.__version__, "methods": ", ".join(registry.methods()),
            "scenarios": ", ".join(registry.scenarios()), "unavailable plugins": missing}


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


EXECUTORS = ("local", "dask")


def make_executor(name: str, workers: int, scheduler: str | None = None):
    """``local`` (``workers`` = 1: in the driver) or ``dask`` (``scheduler``: an existing cluster)."""
    if name == "dask":
        return DaskExecutor(workers, scheduler)
    if scheduler is not None:
        raise ConfigError("--scheduler", "only with --executor dask")
    if name != "local":
        raise ConfigError("--executor", f"unknown executor {name!r} (available: {', '.join(EXECUTORS)})")
    return SerialExecutor() if workers == 1 else LocalExecutor(workers)
