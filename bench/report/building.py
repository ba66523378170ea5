"""How a report is built incrementally (docs/architecture.md, 'Report'): the processes that
draw the figures, started only when a figure must be drawn; the report phase's progress,
a step per section with the figures drawn and reused; report.html's interactive figures,
reused from the user's cache (:mod:`bench.results.figure_cache`)."""

from __future__ import annotations

import contextlib
import importlib

from radarbench.bench import figures
from radarbench.bench.run.processes import default_workers, process_pool
from radarbench.bench.run.progress import Progress
from radarbench.bench.report.html import interactive_figures
from radarbench.bench.results.figure_cache import code_key, harness_key, key_of, reuse_in_effect


#: the most processes that render a report's figures (:func:`figure_pool`)
FIGURE_WORKERS = 4


class LazyPool:
    """A pool of ``workers`` processes (:func:`bench.run.processes.process_pool`) started by its
    second :meth:`submit`: the first job is declined (None: :func:`bench.figures.result_of`
    runs it here, cheaper than starting processes that import matplotlib), so a report
    whose figures are reused but one (the runtime's) starts none."""

    def __init__(self, workers: int):
        self.workers = workers
        self.pool = None
        self.declined = False

    def submit(self, fn, *args):
        if not self.declined:
            self.declined = True
            return None
        if self.pool is None:
            self.pool = process_pool(self.workers)
            for _ in range(self.workers - 1):      # the others start too, importing matplotlib
                figures.submitted(self.pool, importlib.import_module, figures.__name__)
        return self.pool.submit(fn, *args)

    def shutdown(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()


@contextlib.contextmanager
def figure_pool(workers: int | None = None):
    """Processes, one per CPU up to :data:`FIGURE_WORKERS` (and ``workers``), that render the figures while
    the report goes on (:func:`bench.figures.rendering_in`); on one CPU, none. They are
    started when the first figure must be drawn (:class:`LazyPool`)."""
    workers = min(FIGURE_WORKERS, default_workers(), workers or FIGURE_WORKERS)
    if workers < 2:
        yield None
        return
    pool = LazyPool(workers)
    try:
        yield pool
    finally:
        pool.shutdown()


class Sections:
    """The report phase's progress: a step per section (and the tables, the pages), with
    the figures drawn and reused so far."""

    def __init__(self, progress: Progress, tasks: int):
        self.progress = progress
        progress.phase("report", total=4 + 2 * tasks, label="sections")

    def done(self, what: str) -> None:
        """``what`` (a section, the tables) is done."""
        reuse = reuse_in_effect()
        if reuse is not None:
            self.progress.detail(reuse.summary())
        self.progress.advance()


def interactive_job(pool, specs: list):
    """(report.html's interactive figures if the user's cache holds them, else None; the
    pool's job drawing them, else None; their key)."""
    reuse = reuse_in_effect()
    key = key_of(specs, code_key(interactive_figures.__module__))
    kept = reuse.fetch(key, ".html") if reuse is not None and key else None
    if kept is not None:
        return kept.decode("utf-8"), None, key
    return None, figures.submitted(pool, interactive_figures, specs) if pool is not None else None, key


def interactive_html(kept, job, key, specs: list) -> str:
    """report.html's interactive figures: as kept, else drawn (by ``job``, or here) and kept."""
    if kept is not None:
        return kept
    text = figures.result_of(job, interactive_figures, specs)
    reuse = reuse_in_effect()
    if reuse is not None and key:
        reuse.keep(key, ".html", text.encode("utf-8"))
    return text


def each_done(parts, sections: Sections, what: str) -> list:
    """``parts`` (a task's sections), counted as one step of ``sections`` once drawn."""
    parts = list(parts)
    sections.done(what)
    return parts


def reused_output(path, inputs, write) -> None:
    """``write(path)`` (an output drawn by the harness from ``inputs`` alone, the
    recording), unless the run folder or the user's cache holds it for the same inputs and
    harness code (:mod:`bench.results.figure_cache`)."""
    reuse = reuse_in_effect()
    key = key_of(inputs, harness_key()) if reuse is not None else None
    if key is not None and reuse.reuse(path, key, figure=False):
        return
    write(path)
    if key is not None:
        with open(path, "rb") as f:
            reuse.written(path, key, f.read(), figure=False)
