"""The processes the harness starts and the driver's signals (docs/architecture.md,
'Runner'): the forkserver that forks every local worker, warm (:mod:`bench.run._forkserver`
preloaded), with SIGINT ignored, and that ends with the driver; the watch by which a
worker exits when its driver dies; the pool of processes for the harness's own work
(the report's figures) and the fresh process of one call (``bench perf``'s measurements);
SIGINT and SIGTERM held back, restored or read as Ctrl-C.
:mod:`bench.run.executors` runs units on these processes.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import multiprocessing
import os
import signal
import threading
from multiprocessing import forkserver
from multiprocessing.connection import wait as _wait
from typing import Callable

#: the signals the driver handles and the workers ignore
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def _signals_deferred():
    """Hold SIGINT and SIGTERM until the block ends, then deliver them to the
    handlers in force before it (an interrupt that lands while a worker is being
    spawned would leave it half-born).

    A Python-level handler (it always runs in the main thread), not a signal
    mask: helper threads would take a masked signal instead.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    previous = {}
    for sig in STOP_SIGNALS:
        previous[sig] = signal.signal(sig, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        for sig, handler in previous.items():
            restore_handler(sig, handler)
        for sig in dict.fromkeys(received):
            signal.raise_signal(sig)


def restore_handler(sig: int, handler) -> None:
    """Put back a handler ``signal.signal`` returned (None: one set outside Python, taken as the default)."""
    signal.signal(sig, signal.SIG_DFL if handler is None else handler)


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt


def sigterm_as_interrupt() -> Callable[[], None]:
    """From now on SIGTERM is handled as Ctrl-C (KeyboardInterrupt in the main thread):
    a command stopped by a service manager or ``kill`` ends as cleanly as one stopped
    at the terminal. Returns the function that restores the previous handler. A SIGTERM
    ignored when the process started stays ignored."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGTERM) is signal.SIG_IGN:
        return lambda: None
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    return lambda: restore_handler(signal.SIGTERM, previous)


#: what the forkserver of the local workers imports once for all of them (bench.run._forkserver)
LOCAL_PRELOAD = ["radarbench.bench.run._forkserver"]
#: environment variable naming the driver to the forkserver it starts (bench.run._forkserver)
DRIVER_ENV = "BENCH_FORKSERVER_DRIVER"


def _start_forkserver(preload: list[str]) -> None:
    """Start the forkserver (if not running) with SIGINT ignored, a disposition
    that survives exec: the server ignores Ctrl-C (a terminal sends it to the
    whole process group) and the driver alone handles it. The server is told
    the driver's pid (:data:`DRIVER_ENV`) so that it exits when the driver dies
    (:mod:`bench.run._forkserver`)."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(preload)
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    os.environ[DRIVER_ENV] = str(os.getpid())
    try:
        forkserver.ensure_running()
    finally:
        os.environ.pop(DRIVER_ENV, None)
        if main:
            restore_handler(signal.SIGINT, previous)


def _exit_with_driver() -> None:
    """In a worker: exit at once when the driver (the parent process) dies, even in the
    middle of a unit. A thread waits on the parent's sentinel (a pipe only the driver
    holds open), so it works whatever started the worker and on every platform."""
    parent = multiprocessing.parent_process()
    sentinel = getattr(parent, "sentinel", None)
    if sentinel is None:
        return

    def watch() -> None:
        try:
            _wait([sentinel])
        finally:
            os._exit(EXIT_DRIVER_GONE)

    threading.Thread(target=watch, name="bench-driver-watch", daemon=True).start()


#: exit status of a worker whose driver died
EXIT_DRIVER_GONE = 75


def prestart_forkserver() -> None:
    """Start the local workers' forkserver now: it imports the harness and the plugins (a
    few seconds of one CPU) while the driver reads the sweep on the other."""
    _start_forkserver(LOCAL_PRELOAD)


def process_pool(workers: int) -> concurrent.futures.ProcessPoolExecutor:
    """A :mod:`concurrent.futures` pool of ``workers`` processes forked by the forkserver
    :class:`LocalExecutor` uses (so they ignore SIGINT), each exiting when the driver dies
    (:func:`_exit_with_driver`: a killed driver leaves none behind), for the harness's own
    work between phases (the report's figures, :mod:`bench.figures`); a plugin's code runs
    only in :class:`LocalExecutor`'s workers, which survive its crashes."""
    _start_forkserver(LOCAL_PRELOAD)
    return concurrent.futures.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("forkserver"),
                                                  initializer=_exit_with_driver)


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


def call_in_fresh_process(fn: Callable, *args):
    """``fn(*args)`` in a fresh spawned process (with this process's environment, so a
    caller can hold it to one core), returned or raised here. The process exits when the
    driver dies (:func:`_exit_with_driver`) and is killed when the call is interrupted
    (Ctrl-C, SIGTERM): an interrupted ``bench perf`` ends at once and leaves no measurement
    running (with a pool, the interrupt waited for the measurement in flight, minutes for
    a peer tracker, and a killed driver left it running as an orphan)."""
    ctx = multiprocessing.get_context("spawn")
    receive, send = ctx.Pipe(duplex=False)
    process = ctx.Process(target=_call_and_send, args=(send, fn, args), name="bench-fresh-process")
    process.start()
    try:
        send.close()                    # the child's end: its death is then an EOF here
        try:
            succeeded, value = receive.recv()
        except EOFError:
            process.join()
            raise RuntimeError(f"the process running {getattr(fn, '__qualname__', fn)} died "
                               f"(exit status {process.exitcode})") from None
    finally:
        if process.is_alive():
            process.kill()
        process.join()
        receive.close()
    if not succeeded:
        raise value
    return value


def _call_and_send(send, fn: Callable, args: tuple) -> None:
    _exit_with_driver()
    try:
        outcome = (True, fn(*args))
    except BaseException as exc:        # noqa: BLE001 - raised again in the caller
        outcome = (False, exc)
    try:
        send.send(outcome)
    except Exception as exc:            # noqa: BLE001 - an unpicklable result or exception
        send.send((False, RuntimeError(f"{getattr(fn, '__qualname__', fn)}: {outcome[1]!r} "
                                       f"could not be sent back ({exc})")))
    send.close()
