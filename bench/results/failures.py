"""Failures are loud: where a plugin's exception was raised in its own code, its full
traceback, and the summary a run with failed units ends with (docs/architecture.md,
'Run folders and faults').

Worker side (:func:`describe`): the one-line cause a unit's failure is stored with names
the deepest frame of the traceback inside the plugin's own package — the line of the
method or scenario that called the library, not the library's innermost line — and the
full traceback is stored beside it (``runs.traceback``). Driver side: :func:`summary_lines`
(stderr at the end of ``bench run``, which then exits 6, ``bench.cli.EXIT_FAILED_UNITS``) and
:func:`traceback_text` (``bench report DIR --tracebacks``).
"""

from __future__ import annotations

import functools
import sys
import traceback
from pathlib import Path

#: characters of a traceback the store keeps (a recursion error's can be huge)
MAX_TRACEBACK = 20_000


@functools.lru_cache(maxsize=None)
def plugin_root(module: str) -> Path | None:
    """The folder of the top-level package of ``module`` (its file for a top-level module):
    the plugin's own code."""
    path = getattr(sys.modules.get(module), "__file__", None)
    if path is None:
        return None
    path = Path(path).resolve()
    if "." not in module and path.name != "__init__.py":
        return path
    return path.parents[module.count(".") - (path.name != "__init__.py")]


def _frame(exc: BaseException, root: Path | None) -> traceback.FrameSummary | None:
    """The deepest frame of ``exc``'s traceback inside ``root``, else the innermost one."""
    frames = traceback.extract_tb(exc.__traceback__)
    own = [f for f in frames if root is not None and Path(f.filename).resolve().is_relative_to(root)]
    return (own or frames or [None])[-1]


def describe(exc: BaseException, cls: type | None = None) -> tuple[str, str]:
    """(``Type: message (file.py:line)`` on one line, the full traceback) of a plugin's
    exception; the line is the deepest frame in the code of plugin class ``cls``."""
    frame = _frame(exc, plugin_root(cls.__module__) if cls is not None else None)
    where = f" ({Path(frame.filename).name}:{frame.lineno})" if frame is not None else ""
    message = " ".join(str(exc).split())
    line = f"{type(exc).__name__}{': ' + message if message else ''}{where}"[:500]
    return line, "".join(traceback.format_exception(exc))[-MAX_TRACEBACK:]


def failed(runs) -> "object":
    """The failed rows of :meth:`bench.results.store.Store.runs`."""
    return runs[runs.error.notna()]


def summary_lines(runs) -> list[str]:
    """Per method config with failures: how many of its units failed (calibration and
    evaluation), on which scenario configs, and the first cause; [] when none failed."""
    bad = failed(runs)
    lines = []
    for method, rows in bad.groupby("method", sort=False):
        total = int((runs.method == method).sum())
        scenarios = ", ".join(dict.fromkeys(rows.scenario))
        lines.append(f"  {method}: {len(rows)} of {total} units failed (on {scenarios}); first: "
                     f"{rows.sort_values('unit').error.iloc[0]}")
    return lines


def traceback_text(runs) -> str:
    """Every distinct stored traceback, once, headed by the configs and units it ended."""
    bad = failed(runs)
    if bad.empty:
        return "No failures: every method config ran on every unit.\n"
    out = []
    for (method, tb), rows in bad.fillna({"traceback": ""}).groupby(["method", "traceback"], sort=False):
        units = list(rows.unit)
        head = f"== {method}: {len(units)} unit{'s' if len(units) != 1 else ''} ({units[0]}" \
               f"{f' and {len(units) - 1} more' if len(units) > 1 else ''})"
        out.append(f"{head}\n{tb or rows.error.iloc[0] + ' (no traceback: the worker did not return)'}")
    return "\n".join(out).rstrip("\n") + "\n"
