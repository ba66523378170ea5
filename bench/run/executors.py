"""Executors map units of work to results; results never depend on them.

An executor has one job: ``imap_unordered(fn, tasks, stop=..., timeout=...)``
yields ``fn(task)`` for every task, in any order, as they finish. The driver
stores each result as it arrives, so the store, the recording and the progress
bar stay in one process. ``tasks`` is read one task at a time, when a worker is
free: the driver may add tasks while it consumes results. A task that yields
no result — its worker died, it ran past ``timeout`` seconds, its result could
not be sent back — yields a :class:`UnitFailure` instead, and the executor goes
on (it replaces the worker). Once ``stop()`` is true no task is started; the
ones in flight end and are yielded, then the iteration ends.

* :class:`LocalExecutor` — ``--workers`` processes (default: one per CPU), forked
  by a forkserver. Each worker holds one unit at a time, so a worker that dies
  (``os._exit`` in a plugin, a crash, the out-of-memory killer) or overruns the
  sweep's ``unit_timeout_s`` costs exactly its unit. Workers ignore SIGINT and
  SIGTERM (a terminal or a service manager signals the whole process group): the
  driver alone handles them. Workers exit when the driver dies (they watch it),
  the forkserver too, so no process of a run outlives it.
* :class:`SerialExecutor` — units in the calling process (``executor="serial"``:
  tests and library use; a unit that kills its process kills the caller).
* :class:`DaskExecutor` — a dask.distributed cluster (``--executor dask``):
  an existing one (``--scheduler tcp://HOST:8786``) or a ``LocalCluster`` of
  ``--workers`` processes. Optional: ``pip install "radar-maneuver-bench[dask]"``.
"""

from __future__ import annotations

import atexit
import contextlib
import multiprocessing
import os
import signal
import time
import traceback
import weakref
from multiprocessing.connection import wait as _wait
from pathlib import Path
from typing import Callable, Iterable, Iterator

from radarbench.bench.errors import ConfigError
from radarbench.bench.run.processes import LOCAL_PRELOAD, STOP_SIGNALS, _exit_with_driver, _signals_deferred, _start_forkserver


class UnitFailure:
    """A task that produced no result, and why (one line)."""

    __slots__ = ("task", "cause")

    def __init__(self, task, cause: str):
        self.task, self.cause = task, cause

    def __repr__(self) -> str:
        return f"UnitFailure({self.cause!r})"


def error_text(exc: BaseException) -> str:
    """``Type: message (file.py:line)`` of an exception, on one line."""
    frames = traceback.extract_tb(exc.__traceback__)
    where = f" ({Path(frames[-1].filename).name}:{frames[-1].lineno})" if frames else ""
    message = " ".join(str(exc).split())
    return f"{type(exc).__name__}{': ' + message if message else ''}{where}"[:500]


_END = object()
_IN_WORKER = False


def in_worker() -> bool:
    """Whether this process is a worker of :class:`LocalExecutor` or :class:`DaskExecutor` (no
    user at its terminal: a KeyboardInterrupt there can only come from the code it runs)."""
    return _IN_WORKER


class SerialExecutor:
    workers = 1
    local = True        # its processes share this machine's numba cache (bench.run.warmup)

    def imap_unordered(self, fn: Callable, tasks: Iterable, *, stop: Callable[[], bool] | None = None,
                       timeout: float | None = None) -> Iterator:
        todo = iter(tasks)
        while not (stop is not None and stop()):
            task = next(todo, _END)
            if task is _END:
                return
            try:
                out = fn(task)
            except Exception as exc:  # noqa: BLE001 - a unit's failure, never the run's
                out = UnitFailure(task, error_text(exc))
            yield out

    def shutdown(self, cancel: bool = False) -> None:
        pass

    def kill(self) -> None:
        pass


def _worker_main(conn) -> None:
    """A LocalExecutor worker: ``(fn, task)`` in, ``("ok", result)`` or ``("error", text)`` out,
    until ``None`` or the driver's end of the pipe closes."""
    global _IN_WORKER
    _IN_WORKER = True
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)
    _exit_with_driver()
    from multiprocessing.reduction import ForkingPickler

    while True:
        try:
            raw = conn.recv_bytes()
        except (EOFError, OSError):
            return
        try:
            msg = ForkingPickler.loads(raw)
        except BaseException as exc:  # noqa: BLE001 - e.g. a plugin class this process cannot import
            msg = ("unreadable", error_text(exc))
        if msg is None:
            return
        fn, task = msg
        try:
            if fn == "unreadable":
                raise RuntimeError(f"the worker cannot read the unit: {task}")
            out = ("ok", fn(task))
        except BaseException as exc:  # noqa: BLE001 - SystemExit too: a failed unit, never a dead worker
            out = ("error", error_text(exc))
        try:
            conn.send(out)
        except (EOFError, OSError):
            return
        except BaseException as exc:  # noqa: BLE001 - e.g. a result that cannot be pickled
            try:
                conn.send(("error", f"the unit's result could not be sent back: {error_text(exc)}"))
            except (EOFError, OSError):
                return


def _death_cause(proc) -> str:
    proc.join(timeout=2)
    code = proc.exitcode
    if code is None:
        how = "stopped answering"
    elif code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        how = f"was killed by {name}" + (" (out of memory, or killed by hand?)" if -code == signal.SIGKILL else "")
    else:
        how = f"exited with code {code}"
    return f"worker process died: it {how} while running this unit"


class _Worker:
    __slots__ = ("proc", "conn", "task", "started")

    def __init__(self, proc, conn):
        self.proc, self.conn = proc, conn
        self.task = None
        self.started = 0.0

    def kill(self) -> None:
        """SIGKILL (workers ignore SIGTERM), then reap."""
        with contextlib.suppress(Exception):
            self.conn.close()
        if self.proc.pid is not None:
            with contextlib.suppress(ProcessLookupError, PermissionError, ValueError):
                # 255: also what a dead forkserver leaves as the status of a live worker
                if self.proc.exitcode in (None, 255):
                    os.kill(self.proc.pid, signal.SIGKILL)
        with contextlib.suppress(Exception):
            self.proc.join(timeout=2)


_LIVE: "weakref.WeakSet[LocalExecutor]" = weakref.WeakSet()


@atexit.register
def _kill_live_executors() -> None:
    """At exit (an error path that skipped shutdown): no worker outlives the driver."""
    for ex in list(_LIVE):
        ex.kill()


class LocalExecutor:
    """``workers`` processes, one unit each at a time; a dead or overdue worker is replaced."""

    local = True

    def __init__(self, workers: int):
        self.workers = workers
        # forkserver: no fork of a driver that may hold threads (rerun, BLAS).
        self._ctx = multiprocessing.get_context("forkserver")
        self._pool: list[_Worker] = []
        _LIVE.add(self)
        try:
            # Start every worker now, with signals held back: an interrupt that
            # lands while a worker is being spawned would leave it half-born.
            with _signals_deferred():
                for _ in range(workers):
                    self._pool.append(self._spawn())
        except BaseException:
            self.kill()
            raise

    def _spawn(self) -> _Worker:
        for attempt in range(5):
            _start_forkserver(LOCAL_PRELOAD)        # again if someone killed it
            parent, child = self._ctx.Pipe(duplex=True)
            proc = self._ctx.Process(target=_worker_main, args=(child,), name="bench-worker")
            try:
                proc.start()
                break
            except (OSError, EOFError):        # a forkserver killed but not yet dead: wait, start another
                parent.close()
                child.close()
                if attempt == 4:
                    raise
                time.sleep(0.2 * (attempt + 1))
        child.close()          # the worker's end lives in the worker only: its death closes the pipe
        # Reaped by this executor, never by multiprocessing's exit handler (which would
        # wait forever for a worker that ignores SIGTERM).
        multiprocessing.process._children.discard(proc)
        return _Worker(proc, parent)

    def _replace(self, w: _Worker) -> None:
        w.kill()
        self._pool[self._pool.index(w)] = self._spawn()

    def imap_unordered(self, fn: Callable, tasks: Iterable, *, stop: Callable[[], bool] | None = None,
                       timeout: float | None = None) -> Iterator:
        todo = iter(tasks)
        while True:
            if not (stop is not None and stop()):
                for i, w in enumerate(self._pool):
                    if w.task is None:
                        task = next(todo, _END)
                        if task is _END:
                            break
                        self._send(i, fn, task)
            busy = [w for w in self._pool if w.task is not None]
            if not busy:
                return
            wait_s = None
            if timeout is not None:
                wait_s = max(0.0, min(w.started for w in busy) + timeout - time.monotonic())
            ready = set(_wait([w.conn for w in busy], timeout=wait_s))
            now = time.monotonic()
            for w in busy:
                if w.conn in ready:
                    out = self._receive(w)
                elif timeout is not None and now - w.started >= timeout:
                    task = w.task
                    self._replace(w)
                    out = UnitFailure(task, f"timeout: the unit ran longer than unit_timeout_s = {timeout:g} s; "
                                            "its worker was stopped")
                else:
                    continue
                yield out       # the consumer may add tasks meanwhile: the next round starts them

    def _send(self, i: int, fn: Callable, task) -> None:
        for _ in range(3):
            w = self._pool[i]
            try:
                w.conn.send((fn, task))
            except (OSError, EOFError):      # it died while idle (killed by hand): a new one takes the unit
                self._replace(w)
                continue
            w.task, w.started = task, time.monotonic()
            return
        raise RuntimeError("the worker processes die as soon as they start")

    def _receive(self, w: _Worker):
        task = w.task
        try:
            kind, payload = w.conn.recv()
        except Exception:  # noqa: BLE001 - EOF (the worker died) or a torn message
            cause = _death_cause(w.proc)
            self._replace(w)
            return UnitFailure(task, cause)
        w.task = None
        return payload if kind == "ok" else UnitFailure(task, payload)

    def shutdown(self, cancel: bool = False) -> None:
        """Stop the workers (none holds a unit once an iteration has ended)."""
        for w in self._pool:
            if w.task is None:
                with contextlib.suppress(Exception):
                    w.conn.send(None)
        deadline = time.monotonic() + 5
        for w in self._pool:
            if w.task is None:
                w.proc.join(timeout=max(0.0, deadline - time.monotonic()))
            w.kill()
        self._pool.clear()
        _LIVE.discard(self)

    def kill(self) -> None:
        """Stop at once: kill the workers (their units are lost, never half-stored)."""
        for w in self._pool:
            w.kill()
        self._pool.clear()
        _LIVE.discard(self)


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
    scheduler. Dask fails every unit of a worker that dies (``KilledWorker``), the
    innocent ones beside the culprit too, so a unit whose worker died is run again
    *alone* on the cluster once the units in flight are done: only a unit that kills
    its worker while alone yields a :class:`UnitFailure`, and the runner then runs it
    config by config as it does for the local pool (``bench.run.runner._run_phase``), so no
    innocent config is recorded as failed. A unit that raises is
    retried ``retries`` times. Each submitted unit yields exactly one result, and
    the store ignores a second result of a unit it already holds, so a unit is
    never counted twice. Results never depend on the cluster: a unit's random
    streams come from the sweep seed and the unit's trials only.
    """

    local = False       # its workers, on other machines too, keep their own numba caches (bench.run.warmup)
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

            _start_forkserver(["radarbench.bench.run._forkserver", "distributed"])
            # allowed-failures 0: a unit whose worker dies comes back at once (imap_unordered
            # runs it again, alone), rather than after killing three more workers.
            self._config = dask.config.set({"distributed.worker.multiprocessing-method": "forkserver",
                                           "distributed.scheduler.allowed-failures": 0})
            try:
                # CRITICAL: a worker that dies is a unit's failure, which the run reports itself
                self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                            dashboard_address=None, silence_logs=logging.CRITICAL)
                self.client = Client(self.cluster, set_as_default=False)
            except BaseException:
                self.shutdown(cancel=True)
                raise
        else:
            check_scheduler(scheduler)
            try:
                self.client = _client(scheduler, self.connect_timeout)
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

    def imap_unordered(self, fn: Callable, tasks: Iterable, *, stop: Callable[[], bool] | None = None,
                       timeout: float | None = None) -> Iterator:
        """As :meth:`LocalExecutor.imap_unordered`; a unit whose worker died (``KilledWorker``)
        is run again alone once the units in flight are done, and yields a :class:`UnitFailure`
        only if it kills its worker alone too. ``timeout`` is not enforced: a dask worker
        cannot be stopped in the middle of a unit."""
        from distributed import KilledWorker, as_completed

        todo = iter(tasks)
        running = as_completed(loop=self.client.loop)
        task_of: dict = {}
        suspects: list = []         # units whose worker died while other units were in flight
        alone: set = set()          # the key of the unit running alone, if any

        def submit(task):
            fut = self.client.submit(_on_dask_worker, fn, task, pure=False, retries=self.retries)
            self._futures.add(fut)
            task_of[fut.key] = task
            running.add(fut)
            return fut

        def refill() -> None:
            if stop is not None and stop():
                return
            if suspects:            # drain the cluster, then run the suspects one at a time
                if not self._futures:
                    alone.add(submit(suspects.pop(0)).key)
                return
            while len(self._futures) < self._limit():
                task = next(todo, _END)
                if task is _END:
                    return
                submit(task)

        refill()
        while self._futures:
            for fut in running:
                self._futures.discard(fut)
                task = task_of.pop(fut.key)
                try:
                    result = fut.result()         # the unit's own exception, after its retries
                except KilledWorker:
                    # Dask blames every unit on a worker that dies, so an innocent unit beside
                    # the one that killed it fails too: only a unit that kills its worker while
                    # alone on the cluster is a failure (the runner then isolates its configs).
                    if fut.key not in alone:
                        suspects.append(task)
                        fut.release()
                        refill()
                        continue
                    result = UnitFailure(task, "worker process died while running this unit "
                                               "(alone on the Dask cluster: KilledWorker)")
                except Exception as exc:  # noqa: BLE001 - e.g. a result that cannot be sent back: this unit failed
                    result = UnitFailure(task, f"on the Dask cluster: {error_text(exc)}")
                alone.discard(fut.key)
                fut.release()
                yield result
                refill()
            refill()

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


def _on_dask_worker(fn: Callable, task):
    """``fn(task)`` on a Dask worker, which from then on is a worker (:func:`in_worker`): a
    KeyboardInterrupt there comes from the code it runs (a unit's failure), never from a user."""
    global _IN_WORKER
    _IN_WORKER = True
    return fn(task)


def check_scheduler(address: str) -> None:
    """A scheduler address dask can use, and something listening there: one ConfigError line
    at once, never dask's retries for a scheme it does not know or a port nobody listens on."""
    import socket

    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import get_backend

    try:
        scheme, location = parse_address(address, strict=True)
        get_backend(scheme)
        if scheme in ("tcp", "tls", "ws", "wss"):
            host, port = parse_host_port(location, 8786)
    except (ValueError, TypeError) as exc:
        raise ConfigError("--scheduler", f"{address!r} is not a scheduler address such as "
                                         f"tcp://HOST:8786 ({exc})"[:300]) from None
    if scheme in ("tcp", "tls", "ws", "wss"):
        try:
            with socket.create_connection((host, port), timeout=10):
                pass
        except OSError as exc:
            raise ConfigError("--scheduler", f"cannot connect to {address}: "
                                             f"{exc.strerror or type(exc).__name__}"[:300]) from None


def _client(address: str, timeout: str):
    """A dask Client of ``address``; one that fails to connect is closed at once and
    quietly (dask's own clean-up would wait 30 s, then print a traceback)."""
    from distributed import Client

    class QuietClient(Client):
        def __del__(self):
            if not getattr(self, "_bench_failed", False):
                super().__del__()

    client = QuietClient.__new__(QuietClient)
    try:
        client.__init__(address, timeout=timeout, set_as_default=False)
    except BaseException:
        client._bench_failed = True
        with contextlib.suppress(BaseException):
            client.close(timeout=1)
        raise
    return client


def worker_environment() -> dict[str, str]:
    """What must match between the driver and a worker for results to be the same: the
    harness version and the registered plugins (importing them warms the worker up)."""
    from radarbench import bench
    from radarbench.bench import registry

    missing = ", ".join(u.source for u in registry.unavailable()) or "-"
    return {"bench": bench.__version__, "methods": ", ".join(registry.methods()),
            "scenarios": ", ".join(registry.scenarios()), "unavailable plugins": missing}


EXECUTORS = ("local", "dask")


def make_executor(name: str, workers: int, scheduler: str | None = None):
    """``local`` (``workers`` processes, even one: a unit that kills its process never kills
    the run), ``dask`` (``scheduler``: an existing cluster) or ``serial`` (in this process;
    for tests and library use)."""
    if name == "dask":
        return DaskExecutor(workers, scheduler)
    if scheduler is not None:
        raise ConfigError("--scheduler", "only with --executor dask")
    if name == "serial":
        return SerialExecutor()
    if name != "local":
        raise ConfigError("--executor", f"unknown executor {name!r} (available: {', '.join(EXECUTORS)})")
    return LocalExecutor(workers)
