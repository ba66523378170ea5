"""The TOML writer of the resolved plan: ``tomli-w`` (``tomllib`` only reads).

Two things ``tomli_w.dumps`` does not do are kept here, and only these: it
refuses ``None`` (a plan leaves an unset optional key out: dropped here,
recursively), and it writes the C1 control characters (U+0080–U+009F) raw,
which TOML allows but a terminal showing the file obeys; they are escaped
(``\\u0080``) so no control character reaches plan.toml. tomli-w writes every
string as a basic string (``"..."``), the only place such a character can be,
so the escape is always valid there; tomllib reads it back to the same string.
"""

from __future__ import annotations

from typing import Any, Mapping

import tomli_w

_C1 = {i: f"\\u{i:04x}" for i in range(0x80, 0xa0)}


def _without_none(v: Any) -> Any:
    if isinstance(v, Mapping):
        return {k: _without_none(x) for k, x in v.items() if x is not None}
    if isinstance(v, (list, tuple)):
        return [_without_none(x) for x in v]
    return v


def dumps(data: Mapping[str, Any]) -> str:
    """``data`` as TOML text (None values left out, every control character escaped)."""
    return tomli_w.dumps(_without_none(data)).translate(_C1)
