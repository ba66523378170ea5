"""Text that is not ours, made harmless to show: its control characters as escapes.

A sweep's description, a plugin's docstring or error text, a cached listing: any of them
may hold terminal escape sequences (ESC, the C1 CSI), NULs, or bidirectional formatting
characters that reorder what a reader sees ("Trojan Source"). Written as Python-style
escapes (``\\x1b``, ``\\u202e``) they are shown, never obeyed. This module imports nothing
heavy: ``bench list`` prints its cached listing through it (:mod:`bench.sweep.listing`);
:mod:`bench.markdown` builds its Markdown escaping on it.
"""

from __future__ import annotations

import re

#: Bidirectional formatting characters, and the line and paragraph separators.
_BIDI = [0x061C, 0x200E, 0x200F, 0x2028, 0x2029, *range(0x202A, 0x202F), *range(0x2066, 0x206A)]
#: C0 controls but newline and tab, DEL, the C1 controls and the characters above.
_CONTROLS = {i: repr(chr(i))[1:-1] for i in [*range(0x20), *range(0x7f, 0xa0), *_BIDI] if chr(i) not in "\n\t"}
#: The same and newline, tab: for text kept on one line.
_CONTROLS_INLINE = {**_CONTROLS, ord("\n"): "\\n", ord("\t"): "\\t"}


def _finder(table: dict[int, str]) -> re.Pattern:
    return re.compile("[" + "".join(re.escape(chr(i)) for i in sorted(table)) + "]")


#: One character class per table: a regular-expression scan finds the few characters to
#: replace about ten times faster than ``str.translate`` visits every one (a report's
#: HTML embeds megabytes of plotly.js), with the same result.
_FIND = {False: (_finder(_CONTROLS), _CONTROLS), True: (_finder(_CONTROLS_INLINE), _CONTROLS_INLINE)}


def escape_controls(text: str, inline: bool = False) -> str:
    """``text`` with its control and bidi characters written as escapes; newline and tab
    kept unless ``inline``."""
    find, table = _FIND[bool(inline)]
    return find.sub(lambda m: table[ord(m.group())], text)


__all__ = ["escape_controls"]
