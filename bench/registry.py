"""Discovery and registration of tasks, methods and scenarios.

A plugin module registers its classes with the decorators::

    from bench.registry import register_method

    @register_method
    class Innovation(Method):
        name = "innovation"
        ...

:func:`discover` imports every module of the ``methods`` and ``scenarios``
packages and every entry point of the groups ``bench.methods`` and
``bench.scenarios`` (third-party packages). Tasks (:mod:`bench.tasks`) are
the built-ins and the entry points of the group ``bench.tasks``, found before
any method registers (a method's task must exist). A module that fails to
import is kept as an :class:`Unavailable` entry with its error, shown by
``bench list``; it never breaks the rest. The harness never imports a plugin
by name (docs/architecture.md, 'Plugins').
"""

from __future__ import annotations

import importlib
import importlib.metadata
import pkgutil
import re
import traceback
from dataclasses import dataclass

from bench.core import Method, Scenario
from bench.errors import ConfigError

_METHODS: dict[str, type[Method]] = {}
_SCENARIOS: dict[str, type[Scenario]] = {}
_TASK_CLASSES: dict[str, type] = {}
_TASKS: dict = {}        # name -> the instance of its class (bench.tasks.base.Task)


@dataclass(frozen=True)
class Unavailable:
    """A plugin module that could not be imported."""

    source: str   # module or entry point
    error: str    # last line of the exception


_UNAVAILABLE: list[Unavailable] = []
_DISCOVERED = False
_TASKS_DISCOVERED = False


def _register(table: dict, cls: type, kind: str) -> type:
    if not cls.name:
        raise TypeError(f"{cls.__qualname__} has no registry name")
    existing = table.get(cls.name)
    if existing is not None and existing is not cls and \
            f"{existing.__module__}.{existing.__qualname__}" != f"{cls.__module__}.{cls.__qualname__}":
        raise TypeError(f"{kind} name {cls.name!r} registered twice "
                        f"({existing.__module__} and {cls.__module__})")
    table[cls.name] = cls
    return cls


def register_method(cls: type[Method]) -> type[Method]:
    known = tasks()
    if cls.task not in known:
        raise TypeError(f"method {cls.name!r}: task {cls.task!r} is not one of {tuple(known)}")
    return _register(_METHODS, cls, "method")


def register_scenario(cls: type[Scenario]) -> type[Scenario]:
    return _register(_SCENARIOS, cls, "scenario")


def register_task(cls: type) -> type:
    """Register a :class:`bench.tasks.base.Task` subclass (one instance serves every run)."""
    from bench.tasks.base import Task

    if not (isinstance(cls, type) and issubclass(cls, Task)):
        raise TypeError(f"{cls!r} is not a Task subclass")
    _register(_TASK_CLASSES, cls, "task")
    _TASKS[cls.name] = cls()
    return cls


def _import_package_modules(package: str) -> None:
    try:
        pkg = importlib.import_module(package)
    except Exception as exc:  # noqa: BLE001 - reported, not raised
        _UNAVAILABLE.append(Unavailable(package, _last_line(exc)))
        return
    for info in pkgutil.iter_modules(pkg.__path__, prefix=f"{package}."):
        if info.name.rsplit(".", 1)[-1].startswith("_"):
            continue
        try:
            importlib.import_module(info.name)
        except Exception as exc:  # noqa: BLE001
            _UNAVAILABLE.append(Unavailable(info.name, _last_line(exc)))


def _load_entry_points(group: str) -> None:
    for ep in importlib.metadata.entry_points(group=group):
        try:
            obj = ep.load()
        except Exception as exc:  # noqa: BLE001
            _UNAVAILABLE.append(Unavailable(f"{group}:{ep.name}", _last_line(exc)))
            continue
        # An entry point may name a module (whose decorators register) or a class.
        try:
            _register_class(obj)
        except Exception as exc:  # noqa: BLE001
            _UNAVAILABLE.append(Unavailable(f"{group}:{ep.name}", _last_line(exc)))


def _register_class(obj) -> None:
    from bench.tasks.base import Task

    if isinstance(obj, type):
        if issubclass(obj, Method):
            register_method(obj)
        elif issubclass(obj, Scenario):
            register_scenario(obj)
        elif issubclass(obj, Task):
            register_task(obj)


def _last_line(exc: BaseException) -> str:
    return traceback.format_exception_only(type(exc), exc)[-1].strip()


def discover() -> None:
    """Import all plugins once per process."""
    global _DISCOVERED
    if _DISCOVERED:
        return
    _DISCOVERED = True
    _discover_tasks()
    _import_package_modules("scenarios")
    _import_package_modules("methods")
    _load_entry_points("bench.scenarios")
    _load_entry_points("bench.methods")


def _discover_tasks() -> None:
    """The built-in tasks, then the entry points of ``bench.tasks``, once per process."""
    global _TASKS_DISCOVERED
    if _TASKS_DISCOVERED:
        return
    _TASKS_DISCOVERED = True
    from bench.tasks import BUILTIN_TASKS

    for cls in BUILTIN_TASKS:
        register_task(cls)
    _load_entry_points("bench.tasks")


def tasks() -> dict:
    """Task name -> :class:`bench.tasks.base.Task`: the built-ins, then the plugins'."""
    _discover_tasks()
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


def _lookup(table: dict, name: str, kind: str, field: str):
    if name in table:
        return table[name]
    hint = next((u for u in unavailable() if re.split(r"[.:]", u.source)[-1].replace("_", "-") == name), None)
    if hint is not None:
        raise ConfigError(field, f"{kind} {name!r} is unavailable: {hint.error}")
    known = ", ".join(table) or "none"
    raise ConfigError(field, f"unknown {kind} {name!r} (known: {known})")


def get_method(name: str, field: str = "method") -> type[Method]:
    return _lookup(methods(), name, "method", field)


def get_scenario(name: str, field: str = "scenario") -> type[Scenario]:
    return _lookup(scenarios(), name, "scenario", field)
