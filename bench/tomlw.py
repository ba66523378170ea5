"""A minimal TOML writer for the resolved plan (``tomllib`` only reads).

Supports what a plan holds: strings, bools, ints, finite floats, arrays of
those (nested arrays too), tables and arrays of tables.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

_BARE_KEY = set("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-")
#: Escaped in strings: what TOML forbids raw (C0 controls, DEL) and the C1 controls, so
#: no control character (a terminal escape, a NUL) reaches the file; tomllib reads the
#: escapes back to the same string.
_ESCAPES = {**{i: f"\\u{i:04x}" for i in [*range(0x20), *range(0x7f, 0xa0)]},
            0x08: "\\b", 0x09: "\\t", 0x0A: "\\n", 0x0C: "\\f", 0x0D: "\\r",
            ord('"'): '\\"', ord("\\"): "\\\\"}


def _string(s: str) -> str:
    """A TOML basic string holding ``s`` exactly, every control character escaped."""
    return '"' + s.translate(_ESCAPES) + '"'


def _key(k: str) -> str:
    return k if k and set(k) <= _BARE_KEY else _string(k)


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"TOML cannot hold {v!r}")
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"TOML cannot hold {type(v).__name__}")


def _is_table_array(v: Any) -> bool:
    return isinstance(v, (list, tuple)) and bool(v) and all(isinstance(x, Mapping) for x in v)


def dumps(data: Mapping[str, Any], _prefix: str = "") -> str:
    lines: list[str] = []
    nested: list[tuple[str, Any]] = []
    for k, v in data.items():
        if isinstance(v, Mapping) or _is_table_array(v):
            nested.append((k, v))
        elif v is not None:
            lines.append(f"{_key(k)} = {_value(v)}")
    for k, v in nested:
        name = f"{_prefix}{_key(k)}"
        if isinstance(v, Mapping):
            lines += ["", f"[{name}]", dumps(v, name + ".").rstrip("\n")]
        else:
            for item in v:
                # inline the nested tables of an array element: simpler and still valid
                body = [f"{_key(ik)} = {_value(iv)}" for ik, iv in item.items() if iv is not None]
                lines += ["", f"[[{name}]]", *body]
    return "\n".join(line for line in lines if line is not None).lstrip("\n") + "\n"
