"""What ``bench list`` prints: the presets, then the tasks, scenarios and methods.

The presets are read from their TOML files (``name`` and ``description``) without
importing any plugin. Listing the plugins needs them imported (each registers itself,
docs/architecture.md, 'Plugins'), which costs seconds (NumPy, SciPy, pandas, numba).
So the plugin listing is cached: a text file under the user's cache folder
(``$XDG_CACHE_HOME`` or ``~/.cache``, ``radar-maneuver-bench/``) named by a
fingerprint of everything the listing depends on — this package's version, the
interpreter, the size and modification time of every ``.py`` file of the ``bench``,
``methods``, ``scenarios`` and ``models`` packages, and the ``bench.*`` entry points
with their distributions' versions and source files, and the name and version of every
installed distribution (so installing a missing dependency, e.g. the ``[peers]`` extra,
refreshes a listing that showed its plugin as unavailable). Any edit, install or upgrade
changes the fingerprint, so a stale listing is never shown. An unwritable cache folder
only costs the speed.

The cache folder may sit on a shared file system (``XDG_CACHE_HOME``), so it is used only
when it is a real folder (not a link) owned by the user and writable by no one else
(created 0700); a listing is written to an unpredictable name created exclusively
(``mkstemp``) then renamed into place, and read without following a link; what is read
is printed with its control characters escaped (:mod:`bench.escapes`), so a forged
entry can send no terminal escape sequence.
"""

from __future__ import annotations

import hashlib
import importlib.resources
import importlib.util
import json
import os
import sys
import tomllib
from pathlib import Path

from radarbench.bench.escapes import escape_controls
from radarbench.bench.sweep.user_cache import cache_dir, private_dir, read_own, write_whole

__all__ = ["plugin_listing", "preset_descriptions", "presets"]

#: The packages whose sources the plugin listing depends on.
PACKAGES = ("radarbench.bench", "radarbench.methods", "radarbench.scenarios", "radarbench.models")
ENTRY_POINT_GROUPS = ("bench.tasks", "bench.scenarios", "bench.methods")
#: a paper's claims beside its preset: ``bench/presets/NAME`` + this (:mod:`bench.report.claims`)
CLAIMS_SUFFIX = ".claims.toml"


def presets() -> dict[str, object]:
    """Preset name -> its packaged sweep file (``bench/presets/NAME.toml``; a paper's
    claims beside it, ``NAME.claims.toml``, are not a sweep)."""
    root = importlib.resources.files("radarbench.bench") / "presets"
    return {p.name[:-5]: p for p in sorted(root.iterdir(), key=lambda p: p.name)
            if p.name.endswith(".toml") and not p.name.endswith(CLAIMS_SUFFIX)}


def preset_descriptions() -> list[tuple[str, str]]:
    """(name, description) of every preset, from its sweep file alone."""
    out = []
    for name, path in presets().items():
        try:
            description = str(tomllib.loads(path.read_text(encoding="utf-8")).get("description", ""))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            description = f"(unreadable: {type(exc).__name__})"
        out.append((name, " ".join(description.split())))
    return out


def _tree_stats(root: Path, digest) -> None:
    """Feed the path, size and mtime of every .py file under ``root`` to ``digest``."""
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
        for name in sorted(filenames):
            if name.endswith(".py"):
                st = os.stat(os.path.join(dirpath, name))
                digest.update(f"{dirpath}/{name}:{st.st_size}:{st.st_mtime_ns}\n".encode())


def _package_dir(name: str) -> Path | None:
    """Where a top-level package's sources are, found without importing it."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    if spec is None:
        return None
    if spec.submodule_search_locations:
        return Path(next(iter(spec.submodule_search_locations)))
    return Path(spec.origin).parent if spec.origin else None


def fingerprint() -> str:
    """A digest that changes whenever the plugin listing could."""
    import importlib.metadata

    from radarbench.bench import __version__

    digest = hashlib.sha256(f"{__version__}\n{sys.executable}\n{sys.version}\n".encode())
    for package in PACKAGES:
        where = _package_dir(package)
        digest.update(f"package {package} {where}\n".encode())
        if where is not None:
            _tree_stats(where, digest)
    eps = importlib.metadata.entry_points()
    for group in ENTRY_POINT_GROUPS:
        for ep in sorted(eps.select(group=group), key=lambda e: e.name):
            dist = getattr(ep, "dist", None)
            digest.update(f"{group} {ep.name} {ep.value} {getattr(dist, 'name', '')} "
                          f"{getattr(dist, 'version', '')}\n".encode())
            where = _package_dir(ep.value.split(":")[0].split(".")[0])
            if where is not None and where.name not in ("site-packages", "dist-packages"):
                _tree_stats(where, digest)
    installed = sorted(f"{d.metadata['Name']}=={d.version}" for d in importlib.metadata.distributions())
    digest.update(("\n".join(installed) + "\n").encode())
    return digest.hexdigest()[:32]


def read_cached(path: Path) -> str | None:
    """The cached listing at ``path`` (:func:`read_own`); None if none."""
    data = read_own(path, 1 << 22)
    try:
        text = json.loads(data.decode("utf-8"))["text"] if data is not None else None
    except (ValueError, KeyError, TypeError):
        return None
    return text if isinstance(text, str) else None


def write_cached(path: Path, text: str) -> None:
    """``text`` to ``path``, whole (:func:`write_whole`)."""
    write_whole(path, json.dumps({"text": text}).encode("utf-8"))


def read_table(name: str) -> dict:
    """The JSON object kept as ``name`` in the user's cache folder (:func:`cache_dir`); {}
    when there is none, it is damaged, or the folder is not private (:func:`private_dir`)."""
    folder = cache_dir()
    text = read_cached(folder / name) if private_dir(folder) else None
    try:
        table = json.loads(text) if text else {}
    except ValueError:
        return {}
    return table if isinstance(table, dict) else {}


def write_table(name: str, table: dict, keep: int) -> bool:
    """Keep ``table``'s newest ``keep`` entries as ``name`` in the user's cache folder;
    whether it was written (a folder that is not private or cannot be written: not)."""
    folder = cache_dir()
    if not private_dir(folder):
        return False
    try:
        write_cached(folder / name, json.dumps(dict(list(table.items())[-keep:])))
    except OSError:
        return False
    return True


def _render(verbose: bool) -> str:
    """The plugin listing from the registry (imports every plugin)."""
    from radarbench.bench import registry
    from radarbench.bench.sweep.capabilities import CAPABILITIES
    from radarbench.bench.params import describe_params

    lines = ["tasks:"]
    lines += [f"  {name:<20} {task.summary()}" for name, task in registry.tasks().items()]
    for title, table in (("scenarios", registry.scenarios()), ("methods", registry.methods())):
        lines.append(f"{title}:")
        for name, cls in table.items():
            kind = ", ".join(cls.tasks) if title == "scenarios" else cls.task
            lines.append(f"  {name:<14} {kind:<20} {cls.summary()}")
            if verbose:
                lines += _capability_lines(cls)
                lines += [f"      {pname} ({ptype}, default {default!r}): {doc}"
                          for pname, ptype, default, doc in describe_params(cls.Params)]
    if verbose:
        lines.append("capabilities:")
        lines += [f"  {name:<18} {meaning}" for name, meaning in CAPABILITIES.items()]
    taken_twice = [line for table in registry.collisions().values() for line in table.values()]
    if taken_twice:
        lines.append("names registered twice (a sweep names one by its qualified name):")
        lines += [f"  {line}" for line in taken_twice]
    missing = registry.unavailable()
    if missing:
        lines.append("unavailable:")
        lines += [f"  {u.source:<14} {u.error}" for u in missing]
    return "\n".join(lines)


def _capability_lines(cls) -> list[str]:
    """A plugin's capabilities as ``bench list -v`` shows them (nothing when it declares none)."""
    declared = {"provides": getattr(cls, "provides", ()), "needs": getattr(cls, "needs", ()),
                "handles": getattr(cls, "handles", ())}
    return [f"      {what}: {', '.join(sorted(names))}" for what, names in declared.items() if names]


def _names_file(fingerprint_: str) -> Path | None:
    folder = cache_dir()
    return folder / f"names-{fingerprint_}.json" if private_dir(folder) else None


def cached_names(fingerprint_: str) -> dict | None:
    """The registry's names (:func:`bench.registry.names`) as a process that imported the
    plugins kept them under ``fingerprint_`` (:func:`fingerprint`, taken before it imported
    them), so a sweep's plugin names are checked without the plugins; None when none did."""
    path = _names_file(fingerprint_)
    text = read_cached(path) if path is not None else None
    try:
        table = json.loads(text) if text else None
    except ValueError:
        return None
    ok = isinstance(table, dict) and isinstance(table.get("unavailable"), list) and all(
        isinstance(table.get(kind), dict) and isinstance(table[kind].get("claimed"), list)
        and isinstance(table[kind].get("named"), list) for kind in ("method", "scenario"))
    return table if ok else None


def keep_names(fingerprint_: str) -> None:
    """Keep the registry's names under ``fingerprint_`` (:func:`fingerprint`, taken before
    this process imported the plugins) for :func:`cached_names`; those of earlier sources go."""
    from radarbench.bench import registry

    path = _names_file(fingerprint_)
    table = registry.names() if path is not None and not path.exists() else None
    if table is None:
        return
    try:
        write_cached(path, json.dumps(table))
        for old in path.parent.glob("names-*.json"):
            if old != path:
                old.unlink(missing_ok=True)
    except OSError:
        pass


def plugin_listing(verbose: bool = False) -> str:
    """The tasks, scenarios and methods as ``bench list`` prints them (cached, see above).

    A process that has already imported the plugins (or registered one in-process, as
    tests do) lists its registry as it is, without the cache."""
    from radarbench.bench import registry

    folder = None if registry.discovered() else cache_dir()
    path = folder / f"list-{fingerprint()}{'-v' if verbose else ''}.json" \
        if folder is not None and private_dir(folder) else None
    text = read_cached(path) if path is not None else None
    if text is None:
        text = _render(verbose)
        if path is not None:
            try:
                write_cached(path, text)
                for old in path.parent.glob("list-*.json"):      # listings of earlier sources
                    if not old.name.startswith(path.name.split("-v")[0].removesuffix(".json")):
                        old.unlink(missing_ok=True)
            except OSError:
                pass
    return escape_controls(text)
