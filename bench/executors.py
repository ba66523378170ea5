"""Executors map units of work to results; results never depend on them.

An executor has one job: ``imap_unordered(fn, tasks)`` yields ``fn(task)`` for
every task, in any order, as they finish. The driver stores each result as it
arrives, so the store, the recording and the progress bar stay in one process.

* :class:`SerialExecutor` — in the driver process (``--workers 1``).
* :class:`LocalExecutor` — a process pool (default: one worker per CPU). Workers
  ignore SIGINT: Ctrl-C reaches the driver, which drops the units not yet
  started, lets the ones in flight end (a second Ctrl-C kills them) and keeps
  what is stored.

A Dask executor implements the same interface (DESIGN.md section 5).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import multiprocessing
import os
import signal
from multiprocessing import forkserver
import threading
from typing import Callable, Iterable, Iterator


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


class LocalExecutor:
    """A process pool with a bounded number of units in flight."""

    def __init__(self, workers: int):
        self.workers = workers
        # forkserver: no fork of a driver that may hold threads (rerun, BLAS).
        # It is started with SIGINT ignored, a disposition that survives exec:
        # the server and every worker it forks ignore Ctrl-C (a terminal sends
        # it to the whole process group) and the driver alone handles it.
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["bench._forkserver"])
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            forkserver.ensure_running()
        finally:
            signal.signal(signal.SIGINT, previous)
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


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


def make_executor(name: str, workers: int):
    if name != "local":
        from bench.errors import ConfigError
        raise ConfigError("--executor", f"unknown executor {name!r} (available: local)")
    return SerialExecutor() if workers == 1 else LocalExecutor(workers)
