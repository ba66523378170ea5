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

**Bounds.** Every number a component declares is bounded on both sides
(``ge``/``gt`` and ``le``/``lt``) and the reason for the bounds is documented
with ``why=`` (e.g. "beyond it the trellis has more nodes than a unit can
hold"): validation must cover what runs, so a value the checks accept is one
the component runs to completion at a small size (``tests/property/
test_hostile_input.py`` runs every bound). Bounds are metadata: they never
change a config's resolved values (:func:`params_as_dict`) nor its random
stream. Integers of any size and floats are compared exactly; an integer too
large for a float is refused with one line, never an ``OverflowError``.
"""

from __future__ import annotations

import dataclasses
import math
import operator
import os
import re
import stat
import typing
from typing import Any, Mapping

from radarbench.bench.errors import ConfigError

#: the ``kind`` of a parameter that names a data file
PATH = "path"
#: a declared choice: a word of a config label's alphabet (:data:`bench.sweep.grid.LABEL_PATTERN`)
#: without the label's own punctuation (``,=[]()``) or blanks at its ends, so a config that
#: sets it has a label that reads back as its own (``name[key=choice]``)
CHOICE_PATTERN = re.compile(r"[A-Za-z0-9_.+\-]([A-Za-z0-9_.+\- ]{0,62}[A-Za-z0-9_.+\-])?\Z")


def param(default: Any, doc: str, *, ge=None, gt=None, le=None, lt=None,
          choices: tuple | None = None, min_len: int | None = None,
          max_len: int | None = None, why: str | None = None, kind: str | None = None) -> Any:
    """A dataclass field with documentation and range checks.

    ``ge``/``gt``/``le``/``lt`` bound numbers (and each element of a tuple of
    numbers); ``choices`` restricts strings; ``min_len``/``max_len`` bound the
    length of a tuple; ``why`` says why the bounds are where they are (shown by
    ``bench list -v``). ``kind="path"`` (a ``str`` field): a data file the
    component reads; a sweep's relative path is read from the sweep file's folder
    (:func:`resolve_path`), "" means none, and the file's content is part of the
    config's identity (:mod:`bench.run.identity`).
    """
    if kind not in (None, PATH):
        raise TypeError(f"param kind {kind!r}: expected None or {PATH!r}")
    meta = {"doc": doc, "ge": ge, "gt": gt, "le": le, "lt": lt,
            "choices": choices, "min_len": min_len, "max_len": max_len, "why": why, "kind": kind}
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


#: integers with more digits than this are shown by their size, not their digits
_SHOWN_DIGITS = 40


def show(value: Any, limit: int = 120) -> str:
    """``repr(value)`` for an error message: an integer too long to print
    (Python refuses to convert one above 4300 digits) by its size, anything
    else cut to ``limit`` characters."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 3.33 * _SHOWN_DIGITS:
        digits = int(value.bit_length() * math.log10(2)) + 1
        return f"{'-' if value < 0 else ''}an integer of about {digits} digits"
    if isinstance(value, (list, tuple, dict)) and len(value) > 50:
        return f"a {type(value).__name__} of {len(value)} values"
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def as_float(value: Any) -> float | None:
    """``value`` (an int or a float, not a bool) as a float; None if it is not
    a number or an integer too large for a float (never an OverflowError)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        return float(value)
    except OverflowError:
        return None


_COMPARE = {"ge": operator.ge, "gt": operator.gt, "le": operator.le, "lt": operator.lt}


def within_bounds(value: Any, meta: Mapping[str, Any]) -> bool:
    """Whether the number ``value`` satisfies the ``ge``/``gt``/``le``/``lt`` of ``meta``
    (compared exactly, ints with floats too: ``int.__ge__(float)`` is NotImplemented)."""
    return all(meta.get(key) is None or holds(value, meta[key]) for key, holds in _COMPARE.items())


def _check_scalar(tp: type, value: Any, meta: Mapping[str, Any]) -> Any:
    """Coerce ``value`` to ``tp`` or raise ConfigError('', problem)."""
    bounds = _describe_bounds(meta)
    want = f"{_type_name(tp)}{' ' + bounds if bounds else ''}"
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError("", f"expected true or false, got {show(value)}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError("", f"expected {want}, got {show(value)}")
    elif tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError("", f"expected {want}, got {show(value)}")
        number = as_float(value)
        if number is None or not math.isfinite(number):
            raise ConfigError("", f"expected a finite {want}, got {show(value)}")
        value = number
    elif tp is str:
        if not isinstance(value, str):
            raise ConfigError("", f"expected a string, got {show(value)}")
        choices = meta.get("choices")
        if choices and value not in choices:
            raise ConfigError("", f"expected one of {', '.join(map(repr, choices))}, got {show(value)}")
        return value
    else:  # pragma: no cover - a component declared an unsupported type
        raise TypeError(f"unsupported parameter type {tp!r}")
    for key, holds in _COMPARE.items():
        if meta.get(key) is not None and not holds(value, meta[key]):     # name the bound it breaks
            why = meta.get("why")
            raise ConfigError("", f"expected {_type_name(tp)} {_describe_bounds({key: meta[key]})}, "
                                  f"got {show(value)}" + (f" ({why})" if why else ""))
    return value


def check_value(tp: Any, value: Any, meta: Mapping[str, Any]) -> Any:
    """Validate one value against a field type (scalar or tuple of scalars)."""
    if typing.get_origin(tp) is tuple:
        elem = typing.get_args(tp)[0]
        if not isinstance(value, (list, tuple)):
            raise ConfigError("", f"expected a {_type_name(tp)}, got {show(value)}")
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


def resolve_path(value: str, base: str | os.PathLike) -> str:
    """A ``kind="path"`` value of a sweep read from folder ``base``: absolute (a relative
    path is taken from ``base``, never from the working directory), and an existing
    regular file (a folder, a FIFO or a device is not data: reading a FIFO would block
    and ``/dev/zero`` never ends)."""
    if not value:
        return value
    path = os.path.normpath(os.path.join(base, os.path.expanduser(value)))
    where = "" if os.path.isabs(os.path.expanduser(value)) else f" (relative to the sweep file's folder {base})"
    try:
        mode = os.stat(path).st_mode         # follows a symlink: what would be read
    except (FileNotFoundError, NotADirectoryError):
        raise ConfigError("", f"no such file: {path}{where}") from None
    except OSError as exc:
        raise ConfigError("", f"cannot read {path}{where} ({exc.strerror or exc})") from None
    if not stat.S_ISREG(mode):
        raise ConfigError("", f"not a regular file: {path}{where} is {_file_kind(mode)}")
    return path


def _file_kind(mode: int) -> str:
    kinds = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
             (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))
    return next((name for is_kind, name in kinds if is_kind(mode)), "a special file")


def path_fields(cls: type) -> frozenset[str]:
    """The names of the ``kind="path"`` fields of the params dataclass ``cls``."""
    return frozenset(f.name for f in dataclasses.fields(cls) if f.metadata.get("kind") == PATH)


def shown_path(path: str, folder: str | os.PathLike | None) -> str:
    """How a report or a written sweep names the data file ``path``: relative to
    ``folder`` (the folder of the sweep that names it), never absolute, so that a shared
    report does not disclose its author's folders; its name alone without a folder."""
    if not path or not os.path.isabs(path):
        return path
    if folder is None:
        return os.path.basename(path)
    try:
        return os.path.relpath(path, folder)
    except ValueError:                        # another drive (Windows): no relative path
        return os.path.basename(path)


def build_params(cls: type, values: Mapping[str, Any] | None, base: str | os.PathLike | None = None):
    """Instantiate the params dataclass ``cls`` from a user mapping.

    Unknown names and bad values raise ConfigError naming the field. ``base``: the
    folder of the sweep file, from which the ``kind="path"`` values are resolved
    (:func:`resolve_path`); None: taken as given (an already resolved plan).
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
            if base is not None and fields[name].metadata.get("kind") == PATH:
                kwargs[name] = resolve_path(kwargs[name], base)
        except ConfigError as err:
            raise ConfigError(f"{name}{err.field}" if err.field.startswith("[") else name,
                              err.problem) from None
    instance = cls(**kwargs)
    validate = getattr(instance, "validate", None)
    if callable(validate):
        validate()
    return instance


_SCALARS = (bool, int, float, str)


def declaration_problem(cls: type) -> str | None:
    """Why the params dataclass ``cls`` breaks the project's convention, naming the
    parameter (None if it keeps it): every field a supported type with a default its own
    checks accept, every number bounded on both sides with a reason (``why``), every
    string choice a word of the label alphabet (:data:`CHOICE_PATTERN`). Checked
    when a plugin registers (:mod:`bench.registry`), so a sweep can never run a value
    the plugin did not bound, nor a declared choice its config's label cannot hold."""
    types = field_types(cls)
    for f in dataclasses.fields(cls):
        tp, meta = types[f.name], f.metadata
        elem = typing.get_args(tp)[0] if typing.get_origin(tp) is tuple else tp
        if elem not in _SCALARS:
            return f"parameter {f.name!r}: type {_type_name(tp)} is not supported (bool, int, float, str or a " \
                   "tuple of one of them)"
        lower, upper = (any(meta.get(k) is not None for k in pair) for pair in (("ge", "gt"), ("le", "lt")))
        if elem in (int, float) and not (lower and upper):
            return f"parameter {f.name!r} is not bounded on both sides (declare it with param(..., ge= or gt=, " \
                   "le= or lt=, why=...))"
        if elem in (int, float) and not meta.get("why"):
            return f"parameter {f.name!r}: its bounds give no reason (param(..., why=...))"
        if meta.get("kind") == PATH and tp is not str:
            return f"parameter {f.name!r}: a path is a str, not a {_type_name(tp)}"
        if f.default is dataclasses.MISSING:
            return f"parameter {f.name!r} has no default"
        odd = [c for c in meta.get("choices") or () if isinstance(c, str) and not CHOICE_PATTERN.match(c)]
        if odd:
            return f"parameter {f.name!r}: choice {show(odd[0])} is not letters, digits, inner spaces or " \
                   "'_.+-' (at most 64): a config label could not name it"
        try:
            check_value(tp, f.default, meta)
        except ConfigError as err:
            return f"parameter {f.name!r}: its default {show(f.default)} breaks its own declaration: {err.problem}"
    return None


def params_as_dict(params: Any, paths_from: str | os.PathLike | None = None) -> dict[str, Any]:
    """Plain mapping of a params instance (tuples as lists), for TOML/JSON; with
    ``paths_from``, its data files named relative to that folder (:func:`shown_path`)."""
    out = {}
    for f in dataclasses.fields(params):
        v = getattr(params, f.name)
        out[f.name] = list(v) if isinstance(v, tuple) else v
    return out if paths_from is None else shown_paths(type(params), out, paths_from)


def shown_paths(cls: type, values: Mapping[str, Any], folder: str | os.PathLike | None) -> dict[str, Any]:
    """``values`` (parameters of the params dataclass ``cls``) with its data files named
    relative to ``folder`` (:func:`shown_path`)."""
    paths = path_fields(cls)
    return {k: shown_path(v, folder) if k in paths and isinstance(v, str) else v for k, v in values.items()}


def bounds_of(cls: type, name: str) -> dict[str, Any]:
    """The declared ``ge``/``gt``/``le``/``lt``/``why`` of field ``name`` (those set)."""
    meta = {f.name: f.metadata for f in dataclasses.fields(cls)}[name]
    return {k: meta[k] for k in ("ge", "gt", "le", "lt", "why") if meta.get(k) is not None}


def describe_params(cls: type) -> list[tuple[str, str, Any, str]]:
    """(name, type, default, doc) of each field, for ``bench list`` and the documentation
    site (:mod:`bench.cli.docs`); the doc ends with the bounds and their reason, or a string's
    choices, when declared."""
    types = field_types(cls)
    out = []
    for f in dataclasses.fields(cls):
        doc = f.metadata.get("doc", "")
        bounds = _describe_bounds(f.metadata)
        if bounds:
            why = f.metadata.get("why")
            doc += f" [{bounds}{': ' + why if why else ''}]"
        if f.metadata.get("choices"):
            doc += f" [one of {', '.join(map(repr, f.metadata['choices']))}]"
        out.append((f.name, _type_name(types[f.name]), f.default, doc))
    return out
