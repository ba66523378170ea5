"""Discovery and registration of tasks, methods and scenarios.

A plugin module registers its classes with the decorators::

    from radarbench.bench.registry import register_method

    @register_method
    class Innovation(Method):
        name = "innovation"
        ...

:func:`discover` imports every module of the ``methods`` and ``scenarios``
packages and of their family folders (``methods/tbd/``; a name starting with ``_``
is a helper and left out) and every entry point of the groups ``bench.methods`` and
``bench.scenarios`` (third-party packages). Tasks (:mod:`bench.tasks`) are
the built-ins and the entry points of the group ``bench.tasks``. The built-ins
come first (tasks, scenarios, methods), then the entry points (tasks before the
scenarios and methods that may name them), so a plugin can never take a
built-in's name.

One bad plugin never breaks the tool: a module that fails to import (whatever
it raises, ``SystemExit`` from a ``sys.exit`` at import included), an entry
point that reuses a registered name, names a class of another group, or
declares an unknown task is kept as an :class:`Unavailable` entry with the
reason, shown by ``bench list``; a sweep that names it is told it is
unavailable and why. The harness never imports a plugin by name
(docs/architecture.md, 'Plugins').
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.metadata
import pkgutil
import re
import traceback
from dataclasses import dataclass
from typing import TYPE_CHECKING

from radarbench.bench.errors import ConfigError, is_out_of_memory, unknown_name

if TYPE_CHECKING:  # pragma: no cover - typing only; bench.core (NumPy) is imported on discovery
    from radarbench.bench.core import Method, Scenario

_METHODS: dict[str, type[Method]] = {}
_SCENARIOS: dict[str, type[Scenario]] = {}
_TASK_CLASSES: dict[str, type] = {}
_TASKS: dict = {}        # name -> the instance of its class (bench.tasks.base.Task)


@dataclass(frozen=True)
class Unavailable:
    """A plugin that could not be imported or registered."""

    source: str   # module or entry point
    error: str    # last line of the exception
    name: str = ""   # the registry name it claimed, when known


class PluginError(TypeError):
    """A class that cannot be registered; ``name`` is the registry name it claimed."""

    def __init__(self, message: str, name=""):
        super().__init__(message)
        self.name = name if isinstance(name, str) else ""


#: registry names: what a sweep file can spell and a terminal can print
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}\Z")


_UNAVAILABLE: list[Unavailable] = []
_DISCOVERED = False
_TASKS_DISCOVERED = False
_BUILTIN_TASKS_DONE = False


def _register(table: dict, cls: type, kind: str) -> type:
    name = getattr(cls, "name", "")
    if not isinstance(name, str) or not name:
        raise PluginError(f"{cls.__qualname__} has no registry name")
    if not NAME_PATTERN.match(name):
        raise PluginError(f"{kind} name {name!r}: expected letters, digits and '_.+-' (at most 64)", "")
    existing = table.get(name)
    if existing is not None and existing is not cls and \
            f"{existing.__module__}.{existing.__qualname__}" != f"{cls.__module__}.{cls.__qualname__}":
        raise PluginError(f"{kind} name {name!r} registered twice "
                          f"({existing.__module__} and {cls.__module__})")
    table[name] = cls
    return cls


def _check_params(cls: type, kind: str) -> None:
    """Params a dataclass that keeps the parameter convention (bench.params.declaration_problem)."""
    from radarbench.bench.params import declaration_problem

    name = getattr(cls, "name", cls.__qualname__)
    if not dataclasses.is_dataclass(getattr(cls, "Params", None)):
        raise PluginError(f"{kind} {name!r}: Params is not a dataclass", name)
    problem = declaration_problem(cls.Params)
    if problem:
        raise PluginError(f"{kind} {name!r}: {problem}", name)


def register_method(cls: type[Method]) -> type[Method]:
    known = tasks()
    task = getattr(cls, "task", None)
    if not isinstance(task, str) or task not in known:
        raise PluginError(f"method {getattr(cls, 'name', cls.__qualname__)!r}: task {task!r} is not one of "
                          f"{tuple(known)}", getattr(cls, "name", ""))
    _check_params(cls, "method")
    return _register(_METHODS, cls, "method")


def register_scenario(cls: type[Scenario]) -> type[Scenario]:
    known = tasks()
    served = getattr(cls, "tasks", ())
    name = getattr(cls, "name", cls.__qualname__)
    if not isinstance(served, (tuple, list)) or not all(isinstance(t, str) for t in served):
        raise PluginError(f"scenario {name!r}: tasks must be a tuple of task names, got {served!r}"[:300], name)
    unknown = [t for t in served if t not in known]
    if unknown:
        raise PluginError(f"scenario {name!r}: task {unknown[0]!r} is not one of {tuple(known)}", name)
    _check_params(cls, "scenario")
    return _register(_SCENARIOS, cls, "scenario")


def register_task(cls: type) -> type:
    """Register a :class:`bench.tasks.base.Task` subclass (one instance serves every run)."""
    from radarbench.bench.tasks.base import Task

    if not (isinstance(cls, type) and issubclass(cls, Task)):
        raise PluginError(f"{cls!r} is not a Task subclass")
    instance = cls()
    _register(_TASK_CLASSES, cls, "task")
    _TASKS[cls.name] = instance
    return cls


def _failure(exc: BaseException) -> None:
    """Let a Ctrl-C and the machine's lack of memory through (an import that could not map
    its library is no unavailable plugin: exit 3, never "unknown method"); anything else a
    plugin raises is its own failure."""
    if isinstance(exc, KeyboardInterrupt):
        raise exc
    if is_out_of_memory(exc):
        raise MemoryError(f"out of memory while importing plugins ({_last_line(exc)})") from exc


def _unavailable(source: str, exc: BaseException, name: str = "") -> None:
    claimed = exc.name if isinstance(exc, PluginError) else ""
    _UNAVAILABLE.append(Unavailable(source, _last_line(exc), claimed or name))


def _import_package_modules(package: str) -> None:
    try:
        pkg = importlib.import_module(package)
    except BaseException as exc:  # noqa: BLE001 - reported, not raised (SystemExit too)
        _failure(exc)
        _unavailable(package, exc)
        return
    for info in pkgutil.iter_modules(pkg.__path__, prefix=f"{package}."):
        if info.name.rsplit(".", 1)[-1].startswith("_"):
            continue
        if info.ispkg:               # a family folder (methods/tbd/): its modules, in turn
            _import_package_modules(info.name)
            continue
        try:
            importlib.import_module(info.name)
        except BaseException as exc:  # noqa: BLE001
            _failure(exc)
            _unavailable(info.name, exc)


#: the kind of class each entry-point group registers
_GROUP_KIND = {"bench.tasks": "Task", "bench.scenarios": "Scenario", "bench.methods": "Method"}


def _load_entry_points(group: str) -> None:
    try:
        eps = list(importlib.metadata.entry_points(group=group))
    except BaseException as exc:  # noqa: BLE001 - e.g. unreadable package metadata
        _failure(exc)
        _unavailable(group, exc)
        return
    for ep in eps:
        source = f"{group}:{ep.name}"
        try:
            obj = ep.load()
        except BaseException as exc:  # noqa: BLE001 - SystemExit at import too
            _failure(exc)
            _unavailable(source, exc, ep.name)
            continue
        # An entry point may name a module (whose decorators register) or a class of its group.
        try:
            _register_class(obj, group)
        except BaseException as exc:  # noqa: BLE001
            _failure(exc)
            _unavailable(source, exc, ep.name)


def _register_class(obj, group: str) -> None:
    from radarbench.bench.core import Method, Scenario
    from radarbench.bench.tasks.base import Task

    if not isinstance(obj, type):
        return                       # a module: its decorators registered what it holds
    kinds = {"Task": Task, "Scenario": Scenario, "Method": Method}
    wanted = _GROUP_KIND[group]
    if not issubclass(obj, kinds[wanted]):
        actual = next((k for k, base in kinds.items() if issubclass(obj, base)), None)
        raise PluginError(f"{obj.__module__}.{obj.__qualname__} is "
                          f"{f'a {actual}' if actual else 'not a Task, Scenario or Method'}, "
                          f"not a {wanted} (entry-point group {group})", getattr(obj, "name", "") or "")
    {"Task": register_task, "Scenario": register_scenario, "Method": register_method}[wanted](obj)


def _last_line(exc: BaseException) -> str:
    """The exception as one printable line (a plugin's message may hold newlines or terminal codes)."""
    if isinstance(exc, SystemExit):
        return f"SystemExit: {exc.code!r} (sys.exit called at import)"
    line = str(exc) if isinstance(exc, PluginError) else traceback.format_exception_only(type(exc), exc)[-1].strip()
    line = "".join(c if c.isprintable() else repr(c)[1:-1] for c in line[:1200])
    return line if len(line) <= 300 else line[:297] + "..."


def discovered() -> bool:
    """Whether this process has imported the plugins already."""
    return _DISCOVERED


def discover() -> None:
    """Import all plugins once per process: the built-ins, then the entry points; their
    numba kernels keep a cache whose failures never fail them (:mod:`bench.numba_cache`)."""
    global _DISCOVERED
    if _DISCOVERED:
        return
    _DISCOVERED = True
    from radarbench.bench import numba_cache
    numba_cache.install()           # before any plugin's kernel is decorated (bench/numba_cache.py)
    _builtin_tasks()
    _import_package_modules("radarbench.scenarios")
    _import_package_modules("radarbench.methods")
    _discover_tasks()
    _load_entry_points("bench.scenarios")
    _load_entry_points("bench.methods")


def _builtin_tasks() -> None:
    global _BUILTIN_TASKS_DONE
    if _BUILTIN_TASKS_DONE:
        return
    _BUILTIN_TASKS_DONE = True
    from radarbench.bench.tasks import BUILTIN_TASKS

    for cls in BUILTIN_TASKS:
        register_task(cls)


def _discover_tasks() -> None:
    """The entry points of ``bench.tasks``, once per process, after the built-ins (a plugin
    task cannot take a built-in's name, nor register a method before the built-in ones)."""
    global _TASKS_DISCOVERED
    if _TASKS_DISCOVERED:
        return
    _TASKS_DISCOVERED = True
    _load_entry_points("bench.tasks")


def tasks() -> dict:
    """Task name -> :class:`bench.tasks.base.Task`: the built-ins, then the plugins'."""
    if not _DISCOVERED:
        discover()
    return dict(_TASKS)


def get_task(name: str, field: str = "task"):
    """The task ``name`` (ConfigError naming ``field`` when unknown or unavailable)."""
    return _lookup(tasks(), name, "task", field)


def methods() -> dict[str, type[Method]]:
    discover()
    return dict(sorted(_METHODS.items()))


def scenarios() -> dict[str, type[Scenario]]:
    discover()
    return dict(sorted(_SCENARIOS.items()))


def unavailable() -> list[Unavailable]:
    discover()
    return list(_UNAVAILABLE)


def unavailable_reason(name: str) -> str | None:
    """Why the plugin ``name`` (or the module of that name) could not be
    registered, in one line; None when it is not among the unavailable ones."""
    hint = next((u for u in unavailable()
                 if name in (u.name, re.split(r"[.:]", u.source)[-1].replace("_", "-"))), None)
    return None if hint is None else hint.error


def _lookup(table: dict, name: str, kind: str, field: str):
    if name in table:
        return table[name]
    reason = unavailable_reason(name)
    if reason is not None:
        raise ConfigError(field, f"{kind} {name!r} is unavailable: {reason}")
    raise ConfigError(field, unknown_name(kind, name, table))


def get_method(name: str, field: str = "method") -> type[Method]:
    return _lookup(methods(), name, "method", field)


def get_scenario(name: str, field: str = "scenario") -> type[Scenario]:
    return _lookup(scenarios(), name, "scenario", field)
