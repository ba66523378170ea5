"""Typed, documented, validated parameters for methods and scenarios.

A component declares its parameters in one place, as a frozen dataclass whose
fields are made with :func:`param` (after Stone Soup's ``Property``)::

    @dataclass(frozen=True)
    class Params:
        window: int = param(32, "sliding-window length M (steps)", ge=3)
        normalisation: str = param("consistent", "...", choices=("consistent", "paper"))

:func:`build_params` turns a user's mapping into an instance, checking every
value at the boundary (scikit-learn style) and raising
:class:`~bench.errors.ConfigError` naming the field. A dataclass may add a
``validate(self)`` method for checks across fields; it raises ``ConfigError``.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from typing import Any, Mapping

from bench.errors import ConfigError


def param(default: Any, doc: str, *, ge=None, gt=None, le=None, lt=None,
          choices: tuple | None = None, min_len: int | None = None,
          max_len: int | None = None) -> Any:
    """A dataclass field with documentation and range checks.

    ``ge``/``gt``/``le``/``lt`` bound numbers (and each element of a tuple of
    numbers); ``choices`` restricts strings; ``min_len``/``max_len`` bound the
    length of a tuple.
    """
    meta = {"doc": doc, "ge": ge, "gt": gt, "le": le, "lt": lt,
            "choices": choices, "min_len": min_len, "max_len": max_len}
    if isinstance(default, list):
        default = tuple(default)
    return dataclasses.field(default=default, metadata=meta)


def _type_name(tp: Any) -> str:
    if typing.get_origin(tp) is tuple:
        return f"list of {_type_name(typing.get_args(tp)[0])}"
    return getattr(tp, "__name__", str(tp))


def _describe_bounds(meta: Mapping[str, Any]) -> str:
    parts = []
    for key, sym in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")):
        if meta.get(key) is not None:
            parts.append(f"{sym} {meta[key]}")
    return " and ".join(parts)


def _check_scalar(tp: type, value: Any, meta: Mapping[str, Any]) -> Any:
    """Coerce ``value`` to ``tp`` or raise ConfigError('', problem)."""
    bounds = _describe_bounds(meta)
    want = f"{_type_name(tp)}{' ' + bounds if bounds else ''}"
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError("", f"expected true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError("", f"expected {want}, got {value!r}")
    elif tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError("", f"expected {want}, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError("", f"expected a finite {want}, got {value!r}")
    elif tp is str:
        if not isinstance(value, str):
            raise ConfigError("", f"expected a string, got {value!r}")
        choices = meta.get("choices")
        if choices and value not in choices:
            raise ConfigError("", f"expected one of {', '.join(map(repr, choices))}, got {value!r}")
        return value
    else:  # pragma: no cover - a component declared an unsupported type
        raise TypeError(f"unsupported parameter type {tp!r}")
    tests = {"ge": value.__ge__, "gt": value.__gt__, "le": value.__le__, "lt": value.__lt__}
    for key, holds in tests.items():
        if meta.get(key) is not None and not holds(meta[key]):
            raise ConfigError("", f"expected {want}, got {value!r}")
    return value


def check_value(tp: Any, value: Any, meta: Mapping[str, Any]) -> Any:
    """Validate one value against a field type (scalar or tuple of scalars)."""
    if typing.get_origin(tp) is tuple:
        elem = typing.get_args(tp)[0]
        if not isinstance(value, (list, tuple)):
            raise ConfigError("", f"expected a {_type_name(tp)}, got {value!r}")
        n = len(value)
        if meta.get("min_len") is not None and n < meta["min_len"]:
            raise ConfigError("", f"expected at least {meta['min_len']} values, got {n}")
        if meta.get("max_len") is not None and n > meta["max_len"]:
            raise ConfigError("", f"expected at most {meta['max_len']} values, got {n}")
        out = []
        for i, v in enumerate(value):
            try:
                out.append(_check_scalar(elem, v, meta))
            except ConfigError as err:
                raise ConfigError(f"[{i}]", err.problem) from None
        return tuple(out)
    return _check_scalar(tp, value, meta)


def field_types(cls: type) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def is_tuple_field(cls: type, name: str) -> bool:
    return typing.get_origin(field_types(cls)[name]) is tuple


def build_params(cls: type, values: Mapping[str, Any] | None):
    """Instantiate the params dataclass ``cls`` from a user mapping.

    Unknown names and bad values raise ConfigError naming the field.
    """
    values = dict(values or {})
    types = field_types(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kwargs = {}
    for name, value in values.items():
        if name not in fields:
            known = ", ".join(sorted(fields)) or "none"
            raise ConfigError(str(name), f"unknown parameter (known: {known})")
        try:
            kwargs[name] = check_value(types[name], value, fields[name].metadata)
        except ConfigError as err:
            raise ConfigError(f"{name}{err.field}" if err.field.startswith("[") else name,
                              err.problem) from None
    instance = cls(**kwargs)
    validate = getattr(instance, "validate", None)
    if callable(validate):
        validate()
    return instance


def params_as_dict(params: Any) -> dict[str, Any]:
    """Plain mapping of a params instance (tuples as lists), for TOML/JSON."""
    out = {}
    for f in dataclasses.fields(params):
        v = getattr(params, f.name)
        out[f.name] = list(v) if isinstance(v, tuple) else v
    return out


def describe_params(cls: type) -> list[tuple[str, str, Any, str]]:
    """(name, type, default, doc) of each field, for ``bench list`` and docs."""
    types = field_types(cls)
    return [(f.name, _type_name(types[f.name]), f.default, f.metadata.get("doc", ""))
            for f in dataclasses.fields(cls)]
