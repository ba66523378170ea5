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
scenarios and methods that may name them).

A name two classes claim (a built-in and a plugin, two plugins) keeps both: the bare
name is refused wherever a sweep names it, in one line naming both modules and the
qualified names to choose between, ``qualifier:name`` (:data:`QUALIFIED`). A class's
qualifier is the name of the distribution whose entry point registered it, else the
top-level package of its module (``radarbench`` for the built-ins); its top-level
package and its module are accepted too. A qualified name works whether or not the
bare name is contested, so a sweep can say which plugin it means before a collision
happens (docs/architecture.md, 'Plugins').

One bad plugin never breaks the tool: a module that fails to import (whatever
it raises, ``SystemExit`` from a ``sys.exit`` at import included), an entry
point that names a class of another group, or declares an unknown task is kept
as an :class:`Unavailable` entry with the reason, shown by ``bench list``; a
sweep that names it is told it is unavailable and why. The harness never
imports a plugin by name (docs/architecture.md, 'Plugins').
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

#: name -> the first class registered under it (the later ones are in _RIVALS)
_METHODS: dict[str, type[Method]] = {}
_SCENARIOS: dict[str, type[Scenario]] = {}
_TASK_CLASSES: dict[str, type] = {}
_TASKS: dict = {}        # name -> the instance of its class (bench.tasks.base.Task)
_INSTANCES: dict = {}    # task class -> its instance (every claimant of a task name)
#: kind -> name -> the classes registered under a name after the first, in order
_RIVALS: dict[str, dict[str, list[type]]] = {"method": {}, "scenario": {}, "task": {}}
#: class -> its qualifier, for a class an entry point registered (else: qualifier())
_QUALIFIERS: dict[type, str] = {}
#: class -> the distribution (importlib.metadata) whose entry point registered it
_DISTRIBUTIONS: dict[type, object] = {}
#: (qualifier, distribution) of the entry point being loaded: what its module registers is theirs
_LOADING: tuple[str, object] | None = None


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
#: a qualified name, ``qualifier:name``: the class registered under ``name`` by the
#: distribution, top-level package or module ``qualifier`` (a registry name has no ':')
QUALIFIED = re.compile(r"^([A-Za-z0-9][A-Za-z0-9_.-]{0,199}):([^:]*)\Z")


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
    if existing is None or _same_class(existing, cls):
        table[name] = cls
    else:                            # a rival: kept, and the bare name refused (_find)
        rivals = _RIVALS[kind].setdefault(name, [])
        rivals[:] = [c for c in rivals if not _same_class(c, cls)] + [cls]
    if _LOADING is not None:
        _QUALIFIERS[cls], _DISTRIBUTIONS[cls] = _LOADING
    return cls


def _same_class(a: type, b: type) -> bool:
    """One class (a module imported again defines it anew)."""
    return a is b or f"{a.__module__}.{a.__qualname__}" == f"{b.__module__}.{b.__qualname__}"


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
    known = _task_names(getattr(cls, "task", None))   # the names claimed: one claimed twice is refused where used
    task = getattr(cls, "task", None)
    if not isinstance(task, str) or task not in known:
        raise PluginError(f"method {getattr(cls, 'name', cls.__qualname__)!r}: task {task!r} is not one of "
                          f"{known}", getattr(cls, "name", ""))
    if "scenarios" in vars(cls) or any("scenarios" in vars(base) for base in cls.__mro__[1:-1]):
        # the pairing by a list of scenario names gave way to capabilities: a class that
        # still sets one would be paired with every scenario of its task, without a word
        raise PluginError(f"method {getattr(cls, 'name', cls.__qualname__)!r}: 'scenarios' is no longer read; "
                          "declare what it reads from a scene in 'needs' (docs/extending.md)", getattr(cls, "name", ""))
    _check_params(cls, "method")
    return _register(_METHODS, cls, "method")


def register_scenario(cls: type[Scenario]) -> type[Scenario]:
    served = getattr(cls, "tasks", ())
    known = _task_names(*(served if isinstance(served, (tuple, list)) else (None,)))
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
    _INSTANCES[cls] = instance
    if _TASK_CLASSES[cls.name] is cls:
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
    global _LOADING
    for ep in eps:
        source = f"{group}:{ep.name}"
        _LOADING = (_entry_point_qualifier(ep), getattr(ep, "dist", None))
        try:
            _load_entry_point(ep, group, source)
        finally:
            _LOADING = None


def _load_entry_point(ep, group: str, source: str) -> None:
    try:
        obj = ep.load()
    except BaseException as exc:  # noqa: BLE001 - SystemExit at import too
        _failure(exc)
        _unavailable(source, exc, ep.name)
        return
    # An entry point may name a module (whose decorators register) or a class of its group.
    try:
        _register_class(obj, group)
    except BaseException as exc:  # noqa: BLE001
        _failure(exc)
        _unavailable(source, exc, ep.name)


def _entry_point_qualifier(ep) -> str:
    """The qualifier of what an entry point registers: its distribution's name (normalised
    as pip does, ``My_Lab`` -> ``my-lab``), else the top-level package it names."""
    dist = getattr(ep, "dist", None)
    name = getattr(dist, "name", None) or ep.value.split(":")[0].split(".")[0]
    return _normal(name)


def _normal(qualifier: str) -> str:
    return re.sub(r"[-_.]+", "-", qualifier).lower()


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


#: whether discover() ran to its end (out of memory stops it half-way)
_WHOLE = False


def discovered() -> bool:
    """Whether this process has imported the plugins already."""
    return _DISCOVERED


def discover() -> None:
    """Import all plugins once per process: the built-ins, then the entry points; their
    numba kernels keep a cache whose failures never fail them (:mod:`bench.run.numba_cache`)."""
    global _DISCOVERED, _WHOLE
    if _DISCOVERED:
        return
    _DISCOVERED = True
    from radarbench.bench.run import numba_cache
    numba_cache.install()           # before any plugin's kernel is decorated (bench/run/numba_cache.py)
    _builtin_tasks()
    _import_package_modules("radarbench.scenarios")
    _import_package_modules("radarbench.methods")
    _discover_tasks()
    _load_entry_points("bench.scenarios")
    _load_entry_points("bench.methods")
    _WHOLE = True


def _task_names(*wanted: str) -> tuple[str, ...]:
    """The task names a method or scenario may name. The built-ins answer for a built-in
    task without importing the other plugins (a module registering its class, imported on
    its own, would otherwise import its siblings while half-initialised, and a sibling
    importing from it would fail as unavailable); a task they lack is looked for by the
    whole discovery, which finds the plugins' tasks after the built-in plugins."""
    if not _BUILTIN_TASKS_DONE:
        from radarbench.bench.run import numba_cache
        numba_cache.install()       # as discover() does, before the registering module's kernels compile
    _builtin_tasks()
    if any(not isinstance(t, str) or t not in _TASKS for t in wanted):
        tasks()
    return tuple(_TASKS)


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
    """Task name -> :class:`bench.tasks.base.Task`: the built-ins, then the plugins' (a
    name claimed twice as each claimant's qualified name)."""
    if not _DISCOVERED:
        discover()
    return {name: _INSTANCES.get(cls) or _TASKS[cls.name] for name, cls in _named("task").items()}


def get_task(name: str, field: str = "task"):
    """The task ``name`` (ConfigError naming ``field`` when unknown, unavailable or claimed twice)."""
    if not _DISCOVERED:
        discover()
    cls = _lookup("task", name, field)
    return _INSTANCES.get(cls) or _TASKS[cls.name]


def methods() -> dict[str, type[Method]]:
    """Method name -> class; a name claimed twice as each claimant's qualified name."""
    discover()
    return dict(sorted(_named("method").items()))


def scenarios() -> dict[str, type[Scenario]]:
    discover()
    return dict(sorted(_named("scenario").items()))


def unavailable() -> list[Unavailable]:
    discover()
    return list(_UNAVAILABLE)


def unavailable_reason(name: str) -> str | None:
    """Why the plugin ``name`` (or the module of that name) could not be
    registered, in one line; None when it is not among the unavailable ones."""
    return _reason_among(name, unavailable())


def _reason_among(name: str, missing: list[Unavailable]) -> str | None:
    name = bare_name(name)
    hint = next((u for u in missing if name in (u.name, re.split(r"[.:]", u.source)[-1].replace("_", "-"))), None)
    return None if hint is None else hint.error


def absent(kind: str, name: str, named, missing: list[Unavailable]) -> str:
    """Why ``name``, claimed by no ``kind`` registered, names none: its plugin is one of
    ``missing`` (unavailable), or it is unknown among ``named`` (the registry's names)."""
    reason = _reason_among(name, missing)
    if reason is not None:
        return f"{kind} {name!r} is unavailable: {reason}"
    return unknown_name(kind, name, named)


def names() -> dict | None:
    """What :func:`absent_from` needs to answer a name without the plugins: per kind the
    names claimed and the registry's names (a name claimed twice qualified), and the
    unavailable plugins (kept by :mod:`bench.sweep.listing` beside the listing); None
    when the discovery stopped half-way (out of memory), so no partial table is kept."""
    discover()
    if not _WHOLE:
        return None
    return {**{kind: {"claimed": sorted(_table(kind)), "named": sorted(_named(kind))}
               for kind in ("method", "scenario")},
            "unavailable": [dataclasses.astuple(u) for u in _UNAVAILABLE]}


def absent_from(table: dict, kind: str, name: str) -> str:
    """Why the bare ``name`` names no ``kind`` of ``table`` (:func:`names`), "" when some
    plugin claims it or it is qualified (only the registry can judge a qualifier)."""
    if QUALIFIED.match(name) or name in table[kind]["claimed"]:
        return ""
    return absent(kind, name, table[kind]["named"], [Unavailable(*u) for u in table["unavailable"]])


def bare_name(name: str) -> str:
    """``glr`` of ``mylab:glr`` (a bare name is its own)."""
    match = QUALIFIED.match(name)
    return match.group(2) if match else name


def _table(kind: str) -> dict:
    return {"method": _METHODS, "scenario": _SCENARIOS, "task": _TASK_CLASSES}[kind]


def _claimants(kind: str, name: str) -> list[type]:
    """Every class registered under ``name``, the first first."""
    first = _table(kind).get(name)
    return ([first] if first is not None else []) + _RIVALS[kind].get(name, [])


def _named(kind: str) -> dict[str, type]:
    """Name -> class, a name claimed twice under each claimant's qualified name."""
    out = {}
    for name in _table(kind):
        claims = _claimants(kind, name)
        out |= {name: claims[0]} if len(claims) == 1 else dict(zip(_choices(claims), claims))
    return out


def qualifier(cls: type) -> str:
    """The qualifier of a registered class (see the module doc)."""
    return _QUALIFIERS.get(cls) or cls.__module__.split(".")[0]


def origin(cls: type) -> dict[str, str]:
    """``{"module": ..., "distribution": ...}`` of a registered class: the distribution whose
    entry point registered it, else the one installing its package
    (:func:`bench.results.provenance.distribution_of`)."""
    from radarbench.bench.results.provenance import distribution_of

    return {"module": cls.__module__, "distribution": distribution_of(cls.__module__, _DISTRIBUTIONS.get(cls))}


def _qualifiers_of(cls: type) -> list[str]:
    """What a qualified name may say to pick ``cls``, from the shortest."""
    return [qualifier(cls), cls.__module__.split(".")[0], cls.__module__, f"{cls.__module__}.{cls.__qualname__}"]


def _choices(claims: list[type]) -> list[str]:
    """A qualified name for each claimant: the first kind of qualifier that tells them all apart."""
    for level in range(4):
        names = [f"{_qualifiers_of(c)[level]}:{c.name}" for c in claims]
        if len({_normal(n) for n in names}) == len(names):
            return names
    return names


def collisions() -> dict[str, dict[str, str]]:
    """Kind -> name -> the one line that refuses it, for every name claimed twice."""
    discover()
    return {kind: {name: _collision(kind, name, _claimants(kind, name))
                   for name, rivals in table.items() if rivals and name in _table(kind)}
            for kind, table in _RIVALS.items()}


def _collision(kind: str, name: str, claims: list[type]) -> str:
    """``method 'glr' is registered twice (a.glr (dist-a 1.0), b.glr (dist-b 0.1)): name 'a:glr' or 'b:glr'``."""
    from radarbench.bench.results.provenance import origin_text

    times = "twice" if len(claims) == 2 else f"{len(claims)} times"
    where = ", ".join(origin_text(origin(c)) for c in claims)
    if kind == "task":             # methods and scenarios name their task bare: a sweep cannot choose
        return f"task {name!r} is registered {times} ({where}): its methods cannot say which; uninstall one of them"
    choices = [repr(q) for q in _choices(claims)]
    return f"{kind} {name!r} is registered {times} ({where}): name {', '.join(choices[:-1])} or {choices[-1]}"


def _find(kind: str, name: str) -> tuple[type | None, str]:
    """(the class ``name`` means, "") or (None, why it means none)."""
    match = QUALIFIED.match(name)
    bare = match.group(2) if match else name
    claims = _claimants(kind, bare)
    if match:
        chosen = _picked(kind, *match.groups())
        if len(chosen) > 1:
            return None, _collision(kind, bare, chosen)
        if chosen:
            return chosen[0], ""
        if claims:
            choices = " or ".join(map(repr, _choices(claims)))
            return None, (f"{kind} {name!r}: no {kind} {bare!r} registered by {match.group(1)!r} (it is registered "
                          f"by {', '.join(c.__module__ for c in claims)}: name {choices})")
    if len(claims) == 1:
        return claims[0], ""
    if len(claims) > 1:
        return None, _collision(kind, bare, claims)
    return None, absent(kind, name, _named(kind), unavailable())


def _picked(kind: str, qualifier: str, bare: str) -> list[type]:
    """The classes registered under ``bare`` that ``qualifier`` names."""
    wanted = _normal(qualifier)
    return [c for c in _claimants(kind, bare) if wanted in {_normal(q) for q in _qualifiers_of(c)}]


def missing_reason(kind: str, name: str) -> str | None:
    """Why ``name`` names nothing installed here (its plugin is unavailable, or its
    qualifier registered no such name), for an ``optional`` sweep entry to be skipped;
    None when it is registered, even twice (refused where used, never skipped)."""
    discover()
    match = QUALIFIED.match(name)
    if match and not _picked(kind, *match.groups()):
        return unavailable_reason(name) or _find(kind, name)[1]
    return None if _claimants(kind, bare_name(name)) else unavailable_reason(name)


def problem(kind: str, name: str) -> str:
    """Why ``name`` names no single registered ``kind`` ("method", "scenario" or "task"); "" if it does."""
    discover()
    return _find(kind, name)[1]


def claimed(kind: str, name: str) -> bool:
    """Whether some ``kind`` is registered under the registry name of ``name``."""
    discover()
    return bool(_claimants(kind, bare_name(name)))


def _lookup(kind: str, name: str, field: str):
    cls, why = _find(kind, name)
    if cls is None:
        raise ConfigError(field, why)
    return cls


def get_method(name: str, field: str = "method") -> type[Method]:
    discover()
    return _lookup("method", name, field)


def find_scenario(name: str) -> type[Scenario] | None:
    """The scenario class ``name`` (bare or qualified) means, None when it means none."""
    discover()
    return _find("scenario", name)[0]


def get_scenario(name: str, field: str = "scenario") -> type[Scenario]:
    discover()
    return _lookup("scenario", name, field)
