"""Entity paths of a recording: readable names for configs, SNR levels and trials.

Every trial lives under ``/{scenario}/snr_{±NN}dB/trial_{NNN}``; its method
configs under ``.../{method}`` where ``{method}`` is :func:`entity_name` of the
config label, made unique by :func:`method_entity_names`. What lies under
them is the business of the harness (truth, measurements, traces) and of
each task (docs/architecture.md, 'Recordings').

SNR parts: ``snr_+05dB``, ``snr_-05dB``, ``snr_+02p5dB`` (non-integer SNR; ``p``
stands for the decimal point), ``null`` for null-hypothesis trials. Rerun keeps
paths in an escaped canonical form in which ``+`` becomes ``\\+``
(``/cv-turn-cv/snr_\\+05dB/trial_000``); the viewer shows the readable form.
:func:`rerun_path` converts a readable path to the canonical one, which is
what :class:`rerun.chunk.RrdReader` returns.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Iterable

__all__ = ["entity_name", "entity_root", "method_entity_names", "rerun_path", "snr_part"]

_SEPARATORS = re.compile(r"[\[\](){},;\s]+")
_UNSAFE = re.compile(r"[^A-Za-z0-9_.\-]+")


def entity_name(label: str) -> str:
    """A readable entity-path part for a method config label.

    Rerun leaves only ``A-Z a-z 0-9 _ - .`` unescaped in entity paths; any
    other character is stored backslash-escaped (``[`` -> ``\\[``), which is
    unreadable and error-prone in blueprints and queries. So: ``=`` becomes
    ``-``, brackets, commas and whitespace become ``_`` (runs collapse, ends
    are trimmed), anything else becomes ``-``::

        cumulant[window=32]                  -> cumulant_window-32
        innovation[window=5, variant=fading] -> innovation_window-5_variant-fading

    Not injective in general (``a[b_c=1]`` and ``a_b[c=1]`` meet), so a set of
    labels is named with :func:`method_entity_names`, which disambiguates.
    """
    name = _SEPARATORS.sub("_", str(label).replace("=", "-"))
    name = _UNSAFE.sub("-", name).strip("_")
    # A leading "__" would also be trimmed: rerun reserves it (/__properties).
    return name or "unnamed"


def method_entity_names(labels: Iterable[str], reserved: Iterable[str] = ()) -> dict[str, str]:
    """Injective label -> entity name map for the labels of one parent entity.

    Labels whose :func:`entity_name` collides (with each other or with a
    ``reserved`` sibling name) get a short stable hash of the label appended,
    so the mapping never depends on the order of the labels.
    """
    labels = list(dict.fromkeys(str(x) for x in labels))
    reserved = set(reserved)
    base = {label: entity_name(label) for label in labels}
    counts: dict[str, int] = {}
    for name in base.values():
        counts[name] = counts.get(name, 0) + 1
    out = {}
    for label, name in base.items():
        if counts[name] > 1 or name in reserved:
            name = f"{name}-{hashlib.sha1(label.encode('utf-8')).hexdigest()[:6]}"
        out[label] = name
    return out


def snr_part(snr_db: float | None) -> str:
    """``snr_+05dB`` / ``snr_-05dB`` / ``snr_+02p5dB``; ``null`` for None."""
    if snr_db is None:
        return "null"
    x = round(float(snr_db), 6)
    if not math.isfinite(x):
        raise ValueError(f"snr_db must be finite or None, got {snr_db!r}")
    sign = "-" if x < 0 else "+"  # round() turned -0.0-ish values into 0 -> "+"
    whole, _, frac = f"{abs(x):.6f}".rstrip("0").rstrip(".").partition(".")
    return f"snr_{sign}{int(whole):02d}{'p' + frac if frac else ''}dB"


def entity_root(scenario: str, snr_db: float | None, trial: int) -> str:
    """Readable root entity of one trial, e.g. ``/cv-turn-cv/snr_+05dB/trial_003``."""
    if int(trial) < 0:
        raise ValueError(f"trial must be >= 0, got {trial!r}")
    return f"/{entity_name(scenario)}/{snr_part(snr_db)}/trial_{int(trial):03d}"


def rerun_path(path: str) -> str:
    """Rerun's canonical (escaped) form of a readable path made by this module.

    ``/cv-turn-cv/snr_+05dB/trial_000`` -> ``/cv-turn-cv/snr_\\+05dB/trial_000``.
    This is the form :class:`rerun.chunk.RrdReader` reports, and the one this
    module passes to the SDK (so rerun never has to guess).
    """
    import rerun as rr

    parts = [p for p in path.split("/") if p]
    return "/" + "/".join(rr.escape_entity_path_part(p) for p in parts)
