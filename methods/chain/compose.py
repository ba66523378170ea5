"""A registered method named by a string with its parameters, ``name[key=value,...]``
(the form of a config label, docs/architecture.md, 'Sweep files and presets'), as a
chain's component: looked up in the registry, its parameters built and checked as a
sweep's would be, every problem one :class:`~bench.errors.ConfigError` naming the
chain's parameter."""

from __future__ import annotations

import functools
import re
import tomllib
from typing import Any

from radarbench.bench.errors import ConfigError
from radarbench.bench.sweep.grid import split_top_level
from radarbench.bench.params import build_params
from radarbench.bench.registry import get_method

SPEC = re.compile(r"([A-Za-z0-9][A-Za-z0-9_.:+\-]*)(?:\[(.*)\])?\Z", re.DOTALL)


def _value(text: str) -> Any:
    """A TOML value (a tuple written ``(a,b)`` as in labels), else the text as a string."""
    toml = "[" + text[1:-1] + "]" if text.startswith("(") and text.endswith(")") else text
    try:
        return tomllib.loads(f"v = {toml}")["v"]
    except tomllib.TOMLDecodeError:
        return text


@functools.lru_cache(maxsize=64)
def component(spec: str, field: str, task: str) -> tuple[Any, Any]:
    """(method instance, its params) of ``spec``, a method of ``task``; ConfigError naming ``field``."""
    match = SPEC.match(spec.strip())
    if match is None:
        raise ConfigError(field, f"expected name or name[key=value,...], got {spec!r}"[:200])
    name, inner = match.groups()
    cls = get_method(name, field)
    if cls.task != task:
        raise ConfigError(field, f"{name!r} is a method of task {cls.task!r}, not of {task!r}")
    values = {}
    for part in split_top_level(inner or ""):
        if not part.strip():
            continue
        key, eq, text = (x.strip() for x in part.partition("="))
        if not eq:
            raise ConfigError(field, f"{spec!r}: expected key=value, got {part!r}"[:200])
        values[key] = _value(text)
    try:
        params = build_params(cls.Params, values)
    except ConfigError as err:
        raise ConfigError(field, f"{name}: {err.field}: {err.problem}"[:300]) from None
    return cls(), params
