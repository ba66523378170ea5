"""Executors map units of work to results; results never depend on them.

An executor has one job: ``imap_unordered(fn, tasks)`` yields ``fn(task)`` for
every task, in any order, as they finish. The driver stores each result as it
arrives, so the store, the recording and the progress bar stay in one process.

* :class:`SerialExecutor` — in the driver process (``--workers 1``).
* :class:`LocalExecutor` — a process pool (default: one worker per CPU). Workers
  ignore SIGINT: Ctrl-C reaches the driver, which stops the pool and keeps what
  finished.

A Dask executor implements the same interface (DESIGN.md section 5).
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import signal
from typing import Callable, Iterable, Iterator


class SerialExecutor:
    workers = 1

    def imap_unordered(self, fn: Callable, tasks: Iterable) -> Iterator:
        for task in tasks:
            yield fn(task)

    def shutdown(self) -> None:
        pass


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


class LocalExecutor:
    """A process pool with a bounded number of units in flight."""

    def __init__(self, workers: int):
        self.workers = workers
        # forkserver: no fork of a driver that may hold threads (rerun, BLAS)
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["bench.runner"])
        self.pool = cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                           initializer=_ignore_sigint)

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
        if cancel:
            for proc in list(getattr(self.pool, "_processes", {}).values()):
                proc.terminate()
        self.pool.shutdown(wait=not cancel, cancel_futures=cancel)


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


def make_executor(name: str, workers: int):
    if name != "local":
        from bench.errors import ConfigError
        raise ConfigError("--executor", f"unknown executor {name!r} (available: local)")
    return SerialExecutor() if workers == 1 else LocalExecutor(workers)
