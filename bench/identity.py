"""What produced a stored result: each config's code, data files and numeric libraries
(docs/architecture.md, 'Identities').

A config's **identity** is a short hash of

* its plugin's **code**: the source of the plugin's module and of every module it
  imports, transitively, from its own code — for a plugin beside the harness (the
  built-ins: ``methods/tbd/dp_tbd.py`` with the ``models/`` and ``methods/tbd/`` modules it
  imports) the modules under the same folder of ``sys.path``, installed packages left out;
  for a plugin installed from a distribution, the modules of that distribution's packages,
  and its name and version; the harness itself (``bench/``) left out of both;
* the content of the **data files** it reads (:meth:`bench.core.Component.data_files`:
  by default the values of its ``kind="path"`` parameters);
* the versions of the numeric libraries (:data:`LIBRARIES`).

The driver computes the identities once per run (sources are scanned for their
imports, never imported again); the store stamps each unit with its scenario config's
identity and each (unit, method config) run with its method config's
(:mod:`bench.store`), and a run re-computes exactly the results whose identity changed.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import importlib.util
import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path

#: the libraries whose versions belong to every identity (their numerics are the results')
LIBRARIES = ("numpy", "scipy", "numba")
#: hex digits of a shown identity
SHORT = 12
_HARNESS = Path(__file__).resolve().parent
_INSTALLED = {"site-packages", "dist-packages"}


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:SHORT]


def file_digest(path: str | Path) -> str:
    """The content hash of a file, read in blocks (a data file may be large)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:SHORT]


@functools.lru_cache(maxsize=None)
def library_versions() -> dict[str, str]:
    out = {}
    for name in LIBRARIES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


@functools.lru_cache(maxsize=None)
def _module_file(name: str) -> Path | None:
    """The source file of module ``name`` (imported or not), None if it has none."""
    module = sys.modules.get(name)
    origin = getattr(module, "__file__", None) if module is not None else None
    if origin is None:
        try:
            spec = importlib.util.find_spec(name)
        except Exception:       # noqa: BLE001 - finding "a.b.c" imports a.b, which may fail (a plugin's
            return None         # missing extra raises PluginError): c is then a name in it, not a module
        origin = spec.origin if spec is not None else None
    return Path(origin).resolve() if origin and origin.endswith(".py") else None


_IMPORT = re.compile(r"^[ \t]*import[ \t]+([\w. \t,]+)", re.M)
_FROM = re.compile(r"^[ \t]*from[ \t]+(\.*)([\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n#;]*)", re.M)


def _names(clause: str) -> list[str]:
    """``a as b, c`` (parenthesised, commented, over several lines) -> ["a", "c"]."""
    clause = re.sub(r"#[^\n]*", "", clause).strip("() \t\n")
    return [part.split()[0] for part in clause.split(",") if part.split() and part.split()[0] != "*"]


def imported_names(source: str | bytes, module: str, is_package: bool = False) -> set[str]:
    """Absolute dotted names the source of ``module`` imports, at any indentation
    (``from a.b import c``: ``a.b`` and ``a.b.c``, since ``c`` may be a module; relative
    imports resolved). Statements are found line by line, not parsed: ten times faster
    than :mod:`ast` (a run computes every plugin's identity), and a docstring line that
    reads like an import at worst widens an identity."""
    text = source.decode("utf-8", "replace") if isinstance(source, bytes) else source
    text = text.replace("\\\n", " ")
    package = module if is_package else module.rpartition(".")[0]
    names = {name for match in _IMPORT.finditer(text) for name in _names(match.group(1))}
    for dots, base, clause in _FROM.findall(text):
        if dots:
            parts = package.split(".")
            parent = ".".join(parts[:len(parts) - len(dots) + 1])
            base = f"{parent}.{base}" if base else parent
        names.add(base)
        names.update(f"{base}.{name}" for name in _names(clause))
    return names


@dataclass(frozen=True)
class Scope:
    """Which modules are a plugin's own code: under ``root`` (not the harness, not an
    installed package), or the packages of its distribution."""

    root: Path | None
    packages: frozenset[str] = frozenset()

    def owns(self, name: str, path: Path) -> bool:
        if path.is_relative_to(_HARNESS):
            return False
        if self.packages:
            return name.split(".")[0] in self.packages
        return self.root is not None and path.is_relative_to(self.root) and not _INSTALLED & set(path.parts)


@functools.lru_cache(maxsize=1)
def _package_owners() -> dict[str, list[str]]:
    """Top-level package -> the distributions installing it (a scan of every one: once)."""
    return importlib.metadata.packages_distributions()


def _distribution(top: str, path: Path) -> tuple[str, frozenset[str]]:
    """("name version", its top-level packages) of the installed distribution holding
    package ``top`` at ``path``; ("", {}) for code that is not installed (a checkout)."""
    if not _INSTALLED & set(path.parts):
        return "", frozenset()
    owners = _package_owners()
    for name in owners.get(top) or []:
        try:
            dist = importlib.metadata.distribution(name)
        except importlib.metadata.PackageNotFoundError:
            continue
        tops = frozenset(t for t, ds in owners.items() if name in ds)
        return f"{dist.metadata['Name']} {dist.version}", tops or frozenset({top})
    return "", frozenset({top})


def _read_module(name: str, file: Path) -> tuple[str, frozenset[str]]:
    """(source hash, the modules it may import) of module ``name``; scanned again only
    when the file changed (an edit between two runs of one process is seen)."""
    st = file.stat()
    return _scan_module(name, file, st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=None)
def _scan_module(name: str, file: Path, _mtime_ns: int, _size: int) -> tuple[str, frozenset[str]]:
    data = file.read_bytes()
    imported = imported_names(data, name, file.name == "__init__.py")
    # importing a.b.c runs a/__init__.py and a/b/__init__.py too
    return digest(data), frozenset(".".join(n.split(".")[:i]) for n in imported if n for i in range(1, n.count(".") + 2))


def _search_folder(module: str, path: Path) -> Path:
    """The folder of sys.path the plugin's top-level package (or module) lives in, found from
    the top-level package's own file: a package may hold folders that are not in it (in a
    checkout, radarbench's subpackages are the folders beside it; radarbench/__init__.py)."""
    top = module.split(".")[0]
    top_file = path if top == module else _module_file(top)
    if top_file is None:                      # a namespace package: no file of its own
        return path.parents[module.count(".") + (path.name == "__init__.py")]
    return top_file.parents[1] if top_file.name == "__init__.py" else top_file.parent


@dataclass(frozen=True)
class CodeIdentity:
    hash: str
    distribution: str                        # "name version" of an installed plugin, else ""
    modules: tuple[tuple[str, str], ...]     # (module, its source hash), sorted


def code_identity(module: str) -> CodeIdentity:
    """The code identity of a plugin whose class lives in ``module`` (see the module doc)."""
    path = _module_file(module)
    if path is None:
        return CodeIdentity("unknown", "", ())
    top = module.split(".")[0]
    dist, packages = _distribution(top, path)
    scope = Scope(_search_folder(module, path), packages)
    sources: dict[str, str] = {}
    todo = [(module, path)]
    while todo:
        name, file = todo.pop()
        if name in sources:
            continue
        sources[name], imported = _read_module(name, file)
        for other in imported - set(sources):
            top_file = _module_file(other.split(".")[0])       # never resolve inside a library
            if top_file is None or not scope.owns(other.split(".")[0], top_file):
                continue
            other_file = _module_file(other)
            if other_file is not None and scope.owns(other, other_file):
                todo.append((other, other_file))
    modules = tuple(sorted(sources.items()))
    return CodeIdentity(digest(json.dumps([dist, modules]).encode()), dist, modules)


def config_identity(cls: type, params, code: CodeIdentity | None = None) -> dict:
    """The identity of one config of plugin ``cls`` with ``params``: ``identity`` (the
    short hash), ``code``, ``distribution``, ``modules`` and ``data`` (file -> hash)."""
    code = code or code_identity(cls.__module__)
    data = {str(p): file_digest(p) for p in cls().data_files(params)}
    versions = dict(library_versions())
    whole = json.dumps([code.hash, data, versions], sort_keys=True).encode()
    return {"identity": digest(whole), "code": code.hash, "distribution": code.distribution,
            "modules": dict(code.modules), "data": data, "versions": versions}


def plan_identities(plan) -> dict[str, dict[str, dict]]:
    """``{"scenarios": {label: identity}, "methods": {label: identity}}`` of a plan's configs."""
    from radarbench.bench import registry
    codes: dict[str, CodeIdentity] = {}

    def of(cls: type, params) -> dict:
        if cls.__module__ not in codes:
            codes[cls.__module__] = code_identity(cls.__module__)
        return config_identity(cls, params, codes[cls.__module__])

    return {"scenarios": {sc.label: of(registry.get_scenario(sc.name), sc.params) for sc in plan.scenarios},
            "methods": {m.label: of(registry.get_method(m.name), m.params) for m in plan.methods}}


#: where a run folder keeps the results its last run replaced (a store of its own)
PREVIOUS = "previous"


def _old_identities(store, units: list[str], runs: dict[str, set[str]]) -> dict[str, dict[str, list[str]]]:
    """Config label -> the identities (or "unrecorded") of the results about to be replaced:
    the scenario configs of the units replaced whole, the method configs of the other runs."""
    out: dict[str, dict[str, set]] = {"scenarios": {}, "methods": {}}
    for key in units:
        scenario, identity = store.db.execute("SELECT scenario, identity FROM units WHERE key=?", (key,)).fetchone()
        out["scenarios"].setdefault(scenario, set()).add(identity or "unrecorded")
    for key, methods in runs.items():
        for method in methods:
            (identity,) = store.db.execute("SELECT identity FROM runs WHERE unit=? AND method=?",
                                           (key, method)).fetchone()
            out["methods"].setdefault(method, set()).add(identity or "unrecorded")
    return {kind: {label: sorted(ids) for label, ids in table.items()} for kind, table in out.items()}


def set_aside_changed(store, plan, out_dir: Path, quiet: bool = False) -> dict[str, set[str]]:
    """Bind ``store`` to the identities of ``plan``'s configs now; move the stored results
    they no longer match into ``out_dir/previous/`` (:meth:`bench.store.Store.set_aside`),
    saying so in one line; returns the (unit -> method configs) runs to compute again (the
    units set aside whole are simply no longer stored)."""
    from radarbench.bench import runfolder
    from radarbench.bench.store import Store

    store.use_identities(plan_identities(plan))
    units, runs = store.stale()
    if not units and not runs:
        return {}
    old = _old_identities(store, units, runs)
    folder = runfolder.folder_for(Path(out_dir) / PREVIOUS)
    if runfolder.read_manifest(Path(out_dir)) is not None:
        runfolder.claim(Path(out_dir), [f"{PREVIOUS}/{name}" for name in runfolder.STORE_FILES])
    previous = Store(folder / runfolder.STORE)
    try:
        store.set_aside(units, runs, previous)
    finally:
        previous.close()
    store.set_meta("replaced", json.dumps(old))
    if not quiet:
        print(_changed_line(old, store.stamps, len(units), sum(map(len, runs.values())), Path(out_dir)),
              file=sys.stderr)
    return runs


def _changed_line(old: dict, new: dict, units: int, runs: int, out_dir: Path) -> str:
    """One line: which configs re-run, from which identity to which, and where the old results are."""
    changes = [f"{label} {'/'.join(ids)} -> {new[kind].get(label, '?')}"
               for kind in ("scenarios", "methods") for label, ids in old[kind].items()]
    shown = "; ".join(changes[:4]) + (f"; and {len(changes) - 4} more" if len(changes) > 4 else "")
    why = "stored without a recorded identity (by an earlier bench)" if all(
        ids == ["unrecorded"] for table in old.values() for ids in table.values()) else "code or data changed"
    what = " and ".join(part for part in (f"{units} units" if units else "",
                                          f"{runs} (unit, method config) runs" if runs else "") if part)
    return (f"{why}: re-running {what} ({shown}); the results they replace are in {out_dir / PREVIOUS} "
            f"(bench compare {out_dir / PREVIOUS} {out_dir})")
